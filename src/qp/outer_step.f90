!> SMALBE's outer-step plug-in (the active-set polish is the one there is):
!> an object that SMALBE calls at defined points of a solve, each time with
!> the one state object `outer_state_t` that holds SMALBE's pair and its
!> counters (SMALBE lends its vectors to it for the call, without a copy):
!> - `start(problem, st)`: before the solve (st%monitor, st%warm: the solve
!>   starts warm);
!> - `first(problem, x, st)`: before the first outer iteration, a step from
!>   x itself (st%ran: it ran, st%restored: given up, pair as before);
!> - `after_outer(problem, x, st)`: after outer iteration st%outer, whose
!>   inner solve made a step when st%moved;
!> - `due(problem, x, st)`: whether a step is due after the multiplier update;
!> - `step(problem, x, st)`: the step (st%restored as for `first`).
!> A step replaces (x, st%muhat) by a better pair and updates st%g (the
!> gradient of the Lagrangian), st%b_lin = b - C^T mu and st%ct_mu = C^T mu,
!> and adds its products to st%n_hessian (at most st%max_hessian) and its
!> preconditioner applications to st%n_preconditioner.
module outer_step
  use kinds, only: dp, ip
  use qp_problem, only: qp_problem_t
  implicit none
  private

  !> SMALBE's state at an outer step.
  type, public :: outer_state_t
    real(dp), allocatable :: g(:)          !< gradient of the Lagrangian at x
    real(dp), allocatable :: muhat(:)      !< the multiplier (hat form)
    real(dp), allocatable :: b_lin(:)      !< b - C^T mu
    real(dp), allocatable :: ct_mu(:)      !< C^T mu
    real(dp) :: tol_gp = 0                 !< the outer test's bound of its g^P measure
    logical :: per_component = .false.     !< the problem's per-component stopping test
    logical :: monitor = .false.           !< SMALBE's monitor is on
    logical :: warm = .false.              !< the solve starts warm (start)
    integer(ip) :: outer = 0               !< the outer iteration just done (0: before the first)
    logical :: moved = .false.             !< its inner solve made a step
    integer(ip) :: n_hessian = 0           !< Hessian products of the solve so far
    integer(ip) :: max_hessian = 0         !< their cap
    integer(ip) :: n_preconditioner = 0    !< preconditioner applications so far
    logical :: ran = .false.               !< first: it ran
    logical :: restored = .false.          !< first / step: given up at once, the pair as before
  end type outer_state_t

  type, abstract, public :: outer_step_t
  contains
    procedure(start_iface), deferred :: start
    procedure(step_iface), deferred :: first
    procedure(step_iface), deferred :: after_outer
    procedure(due_iface), deferred :: due
    procedure(step_iface), deferred :: step
  end type outer_step_t

  abstract interface
    subroutine start_iface(self, problem, st)
      import :: outer_step_t, qp_problem_t, outer_state_t
      class(outer_step_t), intent(inout) :: self
      class(qp_problem_t), intent(inout) :: problem
      type(outer_state_t), intent(inout) :: st
    end subroutine start_iface

    subroutine step_iface(self, problem, x, st)
      import :: outer_step_t, qp_problem_t, outer_state_t, dp
      class(outer_step_t), intent(inout) :: self
      class(qp_problem_t), intent(inout) :: problem
      real(dp), intent(inout) :: x(:)
      type(outer_state_t), intent(inout) :: st
    end subroutine step_iface

    logical function due_iface(self, problem, x, st)
      import :: outer_step_t, qp_problem_t, outer_state_t, dp
      class(outer_step_t), intent(inout) :: self
      class(qp_problem_t), intent(inout) :: problem
      real(dp), intent(inout) :: x(:)
      type(outer_state_t), intent(inout) :: st
    end function due_iface
  end interface
end module outer_step
