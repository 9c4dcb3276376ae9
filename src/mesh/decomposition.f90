!> Decomposition of the global box mesh into subdomains and the map of
!> subdomains to MPI ranks. Arrays over subdomains (subdomain_rank, element
!> counts, the subdomain graph) and, for METIS, over the blocks of the coarse
!> block grid are replicated on every rank; no array on any rank is sized by
!> the global element or node count.
!>
!> 'box': box subdomains (I,J,K) of nel elements, id 1 + I + Nx*(J + Ny*K).
!> Nothing of the size of the global mesh is stored: the subdomain of an
!> element, the elements of a subdomain, the subdomains holding a node and the
!> subdomain graph follow from index arithmetic (arrays of the number of
!> subdomains only: subdomain_rank).
!> 'metis': a partition of the coarse block grid. The elements are grouped
!> into blocks of b x b x b elements (the last block in a direction may be
!> thinner), block (I,J,K) = element (i,j,k) / b, id 1 + I + NBx*(J + NBy*K).
!> b is `&mesh metis_block`, or with 0 (automatic) the smallest b >= 1 that
!> gives at most max_blocks_per_part blocks per requested part (so between
!> about max_blocks_per_part/8 and max_blocks_per_part; b = 1, the dual graph
!> of the elements by faces, whenever the mesh has no more elements than
!> that). Rank 0 cuts the block graph (face neighbours, vertex weights =
!> elements per block) into product(nsub) parts by METIS_PartGraphKway and
!> broadcasts the part of every block. On every rank, a part that is not
!> face-connected is split into its face-connected components, each one a
!> subdomain; empty parts are dropped. Ids are 1..N ordered by (METIS part,
!> smallest block id of the component). Every rank keeps block_subdomain
!> (one entry per block: at most max_blocks_per_part x product(nsub) in the
!> automatic case) and finds by index arithmetic the subdomain of any element
!> (element -> block -> subdomain), hence the subdomains holding any node,
!> and the element lists of its own subdomains. The element counts per
!> subdomain and the subdomain graph (subdomains sharing a node = blocks
!> within one block of each other in every direction) follow from the
!> blocks, on every rank. Nothing is sent but the block parts.
!> Mapping 'block': contiguous blocks of ids, sizes differing by at most one;
!> 'metis': METIS_PartGraphKway on the subdomain adjacency graph (subdomains
!> sharing a node), vertex weights = element counts; a rank METIS leaves empty
!> takes the largest id of the rank with the most subdomains.
module decomposition
  use kinds, only: ip, name_len, MPI_INT_IP
  use errors, only: collective_error, fatal_error, exit_input_error
  use logger, only: log_message
  use mesh_settings, only: mesh_settings_t
  use metis_wrapper, only: metis_part_graph_kway
  use sorting, only: sort_ints, append_unmarked
  use text, only: counted
  use box_mesh, only: box_mesh_t, box_mesh_init
  use mpi_f08, only: MPI_Comm, MPI_Comm_rank, MPI_Comm_size, MPI_Bcast
  implicit none
  private

  public :: build_decomposition, split_into_components, block_mapping, subdomain_graph, automatic_metis_block

  !> 'metis', metis_block = 0: the block size b is the smallest giving at most
  !> this many blocks per requested part
  integer(ip), parameter, public :: max_blocks_per_part = 64

  !> The decomposition, replicated on every rank of `comm`.
  type, public :: decomposition_t
    type(box_mesh_t) :: mesh
    type(MPI_Comm) :: comm                              !< the ranks that share the subdomains
    character(len=name_len) :: method = 'box'           !< 'box' | 'metis'
    logical :: box = .true.                             !< method == 'box' (is_box, in the inner loops)
    integer(ip) :: nsubdomains = 0, nranks = 1, rank = 0
    !> 'metis' only: block size b (elements per block edge), blocks per
    !> direction, and the subdomain of every block (box: subdomain_of_element
    !> by index arithmetic)
    integer(ip) :: block = 0, nblock(3) = 0
    integer(ip), allocatable :: block_subdomain(:)
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

  !> Build the decomposition of the mesh `m` over the ranks of `comm`. Collective.
  !> More ranks than subdomains is an input error (every rank exits, status 2).
  subroutine build_decomposition(m, comm, dec)
    type(mesh_settings_t), intent(in) :: m
    type(MPI_Comm), intent(in) :: comm
    type(decomposition_t), intent(out) :: dec
    integer :: ierr, rank, nranks
    integer(ip) :: s
    character(len=256) :: msg

    call MPI_Comm_rank(comm, rank, ierr)
    call MPI_Comm_size(comm, nranks, ierr)
    dec%comm = comm
    dec%rank = rank
    dec%nranks = nranks
    dec%method = m%decomposition
    dec%box = trim(m%decomposition) == 'box'
    call box_mesh_init(dec%mesh, m%nsub, m%nel, m%lengths, m%distortion, &
                       m%distortion_seed)

    select case (trim(m%decomposition))
    case ('box')
      ! index arithmetic only: no array of the size of the mesh
      dec%nsubdomains = product(m%nsub)
    case ('metis')
      ! arrays over the blocks and the subdomains only
      call metis_block_partition(dec, m%metis_block)
    case default
      call collective_error("group &mesh, variable decomposition: must be 'box' or 'metis' (got "// &
                            trim(m%decomposition)//')', comm, exit_input_error)
    end select

    if (nranks > dec%nsubdomains) then
      write (msg, '(a,3(1x,i0),9a)') 'group &mesh, variable nsub: nsub =', m%nsub, &
        ' gives ', counted(dec%nsubdomains, 'subdomain'), ', fewer than the ', counted(nranks, 'MPI rank'), &
        '; every rank needs a subdomain: run on at most ', counted(dec%nsubdomains, 'rank'), ' or raise nsub'
      call collective_error(msg, comm, exit_input_error)
    end if

    allocate (dec%subdomain_rank(dec%nsubdomains))
    select case (trim(m%mapping))
    case ('block')
      dec%subdomain_rank = block_mapping(dec%nsubdomains, int(nranks, ip))
    case ('metis')
      if (rank == 0) call metis_mapping(dec, dec%subdomain_rank)
      call MPI_Bcast(dec%subdomain_rank, dec%nsubdomains, MPI_INT_IP, 0, comm, ierr)
    case default
      call collective_error("group &mesh, variable mapping: must be 'block' or 'metis' (got "// &
                            trim(m%mapping)//')', comm, exit_input_error)
    end select
    dec%local_subdomains = pack([(s, s=1, dec%nsubdomains)], dec%subdomain_rank == rank)
    if (.not. dec%is_box()) call local_element_lists(dec)
  end subroutine build_decomposition

  !> The block size for `&mesh metis_block = 0`: the smallest b >= 1 such that
  !> the grid of ng(1) x ng(2) x ng(3) elements has at most
  !> max_blocks_per_part * nparts blocks of b^3 elements.
  pure integer(ip) function automatic_metis_block(ng, nparts) result(b)
    integer(ip), intent(in) :: ng(3), nparts
    b = 1
    do while (product((ng + b - 1)/b) > max_blocks_per_part*nparts)
      b = b + 1
    end do
  end function automatic_metis_block

  !> Block (0-based (I,J,K)) of element `gid` and its id in the block grid.
  pure integer(ip) function block_of_element(dec, gid) result(id)
    type(decomposition_t), intent(in) :: dec
    integer(ip), intent(in) :: gid
    integer(ip) :: bijk(3)
    bijk = dec%mesh%element_ijk(gid)/dec%block
    id = 1 + bijk(1) + dec%nblock(1)*(bijk(2) + dec%nblock(2)*bijk(3))
  end function block_of_element

  !> Elements in block (0-based) bijk: b^3, fewer at the high ends of the grid.
  pure integer(ip) function block_weight(dec, bijk)
    type(decomposition_t), intent(in) :: dec
    integer(ip), intent(in) :: bijk(3)
    block_weight = product(min(dec%block, dec%mesh%ng - bijk*dec%block))
  end function block_weight

  !> 'metis': the block size, the METIS parts of the block grid (rank 0,
  !> broadcast), their face-connected components as subdomains, the element
  !> count of every subdomain and the subdomain graph (every rank). Collective.
  subroutine metis_block_partition(dec, metis_block)
    type(decomposition_t), intent(inout) :: dec
    integer(ip), intent(in) :: metis_block
    integer(ip), allocatable :: xadj(:), adjncy(:), part(:), ptr(:), list(:), next(:), marker(:)
    integer(ip), allocatable, target :: weights(:)
    integer(ip) :: nparts, nb, k, d, c, bijk(3), nijk(3), nsplit, ndropped, n, s, t, m, first, nadj, &
                   di, dj, dk
    integer :: ierr
    character(len=256) :: msg

    nparts = product(dec%mesh%nsub)
    if (metis_block == 0) then
      dec%block = automatic_metis_block(dec%mesh%ng, nparts)
    else
      dec%block = metis_block
    end if
    dec%nblock = (dec%mesh%ng + dec%block - 1)/dec%block
    nb = product(dec%nblock)
    if (nb < nparts) then
      write (msg, '(a,i0,5a)') 'group &mesh, variable metis_block: blocks of ', dec%block, &
        ' elements per edge give ', counted(nb, 'block'), ', fewer than the ', counted(nparts, 'part'), &
        ' (product(nsub)); use 0 (automatic) or a smaller b >= 1'
      call collective_error(msg, dec%comm, exit_input_error)
    end if
    allocate (part(nb))
    if (dec%rank == 0) then
      ! the block graph: face neighbours, ascending ids; weights = elements per block
      allocate (xadj(nb + 1), adjncy(max(1_ip, 6*nb)), weights(nb))
      nadj = 0
      xadj(1) = 1
      do k = 1, nb
        bijk = box_ijk(dec%nblock, k)
        weights(k) = block_weight(dec, bijk)
        do d = 3, 1, -1
          do c = -1, 1, 2
            nijk = bijk
            nijk(d) = nijk(d) + c
            if (nijk(d) < 0 .or. nijk(d) >= dec%nblock(d)) cycle
            nadj = nadj + 1
            adjncy(nadj) = 1 + nijk(1) + dec%nblock(1)*(nijk(2) + dec%nblock(2)*nijk(3))
          end do
        end do
        call sort_ints(adjncy(xadj(k):nadj))
        xadj(k + 1) = nadj + 1
      end do
      call metis_part_graph_kway(nb, xadj, adjncy, nparts, part, weights)
      deallocate (xadj, adjncy, weights)
    end if
    call MPI_Bcast(part, nb, MPI_INT_IP, 0, dec%comm, ierr)
    allocate (dec%block_subdomain(nb))
    call split_into_components(dec%nblock, part, nparts, dec%block_subdomain, dec%nsubdomains, nsplit, ndropped)
    deallocate (part)
    if (dec%rank == 0) then
      write (msg, '(a,i0,a,3(1x,i0),a,i0,a)') 'decomposition: METIS on blocks of ', dec%block, &
        '^3 elements (block grid', dec%nblock, ', ', nb, ' blocks)'
      call log_message(msg)
      if (nsplit > 0) then
        write (msg, '(a,i0,a,i0,a)') 'decomposition: ', nsplit, ' METIS part(s) not face-connected, '// &
          'split into their connected components (', dec%nsubdomains, ' subdomains)'
        call log_message(msg)
      end if
      if (ndropped > 0) then
        write (msg, '(a,i0,a)') 'decomposition: ', ndropped, ' empty METIS part(s) dropped'
        call log_message(msg)
      end if
    end if

    ! element counts and the blocks of every subdomain
    n = dec%nsubdomains
    allocate (dec%subdomain_nelem(n), ptr(n + 1), list(nb), next(n))
    dec%subdomain_nelem = 0
    ptr = 0
    do k = 1, nb
      s = dec%block_subdomain(k)
      dec%subdomain_nelem(s) = dec%subdomain_nelem(s) + block_weight(dec, box_ijk(dec%nblock, k))
      ptr(s + 1) = ptr(s + 1) + 1
    end do
    ptr(1) = 1
    do s = 1, n
      ptr(s + 1) = ptr(s + 1) + ptr(s)
    end do
    next = ptr(1:n)
    do k = 1, nb
      s = dec%block_subdomain(k)
      list(next(s)) = k
      next(s) = next(s) + 1
    end do
    ! the subdomain graph: elements of s and t share a node iff some blocks of
    ! s and t are within one block of each other in every direction
    allocate (dec%graph_xadj(n + 1), marker(n), dec%graph_adjncy(max(16_ip, 8*n)))
    marker = 0
    nadj = 0
    dec%graph_xadj(1) = 1
    do s = 1, n
      first = nadj + 1
      do m = ptr(s), ptr(s + 1) - 1
        bijk = box_ijk(dec%nblock, list(m))
        do dk = -1, 1
          do dj = -1, 1
            do di = -1, 1
              nijk = bijk + [di, dj, dk]
              if (any(nijk < 0) .or. any(nijk >= dec%nblock)) cycle
              t = dec%block_subdomain(1 + nijk(1) + dec%nblock(1)*(nijk(2) + dec%nblock(2)*nijk(3)))
              if (t /= s) call append_unmarked(dec%graph_adjncy, nadj, t, marker, s)
            end do
          end do
        end do
      end do
      call sort_ints(dec%graph_adjncy(first:nadj))
      dec%graph_xadj(s + 1) = nadj + 1
    end do
    dec%graph_adjncy = dec%graph_adjncy(1:nadj)
  end subroutine metis_block_partition

  !> The element lists of this rank's subdomains (ascending gids), from the
  !> blocks of those subdomains. Local: no communication.
  subroutine local_element_lists(dec)
    type(decomposition_t), intent(inout) :: dec
    integer(ip), allocatable :: next(:)
    integer(ip) :: k, ls, nl, s, bijk(3), lo(3), hi(3), i, j, kk
    nl = size(dec%local_subdomains, kind=ip)
    allocate (dec%subdomain_element_ptr(nl + 1), next(nl))
    dec%subdomain_element_ptr(1) = 1
    do ls = 1, nl
      dec%subdomain_element_ptr(ls + 1) = dec%subdomain_element_ptr(ls) + &
                                          dec%subdomain_nelem(dec%local_subdomains(ls))
    end do
    allocate (dec%subdomain_elements(dec%subdomain_element_ptr(nl + 1) - 1))
    next = dec%subdomain_element_ptr(1:nl)
    do k = 1, size(dec%block_subdomain, kind=ip)
      s = dec%block_subdomain(k)
      if (dec%subdomain_rank(s) /= dec%rank) cycle
      ls = local_position(dec, s)
      bijk = box_ijk(dec%nblock, k)
      lo = bijk*dec%block
      hi = min(lo + dec%block, dec%mesh%ng) - 1
      do kk = lo(3), hi(3)
        do j = lo(2), hi(2)
          do i = lo(1), hi(1)
            dec%subdomain_elements(next(ls)) = dec%mesh%element_gid([i, j, kk])
            next(ls) = next(ls) + 1
          end do
        end do
      end do
    end do
    if (any(next /= dec%subdomain_element_ptr(2:nl + 1))) &
      call fatal_error('decomposition: the block elements do not match the element counts')
    do ls = 1, nl
      call sort_ints(dec%subdomain_elements(dec%subdomain_element_ptr(ls):dec%subdomain_element_ptr(ls + 1) - 1))
    end do
  end subroutine local_element_lists

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

  !> Turn a partition part(c) in 1..nparts of the cells of a grid of
  !> dims(1) x dims(2) x dims(3) cells (cell id 1 + i + dims(1)*(j + dims(2)*k),
  !> 0-based i,j,k: the elements of the mesh, or the blocks) into subdomains:
  !> each face-connected component of a part becomes one subdomain, ids 1..N
  !> in the order (part, smallest cell id); empty parts give none.
  !> nsplit: parts with more than one component; ndropped: empty parts.
  subroutine split_into_components(dims, part, nparts, cell_subdomain, nsubdomains, nsplit, ndropped)
    integer(ip), intent(in) :: dims(3)
    integer(ip), intent(in) :: part(:), nparts
    integer(ip), intent(out) :: cell_subdomain(:)
    integer(ip), intent(out) :: nsubdomains, nsplit, ndropped
    integer(ip), allocatable :: label(:), queue(:), comp_part(:), ncomp_of(:), offset(:), new_id(:)
    integer(ip) :: ne, e, x, y, head, tail, ncomp, d, c, ijk(3), nijk(3)

    ne = product(dims)
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
        ijk = box_ijk(dims, x)
        do d = 1, 3
          do c = -1, 1, 2
            nijk = ijk
            nijk(d) = nijk(d) + c
            if (nijk(d) < 0 .or. nijk(d) >= dims(d)) cycle
            y = 1 + nijk(1) + dims(1)*(nijk(2) + dims(2)*nijk(3))
            if (label(y) /= 0 .or. part(y) /= part(x)) cycle
            label(y) = ncomp
            tail = tail + 1
            queue(tail) = y
          end do
        end do
      end do
    end do
    ! components in discovery order = ascending smallest cell; stable by part
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
      cell_subdomain(e) = new_id(label(e))
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
  !> Box decompositions by index arithmetic (per direction the one or two
  !> subdomain layers the node touches; ascending with k slowest), others
  !> from the subdomains of the elements around the node.
  pure subroutine node_subdomain_list(this, gid, ids, n)
    class(decomposition_t), intent(in) :: this
    integer(ip), intent(in) :: gid
    integer(ip), intent(out) :: ids(8), n
    integer(ip) :: near(27), nnear, k, s, m, pos, ijk(3), layer(2, 3), nlayer(3), d, i, j
    if (this%is_box()) then
      ijk = this%mesh%node_ijk(gid)
      layer = -1
      nlayer = 0
      do d = 1, 3
        if (ijk(d) > 0) then
          nlayer(d) = 1
          layer(1, d) = (ijk(d) - 1)/this%mesh%nel(d)
        end if
        if (ijk(d) < this%mesh%ng(d)) then
          s = ijk(d)/this%mesh%nel(d)
          if (layer(1, d) /= s) then     ! (layer(1, d) = -1 when unset)
            nlayer(d) = nlayer(d) + 1
            layer(nlayer(d), d) = s
          end if
        end if
      end do
      n = 0
      do k = 1, nlayer(3)
        do j = 1, nlayer(2)
          do i = 1, nlayer(1)
            n = n + 1
            ids(n) = 1 + layer(i, 1) + this%mesh%nsub(1)*(layer(j, 2) + this%mesh%nsub(2)*layer(k, 3))
          end do
        end do
      end do
      return
    end if
    call this%mesh%elements_near(this%mesh%node_ijk(gid), -1_ip, 0_ip, near, nnear)
    n = 0
    do k = 1, nnear
      s = this%subdomain_of_element(near(k))
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
    is_box = this%box
  end function is_box

  !> Id of the subdomain holding element `gid`, by index arithmetic (METIS:
  !> element -> block -> block_subdomain), for every element on every rank.
  pure integer(ip) function subdomain_of_element(this, gid)
    class(decomposition_t), intent(in) :: this
    integer(ip), intent(in) :: gid
    if (this%is_box()) then
      subdomain_of_element = this%mesh%box_subdomain(gid)
    else
      subdomain_of_element = this%block_subdomain(block_of_element(this, gid))
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
