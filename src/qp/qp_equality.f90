!> The equality constraint C x = 0 of a QP (qp_problem), an optional part of
!> the problem (`qp_problem_t%eq`). C (orthonormal rows) is never seen as a
!> matrix; the constraint is given in "hat" form, so that the FETI dual
!> (C = L^{-1} G with G G^T = L L^T) never needs the factor L:
!> - `size()`: length m of the multiplier vector (its local part);
!> - `residual(x, z, cnorm)`: cnorm = ||C x|| and z (length m) such that the
!>   multiplier update mu <- mu + rho C x reads muhat <- muhat + rho z.
!>   Orthonormal explicit C: z = C x. FETI: z = (G G^T)^{-1} G x and
!>   cnorm^2 = (G x)^T z;
!> - `apply_t(muhat, y)`: y = C^T mu, the local slice (FETI: y = G^T muhat);
!> - `penalty()`: the rho > 0 of the penalty rho C^T C that the problem's
!>   Hessian contains (FETI: A = P F P + rho Q, Q = C^T C); `set_penalty`
!>   changes it (A <- A + (rho - penalty()) C^T C), needed only by a solver
!>   that raises rho (SMALBE with rho_growth > 1);
!> - `measure(x, cnorm)`: the per-component stopping test's measure of
!>   C x = 0 at x (qp_problem), ||C x|| by default; with `relative_measure`
!>   a dimensionless measure compared with tol itself;
!> - `moved(how, alpha)`: the solvers' notification of how x changed, so that
!>   a constraint may keep C x up to date and `residual` needs no new work:
!>   `moved_to_argument` (x is now the argument v of the last Hessian
!>   product), `moved_along_argument` (x moved to x - alpha v) or
!>   `moved_other` (any other change). Nothing by default.
!> Every procedure is collective over the problem's communicator unless
!> stated otherwise.
module qp_equality
  use kinds, only: dp, ip
  use errors, only: fatal_error
  implicit none
  private

  !> How x changed (the `how` of `moved`).
  integer, parameter, public :: moved_other = 0           !< in a way the tracking cannot follow
  integer, parameter, public :: moved_to_argument = 1     !< x is the argument v of the last Hessian product
  integer, parameter, public :: moved_along_argument = 2  !< x <- x - alpha v

  type, abstract, public :: qp_equality_t
    !> `measure` is relative (compared with tol itself), not ||C x||
    logical :: relative_measure = .false.
  contains
    procedure(size_iface), deferred :: size
    procedure(residual_iface), deferred :: residual
    procedure(apply_t_iface), deferred :: apply_t
    procedure(penalty_iface), deferred :: penalty
    procedure :: set_penalty => default_set_penalty
    procedure :: measure => default_measure
    procedure :: moved => default_moved
  end type qp_equality_t

  abstract interface
    !> Length of this rank's part of the multiplier. Local.
    integer(ip) function size_iface(self)
      import :: qp_equality_t, ip
      class(qp_equality_t), intent(in) :: self
    end function size_iface

    !> z (the multiplier form) and cnorm = ||C x||.
    subroutine residual_iface(self, x, z, cnorm)
      import :: qp_equality_t, dp
      class(qp_equality_t), intent(inout) :: self
      real(dp), intent(in) :: x(:)
      real(dp), intent(out) :: z(:)
      real(dp), intent(out) :: cnorm
    end subroutine residual_iface

    !> y = C^T mu (local slice) from the multiplier form muhat.
    subroutine apply_t_iface(self, muhat, y)
      import :: qp_equality_t, dp
      class(qp_equality_t), intent(inout) :: self
      real(dp), intent(in) :: muhat(:)
      real(dp), intent(out) :: y(:)
    end subroutine apply_t_iface

    !> The penalty rho > 0 in the Hessian. Local.
    real(dp) function penalty_iface(self)
      import :: qp_equality_t, dp
      class(qp_equality_t), intent(in) :: self
    end function penalty_iface
  end interface

contains

  !> A constraint whose penalty is fixed: any other rho is an error.
  subroutine default_set_penalty(self, rho)
    class(qp_equality_t), intent(inout) :: self
    real(dp), intent(in) :: rho
    if (rho /= self%penalty()) call fatal_error('qp_equality: this problem cannot change its penalty (set_penalty)')
  end subroutine default_set_penalty

  !> ||C x|| (cnorm of the last residual at x).
  real(dp) function default_measure(self, x, cnorm)
    class(qp_equality_t), intent(inout) :: self
    real(dp), intent(in) :: x(:)
    real(dp), intent(in) :: cnorm
    default_measure = cnorm
  end function default_measure

  !> No tracking.
  subroutine default_moved(self, how, alpha)
    class(qp_equality_t), intent(inout) :: self
    integer, intent(in) :: how
    real(dp), intent(in), optional :: alpha
  end subroutine default_moved
end module qp_equality
