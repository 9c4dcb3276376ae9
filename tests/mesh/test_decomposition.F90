#include "assertions.h"
!> The decomposition covers every element exactly once with face-connected
!> subdomains, is identical on every rank, and the rank mapping covers every
!> subdomain exactly once, for box and METIS decompositions and block and METIS
!> mappings. node_subdomains and subdomain_graph against a brute-force count.
!> Box decompositions hold no array of global size: their index-arithmetic
!> answers (subdomain_of_element, subdomain_element_gids, subdomain_nelements,
!> node_subdomain_list, subdomain_graph) equal those of element arrays built
!> here the METIS way. METIS decompositions are distributed: each rank knows
!> exactly the elements of its subdomains and those sharing a node with them
!> (checked against the same partition made on one rank, MPI_COMM_SELF), the
!> element lists of its own subdomains only, and answers node_subdomains for
!> every node of its subdomains.
program test_decomposition
  use kinds, only: dp, ip, MPI_INT_IP
  use params, only: params_t, default_params
  use box_mesh, only: box_mesh_t, box_mesh_init
  use decomposition, only: decomposition_t, build_decomposition, split_into_components, subdomain_graph
  use mpi_f08, only: MPI_Init, MPI_COMM_WORLD, MPI_COMM_SELF, MPI_Comm_rank, MPI_Comm_size, MPI_Bcast, &
                     MPI_Allreduce, MPI_SUM
  use assertions, only: assert_true, assert_equal, test_finish
  implicit none
  integer :: ierr, rank, nranks

  call MPI_Init(ierr)
  call MPI_Comm_rank(MPI_COMM_WORLD, rank, ierr)
  call MPI_Comm_size(MPI_COMM_WORLD, nranks, ierr)

  call check_case([2, 2, 2], [2, 2, 2], 'box', 'block')
  call check_case([3, 1, 2], [2, 3, 1], 'box', 'metis')
  call check_case([4, 1, 1], [1, 1, 1], 'box', 'metis')
  call check_case([5, 1, 1], [1, 2, 1], 'box', 'block')
  call check_case([2, 2, 2], [3, 3, 3], 'metis', 'block')
  call check_case([3, 2, 1], [2, 2, 3], 'metis', 'metis')
  call check_case([2, 2, 2], [2, 2, 2], 'metis', 'metis')
  call check_case([4, 4, 1], [2, 2, 2], 'metis', 'block')
  call check_cross_point()
  call check_split()
  call test_finish()

contains

  subroutine check_case(nsub, nel, method, mapping)
    integer, intent(in) :: nsub(3), nel(3)
    character(len=*), intent(in) :: method, mapping
    type(params_t) :: p
    type(decomposition_t) :: dec, whole
    type(box_mesh_t) :: m
    character(len=80) :: what
    integer(ip) :: ne, nn, n, e, s, g, k, i, r
    integer(ip), allocatable :: root_copy(:), counts(:), mark(:), total(:), owned(:), ids(:), &
                                xadj(:), adjncy(:), seen(:), esub(:), ptr(:), list(:)
    integer(ip) :: list8(8), nlist
    logical, allocatable :: holds(:, :), adjacent(:, :), known(:), mine(:), near_mine(:)
    integer(ip), allocatable :: seen_all(:)
    integer(ip) :: near(27), nnear
    logical :: ok
    integer(ip) :: nodes(8), ijk(3)

    write (what, '(a,1x,a,a,3i2,a,3i2,a,i0)') trim(method), trim(mapping), ' nsub', nsub, ' nel', nel, &
      ' np ', nranks
    p = default_params()
    p%mesh%nsub = nsub
    p%mesh%nel = nel
    p%mesh%decomposition = method
    p%mesh%mapping = mapping
    call build_decomposition(p, MPI_COMM_WORLD, dec)
    call box_mesh_init(m, int(nsub, ip), int(nel, ip), p%mesh%lengths, 0.0_dp, 1_ip)
    ne = m%num_elements()
    nn = m%num_nodes()
    n = dec%nsubdomains
    call assert_true(n >= 1, trim(what)//': at least one subdomain', HERE)
    ! the METIS-style arrays, built here: esub(e) = subdomain of element e, and
    ! the element lists ptr/list by subdomain (ascending gids)
    allocate (esub(ne))
    if (method == 'box') then
      call assert_true(.not. allocated(dec%known_gids) .and. .not. allocated(dec%subdomain_elements) &
                       .and. .not. allocated(dec%subdomain_element_ptr), &
                       trim(what)//': no array of global size for box', HERE)
      call assert_equal(int(product(nsub), ip), n, trim(what)//': box subdomain count', HERE)
      do e = 1, ne
        ijk = m%element_ijk(e)/int(nel, ip)
        esub(e) = 1 + ijk(1) + nsub(1)*(ijk(2) + nsub(2)*ijk(3))
      end do
    else
      ! the same partition made by one rank alone knows every element
      call build_decomposition(p, MPI_COMM_SELF, whole)
      call assert_equal(ne, int(size(whole%known_gids), ip), trim(what)//': one rank knows every element', HERE)
      call assert_equal(n, whole%nsubdomains, trim(what)//': same subdomain count as on one rank', HERE)
      esub = whole%known_subdomain
    end if
    call assert_true(all(esub >= 1 .and. esub <= n), trim(what)//': ids in 1..N', HERE)
    allocate (ptr(n + 1), list(ne))
    ptr = 0
    do e = 1, ne
      ptr(esub(e) + 1) = ptr(esub(e) + 1) + 1
    end do
    ptr(1) = 1
    do s = 1, n
      ptr(s + 1) = ptr(s + 1) + ptr(s)
    end do
    k = 0
    do s = 1, n
      do e = 1, ne
        if (esub(e) /= s) cycle
        k = k + 1
        list(k) = e
      end do
    end do
    ! mine(e): e is in a subdomain of this rank; known(e): e is mine or shares a node with one of mine
    allocate (mine(ne), known(ne), near_mine(ne))
    mine = .false.
    do s = 1, size(dec%local_subdomains)
      mine(list(ptr(dec%local_subdomains(s)):ptr(dec%local_subdomains(s) + 1) - 1)) = .true.
    end do
    do e = 1, ne
      call m%elements_near(m%element_ijk(e), -1_ip, 1_ip, near, nnear)
      near_mine(e) = any(mine(near(1:nnear)))
    end do
    if (method == 'metis') then
      known = .false.
      known(dec%known_gids) = .true.
      call assert_true(size(dec%known_gids) == count(known) .and. all(known .eqv. near_mine), &
                       trim(what)//': known elements = mine and those sharing a node with them', HERE)
      call assert_true(all(dec%known_gids(2:) > dec%known_gids(:size(dec%known_gids) - 1)), &
                       trim(what)//': known gids ascending', HERE)
      call assert_equal(int(size(dec%local_subdomains) + 1, ip), int(size(dec%subdomain_element_ptr), ip), &
                        trim(what)//': element lists of the local subdomains only', HERE)
    else
      known = .true.
    end if

    ! the procedures against the arrays
    ok = .true.
    do e = 1, ne
      if (known(e)) then
        ok = ok .and. dec%subdomain_of_element(e) == esub(e)
      else
        ok = ok .and. dec%subdomain_of_element(e) == 0
      end if
    end do
    call assert_true(ok, trim(what)//': subdomain_of_element = element_subdomain array (0 if unknown)', HERE)
    ok = .true.
    do s = 1, n
      ids = dec%subdomain_element_gids(s)
      ok = ok .and. dec%subdomain_nelements(s) == ptr(s + 1) - ptr(s)
      if (method == 'metis' .and. dec%subdomain_rank(s) /= rank) then
        ok = ok .and. size(ids) == 0
        cycle
      end if
      ok = ok .and. size(ids, kind=ip) == ptr(s + 1) - ptr(s)
      if (ok) ok = all(ids == list(ptr(s):ptr(s + 1) - 1))
    end do
    call assert_true(ok, trim(what)//': subdomain_element_gids, subdomain_nelements = element lists', HERE)

    ! identical on every rank
    root_copy = esub
    call MPI_Bcast(root_copy, ne, MPI_INT_IP, 0, MPI_COMM_WORLD, ierr)
    call assert_true(all(root_copy == esub), trim(what)//': same elements on all ranks', HERE)
    root_copy = dec%subdomain_rank
    call MPI_Bcast(root_copy, n, MPI_INT_IP, 0, MPI_COMM_WORLD, ierr)
    call assert_true(all(root_copy == dec%subdomain_rank), trim(what)//': same mapping on all ranks', HERE)

    ! element lists: every element exactly once (over the ranks' own subdomains); none empty
    allocate (counts(n), seen(ne), seen_all(ne))
    counts = 0
    seen = 0
    do s = 1, n
      if (dec%subdomain_rank(s) /= rank) cycle
      ids = dec%subdomain_element_gids(s)
      seen(ids) = seen(ids) + 1
      counts(s) = size(ids, kind=ip)
    end do
    call MPI_Allreduce(seen, seen_all, int(ne), MPI_INT_IP, MPI_SUM, MPI_COMM_WORLD, ierr)
    call assert_true(all(seen_all == 1), trim(what)//': every element listed exactly once', HERE)
    call assert_true(all(pack(counts, dec%subdomain_rank == rank) > 0), trim(what)//': no empty subdomain', HERE)
    call assert_true(all(ptr(2:) > ptr(:n)), trim(what)//': no empty subdomain (all)', HERE)
    call assert_true(all(face_connected(m, esub, n)), trim(what)//': face-connected', HERE)

    ! mapping: ranks in range, each rank owns >= 1, each subdomain owned exactly once
    call assert_equal(int(nranks, ip), dec%nranks, trim(what)//': nranks', HERE)
    call assert_true(all(dec%subdomain_rank >= 0 .and. dec%subdomain_rank < nranks), &
                     trim(what)//': ranks in range', HERE)
    call assert_true(size(dec%local_subdomains) >= 1, trim(what)//': this rank owns a subdomain', HERE)
    ok = all(dec%subdomain_rank(dec%local_subdomains) == rank)
    do k = 2, size(dec%local_subdomains)
      ok = ok .and. dec%local_subdomains(k - 1) < dec%local_subdomains(k)
    end do
    call assert_true(ok, trim(what)//': local_subdomains ascending and mine', HERE)
    allocate (mark(n), total(n))
    mark = 0
    mark(dec%local_subdomains) = 1
    call MPI_Allreduce(mark, total, n, MPI_INT_IP, MPI_SUM, MPI_COMM_WORLD, ierr)
    call assert_true(all(total == 1), trim(what)//': every subdomain owned exactly once', HERE)
    if (mapping == 'block') then
      allocate (owned(0:nranks - 1))
      owned = 0
      do s = 1, n
        owned(dec%subdomain_rank(s)) = owned(dec%subdomain_rank(s)) + 1
      end do
      ok = .true.
      do s = 2, n
        ok = ok .and. dec%subdomain_rank(s - 1) <= dec%subdomain_rank(s)
      end do
      call assert_true(ok, trim(what)//': block mapping contiguous', HERE)
      call assert_true(maxval(owned) - minval(owned) <= 1, trim(what)//': block sizes differ by <= 1', HERE)
    end if

    ! node_subdomains against a brute-force count over elements
    allocate (holds(nn, n))
    holds = .false.
    do e = 1, ne
      nodes = m%element_nodes(e)
      holds(nodes, esub(e)) = .true.
    end do
    ok = .true.
    do g = 1, nn
      ! METIS: nodes of this rank's subdomains
      if (method == 'metis' .and. .not. any(holds(g, dec%local_subdomains))) cycle
      ids = dec%node_subdomains(g)
      ok = ok .and. size(ids) == count(holds(g, :))
      if (.not. ok) exit
      ok = ok .and. all(holds(g, ids))
      do i = 2, size(ids)
        ok = ok .and. ids(i - 1) < ids(i)
      end do
      call dec%node_subdomain_list(g, list8, nlist)
      ok = ok .and. nlist == size(ids, kind=ip)
      if (ok) ok = all(list8(1:nlist) == ids)
    end do
    call assert_true(ok, trim(what)//': node_subdomains, node_subdomain_list = brute force, sorted', HERE)

    ! subdomain graph: s, t neighbours iff they share a node
    allocate (adjacent(n, n))
    adjacent = .false.
    do g = 1, nn
      do s = 1, n
        if (.not. holds(g, s)) cycle
        where (holds(g, :)) adjacent(s, :) = .true.
      end do
    end do
    call subdomain_graph(dec, xadj, adjncy)
    ok = size(xadj) == n + 1 .and. xadj(1) == 1 .and. xadj(n + 1) == size(adjncy) + 1
    do s = 1, n
      if (.not. ok) exit
      ok = ok .and. count(adjacent(s, :)) - 1 == xadj(s + 1) - xadj(s)
      do k = xadj(s), xadj(s + 1) - 1
        r = adjncy(k)
        ok = ok .and. r /= s .and. adjacent(s, r)
        if (k > xadj(s)) ok = ok .and. adjncy(k - 1) < r
      end do
    end do
    call assert_true(ok, trim(what)//': subdomain_graph = shared nodes', HERE)
  end subroutine check_case

  !> Each subdomain's elements form one face-connected set (own BFS).
  function face_connected(m, esub, n) result(ok)
    type(box_mesh_t), intent(in) :: m
    integer(ip), intent(in) :: esub(:), n
    logical :: ok(n)
    logical, allocatable :: visited(:)
    integer(ip), allocatable :: stack(:)
    integer(ip) :: s, e, top, x, d, nb(3), y, ncomp(n)
    integer :: sgn
    allocate (visited(size(esub)), stack(size(esub)))
    visited = .false.
    ncomp = 0
    do e = 1, size(esub)
      if (visited(e)) cycle
      s = esub(e)
      ncomp(s) = ncomp(s) + 1
      visited(e) = .true.
      top = 1
      stack(1) = e
      do while (top > 0)
        x = stack(top)
        top = top - 1
        do d = 1, 3
          do sgn = -1, 1, 2
            nb = m%element_ijk(x)
            nb(d) = nb(d) + sgn
            if (nb(d) < 0 .or. nb(d) >= m%ng(d)) cycle
            y = m%element_gid(nb)
            if (visited(y) .or. esub(y) /= s) cycle
            visited(y) = .true.
            top = top + 1
            stack(top) = y
          end do
        end do
      end do
    end do
    ok = ncomp == 1
  end function face_connected

  !> The inner cross point of a 2x2x2 box decomposition is held by all 8
  !> subdomains; a corner of the box by 1, a face centre by 1, an edge midpoint
  !> between two subdomains by 2, a point of an inner edge by 4.
  subroutine check_cross_point()
    type(params_t) :: p
    type(decomposition_t) :: dec
    integer(ip), allocatable :: ids(:)
    integer(ip) :: i
    p = default_params()
    p%mesh%nsub = [2, 2, 2]
    p%mesh%nel = [3, 2, 4]
    call build_decomposition(p, MPI_COMM_WORLD, dec)
    ids = dec%node_subdomains(dec%mesh%node_gid([3, 2, 4]))
    call assert_equal(8_ip, int(size(ids), ip), 'cross point multiplicity 8', HERE)
    call assert_true(all(ids == [(i, i=1, 8)]), 'cross point ids 1..8', HERE)
    ids = dec%node_subdomains(1_ip)
    call assert_true(size(ids) == 1 .and. ids(1) == 1, 'corner in subdomain 1 only', HERE)
    ids = dec%node_subdomains(dec%mesh%num_nodes())
    call assert_true(size(ids) == 1 .and. ids(1) == 8, 'far corner in subdomain 8 only', HERE)
    ids = dec%node_subdomains(dec%mesh%node_gid([3, 0, 0]))
    call assert_true(size(ids) == 2 .and. all(ids == [1, 2]), 'x-interface on the bottom edge', HERE)
    ids = dec%node_subdomains(dec%mesh%node_gid([3, 2, 1]))
    call assert_true(size(ids) == 4 .and. all(ids == [1, 2, 3, 4]), 'inner z-edge', HERE)
  end subroutine check_cross_point

  !> split_into_components on hand-made partitions.
  subroutine check_split()
    type(box_mesh_t) :: m
    integer(ip) :: esub(4), n, nsplit, ndropped
    ! a row of 4 elements; part 1 = {1} and {3,4}, part 2 = {2}, part 3 empty
    call box_mesh_init(m, [1_ip, 1_ip, 1_ip], [4_ip, 1_ip, 1_ip], [1.0_dp, 1.0_dp, 1.0_dp], 0.0_dp, 1_ip)
    call split_into_components(m, [1_ip, 2_ip, 1_ip, 1_ip], 3_ip, esub, n, nsplit, ndropped)
    call assert_equal(3_ip, n, 'split: 3 subdomains', HERE)
    call assert_true(all(esub == [1, 3, 2, 2]), 'split: ids by (part, first element)', HERE)
    call assert_equal(1_ip, nsplit, 'split: one part split', HERE)
    call assert_equal(1_ip, ndropped, 'split: one part empty', HERE)
    ! 2x2 elements, parts on the diagonals: only edges shared, so 4 subdomains
    call box_mesh_init(m, [1_ip, 1_ip, 1_ip], [2_ip, 2_ip, 1_ip], [1.0_dp, 1.0_dp, 1.0_dp], 0.0_dp, 1_ip)
    call split_into_components(m, [1_ip, 2_ip, 2_ip, 1_ip], 2_ip, esub, n, nsplit, ndropped)
    call assert_equal(4_ip, n, 'split diagonal: 4 subdomains', HERE)
    call assert_true(all(esub == [1, 3, 4, 2]), 'split diagonal: ids', HERE)
    call assert_equal(2_ip, nsplit, 'split diagonal: both parts split', HERE)
    call assert_equal(0_ip, ndropped, 'split diagonal: none empty', HERE)
  end subroutine check_split
end program test_decomposition
