!> The coarse problem (CP): G G^T with G = R^T B^T, assembled in distributed
!> form and factorized once by MUMPS; solves with it.
!>
!> Coarse vectors have 6 entries per subdomain. Each rank stores the blocks of
!> its own subdomains ("local coarse blocks", in the order of its local
!> subdomain list). The global coarse numbering is rank-major (all subdomains
!> of rank 0, then of rank 1, ...), so a gather of the local blocks to rank 0
!> gives a global vector without any permutation.
!>
!> Assembly: every multiplier row r contributes g_r g_r^T, where g_r has one
!> 6-block per subdomain copy the row touches (the entries val * R^s(dof, :)
!> of G^T). The blocks of a row are summed at its owner with one
!> neighbour exchange (8 slots of 6 values per row), and the owner adds the
!> 6x6 products into a hash of (s, t) blocks. MUMPS sums the blocks different
!> ranks give for the same (s, t) (distributed assembled input).
!> An optional row mask restricts the sum to some rows: the standard
!> reconstruction's G_A G_A^T uses the same code.
!>
!> Placement (&solver coarse_placement): 'distributed' factorizes with MUMPS
!> on all ranks of the communicator (distributed input, centralized RHS on
!> rank 0, solution scattered back); 'redundant' gathers the matrix on every
!> rank and factorizes it there on MPI_COMM_SELF, so that a solve is one
!> MPI_Allgatherv of the right-hand side and a local MUMPS solve, with no
!> message inside MUMPS.
module coarse_problem
  use kinds, only: dp, ip, i8, MPI_REAL_DP, MPI_INT_IP
  use decomposition, only: decomposition_t, subdomain_graph
  use metis_wrapper, only: metis_node_nd
  use constraints, only: constraints_t
  use mumps_wrapper, only: mumps_t
  use block_hash, only: block_hash_t
  use mpi_f08, only: MPI_Comm, MPI_Comm_rank, MPI_Comm_size, MPI_Gatherv, MPI_Scatterv, MPI_Wtime, &
                     MPI_Allgather, MPI_Allgatherv, MPI_INTEGER, MPI_COMM_SELF
  implicit none
  private

  public :: coarse_layout_t, build_coarse_layout, owned_row_blocks, row_blocks

  !> Where the coarse blocks of every subdomain live.
  type :: coarse_layout_t
    integer(ip) :: nsub = 0                 !< subdomains in all
    integer(ip) :: nlocal = 0               !< subdomains of this rank
    integer(ip), allocatable :: position(:) !< subdomain id -> global coarse position 1..nsub
    integer, allocatable :: counts(:), displs(:)  !< per rank: 6*subdomains and offsets (Gatherv)
  end type coarse_layout_t

  type, public :: coarse_problem_t
    private
    type(MPI_Comm) :: comm
    type(coarse_layout_t) :: layout
    integer(ip) :: n = 0                    !< coarse dimension 6*nsub
    integer(i8) :: nnz_local = 0            !< entries this rank gave to MUMPS
    type(mumps_t) :: mumps
    real(dp), allocatable :: rhs(:, :)      !< (n, 1) on rank 0
    logical :: factorized = .false.
    logical :: redundant = .false.          !< every rank holds the whole factorization
    integer :: rank = 0
    real(dp) :: seconds_factorization = 0   !< MUMPS analysis + factorization in init
  contains
    procedure :: init
    procedure :: solve
    procedure :: factorization_seconds
    procedure :: free
  end type coarse_problem_t

contains

  !> The rank-major coarse numbering for the decomposition `dec`.
  subroutine build_coarse_layout(dec, comm, layout)
    type(decomposition_t), intent(in) :: dec
    type(MPI_Comm), intent(in) :: comm
    type(coarse_layout_t), intent(out) :: layout
    integer :: nranks, ierr, r
    integer(ip) :: s, pos
    integer(ip), allocatable :: per_rank(:)

    call MPI_Comm_size(comm, nranks, ierr)
    layout%nsub = dec%nsubdomains
    layout%nlocal = size(dec%local_subdomains, kind=ip)
    allocate (layout%position(layout%nsub), per_rank(0:nranks - 1), layout%counts(nranks), &
              layout%displs(nranks))
    per_rank = 0
    do s = 1, layout%nsub
      per_rank(dec%subdomain_rank(s)) = per_rank(dec%subdomain_rank(s)) + 1
    end do
    layout%displs(1) = 0
    do r = 1, nranks
      layout%counts(r) = 6*per_rank(r - 1)
      if (r > 1) layout%displs(r) = layout%displs(r - 1) + layout%counts(r - 1)
    end do
    ! position: rank-major, ascending id within a rank
    per_rank = 0
    do r = 0, nranks - 1
      if (r > 0) per_rank(r) = per_rank(r - 1) + layout%counts(r)/6
    end do
    do s = 1, layout%nsub
      r = dec%subdomain_rank(s)
      pos = per_rank(r) + 1
      per_rank(r) = pos
      layout%position(s) = pos
    end do
  end subroutine build_coarse_layout

  !> Assemble G G^T (or G_A G_A^T with `mask`) and factorize it. `con%b(:)%g`
  !> must hold the entries of G^T. Collective.
  subroutine init(this, dec, con, layout, comm, mask, placement)
    class(coarse_problem_t), intent(inout) :: this
    type(decomposition_t), intent(in) :: dec
    type(constraints_t), intent(inout) :: con
    type(coarse_layout_t), intent(in) :: layout
    type(MPI_Comm), intent(in) :: comm
    logical, intent(in), optional :: mask(:)
    character(len=*), intent(in), optional :: placement
    real(dp), allocatable :: slots_own(:, :)
    integer(ip), allocatable :: irn(:), jcn(:)
    real(dp), allocatable :: a(:)
    integer(ip) :: i, j1, j2, nb, pos(8)
    real(dp) :: blk(6, 8)
    integer :: rank, ierr
    type(block_hash_t) :: blocks
    real(dp) :: t0

    call this%free()
    this%comm = comm
    this%layout = layout
    this%n = 6*layout%nsub
    call MPI_Comm_rank(comm, rank, ierr)

    ! 1. the 6-blocks of every row, by copy slot, summed at the owner
    call owned_row_blocks(con, slots_own)

    ! 2. g_r g_r^T of every owned row into 6x6 blocks
    call blocks%init(max(64_ip, 8*layout%nlocal + con%n_own/4))
    do i = 1, con%n_own
      if (present(mask)) then
        if (.not. mask(i)) cycle
      end if
      call row_blocks(dec, con, layout, slots_own, i, nb, pos, blk)
      do j1 = 1, nb
        do j2 = j1, nb
          call add_product(pos(j1), pos(j2), blk(:, j1), blk(:, j2))
        end do
      end do
    end do

    ! 3. COO of the upper triangle, to MUMPS
    call blocks%to_coo(irn, jcn, a)
    this%nnz_local = size(a, kind=i8)
    this%rank = rank
    this%redundant = .false.
    if (present(placement)) this%redundant = placement == 'redundant'
    if (this%redundant) then
      call gather_everywhere(irn, jcn, a)
      call this%mumps%init(MPI_COMM_SELF, .true.)
      call this%mumps%set_centralized(this%n, irn, jcn, a)
    else
      call this%mumps%init(comm, .true.)
      call this%mumps%set_distributed(this%n, irn, jcn, a)
    end if
    call this%mumps%set_ordering('metis', coarse_ordering(dec, layout))
    t0 = MPI_Wtime()
    call this%mumps%factorize()
    this%seconds_factorization = MPI_Wtime() - t0
    this%factorized = .true.
    if (rank == 0 .or. this%redundant) then
      allocate (this%rhs(this%n, 1))
    else
      allocate (this%rhs(1, 1))
    end if

  contains

    !> Every rank gets all ranks' COO entries.
    subroutine gather_everywhere(irn, jcn, a)
      integer(ip), allocatable, intent(inout) :: irn(:), jcn(:)
      real(dp), allocatable, intent(inout) :: a(:)
      integer, allocatable :: counts(:), displs(:)
      integer(ip), allocatable :: all_i(:), all_j(:)
      real(dp), allocatable :: all_a(:)
      integer :: nranks, r, mine
      call MPI_Comm_size(comm, nranks, ierr)
      allocate (counts(nranks), displs(nranks))
      mine = size(a)
      call MPI_Allgather(mine, 1, MPI_INTEGER, counts, 1, MPI_INTEGER, comm, ierr)
      displs(1) = 0
      do r = 2, nranks
        displs(r) = displs(r - 1) + counts(r - 1)
      end do
      allocate (all_i(sum(counts)), all_j(sum(counts)), all_a(sum(counts)))
      call MPI_Allgatherv(irn, mine, MPI_INT_IP, all_i, counts, displs, MPI_INT_IP, comm, ierr)
      call MPI_Allgatherv(jcn, mine, MPI_INT_IP, all_j, counts, displs, MPI_INT_IP, comm, ierr)
      call MPI_Allgatherv(a, mine, MPI_REAL_DP, all_a, counts, displs, MPI_REAL_DP, comm, ierr)
      call move_alloc(all_i, irn)
      call move_alloc(all_j, jcn)
      call move_alloc(all_a, a)
    end subroutine gather_everywhere

    !> block(ps, pt) += u v^T, kept as an upper-triangular block pair
    subroutine add_product(ps, pt, u, v)
      integer(ip), intent(in) :: ps, pt
      real(dp), intent(in) :: u(6), v(6)
      real(dp) :: outer(6, 6)
      integer :: a1, a2
      do a2 = 1, 6
        do a1 = 1, 6
          outer(a1, a2) = u(a1)*v(a2)
        end do
      end do
      if (ps <= pt) then
        call blocks%add(ps, pt, outer)
      else
        call blocks%add(pt, ps, transpose(outer))
      end if
    end subroutine add_product
  end subroutine init

  !> The column of G of every owned row, by copy slot: slots(6(j-1)+1:6j, i) is
  !> the 6-block of row i on the j-th subdomain copy of its node (zero where
  !> the row does not touch that copy). Each rank computes the blocks of its
  !> own subdomains; one neighbour scatter-add sums them at the row's owner.
  subroutine owned_row_blocks(con, slots_own)
    type(constraints_t), intent(inout) :: con
    real(dp), allocatable, intent(out) :: slots_own(:, :)
    real(dp), allocatable :: slots_local(:, :)
    integer(ip) :: ls, e, i
    allocate (slots_local(48, con%n_local), slots_own(48, con%n_own))
    slots_local = 0
    do ls = 1, size(con%b, kind=ip)
      associate (bs => con%b(ls))
        do e = 1, bs%nentries
          i = 6*(bs%slot(e) - 1)
          slots_local(i + 1:i + 6, bs%row(e)) = slots_local(i + 1:i + 6, bs%row(e)) + bs%g(:, e)
        end do
      end associate
    end do
    call con%exchange%scatter_add_multi(48, slots_local, slots_own)
  end subroutine owned_row_blocks

  !> The nonzero 6-blocks of owned row i of G^T and the coarse positions of
  !> their subdomains: blk(:, 1:nb), pos(1:nb).
  subroutine row_blocks(dec, con, layout, slots_own, i, nb, pos, blk)
    type(decomposition_t), intent(in) :: dec
    type(constraints_t), intent(in) :: con
    type(coarse_layout_t), intent(in) :: layout
    real(dp), intent(in) :: slots_own(:, :)
    integer(ip), intent(in) :: i
    integer(ip), intent(out) :: nb, pos(8)
    real(dp), intent(out) :: blk(6, 8)
    integer(ip) :: copies(8), ncopies, j
    call dec%node_subdomain_list(con%node(i), copies, ncopies)
    nb = 0
    do j = 1, ncopies
      if (all(slots_own(6*j - 5:6*j, i) == 0)) cycle
      nb = nb + 1
      pos(nb) = layout%position(copies(j))
      blk(:, nb) = slots_own(6*j - 5:6*j, i)
    end do
  end subroutine row_blocks

  !> Fill-reducing pivot order of G G^T (perm(dof) = position, MUMPS PERM_IN):
  !> METIS nested dissection of the subdomain adjacency graph (subdomains
  !> sharing a node), which is the block pattern of G G^T, each subdomain's 6
  !> rows kept together. Every rank computes the same order.
  function coarse_ordering(dec, layout) result(perm)
    type(decomposition_t), intent(in) :: dec
    type(coarse_layout_t), intent(in) :: layout
    integer(ip), allocatable :: perm(:)
    integer(ip), allocatable :: xadj(:), adjncy(:), pxadj(:), padj(:), id_at(:), order(:), position(:)
    integer(ip) :: n, p, s, k, q
    call subdomain_graph(dec, xadj, adjncy)
    n = layout%nsub
    allocate (id_at(n), pxadj(n + 1), padj(size(adjncy)), order(n), position(n), perm(6*n))
    do s = 1, n
      id_at(layout%position(s)) = s
    end do
    ! the same graph with vertices numbered by coarse position
    pxadj(1) = 1
    q = 0
    do p = 1, n
      s = id_at(p)
      do k = xadj(s), xadj(s + 1) - 1
        q = q + 1
        padj(q) = layout%position(adjncy(k))
      end do
      pxadj(p + 1) = q + 1
    end do
    call metis_node_nd(n, pxadj, padj(1:q), order, position)
    do p = 1, n
      do k = 1, 6
        perm(6*(p - 1) + k) = 6*(position(p) - 1) + k
      end do
    end do
  end function coarse_ordering

  !> x = (G G^T)^{-1} b for local coarse blocks b (6*nlocal); x may alias b's
  !> storage only through separate actual arguments. Collective.
  subroutine solve(this, b, x)
    class(coarse_problem_t), intent(inout) :: this
    real(dp), intent(in) :: b(:)
    real(dp), intent(out) :: x(:)
    integer :: ierr, first
    if (this%redundant) then
      call MPI_Allgatherv(b, 6*this%layout%nlocal, MPI_REAL_DP, this%rhs, this%layout%counts, &
                          this%layout%displs, MPI_REAL_DP, this%comm, ierr)
      call this%mumps%solve(this%rhs)
      first = this%layout%displs(this%rank + 1)
      x(1:6*this%layout%nlocal) = this%rhs(first + 1:first + 6*this%layout%nlocal, 1)
    else
      call MPI_Gatherv(b, 6*this%layout%nlocal, MPI_REAL_DP, this%rhs, this%layout%counts, &
                       this%layout%displs, MPI_REAL_DP, 0, this%comm, ierr)
      call this%mumps%solve(this%rhs)
      call MPI_Scatterv(this%rhs, this%layout%counts, this%layout%displs, MPI_REAL_DP, x, &
                        6*this%layout%nlocal, MPI_REAL_DP, 0, this%comm, ierr)
    end if
  end subroutine solve

  !> Seconds of the MUMPS analysis and factorization in `init`.
  real(dp) function factorization_seconds(this)
    class(coarse_problem_t), intent(in) :: this
    factorization_seconds = this%seconds_factorization
  end function factorization_seconds

  subroutine free(this)
    class(coarse_problem_t), intent(inout) :: this
    if (this%factorized) call this%mumps%free()
    this%factorized = .false.
    if (allocated(this%rhs)) deallocate (this%rhs)
  end subroutine free

end module coarse_problem
