!> The interface through which an outer solver (SMALBE) holds its inner
!> bound-constrained solver (MPRGP): the inner loop `minimize` from a warm
!> start with a linear term of the caller and a stopping rule of the caller,
!> the counters the outer solver sums, and the norm estimate it may raise.
module inner_solver
  use kinds, only: dp, ip
  use ritz_values, only: cg_ritz_t
  use qp_problem, only: qp_problem_t, qp_solver_t
  implicit none
  private

  !> A stopping rule asked once per iteration (and at the start) by minimize;
  !> `observe` (nothing by default) is told each step's kind first (the
  !> caller's monitor: module solver_monitor).
  type, abstract, public :: inner_stop_t
  contains
    procedure(stop_test_iface), deferred :: test
    procedure :: observe => observe_nothing
  end type inner_stop_t

  !> An inner solver of bound-constrained QPs. Counters and gp_norm describe
  !> the last call of `minimize` (the outer solver sums them).
  type, abstract, extends(qp_solver_t), public :: inner_solver_t
    real(dp) :: a_norm = 0                     !< ||A|| (an estimate from above is safe)
    integer(ip) :: n_iterations = 0            !< steps of the last call (= cg + expansion + proportioning)
    integer(ip) :: n_cg = 0                    !< CG steps
    integer(ip) :: n_expansion = 0             !< expansion steps
    integer(ip) :: n_proportioning = 0         !< proportioning steps
    integer(ip) :: n_expansion_fallback = 0    !< 'optimal' expansions redone with alpha_bar
    integer(ip) :: n_norm_updates = 0          !< times the last call raised a_norm to a Rayleigh quotient
    real(dp) :: best_gp_norm = 0               !< smallest ||g^P|| of the last call
    integer(ip) :: n_best = 0                  !< iteration of the last call at which it was reached
    integer(ip) :: n_preconditioner = 0        !< preconditioner applications of the last call
    type(cg_ritz_t) :: ritz                    !< Ritz values of the CG runs (reset by the caller)
  contains
    procedure(minimize_iface), deferred :: minimize
    procedure(norm_at_least_iface), deferred :: norm_at_least
    procedure(variant_iface), deferred :: variant
    procedure(free_iface), deferred :: free
  end type inner_solver_t

  abstract interface
    !> Set `stop` when the iterate x with gradient g and projected gradient
    !> norm `gp_norm` is accurate enough. Collective over problem%comm (may
    !> communicate).
    subroutine stop_test_iface(self, problem, x, g, gp_norm, stop)
      import :: inner_stop_t, qp_problem_t, dp
      class(inner_stop_t), intent(inout) :: self
      class(qp_problem_t), intent(inout) :: problem
      real(dp), intent(in) :: x(:), g(:)
      real(dp), intent(in) :: gp_norm
      logical, intent(out) :: stop
    end subroutine stop_test_iface

    !> The inner iteration from a feasible x with linear term b_lin, until
    !> stop_rule holds or max_hessian products; with gradient_given, g holds
    !> A x - b_lin on entry. On return g = A x - b_lin at the last x.
    subroutine minimize_iface(self, problem, b_lin, x, g, stop_rule, max_hessian, gradient_given)
      import :: inner_solver_t, qp_problem_t, inner_stop_t, dp, ip
      class(inner_solver_t), intent(inout) :: self
      class(qp_problem_t), intent(inout) :: problem
      real(dp), intent(in) :: b_lin(:)
      real(dp), intent(inout) :: x(:), g(:)
      class(inner_stop_t), intent(inout) :: stop_rule
      integer(ip), intent(in) :: max_hessian
      logical, intent(in) :: gradient_given
    end subroutine minimize_iface

    !> Raise the norm estimate to at least `bound` (the outer solver's penalty).
    subroutine norm_at_least_iface(self, bound)
      import :: inner_solver_t, dp
      class(inner_solver_t), intent(inout) :: self
      real(dp), intent(in) :: bound
    end subroutine norm_at_least_iface

    !> Release the work vectors.
    subroutine free_iface(self)
      import :: inner_solver_t
      class(inner_solver_t), intent(inout) :: self
    end subroutine free_iface

    !> A few words on the variant (for the outer solver's monitor).
    function variant_iface(self) result(text)
      import :: inner_solver_t
      class(inner_solver_t), intent(in) :: self
      character(len=:), allocatable :: text
    end function variant_iface
  end interface

contains

  !> After a step of `kind` (solver_monitor: step_cg, ...; step_none before the
  !> first): `products` Hessian multiplications of this call so far, ||g^P||
  !> = gp_norm. The default rule watches nothing.
  subroutine observe_nothing(self, kind, products, gp_norm)
    class(inner_stop_t), intent(inout) :: self
    integer, intent(in) :: kind
    integer(ip), intent(in) :: products
    real(dp), intent(in) :: gp_norm
  end subroutine observe_nothing
end module inner_solver
