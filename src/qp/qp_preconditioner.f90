!> The preconditioner of a QP (qp_problem), an optional part of the problem
!> (`qp_problem_t%prec`): `apply(r, z)`, z = M_A^{-1} r with M_A^{-1}
!> symmetric positive definite (an approximate inverse of the Hessian A);
!> MPRGP uses it in the face (its CG steps), the face solve in its CG.
!> A preconditioner may change during a solve (an adaptive choice,
!> `&solver preconditioner = 'auto'`): while `watches()` is true, the solvers
!> hand it after every preconditioned CG step the running condition estimate
!> of the preconditioned face operator (the Ritz values of the CG
!> coefficients, the same on every rank: ritz_values) through
!> `condition(kappa, switched)`; switched = .true. says that it changed, and
!> the solver restarts its CG direction (as on a change of the face). By
!> default nobody watches and nothing changes.
module qp_preconditioner
  use kinds, only: dp
  implicit none
  private

  type, abstract, public :: qp_preconditioner_t
  contains
    procedure(apply_iface), deferred :: apply
    procedure :: watches => default_watches
    procedure :: condition => default_condition
  end type qp_preconditioner_t

  abstract interface
    !> z = M_A^{-1} r (local slices). Collective.
    subroutine apply_iface(self, r, z)
      import :: qp_preconditioner_t, dp
      class(qp_preconditioner_t), intent(inout) :: self
      real(dp), intent(in) :: r(:)
      real(dp), intent(out) :: z(:)
    end subroutine apply_iface
  end interface

contains

  !> False: the preconditioner never changes. Local.
  logical function default_watches(self)
    class(qp_preconditioner_t), intent(in) :: self
    default_watches = .false.
  end function default_watches

  !> kappa: the running condition estimate (globally reduced); switched:
  !> the preconditioner changed in response. Never by default. Collective
  !> when watches() is true.
  subroutine default_condition(self, kappa, switched)
    class(qp_preconditioner_t), intent(inout) :: self
    real(dp), intent(in) :: kappa
    logical, intent(out) :: switched
    switched = .false.
  end subroutine default_condition
end module qp_preconditioner
