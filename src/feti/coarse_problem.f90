!> The coarse problem (CP): G G^T with G = R^T B^T, assembled in distributed
!> form and factorized by MUMPS on groups of ranks; solves with it.
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
!> Rank groups (&solver coarse_ranks, the paper's subcommunicators): the P
!> ranks of the communicator form ngroups = max(1, P / c) groups of
!> consecutive ranks, c = ranks per group; rank r is in group
!> floor(r ngroups / P), so when c does not divide P the groups differ by one
!> rank at most (P = 5, c = 2: ranks {0,1,2} and {3,4}). Every group holds
!> one MUMPS factorization of the whole G G^T on its subcommunicator
!> (distributed assembled input; on a group of one rank, centralized input on
!> that rank). Each rank sends its COO entries to one member of every group
!> (point to point: a rank talks to ngroups + P/c ranks, not to all). A
!> solve gathers the group's blocks to the group's first rank (MPI_Gatherv), the first ranks of all groups exchange their
!> parts (MPI_Allgatherv), MUMPS solves on the group, and the first rank
!> scatters the solution inside the group (MPI_Scatterv). c = 1 is the old
!> 'redundant' placement (every rank factorizes alone; a solve is one
!> MPI_Allgatherv and a local MUMPS solve), c = P the old 'distributed' one
!> (one factorization on all ranks; a solve gathers to rank 0 and scatters).
!>
!> Dense factor (&solver coarse_factor): on a group of
!> one rank the whole G G^T may instead be factorized by LAPACK's dense
!> Cholesky (dpotrf; solves by dpotrs). For small coarse problems (a few
!> hundred rows) MUMPS's fixed cost per call dominates its solves (its
!> driver recomputes the size of a saved instance, duplicates and frees
!> communicators, gathers and scatters the right-hand side on every call)
!> while the dense factor of n = 384 rows is 1.2 MB; 'auto' takes the dense
!> factor up to coarse_dense_max rows (docs/TUNING.md, "The coarse problem").
module coarse_problem
  use kinds, only: dp, ip, i8, MPI_REAL_DP, MPI_INT_IP
  use decomposition, only: decomposition_t, subdomain_graph
  use metis_wrapper, only: metis_node_nd
  use constraints, only: constraints_t
  use mumps_wrapper, only: mumps_t
  use coarse_schur, only: coarse_schur_t, schur_factor_t, group_factors
  use block_hash, only: block_hash_t
  use errors, only: fatal_error
  use text, only: counted
  use timers, only: timer_start, timer_stop
  use lapack_interfaces, only: dpotrf, dpotrs, dtrsv, dgemm, dgemv
  use mpi_f08, only: MPI_Comm, MPI_Comm_rank, MPI_Comm_size, MPI_Gatherv, MPI_Scatterv, MPI_Wtime, &
                     MPI_Allgatherv, MPI_Isend, MPI_Irecv, MPI_Waitall, MPI_Request, MPI_STATUSES_IGNORE, &
                     MPI_INTEGER, MPI_INTEGER8, MPI_Allgather, MPI_Comm_split, &
                     MPI_Comm_free, MPI_COMM_NULL, MPI_UNDEFINED, MPI_IN_PLACE, &
                     MPI_Comm_split_type, MPI_COMM_TYPE_SHARED, MPI_INFO_NULL, MPI_Allreduce, MPI_MIN, MPI_MAX, MPI_SUM, &
                     MPI_Bcast, operator(/=)
  implicit none
  private

  public :: coarse_layout_t, build_coarse_layout, ensure_row_blocks, row_blocks
  public :: dense_for, gathered_counts
  public :: coarse_options_t, group_starts, choose_coarse_ranks, estimated_factor_bytes, ranks_per_node

  !> How the coarse problem is factorized (&solver coarse_ranks, coarse_blr,
  !> coarse_ooc).
  type, public :: coarse_options_t
    integer :: ranks_per_group = 0          !< c; 0 or more than the ranks: one group of all ranks
    real(dp) :: blr = 0                     !< MUMPS BLR dropping tolerance (0: full rank)
    logical :: ooc = .false.                !< MUMPS out-of-core factors
    !> 'mumps' | 'dense' (groups of one rank only) | 'auto' (dense_for)
    character(len=8) :: factor = 'mumps'
  end type coarse_options_t

  !> coarse_factor = 'auto': the dense Cholesky factor on one-rank groups up
  !> to this coarse dimension (docs/TUNING.md, "The coarse problem")
  integer(ip), parameter, public :: coarse_dense_max = 500

  !> Automatic ranks per group: the estimated factor of G G^T divided among
  !> a group's ranks should stay below this many bytes per rank (see
  !> choose_coarse_ranks and docs/INPUT.md).
  integer(i8), parameter, public :: coarse_bytes_per_rank = 1073741824_i8

  !> Above this estimated factor size the automatic group takes at least the
  !> ranks that share a node: every rank of a redundant group streams the
  !> whole factor in each solve, so ranks of one node compete for its memory
  !> bandwidth (docs/TUNING.md, "The coarse problem").
  integer(i8), parameter, public :: coarse_node_share_bytes = 4194304_i8

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
    !> the dense way (coarse_factor): the Cholesky factor U (upper, n x n) of the
    !> whole matrix on this one-rank group, in place of the MUMPS instance
    logical :: dense = .false.
    real(dp), allocatable :: ufac(:, :)
    real(dp), allocatable :: rhs(:, :)      !< (n, 1) on rank 0
    logical :: factorized = .false.
    integer :: rank = 0
    real(dp) :: seconds_factorization = 0   !< MUMPS analysis + factorization in init (or refactorize)
    !> of the last init / refactorize on this rank: assembly, pivot order, MUMPS analysis, numerical factorization
    real(dp) :: seconds_phase(4) = 0
    logical :: reusable = .false.           !< init(reusable): refactorize may follow
    integer(i8) :: pattern_hash = 0         !< of this rank's COO pattern (refactorize checks it)
    integer :: refactorizations = 0         !< refactorize calls since init
    !> low-rank update (set_update): the matrix solved with is K + V V^T, K the
    !> factorized one, V (6 nlocal, k) in local coarse blocks; W = K^{-1} V and
    !> the Cholesky factor of C = I + V^T W (k x k, every rank) for Woodbury's
    !> formula (K + V V^T)^{-1} = K^{-1} - W C^{-1} W^T
    integer :: upd_k = 0
    real(dp), allocatable :: upd_v(:, :), upd_w(:, :), upd_c(:, :)
    !> keys of the update's columns (set_update with keys; ascending, the same on every rank):
    !> the next set_update with keys reuses the columns of W whose key it holds again
    integer(i8), allocatable :: upd_keys(:)
    integer(i8) :: update_solves = 0          !< columns of W solved by set_update since init
    ! rank groups (see the module documentation)
    integer :: ngroups = 1, group = 0, group_rank = 0, group_size = 1
    type(MPI_Comm) :: group_comm            !< this rank's group (MUMPS runs on it)
    type(MPI_Comm) :: roots_comm            !< the first ranks of all groups (MPI_COMM_NULL elsewhere)
    logical :: have_comms = .false.
    integer :: group_offset = 0             !< global coarse offset of the group's first entry
    integer :: group_length = 0             !< coarse entries of the group's ranks
    integer, allocatable :: gcounts(:), gdispls(:)  !< per member: entries, offsets in the group part
    integer, allocatable :: rcounts(:), rdispls(:)  !< per group: entries, global offsets (roots)
    !> Schur mode (init with schur_positions; see coarse_schur): MUMPS leaves the
    !> coarse rows of the contact-face subdomains uneliminated; the group's host
    !> keeps their Schur complement and the Cholesky factor `sfac` solved with
    type(coarse_schur_t) :: schur
    type(schur_factor_t) :: sfac
    real(dp), allocatable :: red(:)         !< host: the reduced right-hand side
    !> (2, k): local subdomain and coarse position of this rank's rotated subdomains
    integer(ip), allocatable :: rotated(:, :)
    real(dp), allocatable :: rotated_b(:)   !< work of a Schur solve: the right-hand side, rotated
    !> a face view (make_view): solves with the factors of view_of and its own sfac
    type(coarse_problem_t), pointer :: view_of => null()
  contains
    procedure :: init
    procedure :: refactorize
    procedure :: solve
    procedure :: solve_base
    procedure :: solve_many
    procedure :: set_update
    procedure :: clear_update
    procedure :: update_rank
    procedure :: n_update_solves
    procedure :: factorization_seconds
    procedure :: factor_flops
    procedure :: phase_seconds
    procedure :: is_reusable
    procedure :: n_refactorizations
    procedure :: ranks_per_group
    procedure :: groups
    procedure :: factor_entries
    procedure :: factor_entries_effective
    procedure :: mumps_memory_mb
    procedure :: is_dense
    procedure :: has_schur
    procedure :: schur_rows
    procedure :: make_view
    procedure :: make_alias
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
  !> `options`: the rank groups and MUMPS's BLR / out-of-core settings
  !> (default: one group of all ranks, full-rank in-core factors).
  !> `reusable`: assemble on the pattern of the whole G G^T (the rows outside
  !> `mask` give explicit zeros) and keep it, so that `refactorize` can
  !> factorize G_M G_M^T for another mask M with MUMPS's numerical phase alone
  !> (the analysis of this init is reused).
  subroutine init(this, dec, con, layout, comm, mask, options, reusable, schur_positions, schur_gram)
    class(coarse_problem_t), intent(inout) :: this
    type(decomposition_t), intent(in) :: dec
    type(constraints_t), intent(inout) :: con
    type(coarse_layout_t), intent(in) :: layout
    type(MPI_Comm), intent(in) :: comm
    logical, intent(in), optional :: mask(:)
    type(coarse_options_t), intent(in), optional :: options
    logical, intent(in), optional :: reusable
    integer(ip), intent(in), optional :: schur_positions(:)
    real(dp), intent(in), optional :: schur_gram(:, :, :)
    type(coarse_options_t) :: opt
    integer(ip), allocatable :: perm(:)
    integer(ip), allocatable :: irn(:), jcn(:)
    real(dp), allocatable :: a(:)
    integer :: rank, ierr
    real(dp) :: t0

    call this%free()
    this%comm = comm
    this%layout = layout
    this%n = 6*layout%nsub
    call MPI_Comm_rank(comm, rank, ierr)
    this%rank = rank
    if (present(options)) opt = options
    this%reusable = .false.
    if (present(reusable)) this%reusable = reusable
    call make_groups(this, opt%ranks_per_group)

    this%dense = dense_for(opt%factor, this%n, this%group_size)
    if (present(schur_positions) .and. .not. this%dense) then
      call this%schur%init(layout%nsub, schur_positions, schur_gram)
      call local_rotations(this, dec)
    end if
    call timer_start('coarse: assembly')
    t0 = MPI_Wtime()
    call assemble(this, dec, con, mask, this%reusable, irn, jcn, a)
    this%pattern_hash = coo_hash(irn, jcn)
    this%nnz_local = size(a, kind=i8)
    this%seconds_phase = 0
    this%seconds_phase(1) = MPI_Wtime() - t0
    call timer_stop('coarse: assembly')
    if (this%dense) then
      call dense_factorize(this, irn, jcn, a)
      deallocate (irn, jcn, a)
      this%factorized = .true.
      allocate (this%rhs(this%n, 1))
      return
    end if
    call this%mumps%init(this%group_comm, .true.)
    if (this%group_size == 1) then
      call this%mumps%set_centralized(this%n, irn, jcn, a)
    else
      call this%mumps%set_distributed(this%n, irn, jcn, a)
    end if
    deallocate (irn, jcn, a)
    ! the pivot order: only the host of each group's instance reads it
    call timer_start('coarse: ordering')
    t0 = MPI_Wtime()
    if (this%group_rank == 0) then
      perm = coarse_ordering(dec, layout)
      if (this%schur%m > 0) call schur_last(perm, this%schur%vars)
    else
      allocate (perm(0))
    end if
    call this%mumps%set_ordering('metis', perm)
    deallocate (perm)
    if (this%schur%m > 0) call this%mumps%set_schur(this%schur%vars)
    this%seconds_phase(2) = MPI_Wtime() - t0
    call timer_stop('coarse: ordering')
    if (opt%blr > 0) call this%mumps%set_low_rank(opt%blr)
    if (opt%ooc) call this%mumps%set_out_of_core()
    call timer_start('coarse: factorization')
    call this%mumps%factorize(keep_pattern=this%reusable)
    call timer_stop('coarse: factorization')
    if (this%schur%m > 0) call take_schur(this)
    this%seconds_phase(3:4) = this%mumps%phase_seconds()
    this%seconds_factorization = sum(this%seconds_phase(3:4))
    this%factorized = .true.
    if (this%group_rank == 0) then
      allocate (this%rhs(this%n, 1))
    else
      allocate (this%rhs(1, 1))
    end if
  end subroutine init

  !> The host keeps MUMPS's Schur complement S and factorizes it (the factor
  !> G G^T's own solves use). Inside the 'coarse: factorization' timer.
  subroutine take_schur(this)
    class(coarse_problem_t), intent(inout) :: this
    real(dp) :: t0
    integer :: ierr
    call timer_start('coarse: factorization')
    t0 = MPI_Wtime()
    if (this%group_rank == 0) then
      allocate (this%schur%s(this%schur%m, this%schur%m), this%red(this%schur%m))
      call this%mumps%schur_complement(this%schur%s)
    else
      allocate (this%red(0))
    end if
    if (group_factors(this%schur%m, this%group_size)) then
      ! every rank of the group holds S: the dense factors of S and of the
      ! face matrices S - D are computed by the group together
      if (this%group_rank /= 0) allocate (this%schur%s(this%schur%m, this%schur%m))
      call MPI_Bcast(this%schur%s, int(this%schur%m)**2, MPI_REAL_DP, 0, this%group_comm, ierr)
      block
        real(dp), allocatable :: a(:, :)
        a = this%schur%s
        call this%sfac%factor_group(a, 'G G^T', this%group_comm, this%group_rank, this%group_size)
      end block
    else if (this%group_rank == 0) then
      call this%sfac%factor(this%schur%s, 'G G^T')
    end if
    this%sfac%seconds = MPI_Wtime() - t0
    call timer_stop('coarse: factorization')
  end subroutine take_schur

  !> Every rank's count n (counts) and their exclusive prefix sums (displs),
  !> as MPI_Allgatherv takes them. Collective.
  subroutine gathered_counts(n, comm, counts, displs)
    integer, intent(in) :: n
    type(MPI_Comm), intent(in) :: comm
    integer, allocatable, intent(out) :: counts(:), displs(:)
    integer :: nranks, ierr, r
    call MPI_Comm_size(comm, nranks, ierr)
    allocate (counts(nranks), displs(nranks))
    call MPI_Allgather(n, 1, MPI_INTEGER, counts, 1, MPI_INTEGER, comm, ierr)
    displs(1) = 0
    do r = 2, nranks
      displs(r) = displs(r - 1) + counts(r - 1)
    end do
  end subroutine gathered_counts

  !> This rank's subdomains with a Schur rotation (local index, position).
  subroutine local_rotations(this, dec)
    class(coarse_problem_t), intent(inout) :: this
    type(decomposition_t), intent(in) :: dec
    integer(ip) :: ls, pos, k
    allocate (this%rotated(2, size(dec%local_subdomains)))
    k = 0
    do ls = 1, size(dec%local_subdomains, kind=ip)
      pos = this%layout%position(dec%local_subdomains(ls))
      if (this%schur%which(pos) == 0) cycle
      k = k + 1
      this%rotated(:, k) = [ls, pos]
    end do
    this%rotated = this%rotated(:, 1:k)
    allocate (this%rotated_b(6*size(dec%local_subdomains)))
  end subroutine local_rotations

  !> Move the pivot positions of `vars` (global rows, ascending) to the end
  !> of the order `perm` (perm(row) = position), the others keeping theirs in
  !> sequence: MUMPS keeps Schur variables last.
  subroutine schur_last(perm, vars)
    integer(ip), intent(inout) :: perm(:)
    integer(ip), intent(in) :: vars(:)
    integer(ip), allocatable :: row_at(:)
    logical, allocatable :: is_schur(:)
    integer(ip) :: n, p, next, row
    n = size(perm, kind=ip)
    allocate (row_at(n), is_schur(n))
    is_schur = .false.
    is_schur(vars) = .true.
    do row = 1, n
      row_at(perm(row)) = row
    end do
    next = 0
    do p = 1, n
      row = row_at(p)
      if (is_schur(row)) cycle
      next = next + 1
      perm(row) = next
    end do
    do p = 1, size(vars, kind=ip)
      perm(vars(p)) = next + p
    end do
  end subroutine schur_last

  !> This instance becomes a view of `parent` (an init with schur_positions):
  !> it solves with G_M G_M^T = G G^T - D, D = sum over the rows r given of
  !> (G e_r)(G e_r)^T, from parent's MUMPS factors and a dense factor of S - D
  !> of its own. The rows come as pieces: on this rank, piece p is the part
  !> g(:, p) of G e_r on the subdomain at coarse position pos(p), keys(p)
  !> naming the row (the same on every rank). Every row must touch only
  !> subdomains with Schur rows. Collective.
  subroutine make_view(this, parent, keys, pos, g)
    class(coarse_problem_t), intent(inout) :: this
    type(coarse_problem_t), intent(in), target :: parent
    integer(i8), intent(in) :: keys(:)
    integer(ip), intent(in) :: pos(:)
    real(dp), intent(in) :: g(:, :)
    integer(i8), allocatable :: all_keys(:)
    integer(ip), allocatable :: all_pos(:)
    real(dp), allocatable :: all_g(:, :)
    integer, allocatable :: counts(:), displs(:)
    integer :: ierr, nmine, total
    real(dp) :: t0
    if (parent%schur%m == 0) call fatal_error('coarse_problem: make_view of an instance without Schur rows')
    call this%free()
    this%view_of => parent
    call timer_start('coarse: assembly')
    nmine = size(keys)
    call gathered_counts(nmine, parent%comm, counts, displs)
    total = sum(counts)
    allocate (all_keys(total), all_pos(total), all_g(6, total))
    call MPI_Allgatherv(keys, nmine, MPI_INTEGER8, all_keys, counts, displs, MPI_INTEGER8, parent%comm, ierr)
    call MPI_Allgatherv(pos, nmine, MPI_INT_IP, all_pos, counts, displs, MPI_INT_IP, parent%comm, ierr)
    call MPI_Allgatherv(g, 6*nmine, MPI_REAL_DP, all_g, 6*counts, 6*displs, MPI_REAL_DP, parent%comm, ierr)
    call timer_stop('coarse: assembly')
    call timer_start('coarse: factorization')
    t0 = MPI_Wtime()
    if (group_factors(parent%schur%m, parent%group_size)) then
      call parent%schur%downdated_factor(all_keys, all_pos, all_g, this%sfac, parent%group_comm, &
                                         parent%group_rank, parent%group_size)
    else if (parent%group_rank == 0) then
      call parent%schur%downdated_factor(all_keys, all_pos, all_g, this%sfac)
    end if
    this%sfac%seconds = MPI_Wtime() - t0
    this%seconds_factorization = this%sfac%seconds
    call timer_stop('coarse: factorization')
    this%factorized = .true.
  end subroutine make_view

  !> This instance becomes a view of `parent` that solves with parent's own
  !> matrix: a mask holding every row (no second factorization).
  subroutine make_alias(this, parent)
    class(coarse_problem_t), intent(inout) :: this
    type(coarse_problem_t), intent(in), target :: parent
    call this%free()
    this%view_of => parent
    this%seconds_factorization = 0
    this%factorized = .true.
  end subroutine make_alias

  !> x = A^{-1} b in Schur mode, A given by the dense factor `fac` of its
  !> Schur complement (this instance's MUMPS factors). Collective.
  subroutine solve_schur(this, fac, b, x)
    class(coarse_problem_t), intent(inout) :: this
    type(schur_factor_t), intent(in) :: fac
    real(dp), intent(in) :: b(:)
    real(dp), intent(out) :: x(:)
    integer(ip) :: k
    this%rotated_b(:) = b(1:size(this%rotated_b))
    do k = 1, size(this%rotated, 2, kind=ip)
      associate (ls => this%rotated(1, k))
        call this%schur%rotate(this%rotated(2, k), this%rotated_b(6*ls - 5:6*ls), .true.)
      end associate
    end do
    call gather_column(this, this%rotated_b, this%rhs(:, 1))
    call this%mumps%solve_condense(this%rhs(:, 1), this%red)
    if (this%group_rank == 0) call fac%solve(this%red)
    call this%mumps%solve_expand(this%rhs(:, 1), this%red)
    call scatter_column(this, this%rhs(:, 1), x)
    do k = 1, size(this%rotated, 2, kind=ip)
      associate (ls => this%rotated(1, k))
        call this%schur%rotate(this%rotated(2, k), x(6*ls - 5:6*ls), .false.)
      end associate
    end do
  end subroutine solve_schur

  logical function has_schur(this)
    class(coarse_problem_t), intent(in) :: this
    has_schur = this%schur%m > 0
  end function has_schur

  !> Rows kept for the Schur complement (0 without Schur mode).
  integer(ip) function schur_rows(this)
    class(coarse_problem_t), intent(in) :: this
    schur_rows = this%schur%m
  end function schur_rows

  !> G_M G_M^T for the rows of `mask` (all rows without it), factorized anew
  !> on the pattern and with the analysis of an init(reusable=.true.): the
  !> same matrix as a fresh init with `mask` gives, up to the rounding of the
  !> factorization. Collective.
  subroutine refactorize(this, dec, con, mask)
    class(coarse_problem_t), intent(inout) :: this
    type(decomposition_t), intent(in) :: dec
    type(constraints_t), intent(inout) :: con
    logical, intent(in), optional :: mask(:)
    integer(ip), allocatable :: irn(:), jcn(:)
    real(dp), allocatable :: a(:)
    real(dp) :: t0
    if (.not. (this%factorized .and. this%reusable)) &
      call fatal_error('coarse_problem: refactorize needs an init(reusable=.true.) before')
    call timer_start('coarse: assembly')
    t0 = MPI_Wtime()
    call assemble(this, dec, con, mask, .true., irn, jcn, a)
    ! the block hash sees the same blocks in the same order: the same COO
    if (size(a, kind=i8) /= this%nnz_local .or. coo_hash(irn, jcn) /= this%pattern_hash) &
      call fatal_error('coarse_problem: refactorize: the assembled pattern differs from that of init')
    this%seconds_phase = 0
    this%seconds_phase(1) = MPI_Wtime() - t0
    call timer_stop('coarse: assembly')
    call this%clear_update()
    if (this%dense) then
      call dense_factorize(this, irn, jcn, a)
      this%refactorizations = this%refactorizations + 1
      return
    end if
    call timer_start('coarse: factorization')
    call this%mumps%refactorize(a)
    call timer_stop('coarse: factorization')
    this%seconds_phase(3:4) = this%mumps%phase_seconds()
    this%seconds_factorization = sum(this%seconds_phase(3:4))
    this%refactorizations = this%refactorizations + 1
  end subroutine refactorize

  !> The COO (upper triangle) of G G^T, or of G_M G_M^T with `mask`, as the
  !> MUMPS instance of this rank's group takes it: on a group of several
  !> ranks each rank's part (distributed input), on a one-rank group the
  !> whole matrix. `full_pattern`: the rows outside `mask` give their blocks
  !> with zero values, so that the pattern is that of G G^T. Collective.
  subroutine assemble(this, dec, con, mask, full_pattern, irn, jcn, a)
    class(coarse_problem_t), intent(inout) :: this
    type(decomposition_t), intent(in) :: dec
    type(constraints_t), intent(inout) :: con
    logical, intent(in), optional :: mask(:)
    logical, intent(in) :: full_pattern
    integer(ip), allocatable, intent(out) :: irn(:), jcn(:)
    real(dp), allocatable, intent(out) :: a(:)
    integer(ip) :: i, j1, j2, nb, pos(8)
    real(dp) :: blk(6, 8)
    type(block_hash_t) :: blocks
    logical :: keep

    ! 1. the 6-blocks of every row, by copy slot, summed at the owner (once per run)
    call ensure_row_blocks(dec, con)

    ! 2. g_r g_r^T of every owned row into 6x6 blocks. The hash is sized by the blocks, not by the
    ! rows: a subdomain has at most 26 neighbours, so about 14 upper blocks (its diagonal one and
    ! one per neighbour pair), plus the pairs with other ranks' subdomains that its owned rows
    ! give; the hash grows if that is too few.
    call blocks%init(max(64_ip, 16*this%layout%nlocal))
    do i = 1, con%n_own
      keep = .true.
      if (present(mask)) keep = mask(i)
      if (.not. (keep .or. full_pattern)) cycle
      call row_blocks(con, this%layout, i, nb, pos, blk)
      if (.not. keep) blk = 0
      if (this%schur%m > 0) then
        do j1 = 1, nb
          call this%schur%rotate(pos(j1), blk(:, j1), .true.)
        end do
      end if
      do j1 = 1, nb
        do j2 = j1, nb
          call add_product(pos(j1), pos(j2), blk(:, j1), blk(:, j2))
        end do
      end do
    end do

    ! 3. COO of the upper triangle, to one member of every group
    call blocks%to_coo(irn, jcn, a)
    blocks = block_hash_t()              ! released before the factorization
    if (this%ngroups > 1) call send_to_groups(this, irn, jcn, a)

  contains

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
  end subroutine assemble

  !> Each rank's entries to one member of every group: in group g (ranks
  !> first(g) .. first(g+1)-1, size s_g) to first(g) + mod(rank, s_g). A
  !> member m of group g receives from the ranks r with mod(r, s_g) = m
  !> (about P / s_g ranks), in ascending rank order. Point to
  !> point with these ranks only (no collective over all ranks: a rank
  !> talks to ngroups + P / c peers, not to all P).
  subroutine send_to_groups(this, irn, jcn, a)
    class(coarse_problem_t), intent(in) :: this
    integer(ip), allocatable, intent(inout) :: irn(:), jcn(:)
    real(dp), allocatable, intent(inout) :: a(:)
    type(MPI_Comm) :: comm
    integer :: rank, ierr
    integer, allocatable :: first(:), sources(:), rcounts(:), rdispls(:), dests(:)
    type(MPI_Request), allocatable :: req(:)
    integer(ip), allocatable :: new_i(:), new_j(:)
    real(dp), allocatable :: new_a(:)
    integer :: nranks, g, k, nsrc, mine, member, gsize, nreq
    comm = this%comm
    rank = this%rank
    call MPI_Comm_size(comm, nranks, ierr)
    call group_starts(nranks, this%ngroups, first)
    allocate (dests(this%ngroups))
    do g = 0, this%ngroups - 1
      dests(g + 1) = first(g) + mod(rank, first(g + 1) - first(g))
    end do
    member = rank - first(this%group)
    gsize = first(this%group + 1) - first(this%group)
    sources = [(k, k = member, nranks - 1, gsize)]
    nsrc = size(sources)
    ! 1. the counts
    mine = size(a)
    allocate (rcounts(nsrc), rdispls(nsrc), req(nsrc + this%ngroups))
    do k = 1, nsrc
      call MPI_Irecv(rcounts(k), 1, MPI_INTEGER, sources(k), 1, comm, req(k), ierr)
    end do
    do g = 1, this%ngroups
      call MPI_Isend(mine, 1, MPI_INTEGER, dests(g), 1, comm, req(nsrc + g), ierr)
    end do
    call MPI_Waitall(nsrc + this%ngroups, req, MPI_STATUSES_IGNORE, ierr)
    rdispls(1) = 0
    do k = 2, nsrc
      rdispls(k) = rdispls(k - 1) + rcounts(k - 1)
    end do
    ! 2. the entries, in ascending source rank order
    allocate (new_i(sum(rcounts)), new_j(sum(rcounts)), new_a(sum(rcounts)))
    deallocate (req)
    allocate (req(3*(nsrc + this%ngroups)))
    nreq = 0
    do k = 1, nsrc
      call MPI_Irecv(new_i(rdispls(k) + 1:), rcounts(k), MPI_INT_IP, sources(k), 2, comm, req(nreq + 1), ierr)
      call MPI_Irecv(new_j(rdispls(k) + 1:), rcounts(k), MPI_INT_IP, sources(k), 3, comm, req(nreq + 2), ierr)
      call MPI_Irecv(new_a(rdispls(k) + 1:), rcounts(k), MPI_REAL_DP, sources(k), 4, comm, req(nreq + 3), ierr)
      nreq = nreq + 3
    end do
    do g = 1, this%ngroups
      call MPI_Isend(irn, mine, MPI_INT_IP, dests(g), 2, comm, req(nreq + 1), ierr)
      call MPI_Isend(jcn, mine, MPI_INT_IP, dests(g), 3, comm, req(nreq + 2), ierr)
      call MPI_Isend(a, mine, MPI_REAL_DP, dests(g), 4, comm, req(nreq + 3), ierr)
      nreq = nreq + 3
    end do
    call MPI_Waitall(nreq, req, MPI_STATUSES_IGNORE, ierr)
    call move_alloc(new_i, irn)
    call move_alloc(new_j, jcn)
    call move_alloc(new_a, a)
  end subroutine send_to_groups

  !> The nonzero 6-blocks of G^T of every owned row with their subdomains, in
  !> `con` (constraints_t g_row_*), unless they are there already. A row has
  !> one B entry per subdomain copy it touches, so every block comes whole
  !> from one rank: the blocks of owned rows are taken where they are, those
  !> of ghost rows go to the row's owner in one neighbour exchange (only the
  !> entries, not a slot per possible copy). Blocks are kept in copy-slot
  !> order. G does not change during a run, so every later coarse assembly
  !> (the faces of the polish, the standard reconstruction) reads them.
  !> Collective the first time.
  subroutine ensure_row_blocks(dec, con)
    type(decomposition_t), intent(in) :: dec
    type(constraints_t), intent(inout) :: con
    integer, parameter :: width = 8               ! slot, subdomain id, the 6-block
    integer(ip), allocatable :: count_local(:), fill(:)
    real(dp), allocatable :: ghost(:, :), received(:, :)
    integer(ip) :: ls, e, r, i, k, n_ghost, per_row, m
    integer :: ierr

    if (con%g_rows_ready) return
    n_ghost = con%n_local - con%n_own
    ! 1. entries per local row; the widest ghost row sets the exchange's width
    allocate (count_local(con%n_local))
    count_local = 0
    do ls = 1, size(con%b, kind=ip)
      associate (bs => con%b(ls))
        do e = 1, bs%nentries
          count_local(bs%row(e)) = count_local(bs%row(e)) + 1
        end do
      end associate
    end do
    per_row = 0
    if (n_ghost > 0) per_row = maxval(count_local(con%n_own + 1:))
    call MPI_Allreduce(MPI_IN_PLACE, per_row, 1, MPI_INT_IP, MPI_MAX, con%exchange%graph_comm, ierr)
    ! 2. ghost rows' entries to their owners (slot 0: unused place)
    allocate (ghost(width*max(per_row, 1_ip), n_ghost))
    ghost = 0
    allocate (fill(con%n_local))
    fill = 0
    do ls = 1, size(con%b, kind=ip)
      associate (bs => con%b(ls))
        do e = 1, bs%nentries
          r = bs%row(e)
          if (r <= con%n_own) cycle
          k = width*fill(r)
          fill(r) = fill(r) + 1
          ghost(k + 1, r - con%n_own) = bs%slot(e)
          ghost(k + 2, r - con%n_own) = dec%local_subdomains(ls)
          ghost(k + 3:k + 8, r - con%n_own) = bs%g(:, e)
        end do
      end associate
    end do
    call con%exchange%ghosts_to_owners(width*max(per_row, 1_ip), ghost, received)
    deallocate (ghost)
    ! 3. blocks per owned row: its own entries and the received ones
    do k = 1, size(received, 2, kind=ip)
      i = con%exchange%send_index(k)
      do m = 0, per_row - 1
        if (received(width*m + 1, k) > 0) count_local(i) = count_local(i) + 1
      end do
    end do
    allocate (con%g_row_first(con%n_own + 1))
    con%g_row_first(1) = 1
    do i = 1, con%n_own
      con%g_row_first(i + 1) = con%g_row_first(i) + count_local(i)
    end do
    k = con%g_row_first(con%n_own + 1) - 1
    allocate (con%g_row_slot(k), con%g_row_sub(k), con%g_row_block(6, k))
    fill(1:con%n_own) = 0
    do ls = 1, size(con%b, kind=ip)
      associate (bs => con%b(ls))
        do e = 1, bs%nentries
          if (bs%row(e) <= con%n_own) &
            call put(bs%row(e), bs%slot(e), dec%local_subdomains(ls), bs%g(:, e))
        end do
      end associate
    end do
    do k = 1, size(received, 2, kind=ip)
      do m = 0, per_row - 1
        if (received(width*m + 1, k) > 0) &
          call put(con%exchange%send_index(k), nint(received(width*m + 1, k), ip), &
                   nint(received(width*m + 2, k), ip), received(width*m + 3:width*m + 8, k))
      end do
    end do
    call drop_zero_blocks(con, fill)
    con%g_rows_ready = .true.

  contains

    !> Block (slot, sub, g) into owned row i, the row's blocks kept in slot order.
    subroutine put(i, slot, sub, g)
      integer(ip), intent(in) :: i, slot, sub
      real(dp), intent(in) :: g(6)
      integer(ip) :: first, j
      first = con%g_row_first(i)
      do j = first, first + fill(i) - 1
        if (con%g_row_slot(j) == slot) then      ! a second entry of the same copy: summed
          con%g_row_block(:, j) = con%g_row_block(:, j) + g
          return
        end if
      end do
      j = first + fill(i)
      do while (j > first)
        if (con%g_row_slot(j - 1) < slot) exit
        con%g_row_slot(j) = con%g_row_slot(j - 1)
        con%g_row_sub(j) = con%g_row_sub(j - 1)
        con%g_row_block(:, j) = con%g_row_block(:, j - 1)
        j = j - 1
      end do
      con%g_row_slot(j) = slot
      con%g_row_sub(j) = sub
      con%g_row_block(:, j) = g
      fill(i) = fill(i) + 1
    end subroutine put
  end subroutine ensure_row_blocks

  !> Keeps of each owned row's filled blocks (`filled`) those that are not
  !> exactly zero, compacting con's g_row_* lists.
  subroutine drop_zero_blocks(con, filled)
    type(constraints_t), intent(inout) :: con
    integer(ip), intent(in) :: filled(:)
    integer(ip) :: i, k, n, first
    n = 0
    do i = 1, con%n_own
      first = con%g_row_first(i)
      con%g_row_first(i) = n + 1
      do k = first, first + filled(i) - 1
        if (all(con%g_row_block(:, k) == 0)) cycle
        n = n + 1
        con%g_row_slot(n) = con%g_row_slot(k)
        con%g_row_sub(n) = con%g_row_sub(k)
        con%g_row_block(:, n) = con%g_row_block(:, k)
      end do
    end do
    con%g_row_first(con%n_own + 1) = n + 1
  end subroutine drop_zero_blocks

  !> The nonzero 6-blocks of owned row i of G^T and the coarse positions of
  !> their subdomains: blk(:, 1:nb), pos(1:nb) (ensure_row_blocks first).
  pure subroutine row_blocks(con, layout, i, nb, pos, blk)
    type(constraints_t), intent(in) :: con
    type(coarse_layout_t), intent(in) :: layout
    integer(ip), intent(in) :: i
    integer(ip), intent(out) :: nb, pos(8)
    real(dp), intent(out) :: blk(6, 8)
    integer(ip) :: k
    nb = 0
    do k = con%g_row_first(i), con%g_row_first(i + 1) - 1
      nb = nb + 1
      pos(nb) = layout%position(con%g_row_sub(k))
      blk(:, nb) = con%g_row_block(:, k)
    end do
  end subroutine row_blocks

  !> Fill-reducing pivot order of G G^T (perm(dof) = position, MUMPS PERM_IN):
  !> nested dissection of the subdomain adjacency graph (subdomains sharing a
  !> node), which is the block pattern of G G^T, each subdomain's 6 rows kept
  !> together: by planes for box subdomains (box_nested_dissection; 6% fewer
  !> factor entries and flops than METIS's at 4096 subdomains, docs/TUNING.md),
  !> else by METIS. Every rank computes the same order.
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
    if (dec%is_box()) then
      call box_nested_dissection(dec%mesh%nsub, layout, position)
    else
      call metis_node_nd(n, pxadj, padj(1:q), order, position)
    end if
    do p = 1, n
      do k = 1, 6
        perm(6*(p - 1) + k) = 6*(position(p) - 1) + k
      end do
    end do
  end function coarse_ordering

  !> Nested dissection of the box grid of subdomains by planes: a box of the
  !> grid is split at the middle plane of its longest side (with 26 neighbours
  !> one plane of subdomains separates the halves); the halves come first, the
  !> plane last. position(p): elimination place of coarse position p.
  subroutine box_nested_dissection(nsub, layout, position)
    integer(ip), intent(in) :: nsub(3)
    type(coarse_layout_t), intent(in) :: layout
    integer(ip), intent(out) :: position(:)
    integer(ip) :: next
    next = 0
    call dissect([0_ip, 0_ip, 0_ip], nsub - 1)
  contains
    recursive subroutine dissect(lo, hi)
      integer(ip), intent(in) :: lo(3), hi(3)
      integer(ip) :: d, m, i, j, k, mlo(3), mhi(3)
      if (any(hi < lo)) return
      d = maxloc(hi - lo, 1)
      if (hi(d) - lo(d) < 2) then
        do k = lo(3), hi(3)
          do j = lo(2), hi(2)
            do i = lo(1), hi(1)
              next = next + 1
              position(layout%position(1 + i + nsub(1)*(j + nsub(2)*k))) = next
            end do
          end do
        end do
        return
      end if
      m = (lo(d) + hi(d))/2
      mhi = hi
      mhi(d) = m - 1
      call dissect(lo, mhi)
      mlo = lo
      mlo(d) = m + 1
      call dissect(mlo, hi)
      mlo = lo
      mhi = hi
      mlo(d) = m
      mhi(d) = m
      call dissect(mlo, mhi)
    end subroutine dissect
  end subroutine box_nested_dissection

  !> x = A^{-1} b for local coarse blocks b (6*nlocal), A the factorized
  !> matrix, or with a low-rank update (set_update) A + V V^T by Woodbury's
  !> formula: x = A^{-1} b - W C^{-1} (V^T A^{-1} b). Collective.
  recursive subroutine solve(this, b, x)
    class(coarse_problem_t), intent(inout) :: this
    real(dp), intent(in) :: b(:)
    real(dp), intent(out) :: x(:)
    real(dp), allocatable :: t(:)
    integer :: nmine, ierr
    if (associated(this%view_of)) then
      if (allocated(this%sfac%l)) then
        call solve_schur(this%view_of, this%sfac, b, x)
      else
        call this%view_of%solve(b, x)
      end if
      return
    end if
    call this%solve_base(b, x)
    if (this%upd_k == 0) return
    nmine = 6*this%layout%nlocal
    allocate (t(this%upd_k))
    t = 0
    if (nmine > 0) call dgemv('T', nmine, this%upd_k, 1.0_dp, this%upd_v, nmine, x, 1, 0.0_dp, t, 1)
    call MPI_Allreduce(MPI_IN_PLACE, t, this%upd_k, MPI_REAL_DP, MPI_SUM, this%comm, ierr)
    call dtrsv('L', 'N', 'N', this%upd_k, this%upd_c, this%upd_k, t, 1)
    call dtrsv('L', 'T', 'N', this%upd_k, this%upd_c, this%upd_k, t, 1)
    if (nmine > 0) call dgemv('N', nmine, this%upd_k, -1.0_dp, this%upd_w, nmine, t, 1, 1.0_dp, x, 1)
  end subroutine solve

  !> X = A^{-1} B for the columns of B (local coarse blocks, 6*nlocal x m),
  !> A the factorized matrix (without an update): one MUMPS solve with m
  !> right-hand sides. Collective.
  subroutine solve_many(this, b, x)
    class(coarse_problem_t), intent(inout) :: this
    real(dp), intent(in) :: b(:, :)
    real(dp), intent(out) :: x(:, :)
    real(dp), allocatable :: rhs(:, :)
    integer :: m, j
    m = size(b, 2)
    if (m == 0) return
    if (this%schur%m > 0) then
      do j = 1, m
        call solve_schur(this, this%sfac, b(:, j), x(:, j))
      end do
      return
    end if
    if (this%group_rank == 0) then
      allocate (rhs(this%n, m))
    else
      allocate (rhs(1, m))
    end if
    do j = 1, m
      call gather_column(this, b(:, j), rhs(:, j))
    end do
    if (this%dense) then
      call dense_solve(this, rhs)
    else
      call this%mumps%solve(rhs)
    end if
    do j = 1, m
      call scatter_column(this, rhs(:, j), x(:, j))
    end do
  end subroutine solve_many

  !> From now on solve with A + V V^T, A the factorized matrix and V (6*nlocal
  !> x k, local coarse blocks; k the same on every rank): W = A^{-1} V (one
  !> solve with k right-hand sides) and the Cholesky factor of C = I + V^T W
  !> (k x k, symmetric positive definite with eigenvalues >= 1 when A is, so
  !> Woodbury's formula adds no ill-conditioning of its own).
  !> `keys` (optional; ascending, the same on every rank): a key per column of
  !> V that names it (column j is the same vector whenever keys(j) is the
  !> same). The columns of W whose key the update in place (made with keys on
  !> the same factorization) holds too are taken from it, and only the others
  !> are solved for: SMALBE's polish rounds that only project rows onto their
  !> bound cost no coarse solve here. Collective.
  subroutine set_update(this, v, keys)
    class(coarse_problem_t), intent(inout) :: this
    real(dp), intent(in) :: v(:, :)
    integer(i8), intent(in), optional :: keys(:)
    integer :: k, nmine, ierr, info, j, jo, nf
    real(dp), allocatable :: old_w(:, :), vf(:, :), wf(:, :)
    integer(i8), allocatable :: old_keys(:)
    integer, allocatable :: new_cols(:)
    logical, allocatable :: fresh(:)
    logical :: have_old
    have_old = .false.
    if (present(keys)) have_old = this%upd_k > 0 .and. allocated(this%upd_keys)
    if (have_old) then
      call move_alloc(this%upd_w, old_w)
      call move_alloc(this%upd_keys, old_keys)
    end if
    call this%clear_update()
    k = size(v, 2)
    if (k == 0) return
    if (present(keys)) then
      if (size(keys) /= k) call fatal_error('coarse_problem: set_update: one key per column of V')
    end if
    nmine = 6*this%layout%nlocal
    allocate (this%upd_v(nmine, k), this%upd_w(nmine, k), this%upd_c(k, k), fresh(k))
    this%upd_v = v(1:nmine, :)
    fresh = .true.
    if (have_old) then
      ! both key lists ascending: one merge
      jo = 1
      do j = 1, k
        do while (jo <= size(old_keys))
          if (old_keys(jo) >= keys(j)) exit
          jo = jo + 1
        end do
        if (jo > size(old_keys)) exit
        if (old_keys(jo) == keys(j)) then
          this%upd_w(:, j) = old_w(:, jo)
          fresh(j) = .false.
        end if
      end do
    end if
    nf = count(fresh)
    if (nf == k) then
      call this%solve_many(this%upd_v, this%upd_w)
    else if (nf > 0) then
      new_cols = pack([(j, j=1, k)], fresh)
      vf = this%upd_v(:, new_cols)
      allocate (wf(nmine, nf))
      call this%solve_many(vf, wf)
      this%upd_w(:, new_cols) = wf
    end if
    this%update_solves = this%update_solves + nf
    this%upd_c = 0
    if (nmine > 0) call dgemm('T', 'N', k, k, nmine, 1.0_dp, this%upd_v, nmine, this%upd_w, nmine, 0.0_dp, &
                              this%upd_c, k)
    call MPI_Allreduce(MPI_IN_PLACE, this%upd_c, k*k, MPI_REAL_DP, MPI_SUM, this%comm, ierr)
    ! symmetric in exact arithmetic: use the mean of both triangles
    this%upd_c = 0.5_dp*(this%upd_c + transpose(this%upd_c))
    do j = 1, k
      this%upd_c(j, j) = this%upd_c(j, j) + 1
    end do
    call dpotrf('L', k, this%upd_c, k, info)
    if (info /= 0) call fatal_error('coarse_problem: set_update: I + V^T A^{-1} V is not positive definite '// &
                                    '(the factorized coarse matrix is not)')
    this%upd_k = k
    if (present(keys)) this%upd_keys = keys
  end subroutine set_update

  !> Solve with the factorized matrix alone again.
  subroutine clear_update(this)
    class(coarse_problem_t), intent(inout) :: this
    this%upd_k = 0
    if (allocated(this%upd_v)) deallocate (this%upd_v)
    if (allocated(this%upd_w)) deallocate (this%upd_w)
    if (allocated(this%upd_c)) deallocate (this%upd_c)
    if (allocated(this%upd_keys)) deallocate (this%upd_keys)
  end subroutine clear_update

  !> Columns of W that set_update solved for since init (reused ones not counted).
  integer(i8) function n_update_solves(this)
    class(coarse_problem_t), intent(in) :: this
    n_update_solves = this%update_solves
  end function n_update_solves

  !> k of the low-rank update (0: none).
  integer function update_rank(this)
    class(coarse_problem_t), intent(in) :: this
    update_rank = this%upd_k
  end function update_rank

  !> Floating-point operations of the last numerical factorization (MUMPS's
  !> RINFOG(3), the whole group's).
  real(dp) function factor_flops(this)
    class(coarse_problem_t), intent(in) :: this
    if (this%dense) then
      factor_flops = real(this%n, dp)**3/3
      return
    end if
    factor_flops = this%mumps%factor_flops()
  end function factor_flops

  !> x = (G G^T)^{-1} b for local coarse blocks b (6*nlocal); x may alias b's
  !> storage only through separate actual arguments. Collective: gather to the
  !> group's first rank, exchange among the first ranks, solve on the group,
  !> scatter inside the group.
  subroutine solve_base(this, b, x)
    class(coarse_problem_t), intent(inout) :: this
    real(dp), intent(in) :: b(:)
    real(dp), intent(out) :: x(:)
    if (this%schur%m > 0) then
      call solve_schur(this, this%sfac, b, x)
      return
    end if
    call gather_column(this, b, this%rhs(:, 1))
    if (this%dense) then
      call dense_solve(this, this%rhs)
    else
      call this%mumps%solve(this%rhs)
    end if
    call scatter_column(this, this%rhs(:, 1), x)
  end subroutine solve_base

  !> The local coarse blocks b of every rank into the column `col` of the
  !> group's right-hand side (on its first rank; the others pass any column):
  !> gathered in the group, exchanged among the groups' first ranks. Collective.
  subroutine gather_column(this, b, col)
    class(coarse_problem_t), intent(inout) :: this
    real(dp), intent(in) :: b(:)
    real(dp), intent(inout) :: col(:)
    integer :: ierr, nmine, lo, hi
    nmine = 6*this%layout%nlocal
    lo = this%group_offset + 1
    hi = this%group_offset + this%group_length
    if (this%group_size == 1) then
      col(lo:lo + nmine - 1) = b(1:nmine)
    else if (this%group_rank == 0) then
      call MPI_Gatherv(b, nmine, MPI_REAL_DP, col(lo:hi), this%gcounts, this%gdispls, MPI_REAL_DP, 0, &
                       this%group_comm, ierr)
    else
      call MPI_Gatherv(b, nmine, MPI_REAL_DP, col, this%gcounts, this%gdispls, MPI_REAL_DP, 0, &
                       this%group_comm, ierr)
    end if
    if (this%group_rank == 0 .and. this%ngroups > 1) &
      call MPI_Allgatherv(MPI_IN_PLACE, 0, MPI_REAL_DP, col, this%rcounts, this%rdispls, MPI_REAL_DP, &
                          this%roots_comm, ierr)
  end subroutine gather_column

  !> The solution column `col` (on the group's first rank) back to the local
  !> coarse blocks x of every rank of the group. Collective.
  subroutine scatter_column(this, col, x)
    class(coarse_problem_t), intent(inout) :: this
    real(dp), intent(in) :: col(:)
    real(dp), intent(inout) :: x(:)
    integer :: ierr, nmine, lo, hi
    nmine = 6*this%layout%nlocal
    lo = this%group_offset + 1
    hi = this%group_offset + this%group_length
    if (this%group_size == 1) then
      x(1:nmine) = col(lo:lo + nmine - 1)
    else if (this%group_rank == 0) then
      call MPI_Scatterv(col(lo:hi), this%gcounts, this%gdispls, MPI_REAL_DP, x, nmine, MPI_REAL_DP, 0, &
                        this%group_comm, ierr)
    else
      call MPI_Scatterv(col, this%gcounts, this%gdispls, MPI_REAL_DP, x, nmine, MPI_REAL_DP, 0, &
                        this%group_comm, ierr)
    end if
  end subroutine scatter_column

  !> First rank of each group, first(0:ngroups), first(ngroups) = nranks:
  !> group g holds ranks first(g) .. first(g+1)-1, first(g) = ceil(g P /
  !> ngroups), so that rank r is in group floor(r ngroups / P) and the sizes
  !> differ by one at most.
  pure subroutine group_starts(nranks, ngroups, first)
    integer, intent(in) :: nranks, ngroups
    integer, allocatable, intent(out) :: first(:)
    integer :: g
    allocate (first(0:ngroups))
    do g = 0, ngroups
      first(g) = int((int(g, i8)*nranks + ngroups - 1)/ngroups)
    end do
  end subroutine group_starts

  !> Estimated bytes of the MUMPS factors of G G^T for `nsub` subdomains
  !> (one group's factorization, in all): nested dissection of an n^3 grid of
  !> 6x6 blocks gives O(nsub^(4/3)) factor entries. The constant is fitted to
  !> the measured box cubes (docs/TUNING.md, "The coarse problem"): 8 bytes
  !> per entry.
  pure integer(i8) function estimated_factor_bytes(nsub)
    integer(ip), intent(in) :: nsub
    real(dp), parameter :: entries_per_nsub43 = 400.0_dp
    estimated_factor_bytes = int(8*entries_per_nsub43*real(nsub, dp)**(4.0_dp/3.0_dp), i8)
  end function estimated_factor_bytes

  !> Ranks per coarse group from &solver coarse_ranks and coarse_placement on
  !> `nranks` ranks with `nsub` subdomains: 'redundant' 1, 'distributed' all
  !> ranks, coarse_ranks > 0 itself, else (auto) the fewest ranks that keep the
  !> estimated factor below coarse_bytes_per_rank per rank and, when the
  !> estimate exceeds coarse_node_share_bytes, at least `node_ranks` (the
  !> ranks sharing a node, default 1); at least 1 and at most nranks. `msg`
  !> is not empty when the value cannot be used.
  subroutine choose_coarse_ranks(coarse_ranks, placement, nranks, nsub, c, msg, node_ranks)
    integer(ip), intent(in) :: coarse_ranks
    character(len=*), intent(in) :: placement
    integer, intent(in) :: nranks
    integer(ip), intent(in) :: nsub
    integer, intent(out) :: c
    character(len=*), intent(out) :: msg
    integer, intent(in), optional :: node_ranks
    integer :: per_node
    msg = ''
    per_node = 1
    if (present(node_ranks)) per_node = max(1, node_ranks)
    select case (placement)
    case ('redundant')
      c = 1
    case ('distributed')
      c = nranks
    case default
      if (coarse_ranks > nranks) then
        write (msg, '(a,i0,3a,i0,a)') 'group &solver, variable coarse_ranks: ', coarse_ranks, &
          ' ranks per coarse group, more than the ', counted(nranks, 'MPI rank'), '; give 1 to ', nranks, &
          ' (or 0: chosen from the coarse dimension)'
        c = nranks
      else if (coarse_ranks < 0) then
        write (msg, '(a,i0,a)') 'group &solver, variable coarse_ranks: ', coarse_ranks, ' must be >= 0'
        c = 1
      else if (coarse_ranks > 0) then
        c = int(coarse_ranks)
      else
        c = int(min(int(nranks, i8), max(1_i8, &
                (estimated_factor_bytes(nsub) + coarse_bytes_per_rank - 1)/coarse_bytes_per_rank)))
        if (estimated_factor_bytes(nsub) > coarse_node_share_bytes) c = max(c, min(per_node, nranks))
      end if
    end select
  end subroutine choose_coarse_ranks

  !> The number of ranks of `comm` that share a node with each other (the
  !> smallest over the nodes, so that every rank gets the same value).
  !> Collective.
  integer function ranks_per_node(comm) result(n)
    type(MPI_Comm), intent(in) :: comm
    type(MPI_Comm) :: node
    integer :: rank, local, ierr
    call MPI_Comm_rank(comm, rank, ierr)
    call MPI_Comm_split_type(comm, MPI_COMM_TYPE_SHARED, rank, MPI_INFO_NULL, node, ierr)
    call MPI_Comm_size(node, local, ierr)
    call MPI_Comm_free(node, ierr)
    call MPI_Allreduce(local, n, 1, MPI_INTEGER, MPI_MIN, comm, ierr)
  end function ranks_per_node

  !> The group communicators for `c` ranks per group (c <= 0 or c >= P: one
  !> group). Collective over this%comm.
  subroutine make_groups(this, c)
    class(coarse_problem_t), intent(inout) :: this
    integer, intent(in) :: c
    integer :: nranks, rank, ierr, color, g, first_member
    integer, allocatable :: first(:)
    call MPI_Comm_size(this%comm, nranks, ierr)
    call MPI_Comm_rank(this%comm, rank, ierr)
    if (c <= 0 .or. c >= nranks) then
      this%ngroups = 1
    else
      this%ngroups = nranks/c
    end if
    call group_starts(nranks, this%ngroups, first)
    this%group = int((int(rank, i8)*this%ngroups)/nranks)
    call MPI_Comm_split(this%comm, this%group, rank, this%group_comm, ierr)
    call MPI_Comm_rank(this%group_comm, this%group_rank, ierr)
    call MPI_Comm_size(this%group_comm, this%group_size, ierr)
    color = MPI_UNDEFINED
    if (this%group_rank == 0) color = 0
    call MPI_Comm_split(this%comm, color, rank, this%roots_comm, ierr)
    this%have_comms = .true.
    first_member = first(this%group)
    this%group_offset = this%layout%displs(first_member + 1)
    this%gcounts = this%layout%counts(first_member + 1:first(this%group + 1))
    this%gdispls = this%layout%displs(first_member + 1:first(this%group + 1)) - this%group_offset
    this%group_length = sum(this%gcounts)
    allocate (this%rcounts(this%ngroups), this%rdispls(this%ngroups))
    do g = 0, this%ngroups - 1
      this%rdispls(g + 1) = this%layout%displs(first(g) + 1)
      this%rcounts(g + 1) = sum(this%layout%counts(first(g) + 1:first(g + 1)))
    end do
  end subroutine make_groups

  !> Seconds of the MUMPS analysis and factorization in `init`.
  real(dp) function factorization_seconds(this)
    class(coarse_problem_t), intent(in) :: this
    factorization_seconds = this%seconds_factorization
  end function factorization_seconds

  !> Seconds of the last init or refactorize on this rank: assembly (with
  !> the exchange to the groups), pivot order, MUMPS analysis (0 after
  !> refactorize: reused), numerical factorization.
  function phase_seconds(this) result(seconds)
    class(coarse_problem_t), intent(in) :: this
    real(dp) :: seconds(4)
    seconds = this%seconds_phase
  end function phase_seconds

  !> Initialized with reusable = .true. (refactorize may be called).
  logical function is_reusable(this)
    class(coarse_problem_t), intent(in) :: this
    is_reusable = this%factorized .and. this%reusable
  end function is_reusable

  !> refactorize calls since init.
  integer function n_refactorizations(this)
    class(coarse_problem_t), intent(in) :: this
    n_refactorizations = this%refactorizations
  end function n_refactorizations

  !> A hash of a COO pattern (index sequence, order included).
  pure integer(i8) function coo_hash(irn, jcn) result(h)
    integer(ip), intent(in) :: irn(:), jcn(:)
    integer(i8), parameter :: modulus = 2147483647_i8
    integer(i8) :: k
    h = size(irn, kind=i8)
    do k = 1, size(irn, kind=i8)
      h = mod(h*31_i8 + int(irn(k), i8)*7919_i8 + int(jcn(k), i8), modulus)
    end do
  end function coo_hash

  !> Ranks in this rank's group (the size of its MUMPS communicator).
  integer function ranks_per_group(this)
    class(coarse_problem_t), intent(in) :: this
    ranks_per_group = this%group_size
  end function ranks_per_group

  !> Number of groups (factorizations of G G^T).
  integer function groups(this)
    class(coarse_problem_t), intent(in) :: this
    groups = this%ngroups
  end function groups

  !> Entries of this group's factors (full rank), summed over its ranks.
  integer(i8) function factor_entries(this)
    class(coarse_problem_t), intent(in) :: this
    if (this%dense) then
      factor_entries = int(this%n, i8)*(this%n + 1)/2
      return
    end if
    factor_entries = this%mumps%factor_entries()
  end function factor_entries

  !> Entries of this group's factors after BLR compression.
  integer(i8) function factor_entries_effective(this)
    class(coarse_problem_t), intent(in) :: this
    if (this%dense) then
      factor_entries_effective = int(this%n, i8)*(this%n + 1)/2
      return
    end if
    factor_entries_effective = this%mumps%factor_entries_effective()
  end function factor_entries_effective

  !> MB MUMPS used in the factorization: the most on one rank of the group,
  !> the sum over the group.
  function mumps_memory_mb(this) result(mb)
    class(coarse_problem_t), intent(in) :: this
    integer(i8) :: mb(2)
    if (this%dense) then
      mb = (8*int(this%n, i8)**2 + 999999)/1000000
      return
    end if
    mb = this%mumps%memory_mb()
  end function mumps_memory_mb

  !> Factorized by the dense Cholesky (coarse_factor) instead of MUMPS.
  logical function is_dense(this)
    class(coarse_problem_t), intent(in) :: this
    is_dense = this%dense
  end function is_dense

  !> Whether a group of `group_size` ranks factorizes a coarse matrix of
  !> dimension n densely for &solver coarse_factor = `factor`: 'dense' on a
  !> one-rank group, 'auto' there up to coarse_dense_max rows, else MUMPS.
  pure logical function dense_for(factor, n, group_size)
    character(len=*), intent(in) :: factor
    integer(ip), intent(in) :: n
    integer, intent(in) :: group_size
    dense_for = group_size == 1 .and. (factor == 'dense' .or. (factor == 'auto' .and. n <= coarse_dense_max))
  end function dense_for

  !> The dense way: the whole upper-triangle COO of this one-rank group
  !> (entries of the same position summed, as MUMPS sums them) into U, then
  !> U^T U = A by LAPACK dpotrf. G G^T (and every G_M G_M^T the polish and
  !> the reconstruction factorize) is symmetric positive definite when the
  !> rows of G are independent, as for MUMPS's SPD mode; a failure is fatal.
  subroutine dense_factorize(this, irn, jcn, a)
    class(coarse_problem_t), intent(inout) :: this
    integer(ip), intent(in) :: irn(:), jcn(:)
    real(dp), intent(in) :: a(:)
    integer(i8) :: e
    integer :: info
    real(dp) :: t0
    character(len=160) :: msg
    call timer_start('coarse: factorization')
    t0 = MPI_Wtime()
    if (.not. allocated(this%ufac)) allocate (this%ufac(this%n, this%n))
    this%ufac = 0
    do e = 1, size(a, kind=i8)
      associate (i => min(irn(e), jcn(e)), j => max(irn(e), jcn(e)))
        this%ufac(i, j) = this%ufac(i, j) + a(e)
      end associate
    end do
    call dpotrf('U', int(this%n), this%ufac, int(this%n), info)
    if (info /= 0) then
      write (msg, '(a,i0,a,i0,a)') 'coarse_problem: the dense Cholesky factorization of the coarse matrix '// &
        '(dimension ', this%n, ') failed at pivot ', info, ': it is not positive definite'
      call fatal_error(trim(msg))
    end if
    this%seconds_phase(3) = 0
    this%seconds_phase(4) = MPI_Wtime() - t0
    this%seconds_factorization = this%seconds_phase(4)
    call timer_stop('coarse: factorization')
  end subroutine dense_factorize

  !> rhs <- A^{-1} rhs (all columns) with the dense factor.
  subroutine dense_solve(this, rhs)
    class(coarse_problem_t), intent(inout) :: this
    real(dp), intent(inout) :: rhs(:, :)
    integer :: info
    call dpotrs('U', int(this%n), size(rhs, 2), this%ufac, int(this%n), rhs, size(rhs, 1), info)
    if (info /= 0) call fatal_error('coarse_problem: LAPACK dpotrs failed')
  end subroutine dense_solve

  subroutine free(this)
    class(coarse_problem_t), intent(inout) :: this
    integer :: ierr
    if (associated(this%view_of)) then
      this%view_of => null()
      this%factorized = .false.
      if (allocated(this%sfac%l)) deallocate (this%sfac%l)
      return
    end if
    call this%schur%free()
    if (allocated(this%sfac%l)) deallocate (this%sfac%l)
    if (allocated(this%red)) deallocate (this%red)
    if (allocated(this%rotated)) deallocate (this%rotated)
    if (allocated(this%rotated_b)) deallocate (this%rotated_b)
    if (this%factorized .and. .not. this%dense) call this%mumps%free()
    if (allocated(this%ufac)) deallocate (this%ufac)
    this%dense = .false.
    this%factorized = .false.
    this%reusable = .false.
    this%refactorizations = 0
    this%pattern_hash = 0
    call this%clear_update()
    this%update_solves = 0
    if (allocated(this%rhs)) deallocate (this%rhs)
    if (this%have_comms) then
      ! after MUMPS's JOB = -2: MUMPS uses the group communicator until then
      call MPI_Comm_free(this%group_comm, ierr)
      if (this%roots_comm /= MPI_COMM_NULL) call MPI_Comm_free(this%roots_comm, ierr)
      this%have_comms = .false.
    end if
    if (allocated(this%gcounts)) deallocate (this%gcounts, this%gdispls)
    if (allocated(this%rcounts)) deallocate (this%rcounts, this%rdispls)
    this%ngroups = 1
    this%group_size = 1
    this%group_rank = 0
  end subroutine free

end module coarse_problem
