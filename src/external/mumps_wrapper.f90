!> MUMPS 5.5 (double precision, Debian's libmumps-dev) behind a small type.
!>
!> The only module that includes 'dmumps_struc.h'. One `mumps_t` is one MUMPS
!> instance on one communicator: the local K^+ of a subdomain lives on
!> MPI_COMM_SELF, the coarse problem on the communicator of the run.
!>
!> Life cycle (collective over the communicator unless said otherwise):
!>
!>     call m%init(comm, spd=.true.)                 ! JOB = -1
!>     call m%set_centralized(n, irn, jcn, a)        ! host only, or
!>     call m%set_distributed(n, irn_loc, jcn_loc, a_loc)  ! every rank
!>     call m%set_ordering('amd')                    ! or ('metis', perm) ...
!>     call m%factorize()                            ! JOB = 1 then JOB = 2
!>     call m%refactorize(a)                         ! JOB = 2 only: new values, same pattern
!>                                                   ! (after factorize(keep_pattern=.true.))
!>     call m%solve(rhs)                             ! JOB = 3, rhs on the host
!>     call m%free()                                 ! JOB = -2
!>
!> Choices:
!> - PAR = 1 (the host works), SYM = 1 for SPD (Cholesky-like LDL^T without
!>   pivoting), SYM = 2 for general symmetric. For SYM = 1 and 2 give one
!>   triangle (either one per entry pair); duplicates are summed by MUMPS.
!> - Nothing is printed unless MUMPS meets an error (ICNTL(1) = 6, ICNTL(2:3)
!>   off, ICNTL(4) = 1); `verbose` turns on MUMPS's statistics.
!> - The wrapper copies the matrix into arrays it owns and points MUMPS at
!>   them; they are released after the factorization (no iterative refinement
!>   nor error analysis is used, so the solve phase never reads them). A new
!>   set_* + factorize refactorizes (a new analysis each time).
!>   `factorize(keep_pattern=.true.)` keeps them instead, and `refactorize(a)`
!>   then factorizes new values on the same pattern (same entry order) with
!>   JOB = 2 alone: MUMPS keeps the analysis (ordering, symbolic
!>   factorization, mapping) until the next JOB = 1 or -2, and its
!>   factorization phase reads the matrix (IRN, JCN, A on the host, or
!>   IRN_loc, JCN_loc, A_loc on every rank) anew.
!> - A factorization that runs out of MUMPS's estimated workspace (-8, -9, -17,
!>   -20) is retried with a larger ICNTL(14), as the MUMPS guide advises.
!> - Every MUMPS error (INFOG(1) < 0) is fatal: `fatal_error` with INFOG(1),
!>   INFOG(2) and a short explanation. Warnings (INFOG(1) > 0) are ignored.
!> - The MUMPS structure (16 KB) is allocated on the heap, so moving a
!>   `mumps_t` (for example in an array of subdomain solvers) never moves it.
!>   A `mumps_t` must not be copied by assignment (the copy would share the
!>   instance; freeing both would free it twice).
!> - Each instance holds three communicators that MUMPS derives from `comm`
!>   in JOB = -1 (measured: Open MPI 4.1's 16-bit communicator ids allow
!>   about 21,800 live instances per process; 4096 are fine).
!> - Cost per MUMPS call, measured with MUMPS 5.5.1 on a 24-dof system:
!>   ~45 us per solve, ~70% of it in DMUMPS_COMPUTE_MEMORY_SAVE, which the
!>   MUMPS driver runs on every call (no control parameter turns it off).
!>   Batch right-hand sides (solve with rhs(:,:)) where possible.
!> - Resident memory of an instance: ~52 KiB fixed (this structure, the
!>   communicators, MUMPS's bookkeeping) plus the factors, MUMPS's copy of the
!>   matrix and its workspace.
module mumps_wrapper
  use kinds, only: dp, ip, i8
  use errors, only: fatal_error
  use mpi_f08, only: MPI_Comm, MPI_Comm_rank, MPI_Comm_size, MPI_Allreduce, MPI_INTEGER, MPI_MAX, MPI_Wtime
  implicit none
  private

  include 'dmumps_struc.h'

  interface
    !> The MUMPS driver (Fortran 90 interface, implicit in the library).
    subroutine dmumps(id)
      import :: DMUMPS_STRUC
      type(DMUMPS_STRUC), intent(inout) :: id
    end subroutine dmumps
  end interface

  integer, parameter :: job_init = -1, job_end = -2, job_analyse = 1, job_factorize = 2, job_solve = 3
  integer, parameter :: max_workspace_retries = 5

  !> One MUMPS instance. See the module documentation for the call sequence.
  type, public :: mumps_t
    private
    type(DMUMPS_STRUC), pointer :: id => null()
    type(MPI_Comm) :: comm
    integer :: rank = -1                    !< rank in comm (0 = host)
    integer :: nranks = 0                   !< size of comm
    integer :: n = 0                        !< order of the matrix
    logical :: spd = .false.
    logical :: factorized = .false.
    logical :: pattern_kept = .false.       !< analysed, the matrix arrays kept for refactorize
    real(dp) :: seconds(2) = 0              !< of the last factorize / refactorize: analysis, numeric factorization
    ! Arrays owned by the wrapper; MUMPS's pointers point at them.
    integer, pointer, contiguous :: irn(:) => null(), jcn(:) => null(), perm(:) => null()
    real(dp), pointer, contiguous :: a(:) => null()
    real(dp), pointer, contiguous :: rhs(:) => null()   !< solve buffer, grows, never shrinks
    integer, pointer, contiguous :: schur_vars(:) => null()   !< Schur variables (set_schur)
    real(dp), pointer, contiguous :: schur(:) => null()       !< the Schur complement, by columns
  contains
    procedure :: init
    procedure :: set_centralized
    procedure :: set_distributed
    procedure :: set_ordering
    procedure :: set_block_size
    procedure :: set_schur
    procedure :: schur_complement
    procedure :: solve_condense
    procedure :: solve_expand
    procedure :: set_low_rank
    procedure :: set_out_of_core
    procedure :: factorize
    procedure :: refactorize
    procedure :: phase_seconds
    procedure, private :: solve_matrix
    procedure, private :: solve_vector
    generic :: solve => solve_matrix, solve_vector
    procedure :: factor_bytes
    procedure :: factor_entries
    procedure :: factor_flops
    procedure :: factor_entries_effective
    procedure :: memory_mb
    procedure :: order
    procedure :: is_factorized
    procedure :: free
  end type mumps_t

contains

  !> Start a MUMPS instance on `comm` (collective). `spd`: the matrix is
  !> symmetric positive definite (SYM = 1), else general symmetric (SYM = 2).
  !> `verbose`: let MUMPS print its diagnostics and statistics (default off).
  !> `comm` must stay valid until `free` (MUMPS keeps using it).
  subroutine init(this, comm, spd, verbose)
    class(mumps_t), intent(inout) :: this
    type(MPI_Comm), intent(in) :: comm
    logical, intent(in) :: spd
    logical, intent(in), optional :: verbose
    integer :: ierr
    logical :: loud

    call this%free()
    loud = .false.
    if (present(verbose)) loud = verbose
    this%comm = comm
    this%spd = spd
    call MPI_Comm_rank(comm, this%rank, ierr)
    call MPI_Comm_size(comm, this%nranks, ierr)

    allocate (this%id)
    call nullify_user_arrays(this%id)
    ! MUMPS reads some of its control words before JOB = -1 sets them
    ! (valgrind: "conditional jump depends on uninitialised value")
    this%id%KEEP = 0
    this%id%KEEP8 = 0
    this%id%ICNTL = 0
    this%id%INFO = 0
    this%id%INFOG = 0
    this%id%COMM = comm%MPI_VAL
    this%id%PAR = 1
    this%id%SYM = merge(1, 2, spd)
    call run(this, job_init, 'initialization')

    if (loud) then
      this%id%ICNTL(1:4) = [6, 6, 6, 2]
    else
      this%id%ICNTL(1:4) = [6, -1, -1, 1]      ! errors only, on standard output
    end if
    this%id%ICNTL(5) = 0                       ! assembled input
    this%id%ICNTL(18) = 0                      ! centralized until set_distributed
    this%id%ICNTL(20) = 0                      ! dense right-hand side
    this%id%ICNTL(21) = 0                      ! centralized solution
    this%id%ICNTL(10) = 0                      ! no iterative refinement
    this%id%ICNTL(11) = 0                      ! no error analysis
  end subroutine init

  !> The assembled matrix, centralized on the host (ICNTL(18) = 0): entries
  !> (irn(k), jcn(k), a(k)), 1-based, duplicates summed; one triangle when
  !> symmetric. Only the host's arguments are used (other ranks may pass
  !> empty arrays or not call). The arrays are copied.
  subroutine set_centralized(this, n, irn, jcn, a)
    class(mumps_t), intent(inout) :: this
    integer(ip), intent(in) :: n
    integer(ip), intent(in) :: irn(:), jcn(:)
    real(dp), intent(in) :: a(:)

    call require_active(this, 'set_centralized')
    this%n = n
    this%factorized = .false.
    this%pattern_kept = .false.
    if (this%rank /= 0) return
    if (size(jcn) /= size(irn) .or. size(a) /= size(irn)) &
      call fatal_error('mumps_wrapper: set_centralized: irn, jcn and a differ in size')
    call release_matrix(this)
    allocate (this%irn, source=irn)
    allocate (this%jcn, source=jcn)
    allocate (this%a, source=a)
    this%id%ICNTL(18) = 0
    this%id%N = n
    this%id%NNZ = size(irn, kind=i8)
    this%id%NZ = 0
    this%id%IRN => this%irn
    this%id%JCN => this%jcn
    this%id%A => this%a
  end subroutine set_centralized

  !> The assembled matrix distributed over the ranks (ICNTL(18) = 3): every
  !> rank gives any subset of the entries, pattern and values; entries given
  !> more than once (on one rank or several) are summed. One triangle when
  !> symmetric. Collective in the sense that every rank must call it.
  subroutine set_distributed(this, n, irn_loc, jcn_loc, a_loc)
    class(mumps_t), intent(inout) :: this
    integer(ip), intent(in) :: n
    integer(ip), intent(in) :: irn_loc(:), jcn_loc(:)
    real(dp), intent(in) :: a_loc(:)

    call require_active(this, 'set_distributed')
    if (size(jcn_loc) /= size(irn_loc) .or. size(a_loc) /= size(irn_loc)) &
      call fatal_error('mumps_wrapper: set_distributed: irn_loc, jcn_loc and a_loc differ in size')
    this%n = n
    this%factorized = .false.
    this%pattern_kept = .false.
    call release_matrix(this)
    allocate (this%irn, source=irn_loc)
    allocate (this%jcn, source=jcn_loc)
    allocate (this%a, source=a_loc)
    this%id%ICNTL(18) = 3
    this%id%N = n
    this%id%NNZ_loc = size(irn_loc, kind=i8)
    this%id%NZ_loc = 0
    this%id%IRN_loc => this%irn
    this%id%JCN_loc => this%jcn
    this%id%A_loc => this%a
  end subroutine set_distributed

  !> The fill-reducing ordering (ICNTL(7)) of the next analysis:
  !> 'amd' (0, the default), 'pord' (4), 'auto' (7: MUMPS chooses among the
  !> orderings it has), or 'metis' / 'user' (1: the caller's pivot order
  !> `perm`, perm(i) = position of variable i in the pivot order, for example
  !> from metis_node_nd's `iperm`). Debian's MUMPS has no METIS inside, hence
  !> 'metis' needs `perm`. Only the host's `perm` is used.
  subroutine set_ordering(this, name, perm)
    class(mumps_t), intent(inout) :: this
    character(len=*), intent(in) :: name
    integer(ip), intent(in), optional :: perm(:)

    call require_active(this, 'set_ordering')
    if (associated(this%perm)) deallocate (this%perm)
    nullify (this%id%PERM_IN)
    select case (name)
    case ('amd')
      this%id%ICNTL(7) = 0
    case ('pord')
      this%id%ICNTL(7) = 4
    case ('auto')
      this%id%ICNTL(7) = 7
    case ('metis', 'user')
      if (.not. present(perm)) &
        call fatal_error("mumps_wrapper: set_ordering('"//trim(name)//"') needs the permutation perm")
      this%id%ICNTL(7) = 1
      if (this%rank == 0) then
        if (size(perm) /= this%n) &
          call fatal_error('mumps_wrapper: set_ordering: perm must have the order of the matrix (set it first)')
        allocate (this%perm, source=perm)
        this%id%PERM_IN => this%perm
      end if
    case default
      call fatal_error("mumps_wrapper: unknown ordering '"//trim(name)//"' (amd, metis, user, pord, auto)")
    end select
  end subroutine set_ordering

  !> Analyse the graph compressed by blocks of `k` consecutive variables
  !> (ICNTL(15) = -k, MUMPS >= 5.5): k = 3 for 3D elasticity with the dofs of
  !> a node numbered together. k = 1 switches it off. n must be a multiple of
  !> k; a user pivot order must keep each block consecutive.
  subroutine set_block_size(this, k)
    class(mumps_t), intent(inout) :: this
    integer(ip), intent(in) :: k
    call require_active(this, 'set_block_size')
    if (k < 1) call fatal_error('mumps_wrapper: set_block_size: k must be >= 1')
    this%id%ICNTL(15) = merge(0, -k, k == 1)
  end subroutine set_block_size

  !> Ask the next factorization for the Schur complement on the variables
  !> `vars` (ICNTL(19) = 1, centralized on the host): the other variables are
  !> eliminated, `vars` are not factorized, and `schur_complement` returns
  !> S = A_vv - A_vi A_ii^{-1} A_iv on the host. Only the host's `vars` are
  !> read (other ranks may pass an empty array). Needs fewer variables than
  !> the order. Call after set_centralized or set_distributed.
  subroutine set_schur(this, vars)
    class(mumps_t), intent(inout) :: this
    integer(ip), intent(in) :: vars(:)
    integer :: m
    call require_active(this, 'set_schur')
    if (associated(this%schur_vars)) deallocate (this%schur_vars)
    if (associated(this%schur)) deallocate (this%schur)
    this%id%ICNTL(19) = 1
    if (this%rank /= 0) return
    m = size(vars)
    if (m < 1 .or. m >= this%n) call fatal_error('mumps_wrapper: set_schur: needs 1 <= size(vars) < n')
    allocate (this%schur_vars, source=vars)
    allocate (this%schur(int(m, i8)*m))
    this%id%SIZE_SCHUR = m
    this%id%LISTVAR_SCHUR => this%schur_vars
    this%id%SCHUR => this%schur
  end subroutine set_schur

  !> Condensation (ICNTL(26) = 1) of one right-hand side `x` (n, host) onto
  !> the Schur variables: `reduced` (host, the size of the Schur list) gets
  !> the reduced right-hand side b_v - A_vi A_ii^{-1} b_i; MUMPS keeps the
  !> forward elimination for `solve_expand`. Collective.
  subroutine solve_condense(this, x, reduced)
    class(mumps_t), intent(inout) :: this
    real(dp), intent(in) :: x(:)
    real(dp), intent(inout), target, contiguous :: reduced(:)
    call schur_solve_step(this, x, reduced, 1)
  end subroutine solve_condense

  !> Expansion (ICNTL(26) = 2) after solve_condense: `reduced` (host) holds
  !> the solution on the Schur variables; `x` (n, host) gets the whole
  !> solution. Collective.
  subroutine solve_expand(this, x, reduced)
    class(mumps_t), intent(inout) :: this
    real(dp), intent(inout) :: x(:)
    real(dp), intent(inout), target, contiguous :: reduced(:)
    call schur_solve_step(this, x, reduced, 2)
    if (this%rank == 0) x = this%rhs(1:this%n)
  end subroutine solve_expand

  subroutine schur_solve_step(this, x, reduced, step)
    class(mumps_t), intent(inout) :: this
    real(dp), intent(in) :: x(:)
    real(dp), intent(inout), target, contiguous :: reduced(:)
    integer, intent(in) :: step
    integer :: n
    if (.not. (this%factorized .and. this%id%ICNTL(19) /= 0)) &
      call fatal_error('mumps_wrapper: Schur solve steps need a factorization with set_schur')
    n = this%n
    if (this%rank == 0) then
      if (size(reduced) /= size(this%schur_vars)) &
        call fatal_error('mumps_wrapper: Schur solve steps: reduced must have the size of the Schur list')
      call reserve_rhs(this, int(n, i8))
      if (step == 1) this%rhs(1:n) = x(1:n)
      this%id%NRHS = 1
      this%id%LRHS = n
      this%id%REDRHS => reduced
      this%id%LREDRHS = size(reduced)
    end if
    this%id%ICNTL(26) = step
    call run(this, job_solve, 'solve')
    this%id%ICNTL(26) = 0
    if (this%rank == 0) nullify (this%id%REDRHS)
  end subroutine schur_solve_step

  !> The Schur complement of the last factorization with set_schur, as a
  !> full (m x m) matrix in the order of `vars`.
  subroutine schur_complement(this, s)
    class(mumps_t), intent(in) :: this
    real(dp), intent(out) :: s(:, :)
    integer :: m, j
    if (.not. (this%factorized .and. associated(this%schur))) &
      call fatal_error('mumps_wrapper: schur_complement without a factorization with set_schur')
    m = size(this%schur_vars)
    if (size(s, 1) /= m .or. size(s, 2) /= m) call fatal_error('mumps_wrapper: schur_complement: s must be m x m')
    s = reshape(this%schur, [m, m])
    ! symmetric: MUMPS returns the lower triangle by rows, i.e. the upper
    ! triangle of this column-major array; the rest is workspace (measured:
    ! not all zero), so the lower triangle is copied from the upper one
    if (this%id%SYM /= 0) then
      do j = 1, m - 1
        s(j + 1:m, j) = s(j, j + 1:m)
      end do
    end if
  end subroutine schur_complement
  !> Block low-rank (BLR) factorization for the next analysis and
  !> factorization: ICNTL(35) = 2 (BLR factorization, the factors kept in
  !> low-rank form, so they take less memory, and used so by the solve) with the
  !> dropping tolerance CNTL(7) = `epsilon` (relative; the solve's error grows
  !> with it). `epsilon` = 0 switches BLR off (ICNTL(35) = 0).
  subroutine set_low_rank(this, epsilon)
    class(mumps_t), intent(inout) :: this
    real(dp), intent(in) :: epsilon
    call require_active(this, 'set_low_rank')
    if (epsilon < 0) call fatal_error('mumps_wrapper: set_low_rank: epsilon must be >= 0')
    if (epsilon == 0) then
      this%id%ICNTL(35) = 0
    else
      this%id%ICNTL(35) = 2
      this%id%CNTL(7) = epsilon
    end if
  end subroutine set_low_rank

  !> Out-of-core factors (ICNTL(22) = 1): MUMPS writes the factors to files in
  !> `directory` (OOC_TMPDIR, at most 255 characters; without it MUMPS takes
  !> the environment variable MUMPS_OOC_TMPDIR, else /tmp) during the
  !> factorization and reads them back in every solve; only the active fronts
  !> stay in memory. The files are deleted by `free` (JOB = -2).
  subroutine set_out_of_core(this, directory)
    class(mumps_t), intent(inout) :: this
    character(len=*), intent(in), optional :: directory
    call require_active(this, 'set_out_of_core')
    this%id%ICNTL(22) = 1
    this%id%OOC_PREFIX = 'feticontact_'
    if (.not. present(directory)) return
    if (len_trim(directory) > len(this%id%OOC_TMPDIR)) &
      call fatal_error('mumps_wrapper: set_out_of_core: directory name longer than 255 characters')
    this%id%OOC_TMPDIR = directory
  end subroutine set_out_of_core

  !> Analysis (JOB = 1) and numerical factorization (JOB = 2). Collective.
  !> The wrapper's copy of the matrix and of the pivot order are released
  !> afterwards, unless `keep_pattern`: then the matrix stays (MUMPS's
  !> factorization phase reads it again) and `refactorize` can follow.
  subroutine factorize(this, keep_pattern)
    class(mumps_t), intent(inout) :: this
    logical, intent(in), optional :: keep_pattern
    real(dp) :: t0

    call require_active(this, 'factorize')
    this%factorized = .false.
    this%pattern_kept = .false.
    t0 = wall_seconds()
    call run(this, job_analyse, 'analysis')
    this%seconds(1) = wall_seconds() - t0
    call numeric_factorization(this)
    if (associated(this%perm)) deallocate (this%perm)
    nullify (this%id%PERM_IN)
    if (present(keep_pattern)) this%pattern_kept = keep_pattern
    if (.not. this%pattern_kept) call release_matrix(this)
  end subroutine factorize

  !> A new numerical factorization (JOB = 2 alone) of the matrix with the
  !> values `a` on the pattern of the last factorize(keep_pattern=.true.):
  !> `a` holds this rank's entries in the order of the irn/jcn given then
  !> (the host's for centralized input; other ranks of a centralized
  !> instance pass an empty array). The analysis (pivot order, symbolic
  !> factorization) is reused; the factors are those of a fresh factorize of
  !> the same matrix up to rounding. Collective.
  subroutine refactorize(this, a)
    class(mumps_t), intent(inout) :: this
    real(dp), intent(in) :: a(:)
    integer :: ierr, bad, any_bad

    call require_active(this, 'refactorize')
    if (.not. this%pattern_kept) &
      call fatal_error('mumps_wrapper: refactorize needs a factorize(keep_pattern=.true.) before')
    bad = 0
    if (associated(this%a)) then
      if (size(a) /= size(this%a)) bad = 1
    else if (size(a) /= 0) then
      bad = 1
    end if
    ! every rank must know (JOB = 2 is collective)
    call MPI_Allreduce(bad, any_bad, 1, MPI_INTEGER, MPI_MAX, this%comm, ierr)
    if (any_bad /= 0) call fatal_error('mumps_wrapper: refactorize: the values differ in number from the pattern')
    if (associated(this%a)) this%a(:) = a
    this%factorized = .false.
    this%seconds(1) = 0
    call numeric_factorization(this)
  end subroutine refactorize

  !> Seconds of the last factorize or refactorize on this rank: analysis
  !> (0 after refactorize) and numerical factorization.
  function phase_seconds(this) result(seconds)
    class(mumps_t), intent(in) :: this
    real(dp) :: seconds(2)
    seconds = this%seconds
  end function phase_seconds

  !> Solve A X = B for the columns of `rhs` (n x nrhs), centralized on the
  !> host; the solution overwrites `rhs` on the host. Collective: the other
  !> ranks pass any array (it is not touched).
  subroutine solve_matrix(this, rhs)
    class(mumps_t), intent(inout) :: this
    real(dp), intent(inout) :: rhs(:, :)
    integer :: n, nrhs, j

    if (.not. this%factorized) call fatal_error('mumps_wrapper: solve before factorize')
    n = this%n
    if (this%rank == 0) then
      if (size(rhs, 1) /= n) call fatal_error('mumps_wrapper: solve: rhs must have n rows')
      nrhs = size(rhs, 2)
      if (nrhs == 0) then
        ! MUMPS refuses NRHS = 0 (-45); alone on its communicator the host can skip
        if (this%nranks > 1) call fatal_error('mumps_wrapper: solve with no right-hand side on a parallel instance')
        return
      end if
      call reserve_rhs(this, int(n, i8)*nrhs)
      do j = 1, nrhs
        this%rhs(1 + (j - 1)*n:j*n) = rhs(:, j)
      end do
      this%id%NRHS = nrhs
      this%id%LRHS = n
    end if
    call run(this, job_solve, 'solve')
    if (this%rank == 0) then
      do j = 1, nrhs
        rhs(:, j) = this%rhs(1 + (j - 1)*n:j*n)
      end do
    end if
  end subroutine solve_matrix

  !> Solve A x = b for one right-hand side `x` (n), in place on the host.
  subroutine solve_vector(this, x)
    class(mumps_t), intent(inout) :: this
    real(dp), intent(inout) :: x(:)
    integer :: n

    if (.not. this%factorized) call fatal_error('mumps_wrapper: solve before factorize')
    n = this%n
    if (this%rank == 0) then
      if (size(x) /= n) call fatal_error('mumps_wrapper: solve: x must have n entries')
      call reserve_rhs(this, int(n, i8))
      this%rhs(1:n) = x
      this%id%NRHS = 1
      this%id%LRHS = n
    end if
    call run(this, job_solve, 'solve')
    if (this%rank == 0) x = this%rhs(1:n)
  end subroutine solve_vector

  !> Memory of the factors in bytes, summed over the ranks:
  !> 8 * INFOG(9) (reals holding the factors) + 4 * INFOG(10) (their integer
  !> index data). INFOG(9) >= INFOG(29) (the entries of the factors) in the
  !> symmetric case: this is what the factors occupy, not only their entries.
  !> MUMPS's other data (analysis arrays, the arrowhead copy of the matrix)
  !> are not included. 0 before a factorization.
  integer(i8) function factor_bytes(this)
    class(mumps_t), intent(in) :: this
    factor_bytes = 0
    if (.not. this%factorized) return
    factor_bytes = 8*count_of(this%id%INFOG(9)) + 4*count_of(this%id%INFOG(10))
  end function factor_bytes

  !> Entries of the factors (INFOG(29)), summed over the ranks; 0 before a
  !> factorization.
  integer(i8) function factor_entries(this)
    class(mumps_t), intent(in) :: this
    factor_entries = 0
    if (this%factorized) factor_entries = count_of(this%id%INFOG(29))
  end function factor_entries

  !> Floating-point operations of the last factorization (RINFOG(3),
  !> summed over the ranks); 0 before a factorization.
  real(dp) function factor_flops(this)
    class(mumps_t), intent(in) :: this
    factor_flops = 0
    if (this%factorized) factor_flops = this%id%RINFOG(3)
  end function factor_flops
  !> Entries of the factors after BLR compression (INFOG(35)), summed over
  !> the ranks; equals factor_entries without BLR. 0 before a factorization.
  integer(i8) function factor_entries_effective(this)
    class(mumps_t), intent(in) :: this
    factor_entries_effective = 0
    if (this%factorized) factor_entries_effective = count_of(this%id%INFOG(35))
  end function factor_entries_effective

  !> Memory MUMPS used in the factorization, in MB (10^6 bytes): the most on
  !> one rank (INFOG(21)) and the sum over the ranks (INFOG(22)). With
  !> out-of-core factors this is the in-core part. 0 before a factorization.
  function memory_mb(this) result(mb)
    class(mumps_t), intent(in) :: this
    integer(i8) :: mb(2)
    mb = 0
    if (this%factorized) mb = [int(this%id%INFOG(21), i8), int(this%id%INFOG(22), i8)]
  end function memory_mb

  !> Order of the matrix.
  integer(ip) function order(this)
    class(mumps_t), intent(in) :: this
    order = this%n
  end function order

  !> True after a successful factorization.
  logical function is_factorized(this)
    class(mumps_t), intent(in) :: this
    is_factorized = this%factorized
  end function is_factorized

  !> End the instance (JOB = -2, collective) and release all memory. Safe to
  !> call on an instance that was never started.
  subroutine free(this)
    class(mumps_t), intent(inout) :: this

    if (associated(this%id)) then
      call run(this, job_end, 'termination')
      call nullify_user_arrays(this%id)
      deallocate (this%id)
    end if
    call release_matrix(this)
    if (associated(this%perm)) deallocate (this%perm)
    if (associated(this%rhs)) deallocate (this%rhs)
    if (associated(this%schur_vars)) deallocate (this%schur_vars)
    if (associated(this%schur)) deallocate (this%schur)
    this%n = 0
    this%rank = -1
    this%nranks = 0
    this%factorized = .false.
    this%pattern_kept = .false.
    this%seconds = 0
  end subroutine free

  ! ---------------------------------------------------------------- private

  subroutine require_active(this, what)
    class(mumps_t), intent(in) :: this
    character(len=*), intent(in) :: what
    if (.not. associated(this%id)) call fatal_error('mumps_wrapper: '//what//' before init')
  end subroutine require_active

  !> JOB = 2, retried with a larger ICNTL(14) when MUMPS runs out of the
  !> workspace its analysis estimated (-8, -9, -17, -20), as the MUMPS guide
  !> advises. Collective.
  subroutine numeric_factorization(this)
    class(mumps_t), intent(inout) :: this
    integer :: attempt, status
    real(dp) :: t0
    t0 = wall_seconds()
    do attempt = 0, max_workspace_retries
      this%id%JOB = job_factorize
      call dmumps(this%id)
      status = this%id%INFOG(1)
      if (status >= 0) exit
      if (attempt == max_workspace_retries .or. .not. any(status == [-8, -9, -17, -20])) &
        call report_error(this, 'factorization')
      ! out of the workspace estimated by the analysis: more relaxation, again
      if (this%rank == 0) this%id%ICNTL(14) = max(2*this%id%ICNTL(14), this%id%ICNTL(14) + 20)
    end do
    this%seconds(2) = wall_seconds() - t0
    this%factorized = .true.
  end subroutine numeric_factorization

  !> Call MUMPS with `job` and stop on an error.
  subroutine run(this, job, phase)
    class(mumps_t), intent(inout) :: this
    integer, intent(in) :: job
    character(len=*), intent(in) :: phase
    this%id%JOB = job
    call dmumps(this%id)
    if (this%id%INFOG(1) < 0) call report_error(this, phase)
  end subroutine run

  !> Make the solve buffer hold at least `length` values; MUMPS's RHS points
  !> at the whole buffer (LRHS and NRHS say how much of it is used).
  subroutine reserve_rhs(this, length)
    class(mumps_t), intent(inout) :: this
    integer(i8), intent(in) :: length
    if (associated(this%rhs)) then
      if (size(this%rhs, kind=i8) >= length) return
      deallocate (this%rhs)
    end if
    allocate (this%rhs(length))
    this%id%RHS => this%rhs
  end subroutine reserve_rhs

  !> Release the wrapper's copy of the matrix and unhook MUMPS from it.
  subroutine release_matrix(this)
    class(mumps_t), intent(inout) :: this
    if (associated(this%irn)) deallocate (this%irn)
    if (associated(this%jcn)) deallocate (this%jcn)
    if (associated(this%a)) deallocate (this%a)
    if (associated(this%id)) then
      nullify (this%id%IRN, this%id%JCN, this%id%A)
      nullify (this%id%IRN_loc, this%id%JCN_loc, this%id%A_loc)
    end if
  end subroutine release_matrix

  real(dp) function wall_seconds()
    wall_seconds = MPI_Wtime()
  end function wall_seconds

  !> The pointers of the structure that the user (this wrapper) sets.
  subroutine nullify_user_arrays(id)
    type(DMUMPS_STRUC), intent(inout) :: id
    nullify (id%IRN, id%JCN, id%A, id%IRN_loc, id%JCN_loc, id%A_loc, id%PERM_IN, id%RHS)
    nullify (id%LISTVAR_SCHUR, id%SCHUR, id%REDRHS)
  end subroutine nullify_user_arrays

  !> A MUMPS count: negative values are millions.
  pure integer(i8) function count_of(value)
    integer, intent(in) :: value
    if (value >= 0) then
      count_of = value
    else
      count_of = -1000000_i8*value
    end if
  end function count_of

  !> Stop with INFOG(1), INFOG(2) and what they mean.
  subroutine report_error(this, phase)
    class(mumps_t), intent(in) :: this
    character(len=*), intent(in) :: phase
    character(len=400) :: msg
    integer :: code, detail

    code = this%id%INFOG(1)
    detail = this%id%INFOG(2)
    write (msg, '(4a,i0,a,i0,a,i0,2a)') 'MUMPS ', phase, ' failed', ' (N = ', this%n, '): INFOG(1) = ', &
      code, ', INFOG(2) = ', detail, ': ', trim(explain(code, detail))
    call fatal_error(trim(msg))
  end subroutine report_error

  !> A short explanation of a MUMPS error code (MUMPS 5.5 users' guide, sec. 8).
  function explain(code, detail) result(text)
    integer, intent(in) :: code, detail
    character(len=200) :: text
    select case (code)
    case (-1)
      write (text, '(a,i0)') 'error on another rank: see its message; rank ', detail
    case (-2)
      text = 'number of entries out of range'
    case (-3)
      text = 'invalid JOB or call sequence (e.g. solve before factorization)'
    case (-4)
      text = 'error in the user pivot order PERM_IN (not a permutation)'
    case (-5, -7)
      text = 'out of memory during the analysis (allocation failed)'
    case (-6)
      text = 'matrix singular in structure (structural rank in INFOG(2))'
    case (-8, -14, -15)
      text = 'integer workspace too small: increase ICNTL(14)'
    case (-9, -11, -12)
      text = 'real workspace too small: increase ICNTL(14)'
    case (-10)
      text = 'numerically singular matrix or zero pivot (INFOG(2) pivots eliminated); '// &
             'for SYM=1 the matrix is not positive definite'
    case (-13)
      text = 'out of memory: a Fortran ALLOCATE of INFOG(2) entries failed (negative: millions); '// &
             'reduce the problem or ICNTL(14)'
    case (-16)
      text = 'N out of range'
    case (-17, -20)
      text = 'MPI buffer too small: increase ICNTL(14)'
    case (-22)
      write (text, '(a,i0,a)') 'a user array is missing or too small (array number ', detail, &
        ': 1 IRN, 2 JCN, 3 PERM_IN, 4 A, 7 RHS, 16 IRN_loc/JCN_loc/A_loc)'
    case (-23)
      text = 'MPI not initialized'
    case (-26)
      text = 'LRHS out of range'
    case (-40)
      text = 'SYM=1 but a negative or zero pivot in the ScaLAPACK root: the matrix is not positive definite'
    case (-45)
      text = 'NRHS <= 0'
    case (-57)
      text = 'block format (ICNTL(15)) inconsistent: N not a multiple of the block size?'
    case default
      text = 'see the MUMPS users guide, section "Error diagnostics"'
    end select
  end function explain
end module mumps_wrapper
