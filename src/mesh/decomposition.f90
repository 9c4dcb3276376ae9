!> Decomposition of the global box mesh into subdomains and the map of
!> subdomains to MPI ranks. Arrays over subdomains (subdomain_rank, element
!> counts, the subdomain graph) are replicated on every rank; nothing of the
!> size of the global mesh is kept after the set-up.
!>
!> 'box': box subdomains (I,J,K) of nel elements, id 1 + I + Nx*(J + Ny*K).
!> Nothing of the size of the global mesh is stored: the subdomain of an
!> element, the elements of a subdomain, the subdomains holding a node and the
!> subdomain graph follow from index arithmetic (arrays of the number of
!> subdomains only: subdomain_rank).
!> 'metis': the global mesh cut into product(nsub) parts by METIS_PartMeshDual
!> (parts share faces: ncommon = 4) on rank 0. A part that is not
!> face-connected is split into its face-connected components, each one a
!> subdomain; empty parts are dropped. Ids are 1..N ordered by (METIS part,
!> smallest element gid of the component).
!> The partition is made on rank 0 from the whole mesh (METIS's dual graph,
!> the part of every element: arrays of the global element count, on rank 0
!> during build_decomposition only). Rank 0 then sends every rank the
!> elements it needs and their subdomains: the elements of its subdomains and
!> every element sharing a node with them (`known_gids`, `known_subdomain`), so
!> that node_subdomain_list answers for every node of its subdomains; the
!> element lists of its own subdomains follow. The subdomain graph and the
!> element count of every subdomain are broadcast (arrays over subdomains).
!> Mapping 'block': contiguous blocks of ids, sizes differing by at most one;
!> 'metis': METIS_PartGraphKway on the subdomain adjacency graph (subdomains
!> sharing a node), vertex weights = element counts; a rank METIS leaves empty
!> takes the largest id of the rank with the most subdomains.
module decomposition
  use kinds, only: ip, name_len, MPI_INT_IP
  use errors, only: collective_error, fatal_error, exit_input_error
  use logger, only: log_message
  use params, only: params_t
  use metis_wrapper, only: metis_part_mesh_dual, metis_part_graph_kway
  use sorting, only: sort_ints, append_unmarked
  use box_mesh, only: box_mesh_t, box_mesh_init
  use mpi_f08, only: MPI_Comm, MPI_Comm_rank, MPI_Comm_size, MPI_Bcast, MPI_Scatter, MPI_Scatterv, MPI_INTEGER
  implicit none
  private

  public :: build_decomposition, split_into_components, block_mapping, subdomain_graph

  !> The decomposition, replicated on every rank of `comm`.
  type, public :: decomposition_t
    type(box_mesh_t) :: mesh
    type(MPI_Comm) :: comm                              !< the ranks that share the subdomains
    character(len=name_len) :: method = 'box'           !< 'box' | 'metis'
    integer(ip) :: nsubdomains = 0, nranks = 1, rank = 0
    !> 'metis' only: the elements this rank knows (its subdomains' elements
    !> and every element sharing a node with them), ascending gids, and their
    !> subdomain ids (box: subdomain_of_element by index arithmetic)
    integer(ip), allocatable :: known_gids(:), known_subdomain(:)
    !> 'metis' only: element count of every subdomain id, and the subdomain
    !> graph (CSR, as subdomain_graph returns it)
    integer(ip), allocatable :: subdomain_nelem(:), graph_xadj(:), graph_adjncy(:)
    integer(ip), allocatable :: subdomain_rank(:)       !< subdomain id -> owning rank (0-based)
    integer(ip), allocatable :: local_subdomains(:)     !< ids owned by this rank, ascending
    !> 'metis' only (box: subdomain_element_gids): elements of the k-th local
    !> subdomain (local_subdomains(k)):
    !> subdomain_elements(subdomain_element_ptr(k):subdomain_element_ptr(k+1)-1), ascending gids
    integer(ip), allocatable :: subdomain_element_ptr(:), subdomain_elements(:)
  contains
    procedure :: is_box
    procedure :: subdomain_of_element
    procedure :: subdomain_element_gids
    procedure :: node_subdomains
    procedure :: node_subdomain_list
    procedure :: subdomain_nelements
  end type decomposition_t

contains

  !> Build the decomposition of `p%mesh` over the ranks of `comm`. Collective.
  !> More ranks than subdomains is an input error (every rank exits, status 2).
  subroutine build_decomposition(p, comm, dec)
    type(params_t), intent(in) :: p
    type(MPI_Comm), intent(in) :: comm
    type(decomposition_t), intent(out) :: dec
    integer :: ierr, rank, nranks
    integer(ip) :: ne, s, nadj
    integer(ip), allocatable :: esub(:)
    character(len=256) :: msg

    call MPI_Comm_rank(comm, rank, ierr)
    call MPI_Comm_size(comm, nranks, ierr)
    dec%comm = comm
    dec%rank = rank
    dec%nranks = nranks
    dec%method = p%mesh%decomposition
    call box_mesh_init(dec%mesh, p%mesh%nsub, p%mesh%nel, p%mesh%lengths, p%mesh%distortion, &
                       p%mesh%distortion_seed)
    ne = dec%mesh%num_elements()

    select case (trim(p%mesh%decomposition))
    case ('box')
      ! index arithmetic only: no array of the size of the mesh
      dec%nsubdomains = product(p%mesh%nsub)
    case ('metis')
      ! rank 0: the partition of the whole mesh, the element counts and the graph
      if (rank == 0) then
        allocate (esub(ne))
        call metis_partition(dec%mesh, esub, dec%nsubdomains)
        call element_graph(dec%mesh, esub, dec%nsubdomains, dec%subdomain_nelem, dec%graph_xadj, &
                           dec%graph_adjncy)
        nadj = size(dec%graph_adjncy, kind=ip)
      end if
      call MPI_Bcast(dec%nsubdomains, 1, MPI_INT_IP, 0, comm, ierr)
      call MPI_Bcast(nadj, 1, MPI_INT_IP, 0, comm, ierr)
      if (rank /= 0) allocate (dec%subdomain_nelem(dec%nsubdomains), dec%graph_xadj(dec%nsubdomains + 1), &
                               dec%graph_adjncy(nadj))
      call MPI_Bcast(dec%subdomain_nelem, dec%nsubdomains, MPI_INT_IP, 0, comm, ierr)
      call MPI_Bcast(dec%graph_xadj, dec%nsubdomains + 1, MPI_INT_IP, 0, comm, ierr)
      call MPI_Bcast(dec%graph_adjncy, nadj, MPI_INT_IP, 0, comm, ierr)
    case default
      call collective_error("group &mesh, variable decomposition: must be 'box' or 'metis' (got "// &
                            trim(p%mesh%decomposition)//')', comm, exit_input_error)
    end select

    if (nranks > dec%nsubdomains) then
      write (msg, '(a,3(1x,i0),a,i0,a,i0,a,i0,a)') 'group &mesh, variable nsub: nsub =', p%mesh%nsub, &
        ' gives ', dec%nsubdomains, ' subdomains, fewer than the ', nranks, &
        ' MPI ranks; every rank needs a subdomain: run on at most ', dec%nsubdomains, &
        ' ranks or raise nsub'
      call collective_error(msg, comm, exit_input_error)
    end if

    allocate (dec%subdomain_rank(dec%nsubdomains))
    select case (trim(p%mesh%mapping))
    case ('block')
      dec%subdomain_rank = block_mapping(dec%nsubdomains, int(nranks, ip))
    case ('metis')
      if (rank == 0) call metis_mapping(dec, dec%subdomain_rank)
      call MPI_Bcast(dec%subdomain_rank, dec%nsubdomains, MPI_INT_IP, 0, comm, ierr)
    case default
      call collective_error("group &mesh, variable mapping: must be 'block' or 'metis' (got "// &
                            trim(p%mesh%mapping)//')', comm, exit_input_error)
    end select
    dec%local_subdomains = pack([(s, s=1, dec%nsubdomains)], dec%subdomain_rank == rank)
    if (.not. dec%is_box()) call distribute_elements(dec, esub)
  end subroutine build_decomposition

  !> Rank 0 sends every rank the elements it needs (see the module
  !> documentation) with their subdomains, then frees the global `esub`; each
  !> rank builds the element lists of its own subdomains. Collective.
  subroutine distribute_elements(dec, esub)
    type(decomposition_t), intent(inout) :: dec
    integer(ip), allocatable, intent(inout) :: esub(:)   !< rank 0: subdomain of every element
    integer, allocatable :: counts(:), displs(:), next(:)
    integer(ip), allocatable :: sendbuf(:, :), recvbuf(:, :)
    integer(ip) :: ne, e, k, nr, ranks(27), ls, s
    integer :: mine, ierr, r

    allocate (counts(0:dec%nranks - 1), displs(0:dec%nranks - 1))
    if (dec%rank == 0) then
      ne = size(esub, kind=ip)
      counts = 0
      do e = 1, ne
        call ranks_needing(e, ranks, nr)
        counts(ranks(1:nr)) = counts(ranks(1:nr)) + 1
      end do
      displs(0) = 0
      do r = 1, dec%nranks - 1
        displs(r) = displs(r - 1) + counts(r - 1)
      end do
      allocate (sendbuf(2, sum(counts)))
      next = displs
      do e = 1, ne
        call ranks_needing(e, ranks, nr)
        do k = 1, nr
          next(ranks(k)) = next(ranks(k)) + 1
          sendbuf(:, next(ranks(k))) = [e, esub(e)]
        end do
      end do
      deallocate (esub)
    else
      allocate (sendbuf(2, 1))
    end if
    call MPI_Scatter(counts, 1, MPI_INTEGER, mine, 1, MPI_INTEGER, 0, dec%comm, ierr)
    allocate (recvbuf(2, mine))
    call MPI_Scatterv(sendbuf, 2*counts, 2*displs, MPI_INT_IP, recvbuf, 2*mine, MPI_INT_IP, 0, dec%comm, ierr)
    deallocate (sendbuf)
    dec%known_gids = recvbuf(1, :)            ! ascending: rank 0 sent them in gid order
    dec%known_subdomain = recvbuf(2, :)
    deallocate (recvbuf)

    ! the element lists of the local subdomains
    associate (nl => size(dec%local_subdomains))
      allocate (dec%subdomain_element_ptr(nl + 1))
      dec%subdomain_element_ptr(1) = 1
      do ls = 1, nl
        dec%subdomain_element_ptr(ls + 1) = dec%subdomain_element_ptr(ls) + &
                                            dec%subdomain_nelem(dec%local_subdomains(ls))
      end do
      allocate (dec%subdomain_elements(dec%subdomain_element_ptr(nl + 1) - 1))
      if (allocated(next)) deallocate (next)
      allocate (next(nl))
      next = dec%subdomain_element_ptr(1:nl)
      do k = 1, size(dec%known_gids)
        s = dec%known_subdomain(k)
        if (dec%subdomain_rank(s) /= dec%rank) cycle
        ls = local_position(dec, s)
        dec%subdomain_elements(next(ls)) = dec%known_gids(k)
        next(ls) = next(ls) + 1
      end do
      if (any(next /= dec%subdomain_element_ptr(2:nl + 1))) &
        call fatal_error('decomposition: the elements received do not match the element counts')
    end associate

  contains

    !> The distinct ranks owning element e or an element sharing a node with it.
    subroutine ranks_needing(e, ranks, nr)
      integer(ip), intent(in) :: e
      integer(ip), intent(out) :: ranks(27), nr
      integer(ip) :: near(27), nnear, m, r
      call dec%mesh%elements_near(dec%mesh%element_ijk(e), -1_ip, 1_ip, near, nnear)
      nr = 0
      do m = 1, nnear
        r = dec%subdomain_rank(esub(near(m)))
        if (any(ranks(1:nr) == r)) cycle
        nr = nr + 1
        ranks(nr) = r
      end do
    end subroutine ranks_needing
  end subroutine distribute_elements

  !> Position of subdomain `id` in local_subdomains (binary search), 0 when
  !> this rank does not own it.
  pure integer(ip) function local_position(dec, id)
    type(decomposition_t), intent(in) :: dec
    integer(ip), intent(in) :: id
    local_position = find_sorted(dec%local_subdomains, id)
  end function local_position

  !> Index of `key` in the ascending `list`, 0 when absent.
  pure integer(ip) function find_sorted(list, key) result(pos)
    integer(ip), intent(in) :: list(:), key
    integer(ip) :: lo, hi, mid
    lo = 1
    hi = size(list, kind=ip)
    pos = 0
    do while (lo <= hi)
      mid = (lo + hi)/2
      if (list(mid) == key) then
        pos = mid
        return
      else if (list(mid) < key) then
        lo = mid + 1
      else
        hi = mid - 1
      end if
    end do
  end function find_sorted

  !> METIS parts of the whole mesh, split into face-connected subdomains (rank 0).
  subroutine metis_partition(mesh, element_subdomain, nsubdomains)
    type(box_mesh_t), intent(in) :: mesh
    integer(ip), intent(out) :: element_subdomain(:)
    integer(ip), intent(out) :: nsubdomains
    integer(ip), allocatable :: eptr(:), eind(:), part(:)
    integer(ip) :: ne, e, nparts, nsplit, ndropped
    character(len=200) :: msg

    ne = mesh%num_elements()
    nparts = product(mesh%nsub)
    allocate (eptr(ne + 1), eind(8*ne), part(ne))
    do e = 1, ne
      eptr(e) = 8*(e - 1) + 1
      eind(8*(e - 1) + 1:8*e) = mesh%element_nodes(e)
    end do
    eptr(ne + 1) = 8*ne + 1
    call metis_part_mesh_dual(ne, mesh%num_nodes(), eptr, eind, 4_ip, nparts, part)
    deallocate (eptr, eind)
    call split_into_components(mesh, part, nparts, element_subdomain, nsubdomains, nsplit, ndropped)
    if (nsplit > 0) then
      write (msg, '(a,i0,a,i0,a)') 'decomposition: ', nsplit, ' METIS part(s) not face-connected, '// &
        'split into their connected components (', nsubdomains, ' subdomains)'
      call log_message(msg)
    end if
    if (ndropped > 0) then
      write (msg, '(a,i0,a)') 'decomposition: ', ndropped, ' empty METIS part(s) dropped'
      call log_message(msg)
    end if
  end subroutine metis_partition

  !> Turn a partition part(e) in 1..nparts of the elements into subdomains:
  !> each face-connected component of a part becomes one subdomain, ids 1..N
  !> in the order (part, smallest element gid); empty parts give none.
  !> nsplit: parts with more than one component; ndropped: empty parts.
  subroutine split_into_components(mesh, part, nparts, element_subdomain, nsubdomains, nsplit, ndropped)
    type(box_mesh_t), intent(in) :: mesh
    integer(ip), intent(in) :: part(:), nparts
    integer(ip), intent(out) :: element_subdomain(:)
    integer(ip), intent(out) :: nsubdomains, nsplit, ndropped
    integer(ip), allocatable :: label(:), queue(:), comp_part(:), ncomp_of(:), offset(:), new_id(:)
    integer(ip) :: ne, e, x, y, head, tail, ncomp, d, c, ijk(3), nijk(3)

    ne = mesh%num_elements()
    if (any(part(1:ne) < 1) .or. any(part(1:ne) > nparts)) &
      call fatal_error('split_into_components: part out of range')
    allocate (label(ne), queue(ne), comp_part(ne))
    label = 0
    ncomp = 0
    do e = 1, ne
      if (label(e) /= 0) cycle
      ncomp = ncomp + 1
      comp_part(ncomp) = part(e)
      label(e) = ncomp
      head = 1
      tail = 1
      queue(1) = e
      do while (head <= tail)
        x = queue(head)
        head = head + 1
        ijk = mesh%element_ijk(x)
        do d = 1, 3
          do c = -1, 1, 2
            nijk = ijk
            nijk(d) = nijk(d) + c
            if (nijk(d) < 0 .or. nijk(d) >= mesh%ng(d)) cycle
            y = mesh%element_gid(nijk)
            if (label(y) /= 0 .or. part(y) /= part(x)) cycle
            label(y) = ncomp
            tail = tail + 1
            queue(tail) = y
          end do
        end do
      end do
    end do
    ! components in discovery order = ascending smallest element; stable by part
    allocate (ncomp_of(nparts), offset(nparts), new_id(ncomp))
    ncomp_of = 0
    do c = 1, ncomp
      ncomp_of(comp_part(c)) = ncomp_of(comp_part(c)) + 1
    end do
    offset(1) = 0
    do x = 2, nparts
      offset(x) = offset(x - 1) + ncomp_of(x - 1)
    end do
    do c = 1, ncomp
      offset(comp_part(c)) = offset(comp_part(c)) + 1
      new_id(c) = offset(comp_part(c))
    end do
    do e = 1, ne
      element_subdomain(e) = new_id(label(e))
    end do
    nsubdomains = ncomp
    nsplit = count(ncomp_of > 1)
    ndropped = count(ncomp_of == 0)
  end subroutine split_into_components

  !> Subdomain -> rank for contiguous blocks of ids (the first mod(n, nranks)
  !> ranks get one more).
  pure function block_mapping(n, nranks) result(rank_of)
    integer(ip), intent(in) :: n, nranks
    integer(ip) :: rank_of(n)
    integer(ip) :: r, q, m, first, nblock
    q = n/nranks
    m = mod(n, nranks)
    first = 1
    do r = 0, nranks - 1
      nblock = q
      if (r < m) nblock = nblock + 1
      rank_of(first:first + nblock - 1) = r
      first = first + nblock
    end do
  end function block_mapping

  !> Element counts and the subdomain graph (s, t neighbours when they share
  !> a node; CSR, neighbours ascending) from the subdomain of every element
  !> (rank 0, at set-up).
  subroutine element_graph(mesh, esub, n, nelem, xadj, adjncy)
    type(box_mesh_t), intent(in) :: mesh
    integer(ip), intent(in) :: esub(:), n
    integer(ip), allocatable, intent(out) :: nelem(:), xadj(:), adjncy(:)
    integer(ip), allocatable :: ptr(:), list(:), next(:), marker(:)
    integer(ip) :: ne, e, s, t, k, m, near(27), nnear, nadj, first
    ne = size(esub, kind=ip)
    allocate (nelem(n), ptr(n + 1), list(ne), next(n))
    nelem = 0
    do e = 1, ne
      nelem(esub(e)) = nelem(esub(e)) + 1
    end do
    ptr(1) = 1
    do s = 1, n
      ptr(s + 1) = ptr(s) + nelem(s)
    end do
    next = ptr(1:n)
    do e = 1, ne
      list(next(esub(e))) = e
      next(esub(e)) = next(esub(e)) + 1
    end do
    allocate (xadj(n + 1), marker(n), adjncy(max(16, 8*n)))
    marker = 0
    nadj = 0
    xadj(1) = 1
    do s = 1, n
      first = nadj + 1
      do k = ptr(s), ptr(s + 1) - 1
        call mesh%elements_near(mesh%element_ijk(list(k)), -1_ip, 1_ip, near, nnear)
        do m = 1, nnear
          t = esub(near(m))
          if (t /= s) call append_unmarked(adjncy, nadj, t, marker, s)
        end do
      end do
      call sort_ints(adjncy(first:nadj))
      xadj(s + 1) = nadj + 1
    end do
    adjncy = adjncy(1:nadj)
  end subroutine element_graph

  !> Subdomain adjacency graph (1-based CSR, no self loops, neighbours
  !> ascending): s and t are neighbours when they share at least one node.
  subroutine subdomain_graph(dec, xadj, adjncy)
    type(decomposition_t), intent(in) :: dec
    integer(ip), allocatable, intent(out) :: xadj(:), adjncy(:)
    if (dec%is_box()) then
      call box_subdomain_graph(dec%mesh%nsub, xadj, adjncy)
    else
      xadj = dec%graph_xadj
      adjncy = dec%graph_adjncy
    end if
  end subroutine subdomain_graph

  !> The subdomain graph of box subdomains: box (I,J,K) shares a node with
  !> every box (I+di,J+dj,K+dk), -1 <= di,dj,dk <= 1, inside the grid (nel >= 1).
  !> The loop order dk, dj, di gives ascending ids.
  subroutine box_subdomain_graph(nsub, xadj, adjncy)
    integer(ip), intent(in) :: nsub(3)
    integer(ip), allocatable, intent(out) :: xadj(:), adjncy(:)
    integer(ip) :: n, s, nadj, b(3), t(3), di, dj, dk
    n = product(nsub)
    allocate (xadj(n + 1), adjncy(26*n))
    nadj = 0
    xadj(1) = 1
    do s = 1, n
      b = box_ijk(nsub, s)
      do dk = -1, 1
        do dj = -1, 1
          do di = -1, 1
            t = b + [di, dj, dk]
            if (any(t < 0) .or. any(t >= nsub) .or. all([di, dj, dk] == 0)) cycle
            nadj = nadj + 1
            adjncy(nadj) = 1 + t(1) + nsub(1)*(t(2) + nsub(2)*t(3))
          end do
        end do
      end do
      xadj(s + 1) = nadj + 1
    end do
    adjncy = adjncy(1:nadj)
  end subroutine box_subdomain_graph

  !> Box subdomain id -> (I,J,K), 0-based.
  pure function box_ijk(nsub, id) result(b)
    integer(ip), intent(in) :: nsub(3), id
    integer(ip) :: b(3), r
    r = id - 1
    b(1) = mod(r, nsub(1))
    r = r/nsub(1)
    b(2) = mod(r, nsub(2))
    b(3) = r/nsub(2)
  end function box_ijk


  !> METIS mapping of subdomains to ranks (rank 0).
  subroutine metis_mapping(dec, rank_of)
    type(decomposition_t), intent(in) :: dec
    integer(ip), intent(out) :: rank_of(:)
    integer(ip), allocatable :: xadj(:), adjncy(:), part(:), owned(:)
    integer(ip), allocatable, target :: weights(:)
    integer(ip) :: n, s, r, big, nr

    n = dec%nsubdomains
    nr = dec%nranks
    if (nr == 1) then
      rank_of = 0
      return
    end if
    if (nr == n) then
      rank_of = [(s - 1, s=1, n)]
      return
    end if
    call subdomain_graph(dec, xadj, adjncy)
    if (size(adjncy) == 0) adjncy = [0_ip]
    allocate (weights(n), part(n))
    weights = [(dec%subdomain_nelements(s), s=1, n)]
    call metis_part_graph_kway(n, xadj, adjncy, nr, part, weights)
    rank_of = part - 1
    ! no rank may stay empty: it takes the largest id of the fullest rank
    allocate (owned(0:nr - 1))
    owned = 0
    do s = 1, n
      owned(rank_of(s)) = owned(rank_of(s)) + 1
    end do
    do r = 0, nr - 1
      if (owned(r) > 0) cycle
      big = maxloc(owned, dim=1) - 1
      do s = n, 1, -1
        if (rank_of(s) == big) exit
      end do
      rank_of(s) = r
      owned(big) = owned(big) - 1
      owned(r) = 1
    end do
  end subroutine metis_mapping

  !> Sorted unique ids of the subdomains holding a copy of node `gid`.
  function node_subdomains(this, gid) result(ids)
    class(decomposition_t), intent(in) :: this
    integer(ip), intent(in) :: gid
    integer(ip), allocatable :: ids(:)
    integer(ip) :: list(8), n
    call this%node_subdomain_list(gid, list, n)
    ids = list(1:n)
  end function node_subdomains

  !> The same as node_subdomains without allocation: ids(1:n), n <= 8.
  pure subroutine node_subdomain_list(this, gid, ids, n)
    class(decomposition_t), intent(in) :: this
    integer(ip), intent(in) :: gid
    integer(ip), intent(out) :: ids(8), n
    integer(ip) :: near(27), nnear, k, s, m, pos
    call this%mesh%elements_near(this%mesh%node_ijk(gid), -1_ip, 0_ip, near, nnear)
    n = 0
    do k = 1, nnear
      s = this%subdomain_of_element(near(k))
      if (s == 0) cycle                  ! unknown element (METIS, not near this rank's subdomains)
      ! insert s into the sorted ids(1:n) unless present
      pos = n + 1
      do m = 1, n
        if (ids(m) >= s) then
          pos = m
          exit
        end if
      end do
      if (pos <= n) then
        if (ids(pos) == s) cycle
      end if
      ids(pos + 1:n + 1) = ids(pos:n)
      ids(pos) = s
      n = n + 1
    end do
  end subroutine node_subdomain_list

  !> Number of elements of subdomain `id`.
  pure integer(ip) function subdomain_nelements(this, id)
    class(decomposition_t), intent(in) :: this
    integer(ip), intent(in) :: id
    if (this%is_box()) then
      subdomain_nelements = product(this%mesh%nel)
    else
      subdomain_nelements = this%subdomain_nelem(id)
    end if
  end function subdomain_nelements

  !> True for a box decomposition (index arithmetic, no global arrays).
  pure logical function is_box(this)
    class(decomposition_t), intent(in) :: this
    is_box = trim(this%method) == 'box'
  end function is_box

  !> Id of the subdomain holding element `gid`. METIS: known for the elements
  !> of this rank's subdomains and those sharing a node with them, else 0.
  pure integer(ip) function subdomain_of_element(this, gid)
    class(decomposition_t), intent(in) :: this
    integer(ip), intent(in) :: gid
    integer(ip) :: k
    if (this%is_box()) then
      subdomain_of_element = this%mesh%box_subdomain(gid)
    else
      k = find_sorted(this%known_gids, gid)
      subdomain_of_element = 0
      if (k > 0) subdomain_of_element = this%known_subdomain(k)
    end if
  end function subdomain_of_element

  !> The element gids of subdomain `id`, ascending. Box: the elements (i,j,k)
  !> with I*nel(1) <= i < (I+1)*nel(1) (and so on), k slowest then j then i.
  !> METIS: for this rank's subdomains (empty for the others).
  pure function subdomain_element_gids(this, id) result(gids)
    class(decomposition_t), intent(in) :: this
    integer(ip), intent(in) :: id
    integer(ip), allocatable :: gids(:)
    integer(ip) :: b(3), lo(3), i, j, k, n
    if (.not. this%is_box()) then
      k = local_position(this, id)
      if (k == 0) then
        allocate (gids(0))
      else
        gids = this%subdomain_elements(this%subdomain_element_ptr(k):this%subdomain_element_ptr(k + 1) - 1)
      end if
      return
    end if
    b = box_ijk(this%mesh%nsub, id)
    lo = b*this%mesh%nel
    allocate (gids(product(this%mesh%nel)))
    n = 0
    do k = lo(3), lo(3) + this%mesh%nel(3) - 1
      do j = lo(2), lo(2) + this%mesh%nel(2) - 1
        do i = lo(1), lo(1) + this%mesh%nel(1) - 1
          n = n + 1
          gids(n) = this%mesh%element_gid([i, j, k])
        end do
      end do
    end do
  end function subdomain_element_gids
end module decomposition
