!> The TFETI dual contact problem of the paper, Eq. (8), as a QP:
!>
!>   min 1/2 nu^T (P F P + rho Q) nu - nu^T P (d - F lambda~)
!>   s.t. nu_I >= -lambda~_I  and  G~ nu = o,  G~ = L^{-1} G,  G G^T = L L^T,
!>
!> with lambda = nu + lambda~. The equality constraint is given in "hat" form
!> (see qp_problem): z = (G G^T)^{-1} G nu, ||G~ nu||^2 = (G nu)^T z and
!> G~^T mu = G^T muhat with muhat = L^{-T} mu, so the factor L is never needed.
!> The multiplier vector is distributed like the coarse vectors (the 6-blocks
!> of this rank's subdomains); SMALBE only scales and adds it.
!>
!> Scaling: the QP handed to the solver is the one above divided by
!> s = ||P F P|| (Hessian A/s, linear term b/s, penalty rho/s), so that its
!> Hessian has norm ~1 and the projected gradient and ||G~ nu|| are measured in
!> the same units (multipliers); without it the SMALBE stopping test compares a
!> displacement with a force. The minimizer nu is the same; the multiplier of
!> the scaled problem is muhat/s, and `unscaled_multiplier` gives muhat back.
module dual_problem
  use kinds, only: dp, ip, MPI_REAL_DP
  use errors, only: fatal_error
  use qp_problem, only: qp_problem_t, no_lower_bound
  use feti_operators, only: feti_t
  use reconstruction, only: alpha_new
  use mpi_f08, only: MPI_Allreduce, MPI_SUM
  implicit none
  private

  type, extends(qp_problem_t), public :: dual_problem_t
    type(feti_t), pointer :: op => null()
    real(dp) :: rho = 0                       !< penalty (regularization) of Eq. (8), unscaled
    real(dp) :: scale = 1                     !< s = ||P F P||: the QP is Eq. (8) divided by s
    real(dp), allocatable, private :: px(:), fpx(:), pfpx(:)
    !> G v and (G G^T)^{-1} G v of the last Hessian argument v (from its
    !> projection), and the same for the iterate x while the solver keeps them
    !> up to date (track_*): then eq_residual costs no coarse solve.
    real(dp), allocatable, private :: last_g(:), last_z(:), x_g(:), x_z(:)
    logical, private :: last_valid = .false., x_valid = .false.
    integer(ip) :: tracked_residuals = 0       !< eq_residual calls answered from the tracking
  contains
    procedure :: init
    procedure :: prepare
    procedure :: apply_projector
    procedure :: hessian
    procedure :: penalty
    procedure :: eq_size
    procedure :: eq_residual
    procedure :: eq_apply_t
    procedure :: track_last
    procedure :: track_step
    procedure :: track_reset
    procedure :: unscaled_multiplier
    procedure :: hessian_norm
    procedure :: alpha_bar
    procedure :: free
  end type dual_problem_t

contains

  !> The problem of `op` (set up) with rho = rho_scale * ||P F P||.
  subroutine init(self, op, rho_scale)
    class(dual_problem_t), intent(inout) :: self
    type(feti_t), intent(inout), target :: op
    real(dp), intent(in) :: rho_scale
    integer(ip) :: n
    call self%free()
    self%op => op
    n = op%n_own()
    call self%init_base(op%comm(), n)
    self%has_equality = .true.
    self%rho = rho_scale*op%norm_pfp()
    if (.not. (op%norm_pfp() > 0 .and. op%norm_pfp() < huge(1.0_dp))) &
      call fatal_error('the norm of the dual operator P F P is not a positive finite number; '// &
                       '&material young (or &mesh lengths) is probably outside what double precision can handle')
    if (.not. self%rho > 0) call fatal_error('dual_problem: &solver rho_scale gives no positive penalty')
    self%scale = op%norm_pfp()
    allocate (self%px(n), self%fpx(n), self%pfpx(n))
    allocate (self%last_g(op%n_coarse()), self%last_z(op%n_coarse()), self%x_g(op%n_coarse()), &
              self%x_z(op%n_coarse()))
    self%last_valid = .false.
    self%x_valid = .false.
    self%tracked_residuals = 0
    call self%prepare()
    ! b = P (d - F lambda~)
    call op%apply_f(op%lambda_tilde_vector(), self%fpx)
    self%fpx = op%dual_rhs() - self%fpx
    call self%apply_projector(self%fpx, self%b, .false.)
    self%b = self%b/self%scale
    self%lower = merge(op%lower_bounds(), no_lower_bound, op%is_contact())
  end subroutine init

  !> y = (P F P x + rho Q x)/s, with Q x = x - P x.
  subroutine hessian(self, x, y)
    class(dual_problem_t), intent(inout) :: self
    real(dp), intent(in) :: x(:)
    real(dp), intent(out) :: y(:)
    call self%apply_projector(x, self%px, .true.)
    call self%op%apply_f(self%px, self%fpx)
    call self%apply_projector(self%fpx, self%pfpx, .false.)
    y = (self%pfpx + self%rho*(x - self%px))/self%scale
  end subroutine hessian

  !> Extra set-up of an extension before b is formed (none here).
  subroutine prepare(self)
    class(dual_problem_t), intent(inout) :: self
  end subroutine prepare

  !> y = P x with one coarse solve; with `keep`, G x and (G G^T)^{-1} G x are
  !> kept as those of the last Hessian argument (see track_*).
  subroutine apply_projector(self, x, y, keep)
    class(dual_problem_t), intent(inout) :: self
    real(dp), intent(in) :: x(:)
    real(dp), intent(inout) :: y(:)
    logical, intent(in) :: keep
    if (keep) then
      call self%op%project(x, y, self%last_g, self%last_z)
      self%last_valid = .true.
    else
      call self%op%project(x, y)
    end if
  end subroutine apply_projector

  !> x is now the argument of the last Hessian product.
  subroutine track_last(self)
    class(dual_problem_t), intent(inout) :: self
    self%x_valid = self%last_valid
    if (self%x_valid) then
      self%x_g = self%last_g
      self%x_z = self%last_z
    end if
  end subroutine track_last

  !> x moved to x - alpha v, v the argument of the last Hessian product.
  subroutine track_step(self, alpha)
    class(dual_problem_t), intent(inout) :: self
    real(dp), intent(in) :: alpha
    if (.not. (self%x_valid .and. self%last_valid)) then
      self%x_valid = .false.
      return
    end if
    self%x_g = self%x_g - alpha*self%last_g
    self%x_z = self%x_z - alpha*self%last_z
  end subroutine track_step

  !> x changed in a way the tracking cannot follow.
  subroutine track_reset(self)
    class(dual_problem_t), intent(inout) :: self
    self%x_valid = .false.
  end subroutine track_reset

  !> The penalty of the scaled QP: rho/s.
  real(dp) function penalty(self)
    class(dual_problem_t), intent(in) :: self
    penalty = self%rho/self%scale
  end function penalty

  !> ||A|| of the scaled QP, for the MPRGP step length: P F P and rho Q act on
  !> complementary subspaces, so ||A|| = max(||P F P||, rho)/s.
  real(dp) function hessian_norm(self)
    class(dual_problem_t), intent(in) :: self
    hessian_norm = max(self%op%norm_pfp(), self%rho)/self%scale
  end function hessian_norm

  !> The rigid body amplitudes by the new formula for this form of the
  !> equality constraint, from the dual gradient g and the multiplier of the
  !> scaled QP: Eq. 24, alpha_bar = (G G^T)^{-1} G g - muhat (hat form; the
  !> explicit G~ overrides it with Eq. 25).
  subroutine alpha_bar(self, g, mu_scaled, alpha)
    class(dual_problem_t), intent(inout) :: self
    real(dp), intent(in) :: g(:), mu_scaled(:)
    real(dp), intent(out) :: alpha(:)
    call alpha_new(self%op, g, self%unscaled_multiplier(mu_scaled), alpha)
  end subroutine alpha_bar

  !> muhat of Eq. (8) from the multiplier of the scaled QP.
  function unscaled_multiplier(self, muhat_scaled) result(muhat)
    class(dual_problem_t), intent(in) :: self
    real(dp), intent(in) :: muhat_scaled(:)
    real(dp) :: muhat(size(muhat_scaled))
    muhat = self%scale*muhat_scaled
  end function unscaled_multiplier

  !> Length of this rank's part of the multiplier: 6 per local subdomain.
  integer(ip) function eq_size(self)
    class(dual_problem_t), intent(in) :: self
    eq_size = self%op%n_coarse()
  end function eq_size

  !> z = (G G^T)^{-1} G x and cnorm = ||G~ x|| = sqrt((G x)^T z); from the
  !> tracked values when the solver kept them up to date, else one coarse solve.
  subroutine eq_residual(self, x, z, cnorm)
    class(dual_problem_t), intent(inout) :: self
    real(dp), intent(in) :: x(:)
    real(dp), intent(out) :: z(:)
    real(dp), intent(out) :: cnorm
    real(dp) :: mine, total
    integer :: ierr
    if (self%x_valid) then
      self%tracked_residuals = self%tracked_residuals + 1
    else
      call self%op%apply_g(x, self%x_g)
      call self%op%coarse_solve(self%x_g, self%x_z)
      self%x_valid = .true.
    end if
    z = self%x_z
    mine = dot_product(self%x_g, self%x_z)
    call MPI_Allreduce(mine, total, 1, MPI_REAL_DP, MPI_SUM, self%comm, ierr)
    cnorm = sqrt(max(total, 0.0_dp))
  end subroutine eq_residual

  !> y = G~^T mu = G^T muhat.
  subroutine eq_apply_t(self, muhat, y)
    class(dual_problem_t), intent(inout) :: self
    real(dp), intent(in) :: muhat(:)
    real(dp), intent(out) :: y(:)
    call self%op%apply_gt(muhat, y)
  end subroutine eq_apply_t

  subroutine free(self)
    class(dual_problem_t), intent(inout) :: self
    call self%free_base()
    if (allocated(self%px)) deallocate (self%px, self%fpx, self%pfpx)
    if (allocated(self%last_g)) deallocate (self%last_g, self%last_z, self%x_g, self%x_z)
    self%op => null()
  end subroutine free
end module dual_problem
