!> F = B K^+ B^T, the dual operator of TFETI, with K^+ of the rank's
!> subdomains behind local_inverse_t (`&solver local_solver`: 'block', one
!> block-diagonal MUMPS factorization, 'subdomain', one per subdomain, or
!> 'dense', kplus_dense split along the dofs B touches, factorized by
!> build_dense once B is known and applied through the Cholesky factors of
!> the Schur complements on those dofs, `apply_touched`). B is passed in: F
!> owns only K^+, the explicit local operators and work vectors.
!> Timer 'F action'.
!>
!> Two ways to apply F (`&solver f_action`, docs/THEORY.md "Explicit local
!> dual operators"):
!> - implicit: xall = B^T x, xall <- K^+ xall (MUMPS forward and backward
!>   substitution), y = B xall;
!> - explicit: every row of B^s has exactly one entry in subdomain s, so
!>   F^s = B^s K^+ B^s^T = B^_s S^_s B^_s^T with S^_s = (K_reg^s)^{-1}
!>   restricted to the n_d dofs that B^s touches (a dense symmetric n_d x n_d
!>   matrix) and B^_s the n_b x n_d matrix with one entry per row. S^_s is
!>   built once (`build_explicit`: the inverse of the Schur complement of
!>   K_reg^s on those dofs, MUMPS + LAPACK) and applied with BLAS
!>   (`storage`: 'symmetric' dsymv on the full square, upper triangle read;
!>   'packed' dspmv on the packed upper triangle; 'general' dgemv on the full
!>   square). n_d <= n_b (Helmert gluing rows touch a corner dof of a
!>   subdomain up to 7 times), so S^_s is smaller than F^s itself.
module f_operator
  use kinds, only: dp, ip, i8
  use lapack_interfaces, only: dpotrf, dpotri, dsymv, dspmv, dgemv, dpptri
  use errors, only: fatal_error
  use timers, only: timer_start, timer_stop
  use subdomain, only: subdomain_t
  use local_inverse, only: local_inverse_t
  use kplus_block, only: kplus_block_t
  use kplus_set, only: kplus_set_t
  use kplus_shared, only: kplus_shared_t
  use kplus_dense, only: kplus_dense_t
  use subdomain_classes, only: subdomain_classes_t, find_classes
  use class_operator, only: class_operator_t, sandwich
  use b_operator, only: b_operator_t
  use sorting, only: sort_unique
  use kplus, only: regularized_system, kplus_t
  use schur_complement, only: dense_schur
  implicit none
  private

  !> what apply_touched multiplies the touched dofs of a subdomain by
  integer, parameter :: touched_explicit = 1, touched_solve = 2, touched_schur = 3

  type, public :: f_operator_t
    private
    class(local_inverse_t), allocatable :: kinv   !< K^+ of all local subdomains
    real(dp), allocatable :: xall(:)              !< work: concatenated primal vector
    integer(i8) :: applications = 0
    integer(ip) :: nsub = 0                       !< local subdomains
    integer(ip), allocatable :: doff(:)           !< (nsub+1) dof offsets in the concatenated vector
    ! ---- explicit local operators (built by build_explicit)
    logical :: explicit = .false.
    ! ---- dense split K^+ (`local_solver = 'dense'`, built by build_dense once B is known)
    logical :: dense = .false.                    !< built: F through the factors of the Schur complements
    logical :: dense_pending = .false.            !< chosen by init, waiting for B
    character(len=16) :: storage = 'symmetric'    !< 'symmetric' | 'packed' | 'general'
    integer(ip), allocatable :: nd(:)             !< (nsub) dofs touched by B^s
    integer(i8), allocatable :: soff(:)           !< (nsub+1) offsets of S^_s in smat
    real(dp), allocatable :: smat(:)              !< all S^_s, one after the other
    integer(ip), allocatable :: eoff(:)           !< (nsub+1) offsets of the entries of B^_s
    integer(ip), allocatable :: erow(:), edof(:)  !< local dual row, compressed dof (1..nd)
    real(dp), allocatable :: eval(:)              !< values of B^_s
    integer(ip) :: n_local_rows = 0
    real(dp) :: build_flop_count = 0              !< flops of build_explicit (MUMPS Schur + LAPACK)
    real(dp), allocatable :: wloc(:), wloc2(:), t(:), u(:)   !< work
    ! ---- shared local operators (`share_subdomains = 'auto'` and classes found)
    type(subdomain_classes_t) :: classes          !< one class per subdomain without sharing
    logical :: sharing = .false.                  !< K^+ served per class (kplus_shared_t)
    type(class_operator_t) :: shared_op           !< S^_c per class, a_s = 1/c_s (explicit and shared)
  contains
    procedure :: init
    procedure :: build_explicit
    procedure :: build_dense
    procedure :: is_dense
    procedure :: dense_schur_ready
    procedure :: apply_dense_schur
    procedure :: is_explicit
    procedure :: explicit_bytes
    procedure :: touched_dofs
    procedure :: implicit_bytes
    procedure :: apply
    procedure :: local_solve
    procedure :: bytes_per_action
    procedure :: n_applications
    procedure :: local_operator
    procedure :: factor_flops
    procedure :: build_flops
    procedure :: is_shared
    procedure :: n_classes
    procedure :: shared_explicit_flops
    procedure :: classes_found
    procedure :: max_class_deviation
    procedure :: flops_per_action
    procedure :: free
  end type f_operator_t


contains

  !> Factorize K_reg of the local subdomains `subs` (K and R assembled) with
  !> `local_solver` 'block' or 'subdomain'; `n_concat`: length of their
  !> concatenated vector.
  !> `share` ('auto' or 'none', default 'none'): with 'auto', classes of
  !> congruent subdomains are looked for (subdomain_classes) and, when some
  !> class has two members or more, K^+ is factorized once per class
  !> (kplus_shared_t) whatever `local_solver` says. `classes`: the classes
  !> the caller found already (find_classes on `subs` with share = 'auto'),
  !> needed when the members' K are shared (subdomain_t%k_of).
  subroutine init(this, subs, local_solver, regularization, ordering, n_concat, share, classes)
    class(f_operator_t), intent(inout) :: this
    type(subdomain_t), intent(in) :: subs(:)
    character(len=*), intent(in) :: local_solver, ordering
    real(dp), intent(in) :: regularization
    integer(ip), intent(in) :: n_concat
    character(len=*), intent(in), optional :: share
    type(subdomain_classes_t), intent(in), optional :: classes
    integer(ip) :: s
    logical :: look
    call this%free()
    look = .false.
    if (present(share)) look = share == 'auto'
    if (present(classes)) then
      this%classes = classes
    else
      call find_classes(subs, this%classes, look)
    end if
    this%sharing = this%classes%shared()
    if (this%sharing) then
      allocate (kplus_shared_t :: this%kinv)
      select type (k => this%kinv)
      type is (kplus_shared_t)
        call k%init_classes(subs, this%classes, regularization, ordering)
      end select
    else
      select case (local_solver)
      case ('dense')
        ! factorized by build_dense once B says which dofs it touches
        allocate (kplus_dense_t :: this%kinv)
        this%dense_pending = .true.
      case ('block')
        allocate (kplus_block_t :: this%kinv)
      case default
        allocate (kplus_set_t :: this%kinv)
      end select
      if (.not. this%dense_pending) call this%kinv%init(subs, regularization, ordering)
    end if
    allocate (this%xall(n_concat))
    this%nsub = size(subs, kind=ip)
    allocate (this%doff(this%nsub + 1))
    this%doff(1) = 0
    do s = 1, this%nsub
      this%doff(s + 1) = this%doff(s) + subs(s)%ndof
    end do
    if (this%doff(this%nsub + 1) /= n_concat) call fatal_error('f_operator%init: n_concat differs from the dofs of subs')
  end subroutine init

  !> Build the explicit local operators S^_s of every local subdomain `subs`
  !> (K and R assembled) from B (`b`): S^_s = (K_reg^s)^{-1} restricted to the
  !> n_d dofs B^s touches = the inverse of the Schur complement of K_reg^s on
  !> them (MUMPS, ICNTL(19), one instance per subdomain, freed at once; K_reg
  !> exactly as K^+ builds it, kplus::regularized_system), inverted by LAPACK
  !> (dpotrf, dpotri). Stored as `storage` ('symmetric', 'packed',
  !> 'general'); F is applied with them from now on. Local (no communication).
  subroutine build_explicit(this, b, subs, regularization, storage)
    class(f_operator_t), intent(inout) :: this
    type(b_operator_t), intent(in) :: b
    type(subdomain_t), intent(in) :: subs(:)
    real(dp), intent(in) :: regularization
    character(len=*), intent(in) :: storage
    integer(ip), allocatable :: dofs(:), tptr(:), touched(:)
    real(dp), allocatable :: sd(:, :), up(:)
    integer(ip) :: s, n, j
    integer(i8) :: o
    integer :: info

    if (storage /= 'symmetric' .and. storage /= 'packed' .and. storage /= 'general') &
      call fatal_error("f_operator%build_explicit: unknown storage '"//trim(storage)//"'")
    if (size(subs, kind=ip) /= this%nsub) call fatal_error('f_operator%build_explicit: subs differ from init')
    if (this%sharing) then
      call build_explicit_shared(this, b, subs, regularization)
      return
    end if
    this%storage = storage
    if (.not. this%dense) call local_rows(this, b, subs, tptr, touched)
    allocate (this%soff(this%nsub + 1))
    this%soff(1) = 0
    do s = 1, this%nsub
      n = this%nd(s)
      if (storage == 'packed') then
        this%soff(s + 1) = this%soff(s) + int(n, i8)*(n + 1)/2
      else
        this%soff(s + 1) = this%soff(s) + int(n, i8)*n
      end if
    end do
    allocate (this%smat(this%soff(this%nsub + 1)))
    do s = 1, this%nsub
      n = this%nd(s)
      if (n == 0) cycle
      if (this%dense) then
        ! S^_s from the packed Cholesky factor of the Schur complement that
        ! the dense K^+ already holds (LAPACK dpptri: 2 n^3 / 3 flops)
        select type (k => this%kinv)
        type is (kplus_dense_t)
          up = k%schur_factor(s)
        end select
        call timer_start('explicit F: inverse')
        call dpptri('U', n, up, info)
        call timer_stop('explicit F: inverse')
        if (info /= 0) call fatal_error('f_operator%build_explicit: the Schur complement of K_reg is not '// &
                                        'positive definite (LAPACK dpptri failed)')
        this%build_flop_count = this%build_flop_count + 2*real(n, dp)**3/3
        if (allocated(sd)) deallocate (sd)
        allocate (sd(n, n))
        do j = 1, n
          sd(1:j, j) = up(int(j, i8)*(j - 1)/2 + 1:int(j, i8)*(j + 1)/2)
        end do
      else
        dofs = touched(tptr(s) + 1:tptr(s + 1))
        call touched_inverse(subs(s), regularization, dofs, sd, this%build_flop_count)
      end if
      o = this%soff(s)
      do j = 1, n
        if (storage == 'packed') then
          this%smat(o + int(j, i8)*(j - 1)/2 + 1:o + int(j, i8)*(j + 1)/2) = sd(1:j, j)
        else
          sd(j + 1:n, j) = sd(j, j + 1:n)
          this%smat(o + int(j - 1, i8)*n + 1:o + int(j, i8)*n) = sd(:, j)
        end if
      end do
    end do
    this%explicit = .true.
  end subroutine build_explicit

  !> B^_s of every local subdomain: the entries of B^s with the n_d dofs
  !> that B^s touches numbered 1..n_d (ascending local dof numbers), and those
  !> dofs (touched(tptr(s)+1:tptr(s+1))); work vectors. Local.
  subroutine local_rows(this, b, subs, tptr, touched)
    type(f_operator_t), intent(inout) :: this
    type(b_operator_t), intent(in) :: b
    type(subdomain_t), intent(in) :: subs(:)
    integer(ip), allocatable, intent(out) :: tptr(:), touched(:)
    integer(ip), allocatable :: row(:), dof(:), cmap(:), dofs(:)
    real(dp), allocatable :: val(:)
    integer(ip) :: s, e, ne, ndmax, n, i
    this%n_local_rows = b%n_local_rows()
    if (allocated(this%nd)) deallocate (this%nd)
    allocate (this%eoff(this%nsub + 1), tptr(this%nsub + 1), this%nd(this%nsub))
    ne = 0
    this%eoff(1) = 0
    tptr(1) = 0
    do s = 1, this%nsub
      call b%subdomain_entries(s, row, dof, val)
      ne = ne + size(row, kind=ip)
      this%eoff(s + 1) = ne
      call sort_unique(dof, this%nd(s))
      tptr(s + 1) = tptr(s) + this%nd(s)
    end do
    allocate (this%erow(ne), this%edof(ne), this%eval(ne), touched(tptr(this%nsub + 1)))
    ndmax = maxval([0_ip, this%nd])
    allocate (this%wloc(max(1, this%n_local_rows)), this%wloc2(max(1, this%n_local_rows)), &
              this%t(max(1, ndmax)), this%u(max(1, ndmax)))
    do s = 1, this%nsub
      call b%subdomain_entries(s, row, dof, val)
      dofs = dof
      call sort_unique(dofs, n)
      touched(tptr(s) + 1:tptr(s + 1)) = dofs(1:n)
      if (allocated(cmap)) deallocate (cmap)
      allocate (cmap(subs(s)%ndof))
      cmap = 0
      do i = 1, n
        cmap(dofs(i)) = i
      end do
      do e = 1, size(row, kind=ip)
        this%erow(this%eoff(s) + e) = row(e)
        this%edof(this%eoff(s) + e) = cmap(dof(e))
        this%eval(this%eoff(s) + e) = val(e)
      end do
    end do
  end subroutine local_rows

  !> `local_solver = 'dense'`: factorize every local K_reg split along the
  !> dofs B touches (kplus_dense), now that B is known; F is applied through
  !> the Cholesky factors of the Schur complements on those dofs from now on
  !> (`apply_touched`). Local (no communication).
  subroutine build_dense(this, b, subs, regularization)
    class(f_operator_t), intent(inout) :: this
    type(b_operator_t), intent(in) :: b
    type(subdomain_t), intent(in) :: subs(:)
    real(dp), intent(in) :: regularization
    integer(ip), allocatable :: tptr(:), touched(:)
    if (.not. this%dense_pending) call fatal_error('f_operator%build_dense: init did not choose the dense solver')
    if (size(subs, kind=ip) /= this%nsub) call fatal_error('f_operator%build_dense: subs differ from init')
    call local_rows(this, b, subs, tptr, touched)
    select type (k => this%kinv)
    type is (kplus_dense_t)
      call k%init_split(subs, regularization, tptr, touched)
    end select
    this%dense_pending = .false.
    this%dense = .true.
  end subroutine build_dense

  !> True when K^+ is the dense split solver (built or pending).
  logical function is_dense(this)
    class(f_operator_t), intent(in) :: this
    is_dense = this%dense .or. this%dense_pending
  end function is_dense

  !> True when the dense solver is built and gives the Schur complement of
  !> K (not K_reg) on the touched dofs of every local subdomain (its fixing
  !> nodes all touched; kplus_dense%schur_product). Local.
  logical function dense_schur_ready(this)
    class(f_operator_t), intent(in) :: this
    dense_schur_ready = .false.
    if (.not. this%dense) return
    select type (k => this%kinv)
    type is (kplus_dense_t)
      dense_schur_ready = k%all_schur_ok()
    end select
  end function dense_schur_ready

  !> y = sum_s a_s B^_s S_s B^_s^T x, S_s the Schur complement of K_s on the
  !> dofs B^s touches (from the dense solver's factors, dense_schur_ready):
  !> the Dirichlet preconditioner's local part with a_s = 1/w_s^2
  !> (dual_preconditioner). Gather and scatter of the rows as for F.
  subroutine apply_dense_schur(this, b, x, y, a)
    class(f_operator_t), intent(inout) :: this
    type(b_operator_t), intent(inout) :: b
    real(dp), intent(in) :: x(:), a(:)
    real(dp), intent(inout) :: y(:)
    call apply_touched(this, b, x, y, touched_schur, a)
  end subroutine apply_dense_schur


  !> n_d of every local subdomain: the number of dofs B^s touches (the
  !> order of S^_s), without building anything.
  function touched_dofs(this, b) result(nd)
    class(f_operator_t), intent(in) :: this
    type(b_operator_t), intent(in) :: b
    integer(ip), allocatable :: nd(:)
    integer(ip), allocatable :: row(:), dof(:)
    real(dp), allocatable :: val(:)
    integer(ip) :: s, n
    allocate (nd(this%nsub))
    do s = 1, this%nsub
      call b%subdomain_entries(s, row, dof, val)
      call sort_unique(dof, n)
      nd(s) = n
    end do
  end function touched_dofs

  logical function is_explicit(this)
    class(f_operator_t), intent(in) :: this
    is_explicit = this%explicit
  end function is_explicit

  !> y = F x = B K^+ B^T x (dual vectors, owned rows).
  subroutine apply(this, b, x, y)
    class(f_operator_t), intent(inout) :: this
    type(b_operator_t), intent(inout) :: b
    real(dp), intent(in) :: x(:)
    real(dp), intent(inout) :: y(:)
    call timer_start('F action')
    if (this%explicit .and. this%sharing) then
      call this%shared_op%apply(b, x, y)
    else if (this%explicit) then
      call apply_touched(this, b, x, y, touched_explicit)
    else if (this%dense) then
      call apply_touched(this, b, x, y, touched_solve)
    else
      this%xall = 0
      call b%add_transpose(x, 1.0_dp, this%xall)
      call this%kinv%solve(this%xall)
      call b%apply_concat(this%xall, y)
    end if
    this%applications = this%applications + 1
    call timer_stop('F action')
  end subroutine apply

  !> y = sum_s a_s B^_s A_s B^_s^T x on the dofs each B^s touches: gather
  !> the rows, t = B^_s^T x_s, u = A_s t, scatter-add a_s B^_s u (a_s = 1
  !> without `a`). A_s by `mode`: touched_explicit the explicit S^_s (one
  !> BLAS matrix-vector product, `storage`), touched_solve S_s^{-1} from the
  !> dense solver's packed factor (two triangular solves), touched_schur the
  !> Schur complement of K_s from those factors (two triangular products).
  subroutine apply_touched(this, b, x, y, mode, a)
    class(f_operator_t), intent(inout), target :: this
    type(b_operator_t), intent(inout) :: b
    real(dp), intent(in) :: x(:)
    real(dp), intent(inout) :: y(:)
    integer, intent(in) :: mode
    real(dp), intent(in), optional :: a(:)
    type(kplus_dense_t), pointer :: kd
    integer(ip) :: s, e, n
    real(dp) :: as
    kd => null()
    select type (k => this%kinv)
    type is (kplus_dense_t)
      kd => k
    end select
    if (mode /= touched_explicit .and. .not. associated(kd)) &
      call fatal_error('f_operator: the dense local solver is not in use')
    call b%gather_rows(x, this%wloc)
    this%wloc2 = 0
    do s = 1, this%nsub
      n = this%nd(s)
      if (n == 0) cycle
      this%t(1:n) = 0
      do e = this%eoff(s) + 1, this%eoff(s + 1)
        this%t(this%edof(e)) = this%t(this%edof(e)) + this%eval(e)*this%wloc(this%erow(e))
      end do
      select case (mode)
      case (touched_explicit)
        select case (this%storage)
        case ('symmetric')
          call dsymv('U', n, 1.0_dp, this%smat(this%soff(s) + 1), n, this%t, 1, 0.0_dp, this%u, 1)
        case ('packed')
          call dspmv('U', n, 1.0_dp, this%smat(this%soff(s) + 1), this%t, 1, 0.0_dp, this%u, 1)
        case default
          call dgemv('N', n, n, 1.0_dp, this%smat(this%soff(s) + 1), n, this%t, 1, 0.0_dp, this%u, 1)
        end select
      case (touched_solve)
        this%u(1:n) = this%t(1:n)
        call kd%solve_touched(s, this%u(1:n))
      case default
        call kd%schur_product(s, this%t(1:n), this%u(1:n))
      end select
      as = 1
      if (present(a)) as = a(s)
      do e = this%eoff(s) + 1, this%eoff(s + 1)
        this%wloc2(this%erow(e)) = this%wloc2(this%erow(e)) + as*this%eval(e)*this%u(this%edof(e))
      end do
    end do
    call b%scatter_rows(this%wloc2, y)
  end subroutine apply_touched

  !> x <- K^+ x for the concatenated vector of all local subdomains.
  subroutine local_solve(this, x)
    class(f_operator_t), intent(inout) :: this
    real(dp), intent(inout) :: x(:)
    if (size(x) /= size(this%xall)) call fatal_error('f_operator%local_solve: x must have the length of '// &
                                                     'the concatenated local vectors')
    call this%kinv%solve(x)
  end subroutine local_solve

  !> Bytes one implicit F action reads and writes on this rank: the factors
  !> of K_reg twice (forward and backward substitution), the entries of B
  !> twice (B^T, then B; 16 bytes each: value, row, dof), and the vectors:
  !> 12 passes over the concatenated primal vector (zeroed, B^T added: read
  !> and write, copied into MUMPS's buffer and back: 4, forward and backward
  !> substitution: read and write each, B read once) and 4 over the local
  !> dual rows (gather, scatter).
  integer(i8) function implicit_bytes(this, b)
    class(f_operator_t), intent(in) :: this
    type(b_operator_t), intent(in) :: b
    integer(ip) :: s
    if (this%dense) then
      ! dense split K^+: the packed factor of every Schur complement twice,
      ! the entries of B^_s twice, 4 passes over the local dual rows
      implicit_bytes = 2*16*b%n_entries() + 4*8*int(b%n_local_rows(), i8)
      do s = 1, this%nsub
        implicit_bytes = implicit_bytes + 2*8*(int(this%nd(s), i8)*(this%nd(s) + 1)/2)
      end do
      return
    end if
    implicit_bytes = 2*this%kinv%factor_bytes() + 2*16*b%n_entries() + 12*8*int(size(this%xall), i8) + &
                     4*8*int(b%n_local_rows(), i8)
  end function implicit_bytes

  !> Bytes one explicit F action reads and writes on this rank: what BLAS
  !> reads of every S^_s (the upper triangle, n_d (n_d+1)/2 values, for
  !> 'symmetric' and 'packed'; n_d^2 for 'general'), the entries of B^_s twice
  !> (16 bytes each) and 4 passes over the local dual rows (gather, zero,
  !> scatter). The short vectors t, u of one subdomain stay in cache.
  !> `storage` and `nd` give the figure before the operators are built.
  integer(i8) function explicit_bytes(this, b, storage, nd)
    class(f_operator_t), intent(in) :: this
    type(b_operator_t), intent(in) :: b
    character(len=*), intent(in) :: storage
    integer(ip), intent(in) :: nd(:)
    integer(ip) :: s
    explicit_bytes = 2*16*b%n_entries() + 4*8*int(b%n_local_rows(), i8)
    do s = 1, size(nd, kind=ip)
      if (storage == 'general') then
        explicit_bytes = explicit_bytes + 8*int(nd(s), i8)*nd(s)
      else
        explicit_bytes = explicit_bytes + 8*(int(nd(s), i8)*(nd(s) + 1)/2)
      end if
    end do
  end function explicit_bytes

  !> Bytes one F action reads and writes on this rank, in the mode in use.
  integer(i8) function bytes_per_action(this, b)
    class(f_operator_t), intent(in) :: this
    type(b_operator_t), intent(in) :: b
    if (this%explicit .and. this%sharing) then
      bytes_per_action = this%shared_op%bytes_per_action()
    else if (this%explicit) then
      bytes_per_action = this%explicit_bytes(b, this%storage, this%nd)
    else
      bytes_per_action = this%implicit_bytes(b)
    end if
  end function bytes_per_action

  integer(i8) function n_applications(this)
    class(f_operator_t), intent(in) :: this
    n_applications = this%applications
  end function n_applications

  !> The dense F^s = B^_s S^_s B^_s^T of local subdomain `s` on its local
  !> dual rows `rows` (for tests); needs build_explicit.
  subroutine local_operator(this, s, rows, fs)
    class(f_operator_t), intent(in) :: this
    integer(ip), intent(in) :: s
    integer(ip), allocatable, intent(out) :: rows(:)
    real(dp), allocatable, intent(out) :: fs(:, :)
    real(dp), allocatable :: sf(:, :)
    integer(ip) :: n, i, j
    integer(i8) :: o
    if (.not. this%explicit) call fatal_error('f_operator%local_operator: the explicit operators are not built')
    if (this%sharing) then
      call this%shared_op%local_matrix(s, rows, fs)
      return
    end if
    n = this%nd(s)
    o = this%soff(s)
    allocate (sf(n, n))
    do j = 1, n
      do i = 1, n
        if (this%storage == 'packed') then
          sf(i, j) = this%smat(o + int(max(i, j), i8)*(max(i, j) - 1)/2 + min(i, j))
        else if (this%storage == 'symmetric') then
          sf(i, j) = this%smat(o + int(max(i, j) - 1, i8)*n + min(i, j))
        else
          sf(i, j) = this%smat(o + int(j - 1, i8)*n + i)
        end if
      end do
    end do
    call sandwich(this%erow(this%eoff(s) + 1:this%eoff(s + 1)), this%edof(this%eoff(s) + 1:this%eoff(s + 1)), &
                  this%eval(this%eoff(s) + 1:this%eoff(s + 1)), sf, rows, fs)
  end subroutine local_operator

  !> Floating-point operations of the factorization of K^+ (MUMPS's count).
  real(dp) function factor_flops(this)
    class(f_operator_t), intent(in) :: this
    factor_flops = 0
    if (allocated(this%kinv)) factor_flops = this%kinv%factor_flops()
  end function factor_flops

  !> Floating-point operations of build_explicit (0 if not built).
  real(dp) function build_flops(this)
    class(f_operator_t), intent(in) :: this
    build_flops = this%build_flop_count
  end function build_flops

  subroutine free(this)
    class(f_operator_t), intent(inout) :: this
    if (allocated(this%kinv)) then
      call this%kinv%free()
      deallocate (this%kinv)
    end if
    if (allocated(this%xall)) deallocate (this%xall)
    if (allocated(this%doff)) deallocate (this%doff)
    if (allocated(this%nd)) deallocate (this%nd)
    if (allocated(this%soff)) deallocate (this%soff)
    if (allocated(this%smat)) deallocate (this%smat)
    if (allocated(this%wloc)) deallocate (this%wloc, this%wloc2, this%t, this%u)
    call this%shared_op%free()
    if (allocated(this%eoff)) deallocate (this%eoff)
    if (allocated(this%erow)) deallocate (this%erow, this%edof, this%eval)
    this%classes = subdomain_classes_t()
    this%sharing = .false.
    this%explicit = .false.
    this%dense = .false.
    this%dense_pending = .false.
    this%build_flop_count = 0
    this%applications = 0
    this%nsub = 0
  end subroutine free

  !> True when K^+ is served per class of congruent subdomains.
  logical function is_shared(this)
    class(f_operator_t), intent(in) :: this
    is_shared = this%sharing
  end function is_shared

  !> Classes of congruent subdomains on this rank (the number of local
  !> subdomains without sharing).
  integer(ip) function n_classes(this)
    class(f_operator_t), intent(in) :: this
    n_classes = this%classes%nclass
  end function n_classes

  !> The classes of congruent subdomains found by init (for the
  !> preconditioner's shared matrices).
  function classes_found(this) result(cl)
    class(f_operator_t), intent(in) :: this
    type(subdomain_classes_t) :: cl
    cl = this%classes
  end function classes_found

  !> Flops of one F action on this rank with the shared explicit operators
  !> (2 n_c^2 m_c per class); 0 on the other paths (memory bound).
  real(dp) function flops_per_action(this)
    class(f_operator_t), intent(in) :: this
    flops_per_action = 0
    if (this%explicit .and. this%sharing) flops_per_action = this%shared_op%flops_per_action()
  end function flops_per_action

  !> max |K_s - c_s K_r| / max |K_s| over the members of the classes.
  real(dp) function max_class_deviation(this)
    class(f_operator_t), intent(in) :: this
    max_class_deviation = this%classes%max_deviation
  end function max_class_deviation

  !> Flops of one shared explicit F action on this rank (2 n_c^2 m_c per
  !> class: the product S^_c X with m_c columns) and of its build (n_c^3 per
  !> class: the dense inverse), without building anything; 0 without sharing.
  function shared_explicit_flops(this, b) result(fl)
    class(f_operator_t), intent(in) :: this
    type(b_operator_t), intent(in) :: b
    real(dp) :: fl(2)
    type(class_operator_t) :: tmp
    fl = 0
    if (.not. this%sharing) return
    call tmp%init(b, this%classes, 1/this%classes%scale)
    fl(1) = tmp%flops_per_action()
    fl(2) = sum(real(tmp%cn, dp)**3)
    call tmp%free()
  end function shared_explicit_flops

  !> Explicit local operators shared per class (class_operator): S^_c =
  !> (K_reg^r)^{-1} of the representative r restricted to the union U_c of
  !> the dofs B touches in the class, built as in build_explicit (MUMPS Schur
  !> complement, LAPACK inverse); member s uses S^_c / c_s.
  subroutine build_explicit_shared(this, b, subs, regularization)
    type(f_operator_t), intent(inout) :: this
    type(b_operator_t), intent(in) :: b
    type(subdomain_t), intent(in) :: subs(:)
    real(dp), intent(in) :: regularization
    integer(ip), allocatable :: dofs(:)
    real(dp), allocatable :: sd(:, :)
    integer(ip) :: c, r, n, j

    this%storage = 'general'
    call this%shared_op%init(b, this%classes, 1/this%classes%scale)
    do c = 1, this%classes%nclass
      r = this%classes%rep(c)
      call this%shared_op%class_dofs(b, c, dofs)
      n = size(dofs, kind=ip)
      if (n == 0) cycle
      if (subs(r)%C%nrows > 0) then
        ! a cluster glued by faces: K^+ is a constrained solve (singular on
        ! the touched dofs, which hold the gluing rows), so its columns come
        ! from solves with the class's factors
        select type (k => this%kinv)
        type is (kplus_shared_t)
          call touched_columns(k%kplus(c), subs(r)%ndof, dofs, sd, this%build_flop_count)
        end select
        call this%shared_op%set_matrix(c, sd)
        cycle
      end if
      call touched_inverse(subs(r), regularization, dofs, sd, this%build_flop_count)
      do j = 1, n
        sd(j + 1:n, j) = sd(j, j + 1:n)
      end do
      call this%shared_op%set_matrix(c, sd)
    end do
    this%explicit = .true.
  end subroutine build_explicit_shared

  !> sd = K^+(dofs, dofs) by solves with `kp` on the unit vectors of `dofs`
  !> (blocks of columns), symmetrized; the solves' flops (4 per factor entry
  !> and column) added to `flops`.
  subroutine touched_columns(kp, ndof, dofs, sd, flops)
    type(kplus_t), intent(inout) :: kp
    integer(ip), intent(in) :: ndof, dofs(:)
    real(dp), allocatable, intent(out) :: sd(:, :)
    real(dp), intent(inout) :: flops
    integer(ip), parameter :: block_columns = 256
    real(dp), allocatable :: w(:, :)
    integer(ip) :: n, j0, m, j
    n = size(dofs, kind=ip)
    allocate (sd(n, n))
    call timer_start('explicit F: solves')
    do j0 = 1, n, block_columns
      m = min(block_columns, n - j0 + 1)
      if (allocated(w)) deallocate (w)
      allocate (w(ndof, m))
      w = 0
      do j = 1, m
        w(dofs(j0 + j - 1), j) = 1
      end do
      call kp%solve_many(w)
      sd(:, j0:j0 + m - 1) = w(dofs, :)
    end do
    sd = 0.5_dp*(sd + transpose(sd))
    flops = flops + 4*real(n, dp)*real(kp%factor_bytes(), dp)/8
    call timer_stop('explicit F: solves')
  end subroutine touched_columns

  !> S^ = (the Schur complement of K_reg of `sub` on its dofs `dofs`)^{-1},
  !> K_reg exactly as K^+ builds it (kplus::regularized_system): the Schur
  !> complement by MUMPS (K_reg itself when `dofs` are all the dofs), its
  !> inverse by LAPACK (upper triangle of `sd` set; n^3/3 + 2n^3/3 flops,
  !> added to `flops` with MUMPS's count of the elimination).
  subroutine touched_inverse(sub, regularization, dofs, sd, flops)
    type(subdomain_t), intent(in) :: sub
    real(dp), intent(in) :: regularization
    integer(ip), intent(in) :: dofs(:)
    real(dp), allocatable, intent(out) :: sd(:, :)
    real(dp), intent(inout) :: flops
    integer(ip), allocatable :: irn(:), jcn(:), perm(:)
    real(dp), allocatable :: a(:)
    integer(ip) :: n
    integer :: info

    n = size(dofs, kind=ip)
    call regularized_system(sub, regularization, 'amd', irn, jcn, a, perm)
    call timer_start('explicit F: Schur')
    call dense_schur(sub%ndof, irn, jcn, a, dofs, sd, flops)
    call timer_stop('explicit F: Schur')
    flops = flops + real(n, dp)**3
    call timer_start('explicit F: inverse')
    call dpotrf('U', n, sd, n, info)
    if (info == 0) call dpotri('U', n, sd, n, info)
    if (info /= 0) call fatal_error('f_operator%build_explicit: the Schur complement of K_reg is not '// &
                                    'positive definite (LAPACK dpotrf/dpotri failed)')
    call timer_stop('explicit F: inverse')
  end subroutine touched_inverse

end module f_operator
