!> The TFETI dual contact problem of the paper, Eq. (8), as a QP with the
!> equality constraint orthonormalized explicitly (`&solver coarse = 'orthonormal'`):
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
!> An extension of dual_problem: the same scaling, Hessian, bounds and
!> linear term (`unscaled_multiplier` gives mu of Eq. (8) back); only the
!> projector and the equality operator are replaced.
module dual_problem_orth
  use kinds, only: dp, ip
  use logger, only: log_message
  use timers, only: timer_start, timer_stop
  use dual_problem, only: dual_problem_t
  use orthonormal_coarse, only: orthonormal_coarse_t
  use reconstruction, only: alpha_orthonormal
  implicit none
  private

  type, extends(dual_problem_t), public :: dual_problem_orth_t
    type(orthonormal_coarse_t) :: orth          !< L and the owned columns of G~
  contains
    procedure :: prepare
    procedure :: apply_projector
    procedure :: eq_size
    procedure :: eq_residual
    procedure :: eq_apply_t
    procedure :: alpha_bar
    procedure :: has_face_solver
    procedure :: free
  end type dual_problem_orth_t

contains

  !> Build the explicit G~ (timer 'orthonormal coarse'). Collective; called by
  !> dual_problem%init before the linear term is formed.
  subroutine prepare(self)
    class(dual_problem_orth_t), intent(inout) :: self
    call timer_start('orthonormal coarse')
    call self%op%init_orthonormal(self%orth)
    call timer_stop('orthonormal coarse')
    call log_message(self%orth%summary())
  end subroutine prepare

  !> y = P x = x - G~^T (G~ x): one MPI_Allreduce, no coarse solve. `keep`
  !> is not needed: eq_residual is as cheap as a projection here.
  subroutine apply_projector(self, x, y, keep)
    class(dual_problem_orth_t), intent(inout) :: self
    real(dp), intent(in) :: x(:)
    real(dp), intent(inout) :: y(:)
    logical, intent(in) :: keep
    call self%orth%project(x, y)
  end subroutine apply_projector

  !> Length of the multiplier: 6N on every rank (replicated).
  integer(ip) function eq_size(self)
    class(dual_problem_orth_t), intent(in) :: self
    eq_size = self%orth%dimension()
  end function eq_size

  !> z = G~ x (replicated) and cnorm = ||G~ x|| = ||z||: one MPI_Allreduce.
  subroutine eq_residual(self, x, z, cnorm)
    class(dual_problem_orth_t), intent(inout) :: self
    real(dp), intent(in) :: x(:)
    real(dp), intent(out) :: z(:)
    real(dp), intent(out) :: cnorm
    call self%orth%apply(x, z)
    cnorm = norm2(z(1:self%orth%dimension()))
  end subroutine eq_residual

  !> y = G~^T mu (local, no communication).
  subroutine eq_apply_t(self, muhat, y)
    class(dual_problem_orth_t), intent(inout) :: self
    real(dp), intent(in) :: muhat(:)
    real(dp), intent(out) :: y(:)
    call self%orth%apply_t(muhat, y)
  end subroutine eq_apply_t

  !> Eq. 25: alpha~_bar = G~ g - mu in the basis R~, then alpha_bar = L^{-T}
  !> alpha~_bar (see reconstruction%alpha_orthonormal).
  subroutine alpha_bar(self, g, mu_scaled, alpha)
    class(dual_problem_orth_t), intent(inout) :: self
    real(dp), intent(in) :: g(:), mu_scaled(:)
    real(dp), intent(out) :: alpha(:)
    call alpha_orthonormal(self%orth, g, self%unscaled_multiplier(mu_scaled), alpha)
  end subroutine alpha_bar

  !> No face solver: the multiplier here is mu itself, not the hat form that
  !> dual_problem%face_coefficient returns (SMALBE does not polish).
  logical function has_face_solver(self)
    class(dual_problem_orth_t), intent(in) :: self
    has_face_solver = .false.
  end function has_face_solver

  subroutine free(self)
    class(dual_problem_orth_t), intent(inout) :: self
    call self%orth%free()
    call self%dual_problem_t%free()
  end subroutine free
end module dual_problem_orth
