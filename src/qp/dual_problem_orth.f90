!> The TFETI dual contact problem of the paper, Eq. (8), as a QP with the
!> equality constraint orthonormalized explicitly (`&solver coarse = 'cholesky'`):
!>
!>   min 1/2 nu^T (P F P + rho Q) nu - nu^T P (d - F lambda~)
!>   s.t. nu_I >= -lambda~_I  and  G~ nu = o,  G~ = L^{-1} G,  G G^T = L L^T,
!>
!> with Q = G~^T G~ and P = I - Q applied through orthonormal_coarse (one
!> MPI_Allreduce of 6N values per projection, no coarse solve). Unlike
!> dual_problem (hat form), C = G~ is at hand, so the multiplier is mu itself:
!> eq_residual returns z = G~ nu (replicated, length 6N) and ||G~ nu|| = ||z||,
!> eq_apply_t(mu) = G~^T mu, and SMALBE's update mu <- mu + rho G~ nu is exact
!> in these variables. mu is replicated on every rank (eq_size = 6N).
!>
!> Same scaling as dual_problem: the QP handed to the solver is Eq. (8)
!> divided by s = ||P F P|| (the estimate of feti_t%setup), rho =
!> rho_scale ||P F P||; `unscaled_multiplier` gives mu of Eq. (8) back.
!> lambda~ and the bounds are those of feti_t (G lambda~ = e).
module dual_problem_orth
  use kinds, only: dp, ip
  use errors, only: fatal_error
  use logger, only: log_message
  use timers, only: timer_start, timer_stop
  use qp_problem, only: qp_problem_t, no_lower_bound
  use feti_operators, only: feti_t
  use orthonormal_coarse, only: orthonormal_coarse_t
  implicit none
  private

  type, extends(qp_problem_t), public :: dual_problem_orth_t
    type(feti_t), pointer :: op => null()
    type(orthonormal_coarse_t) :: orth          !< L and the owned columns of G~
    real(dp) :: rho = 0                         !< penalty (regularization) of Eq. (8), unscaled
    real(dp) :: scale = 1                       !< s = ||P F P||: the QP is Eq. (8) divided by s
    real(dp), allocatable, private :: px(:), fpx(:), pfpx(:)
  contains
    procedure :: init
    procedure :: hessian
    procedure :: penalty
    procedure :: eq_size
    procedure :: eq_residual
    procedure :: eq_apply_t
    procedure :: unscaled_multiplier
    procedure :: free
  end type dual_problem_orth_t

contains

  !> The problem of `op` (set up) with rho = rho_scale * ||P F P||; builds the
  !> explicit G~ (timer 'orthonormal coarse'). Collective.
  subroutine init(this, op, rho_scale)
    class(dual_problem_orth_t), intent(inout) :: this
    type(feti_t), intent(inout), target :: op
    real(dp), intent(in) :: rho_scale
    integer(ip) :: n
    character(len=200) :: line

    call this%free()
    this%op => op
    n = op%con%n_own
    call this%init_base(op%comm, n)
    this%has_equality = .true.
    this%rho = rho_scale*op%norm_pfp
    if (.not. this%rho > 0) call fatal_error('dual_problem_orth: ||P F P|| estimate is not positive')
    this%scale = op%norm_pfp

    call timer_start('orthonormal coarse')
    call this%orth%init(op%dec, op%con, op%layout, op%comm)
    call timer_stop('orthonormal coarse')
    write (line, '(a,i0,a,4(es9.2,a))') 'explicit G~ = L^{-1} G: coarse dimension ', this%orth%n, &
      ', assembly ', this%orth%seconds_assembly, ' s, Cholesky ', this%orth%seconds_factorization, &
      ' s, columns ', this%orth%seconds_columns, ' s, ', real(this%orth%bytes(), dp)/2.0_dp**20, ' MiB (rank 0)'
    call log_message(line)

    allocate (this%px(n), this%fpx(n), this%pfpx(n))
    ! b = P (d - F lambda~)
    call op%apply_f(op%lambda_tilde, this%fpx)
    this%fpx = op%d - this%fpx
    call this%orth%project(this%fpx, this%b)
    this%b = this%b/this%scale
    this%lower = merge(op%lower, no_lower_bound, op%is_contact)
  end subroutine init

  !> y = (P F P x + rho Q x)/s, with Q x = x - P x.
  subroutine hessian(self, x, y)
    class(dual_problem_orth_t), intent(inout) :: self
    real(dp), intent(in) :: x(:)
    real(dp), intent(out) :: y(:)
    call self%orth%project(x, self%px)
    call self%op%apply_f(self%px, self%fpx)
    call self%orth%project(self%fpx, self%pfpx)
    y = (self%pfpx + self%rho*(x - self%px))/self%scale
  end subroutine hessian

  !> The penalty of the scaled QP: rho/s.
  real(dp) function penalty(self)
    class(dual_problem_orth_t), intent(in) :: self
    penalty = self%rho/self%scale
  end function penalty

  !> mu of Eq. (8) from the multiplier of the scaled QP.
  function unscaled_multiplier(self, mu_scaled) result(mu)
    class(dual_problem_orth_t), intent(in) :: self
    real(dp), intent(in) :: mu_scaled(:)
    real(dp) :: mu(size(mu_scaled))
    mu = self%scale*mu_scaled
  end function unscaled_multiplier

  !> Length of the multiplier: 6N on every rank (replicated).
  integer(ip) function eq_size(self)
    class(dual_problem_orth_t), intent(in) :: self
    eq_size = self%orth%n
  end function eq_size

  !> z = G~ x (replicated) and cnorm = ||G~ x|| = ||z||: one MPI_Allreduce.
  subroutine eq_residual(self, x, z, cnorm)
    class(dual_problem_orth_t), intent(inout) :: self
    real(dp), intent(in) :: x(:)
    real(dp), intent(out) :: z(:)
    real(dp), intent(out) :: cnorm
    call self%orth%apply(x, z)
    cnorm = norm2(z(1:self%orth%n))
  end subroutine eq_residual

  !> y = G~^T mu (local, no communication).
  subroutine eq_apply_t(self, muhat, y)
    class(dual_problem_orth_t), intent(inout) :: self
    real(dp), intent(in) :: muhat(:)
    real(dp), intent(out) :: y(:)
    call self%orth%apply_t(muhat, y)
  end subroutine eq_apply_t

  subroutine free(this)
    class(dual_problem_orth_t), intent(inout) :: this
    call this%free_base()
    call this%orth%free()
    if (allocated(this%px)) deallocate (this%px, this%fpx, this%pfpx)
    this%op => null()
  end subroutine free
end module dual_problem_orth
