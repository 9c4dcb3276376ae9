!> SMALBE-M: semimonotonic augmented Lagrangians for bound and equality
!> constraints (Dostal 2006; Dostal, "Optimal Quadratic Programming
!> Algorithms", 2009), with an inner solver for the bound constrained
!> problems (MPRGP by default, through module inner_solver), for
!>
!>     min 1/2 x^T A x - b^T x   s.t.  x >= l,  C x = 0,
!>
!> where A already contains the penalty rho C^T C (rho = problem%eq%penalty()).
!> The augmented Lagrangian is therefore
!>
!>     L(x, mu) = 1/2 x^T A x - b^T x + mu^T C x
!>              = 1/2 x^T (g - b + C^T mu),   g = grad_x L = A x - b + C^T mu,
!>
!> and the inner problem of outer iteration k is the bound constrained QP
!> with Hessian A and linear term b - C^T mu_k. mu is carried in hat form
!> (see qp_problem): C^T mu = eq%apply_t(muhat), and mu <- mu + rho C x is
!> muhat <- muhat + rho z with z from eq%residual.
!>
!> Outer iteration k (M_0 = m_scale ||A||, eta = eta_scale ||b||):
!> 1. x_k: the inner solver from x_{k-1} (warm start, the gradient updated
!>    without a Hessian multiplication) until ||g^P(x, mu_k)|| <= min(M_k ||C x||, eta),
!>    or until the outer criterion below holds (inner_step);
!> 2. stop if ||g^P(x_k, mu_k)|| <= tol ||b|| and ||C x_k|| <= tol ||b||;
!>    the pair (x_k, muhat_k) is returned (mu is not updated after the test).
!>    With a problem that asks for the per-component test (qp_problem,
!>    `stop_weight`): max_i w_i |g^P_i| <= tol S and max(w) ||C x_k|| <= tol S
!>    with S = problem%stop_scale or max_i w_i |b_i| instead (the M test and
!>    eta stay in the 2-norm) (outer_stop);
!> 3. muhat_{k+1} = muhat_k + rho z_k (update_multiplier);
!> 4. if k > 1 and L(x_k, mu_k) < L(x_{k-1}, mu_{k-1}) + rho/2 ||C x_k||^2,
!>    M_{k+1} = beta M_k (beta in (0,1)), else M_{k+1} = M_k (update_m; with
!>    `m_no_step`, what an inner solve without a step does to M);
!> 5. adaptive penalty (rho_growth > 1): rho <- rho_growth rho when
!>    ||C x_k|| > rho_contraction^w ||C x_{k-w}|| (w = rho_window, and at
!>    least w outer iterations after the last raise), at most smalbe_rho_cap rho_0;
!>    with rho_stall > 0 the first raise waits for a stall (update_penalty);
!>    the problem's Hessian follows through problem%set_penalty;
!> 6. the optional outer-step plug-in, the active-set polish (module
!>    active_set_polish, settings%polish): an exact solve on a face that has
!>    settled replaces (x, mu); the L test of 4. is not applied to that step.
!>
!> The test of step 4 compares the Lagrangians of consecutive pairs (x_k, mu_k)
!> as PERMON's SMALXE does. Written with mu_{k+1} and mu_k instead,
!> L(x_k, mu_{k+1}) >= L(x_{k-1}, mu_k) + rho/2 ||C x_k||^2 fails even for
!> exact inner solves (no bounds) as soon as rho > 0.62 / lambda_max(C A_0^{-1}
!> C^T), A_0 = A - rho C^T C the Hessian without the penalty: always for the
!> FETI dual, where A_0 = P F P vanishes on Im C^T. M would be cut in nearly
!> every outer iteration.
!> For exact inner solves the form used here always holds (the dual function
!> grows by at least rho/2 ||C x_{k-1}||^2 per step), which is what keeps M
!> bounded below in the theory.
!> With L(x_{k-1}, mu_k) = L(x_{k-1}, mu_{k-1}) + rho ||C x_{k-1}||^2, the test
!> needs only the change L(x_k, mu_k) - L(x_{k-1}, mu_k) of the inner
!> quadratic, computed as 1/2 (x_k - x_{k-1})^T (g(x_k) + g(x_{k-1})) with both
!> gradients for mu_k at hand (exact for a quadratic). Differencing two values
!> of L instead loses all digits near convergence, where the test would be
!> decided by round-off.
!> When b = 0, ||b|| is replaced by 1 in tol ||b|| and eta.
!>
!> ||C x|| costs one eq%residual (for FETI: one coarse problem solve). The
!> inner stopping rule evaluates it only when ||g^P|| <= max(eta, tol ||b||),
!> since otherwise neither inner criterion can hold (counted in n_eq_residual).
!>
!> Caps: max_outer outer iterations, max_hessian Hessian multiplications in
!> total (inner solves get the remaining budget); either ends the solve with a
!> "not converged" status and a message, as do NaN/Inf (qp_status_not_finite).
!>
!> Settings: smalbe_settings_t (the defaults are the program's, `&solver`,
!> docs/INPUT.md), with the inner solver's (mprgp_settings_t) and the
!> polish's (polish_settings_t) inside; each type checks, reads and writes its
!> own variables. Report: smalbe_t%report writes the solver's section.
!>
!> History: cnorm_history(k) = ||C x_k||, hessian_history(k) = Hessian
!> multiplications after outer iteration k and rho_history(k) = the penalty of
!> its inner solve (the SMALBE monitor's columns).
!>
!> Monitor (monitor = .true., rank 0 through module logger): a header with
!> rho, ||A||, M_0, eta, tol ||b||; one line per outer iteration: outer
!> iteration, inner iterations of this outer iteration, Hessian
!> multiplications so far, ||g^P||, ||C x||, M used by the inner solve, rho,
!> L(x_k, mu_k), number of x_i at their bound (global); then a summary with
!> the status message and the totals.
module smalbe
  use, intrinsic :: ieee_arithmetic, only: ieee_is_finite
  use kinds, only: dp, ip, i8, name_len
  use errors, only: fatal_error
  use logger, only: log_message
  use text, only: lower_case, counted, ints_text, reals_text
  use report_sink, only: report_sink_t
  use qp_problem, only: qp_problem_t, qp_solver_t, qp_message_len, compensated_add, qp_status_converged, &
                        qp_status_max_hessian, qp_status_max_outer, qp_status_not_finite, &
                        qp_status_incompatible, qp_status_not_run, qp_status_name
  use inner_solver, only: inner_solver_t, inner_stop_t
  use mprgp, only: mprgp_t, mprgp_settings_t, ensure_size
  use active_set_polish, only: active_set_polish_t, polish_settings_t
  use outer_step, only: outer_state_t
  use face_recycle, only: face_recycle_t
  use solver_monitor, only: solver_monitor_t
  use settings_base, only: settings_t, refuse
  implicit none
  private

  !> The inner stopping rule of SMALBE-M; keeps z and ||C x|| of the last
  !> evaluation for the multiplier update.
  type, extends(inner_stop_t) :: smalbe_inner_stop_t
    real(dp) :: m_bound = 0, eta = 0
    real(dp) :: tol_gp = 0                 !< the outer test's bound of the measure of g^P
    real(dp) :: tol_c = 0                  !< the outer test's bound of the equality measure
    real(dp) :: rho = 0                    !< the penalty (per-component test: g without rho C^T C x)
    real(dp) :: w_max = 1                  !< max_i w_i of the per-component test
    logical :: per_component = .false.     !< the problem's per-component test (else ||g^P||, ||C x||)
    real(dp) :: gp_measure = 0             !< the measure of g^P at the x of the last evaluation
    real(dp) :: eq_measure = 0             !< the equality measure at that x
    real(dp) :: cnorm = 0                  !< ||C x|| of the last evaluation
    logical :: evaluated = .false.         !< cnorm and z belong to the x of the last test
    !> the next test (the first of an inner solve right after a polish) does not stop on the M test:
    !> m_bound <- beta^j m_bound with the least j that forces a step (n_forced_cuts = j)
    logical :: force_step = .false.
    real(dp) :: beta = 0.5_dp
    integer(ip) :: n_forced_cuts = 0
    integer(ip) :: n_eq_residual = 0
    real(dp), allocatable :: z(:)
    real(dp), allocatable :: work(:)       !< C^T C x, then g - rho C^T C x (per-component test)
    type(solver_monitor_t) :: monitor      !< SMALBE's monitor (its mprgp and outer lines)
  contains
    procedure :: test => inner_stop_test
    procedure :: observe => inner_stop_observe
    procedure :: outer_measures
    procedure :: outer_met
  end type smalbe_inner_stop_t

  !> The settings of SMALBE-M (`&solver`, docs/INPUT.md; the defaults are the
  !> program's), with those of its inner solver and of the polish.
  type, extends(settings_t), public :: smalbe_settings_t
    real(dp) :: tol = 1.0e-6_dp                !< relative tolerance (of ||b||)
    integer(ip) :: max_outer = 200             !< cap of outer iterations
    integer(ip) :: max_hessian = 20000         !< cap of Hessian multiplications in total
    real(dp) :: m_scale = 100                  !< M_0 = m_scale ||A||
    real(dp) :: beta = 0.5_dp                  !< M <- beta M when the Lagrangian grows too little
    real(dp) :: eta_scale = 0.1_dp             !< eta = eta_scale ||b||
    !> what an inner solve that made no step does to M: 'cut' (M <- beta M),
    !> 'temporary' (only the next inner solve uses beta M, beta^2 M, ... while
    !> the solves make no step) or 'keep' (SMALBE-M's theory: nothing)
    character(len=name_len) :: m_no_step = 'cut'
    !> adaptive penalty: rho <- rho_growth rho when ||C x_k|| > rho_contraction^w
    !> ||C x_{k-w}|| (w = rho_window) after an inner solve that made a step, at
    !> least w outer iterations after the last raise (rho_growth 1: rho constant)
    real(dp) :: rho_growth = 2
    real(dp) :: rho_contraction = 0.5_dp
    integer(ip) :: rho_window = 10
    !> > 0: a stall detector for the first raise only: ||C x_k|| >
    !> rho_stall^w ||C x_{k-w}||; after it the per-iteration test with
    !> rho_contraction (w = 1). 0: every raise uses rho_contraction and w
    real(dp) :: rho_stall = 0.95_dp
    logical :: monitor = .true.                !< one line per outer iteration and a summary
    type(mprgp_settings_t) :: inner            !< the inner MPRGP
    type(polish_settings_t) :: polish          !< the active-set polish
  contains
    procedure :: check => smalbe_settings_check
    procedure :: group => smalbe_settings_group
    procedure :: variables => smalbe_settings_variables
    procedure :: read_namelist => smalbe_settings_read
    procedure :: write_namelist => smalbe_settings_write
  end type smalbe_settings_t

  !> rho never exceeds rho_cap times its initial value (adaptive penalty)
  real(dp), parameter, public :: smalbe_rho_cap = 100

  !> What an inner solve without a step does to M (settings%m_no_step, chosen once in init).
  integer, parameter :: m_no_step_cut = 1, m_no_step_temporary = 2, m_no_step_keep = 3

  !> The SMALBE-M solver with its inner solver and the polish. All counters
  !> are totals of the last solve (its report section: `report`).
  type, extends(qp_solver_t), public :: smalbe_t
    type(smalbe_settings_t) :: settings        !< as given to init
    class(inner_solver_t), allocatable :: inner   !< inner solver (its counters: the last inner solve)
    type(active_set_polish_t) :: polish        !< the optional outer step (active when settings%polish%window > 0)
    real(dp) :: a_norm = 0                     !< ||A|| (penalty included)
    real(dp) :: rho_initial = 0                !< problem%eq%penalty() at the start of the last solve
    integer(ip) :: n_rho_updates = 0           !< times rho was raised
    ! results of the last solve
    real(dp), allocatable :: muhat(:)          !< final multiplier, hat form (C^T mu = eq%apply_t(muhat))
    !> when allocated with eq%size() entries, the next solve starts from this
    !> multiplier instead of 0 (and deallocates it): a warm start
    real(dp), allocatable :: muhat_start(:)
    real(dp) :: cnorm = 0                      !< ||C x|| at the returned x
    real(dp) :: lagrangian = 0                 !< L(x, mu) at the returned pair
    real(dp) :: rho = 0                        !< problem%eq%penalty()
    real(dp) :: norm_b = 0                     !< ||b||
    real(dp) :: tol_abs = 0                    !< tol ||b||
    logical :: per_component = .false.         !< the problem's per-component stopping test is used
    real(dp) :: gp_measure = 0                 !< the stopping test's measure of g^P at the returned x
    real(dp) :: eq_measure = 0                 !< its measure of C x = 0 at the returned x
    real(dp) :: tol_gp = 0                     !< the bound of gp_measure: tol ||b||, or tol S (see the module)
    real(dp) :: tol_c = 0                      !< the bound of eq_measure: tol ||b||, or tol
    real(dp) :: eta = 0                        !< eta_scale ||b||
    real(dp) :: m_initial = 0                  !< M_0
    real(dp) :: m_bound = 0                    !< M of the last inner solve
    integer(ip) :: n_outer = 0                 !< outer iterations (inner solves)
    integer(ip) :: n_inner = 0                 !< inner iterations in all
    integer(ip) :: n_cg = 0                    !< CG steps in all
    integer(ip) :: n_expansion = 0             !< expansion steps in all
    integer(ip) :: n_proportioning = 0         !< proportioning steps in all
    integer(ip) :: n_expansion_fallback = 0    !< 'optimal' expansions redone with alpha_bar
    integer(ip) :: n_eq_residual = 0           !< eq_residual calls (FETI: coarse solves for ||C x||)
    integer(ip) :: n_m_updates = 0             !< times M was reduced
    integer(ip) :: n_no_step = 0               !< inner solves that made no step
    integer(ip) :: n_norm_updates = 0          !< times the inner solver raised its ||A|| estimate
    integer(ip) :: n_active = 0                !< components at their bound at the returned x
    integer(ip) :: n_preconditioner = 0        !< preconditioner applications in all (inner solver and face)
    logical :: preconditioned = .false.        !< the inner solver used the problem's preconditioner
    !> per outer iteration k of the last solve: ||C x_k|| after the inner solve
    !> and the Hessian multiplications so far (report.json: the contraction
    !> ||C x_k|| / ||C x_(k-1)|| and the products per outer iteration)
    real(dp), allocatable :: cnorm_history(:)
    integer(ip), allocatable :: hessian_history(:)
    real(dp), allocatable :: rho_history(:)    !< the penalty of outer iteration k's inner solve
    real(dp), allocatable, private :: b_lin(:), ct_mu(:), ct_new(:), x_prev(:), g_prev(:)
    type(smalbe_inner_stop_t), private :: rule
    ! the state of the outer loop of the current solve
    integer, private :: m_no_step_kind = m_no_step_cut
    real(dp), private :: m_now = 0             !< M_k
    real(dp), private :: l_shift = 0           !< L(x_{k-1}, mu_k) - L(x_{k-1}, mu_{k-1}) (step 4)
    integer(ip), private :: n_idle = 0         !< inner solves without a step in a row ('temporary')
    integer(ip), private :: last_raise = 0     !< outer iteration of the last raise of rho
    logical, private :: after_polish = .false. !< the pair comes from a polish
  contains
    procedure :: init => smalbe_init
    procedure :: init_with => smalbe_init
    procedure :: free => smalbe_free
    procedure :: solve => smalbe_solve
    procedure :: is_compatible => smalbe_is_compatible
    procedure :: report => smalbe_report
    procedure :: warm_start
    procedure :: recycle_directions
    procedure :: kept_directions
    procedure :: reuse_counts
    procedure :: report_copy
  end type smalbe_t

contains

  !> Stop the inner loop on ||g^P|| <= min(M ||C x||, eta), or on the outer
  !> criterion (outer_met). A non-finite ||C x|| also stops it (SMALBE then
  !> reports it). ||C x|| is evaluated only where one of the two can hold:
  !> ||g^P|| <= eta, or (classical test) ||g^P|| <= tol_gp, or (per-component
  !> test) max_i w_i |g^P_i| <= tol_gp + rho w_max ||C x|| for a ||C x|| small
  !> enough that the M test would not stop the loop (||C x|| < ||g^P|| / M).
  subroutine inner_stop_test(self, problem, x, g, gp_norm, stop)
    class(smalbe_inner_stop_t), intent(inout) :: self
    class(qp_problem_t), intent(inout) :: problem
    real(dp), intent(in) :: x(:), g(:)
    real(dp), intent(in) :: gp_norm
    logical, intent(out) :: stop
    real(dp) :: gpw
    logical :: force
    stop = .false.
    self%evaluated = .false.
    force = self%force_step
    self%force_step = .false.
    if (self%per_component) then
      gpw = problem%projected_gradient_max(x, g)
      if (gp_norm > self%eta .and. gpw > self%tol_gp + self%rho*self%w_max*gp_norm/self%m_bound) return
    else
      if (gp_norm > max(self%eta, self%tol_gp)) return
    end if
    call problem%eq%residual(x, self%z, self%cnorm)
    self%n_eq_residual = self%n_eq_residual + 1
    self%evaluated = .true.
    if (.not. ieee_is_finite(self%cnorm)) then
      stop = .true.
      return
    end if
    if (force .and. gp_norm <= min(self%m_bound*self%cnorm, self%eta)) then
      ! right after a polish whose pair the outer test may not accept: the outer test first, else the
      ! least cut of the bound (for this inner solve only) that makes the solve take a step
      call self%outer_measures(problem, x, g, gp_norm)
      if (self%outer_met()) then
        stop = .true.
        return
      end if
      do while (gp_norm <= self%m_bound*self%cnorm .and. self%n_forced_cuts < 200)
        self%m_bound = self%beta*self%m_bound
        self%n_forced_cuts = self%n_forced_cuts + 1
      end do
    end if
    if (gp_norm <= min(self%m_bound*self%cnorm, self%eta)) then
      stop = .true.
      return
    end if
    call self%outer_measures(problem, x, g, gp_norm)
    stop = self%outer_met()
  end subroutine inner_stop_test

  !> The monitor's line of a run of MPRGP steps: ||g^P|| against the inner
  !> bound min(M ||C x||, eta) at the last evaluation of ||C x|| (eta before
  !> the first of the solve: cnorm < 0).
  subroutine inner_stop_observe(self, kind, products, gp_norm)
    class(smalbe_inner_stop_t), intent(inout) :: self
    integer, intent(in) :: kind
    integer(ip), intent(in) :: products
    real(dp), intent(in) :: gp_norm
    real(dp) :: bound
    bound = self%eta
    if (self%cnorm >= 0) bound = min(self%m_bound*self%cnorm, self%eta)
    call self%monitor%inner_step(kind, products, gp_norm, bound)
  end subroutine inner_stop_observe

  !> gp_measure and eq_measure at x (g the gradient there; z and cnorm of
  !> eq%residual at x already computed). Classical: ||g^P|| and ||C x||.
  !> Per-component: max_i w_i |v^P_i| with v = g - rho C^T C x, the gradient
  !> without its penalty part (for the FETI dual: the constraint violation of
  !> the displacements the multipliers define), and problem%eq_measure.
  subroutine outer_measures(self, problem, x, g, gp_norm)
    class(smalbe_inner_stop_t), intent(inout) :: self
    class(qp_problem_t), intent(inout) :: problem
    real(dp), intent(in) :: x(:), g(:)
    real(dp), intent(in) :: gp_norm
    integer(ip) :: n
    if (.not. self%per_component) then
      self%gp_measure = gp_norm
      self%eq_measure = self%cnorm
      return
    end if
    n = problem%n
    if (allocated(self%work)) then
      if (size(self%work) /= n) deallocate (self%work)
    end if
    if (.not. allocated(self%work)) allocate (self%work(n))
    call problem%eq%apply_t(self%z, self%work)
    self%work(1:n) = g(1:n) - self%rho*self%work(1:n)
    self%gp_measure = problem%projected_gradient_max(x, self%work)
    self%eq_measure = problem%eq%measure(x, self%cnorm)
  end subroutine outer_measures

  !> The outer criterion on the measures of the last evaluation.
  logical function outer_met(self)
    class(smalbe_inner_stop_t), intent(in) :: self
    outer_met = self%gp_measure <= self%tol_gp .and. self%eq_measure <= self%tol_c
  end function outer_met

  !> Set the settings `s` (checked: fatal_error on a value out of range) with
  !> ||A|| = a_norm > 0 (penalty included). The inner solver is an MPRGP with
  !> s%inner, or a copy of `inner` (initialized by the caller) when given.
  subroutine smalbe_init(self, s, a_norm, inner)
    class(smalbe_t), intent(inout) :: self
    type(smalbe_settings_t), intent(in) :: s
    real(dp), intent(in) :: a_norm
    class(inner_solver_t), intent(in), optional :: inner
    character(len=:), allocatable :: variable, rule, got

    call self%free()
    call s%check(variable, rule, got)
    if (len(variable) > 0) call fatal_error('smalbe: '//variable//' '//rule//' (got '//got//')')
    self%settings = s
    if (allocated(self%inner)) deallocate (self%inner)
    if (present(inner)) then
      allocate (self%inner, source=inner)
    else
      allocate (mprgp_t :: self%inner)
      select type (mp => self%inner)
      type is (mprgp_t)
        call mp%init_with(s%inner, a_norm, s%tol, s%max_hessian, monitor=.false.)
      end select
    end if
    self%a_norm = a_norm
    self%monitor = s%monitor
    self%polish%settings = s%polish
    select case (s%m_no_step)
    case ('temporary')
      self%m_no_step_kind = m_no_step_temporary
    case ('keep')
      self%m_no_step_kind = m_no_step_keep
    case default
      self%m_no_step_kind = m_no_step_cut
    end select
  end subroutine smalbe_init

  !> The first setting out of its range (SMALBE's, then the inner solver's,
  !> then the polish's): `variable` its name ('' if none), `rule` the
  !> allowed values, `got` the value.
  subroutine smalbe_settings_check(self, variable, rule, got)
    class(smalbe_settings_t), intent(in) :: self
    character(len=:), allocatable, intent(out) :: variable, rule, got
    variable = ''
    rule = ''
    got = ''
    if (.not. (self%tol > 0 .and. self%tol < 1)) then
      call refuse('tol', 'must be in (0, 1)', reals_text([self%tol]), variable, rule, got)
    else if (self%max_outer < 1) then
      call refuse('max_outer', 'must be >= 1', ints_text([self%max_outer]), variable, rule, got)
    else if (self%max_hessian < 1) then
      call refuse('max_hessian', 'must be >= 1', ints_text([self%max_hessian]), variable, rule, got)
    else if (.not. (self%m_scale > 0)) then
      call refuse('m_scale', 'must be > 0', reals_text([self%m_scale]), variable, rule, got)
    else if (.not. (self%beta > 0 .and. self%beta < 1)) then
      call refuse('beta', 'must be in (0, 1)', reals_text([self%beta]), variable, rule, got)
    else if (.not. (self%eta_scale > 0)) then
      call refuse('eta_scale', 'must be > 0', reals_text([self%eta_scale]), variable, rule, got)
    else if (.not. any(self%m_no_step == [character(len=9) :: 'cut', 'temporary', 'keep'])) then
      call refuse('m_no_step', "must be 'cut', 'temporary' or 'keep'", self%m_no_step, variable, rule, got)
    else if (.not. (self%rho_growth >= 1)) then
      call refuse('rho_growth', 'must be >= 1', reals_text([self%rho_growth]), variable, rule, got)
    else if (.not. (self%rho_contraction > 0 .and. self%rho_contraction < 1)) then
      call refuse('rho_contraction', 'must be in (0, 1)', reals_text([self%rho_contraction]), variable, rule, got)
    else if (self%rho_window < 1) then
      call refuse('rho_window', 'must be >= 1', ints_text([self%rho_window]), variable, rule, got)
    else if (.not. (self%rho_stall >= 0 .and. self%rho_stall < 1)) then
      call refuse('rho_stall', 'must be in [0, 1) (0: off)', reals_text([self%rho_stall]), variable, rule, got)
    else
      call self%inner%check(variable, rule, got)
      if (len(variable) == 0) call self%polish%check(variable, rule, got)
    end if
  end subroutine smalbe_settings_check

  !> The namelist group of these variables.
  function smalbe_settings_group(self) result(name)
    class(smalbe_settings_t), intent(in) :: self
    character(len=:), allocatable :: name
    name = 'solver'
  end function smalbe_settings_group

  !> The names of the namelist variables (those of read_namelist).
  subroutine smalbe_settings_variables(self, names)
    class(smalbe_settings_t), intent(in) :: self
    character(len=name_len), allocatable, intent(out) :: names(:)
    names = [character(len=name_len) :: 'tol', 'max_outer', 'max_hessian', 'm_scale', 'beta', &
        'eta_scale', 'm_no_step', 'rho_growth', 'rho_contraction', 'rho_window', 'rho_stall', &
        'monitor']
  end subroutine smalbe_settings_variables

  !> Read SMALBE's own variables from the namelist group text `group`
  !> ('&solver ... /', only these variables); strings lower case.
  subroutine smalbe_settings_read(self, group, status, msg)
    class(smalbe_settings_t), intent(inout) :: self
    character(len=*), intent(in) :: group
    integer, intent(out) :: status
    character(len=*), intent(out) :: msg
    real(dp) :: tol, m_scale, beta, eta_scale, rho_growth, rho_contraction, rho_stall
    integer(ip) :: max_outer, max_hessian, rho_window
    character(len=name_len) :: m_no_step
    logical :: monitor
    namelist /solver/ tol, max_outer, max_hessian, m_scale, beta, eta_scale, m_no_step, rho_growth, &
      rho_contraction, rho_window, rho_stall, monitor
    tol = self%tol; max_outer = self%max_outer; max_hessian = self%max_hessian; m_scale = self%m_scale
    beta = self%beta; eta_scale = self%eta_scale; m_no_step = self%m_no_step; rho_growth = self%rho_growth
    rho_contraction = self%rho_contraction; rho_window = self%rho_window; rho_stall = self%rho_stall
    monitor = self%monitor
    read (group, nml=solver, iostat=status, iomsg=msg)
    if (status /= 0) return
    self%tol = tol; self%max_outer = max_outer; self%max_hessian = max_hessian; self%m_scale = m_scale
    self%beta = beta; self%eta_scale = eta_scale; self%m_no_step = lower_case(m_no_step)
    self%rho_growth = rho_growth; self%rho_contraction = rho_contraction; self%rho_window = rho_window
    self%rho_stall = rho_stall; self%monitor = monitor
  end subroutine smalbe_settings_read

  !> Write SMALBE's own variables as the namelist group '&solver ... /'.
  subroutine smalbe_settings_write(self, lines, status, msg)
    class(smalbe_settings_t), intent(in) :: self
    character(len=*), intent(out) :: lines(:)
    integer, intent(out) :: status
    character(len=*), intent(out) :: msg
    real(dp) :: tol, m_scale, beta, eta_scale, rho_growth, rho_contraction, rho_stall
    integer(ip) :: max_outer, max_hessian, rho_window
    character(len=name_len) :: m_no_step
    logical :: monitor
    namelist /solver/ tol, max_outer, max_hessian, m_scale, beta, eta_scale, m_no_step, rho_growth, &
      rho_contraction, rho_window, rho_stall, monitor
    tol = self%tol; max_outer = self%max_outer; max_hessian = self%max_hessian; m_scale = self%m_scale
    beta = self%beta; eta_scale = self%eta_scale; m_no_step = self%m_no_step; rho_growth = self%rho_growth
    rho_contraction = self%rho_contraction; rho_window = self%rho_window; rho_stall = self%rho_stall
    monitor = self%monitor
    lines = ''
    write (lines, nml=solver, delim='quote', iostat=status, iomsg=msg)
  end subroutine smalbe_settings_write


  subroutine smalbe_free(self)
    class(smalbe_t), intent(inout) :: self
    if (allocated(self%inner)) call self%inner%free()
    if (allocated(self%muhat)) deallocate (self%muhat)
    if (allocated(self%gradient)) deallocate (self%gradient)
    if (allocated(self%b_lin)) deallocate (self%b_lin)
    if (allocated(self%ct_mu)) deallocate (self%ct_mu)
    if (allocated(self%ct_new)) deallocate (self%ct_new)
    if (allocated(self%x_prev)) deallocate (self%x_prev)
    if (allocated(self%g_prev)) deallocate (self%g_prev)
    if (allocated(self%rule%z)) deallocate (self%rule%z)
    self%status = qp_status_not_run
    self%message = 'not run'
  end subroutine smalbe_free

  !> SMALBE needs the equality constraint and a positive penalty in A.
  logical function smalbe_is_compatible(self, problem, reason)
    class(smalbe_t), intent(in) :: self
    class(qp_problem_t), intent(inout) :: problem
    character(len=*), intent(out) :: reason
    character(len=40) :: buf
    reason = ''
    smalbe_is_compatible = .false.
    if (self%a_norm <= 0) then
      reason = 'SMALBE is not initialized (call init first)'
    else if (.not. allocated(problem%eq)) then
      reason = 'SMALBE needs the equality constraint C x = 0 (no eq part; use MPRGP)'
    else if (.not. (problem%eq%penalty() > 0)) then
      write (buf, '(es10.3)') problem%eq%penalty()
      reason = 'SMALBE needs a penalty rho > 0 in the Hessian (penalty() = '//trim(adjustl(buf))//')'
    else if (problem%eq%size() < 1) then
      reason = 'SMALBE needs at least one multiplier (eq%size() < 1)'
    else if (.not. (allocated(problem%b) .and. allocated(problem%lower))) then
      reason = 'the problem has no b or lower bounds (not initialized)'
    else if (size(problem%b) < problem%n .or. size(problem%lower) < problem%n) then
      reason = 'the problem has b or lower bounds shorter than its local length n'
    else
      smalbe_is_compatible = .true.
    end if
  end function smalbe_is_compatible


  !> Solve from x (projected onto the bounds first); muhat starts at 0, or at
  !> muhat_start when that is set.
  !> On return: x, muhat, gradient = A x - b + C^T mu, gp_norm, cnorm,
  !> lagrangian belong to the same pair (x_k, mu_k); status and message say
  !> whether tol was met. The steps 1-6 of the module.
  subroutine smalbe_solve(self, problem, x)
    class(smalbe_t), intent(inout) :: self
    class(qp_problem_t), intent(inout) :: problem
    real(dp), intent(inout) :: x(:)
    character(len=qp_message_len) :: reason
    real(dp) :: change
    integer(ip) :: outer
    logical :: gradient_given, polished
    type(outer_state_t) :: st

    call reset_counters(self)
    if (.not. self%is_compatible(problem, reason)) then
      self%status = qp_status_incompatible
      self%message = 'problem refused: '//trim(reason)
      call log_message('SMALBE reason: '//reason_code(self%status)//'; '//trim(self%message))
      return
    end if
    if (size(x) < problem%n) call fatal_error('smalbe: x shorter than the local length of the problem')
    call prepare(self, problem, x, st)
    gradient_given = .false.
    if (self%monitor) call monitor_header(self)

    self%status = qp_status_not_run
    ! 0. the polish first (active_set_polish): SMALBE from its pair, or, given up in its first
    ! round, from that x (the inner solver computes the gradient)
    call lend(self, st)
    call self%polish%first(problem, x, st)
    call take_back(self, st)
    if (st%ran) then
      self%after_polish = .not. st%restored
      gradient_given = .not. st%restored
    end if
    do outer = 1, self%settings%max_outer
      ! 1. the inner problem
      if (.not. inner_step(self, problem, x, outer, gradient_given)) exit
      gradient_given = .true.
      if (.not. outer_values(self, problem, x, outer, change)) exit
      if (self%monitor) call self%rule%monitor%outer_line(outer, self%n_hessian, self%gp_measure, self%tol_gp, &
                                                          self%eq_measure, self%tol_c, self%rho, &
                                                          problem%count_at_bound(x))
      ! the active set: unchanged for how many outer iterations (polish)
      st%outer = outer
      st%moved = self%inner%n_iterations > 0
      call self%polish%after_outer(problem, x, st)
      ! 2. outer stopping criterion, caps
      if (outer_stop(self, outer)) exit
      ! 3. - 5.
      call update_multiplier(self, problem)
      call update_m(self, outer, change)
      call update_penalty(self, problem, outer)
      ! 6. the polish: the exact solve on a face that has settled
      call lend(self, st)
      polished = self%polish%due(problem, x, st)
      if (polished) call self%polish%step(problem, x, st)
      call take_back(self, st)
      if (polished .and. .not. st%restored) then
        self%after_polish = .true.
        self%l_shift = 0
      end if
    end do
    self%n_eq_residual = self%rule%n_eq_residual
    self%n_active = problem%count_at_bound(x)
    call monitor_summary(self)
  end subroutine smalbe_solve

  !> SMALBE's pair and counters handed to the outer step's state for a call
  !> (the vectors moved, not copied; take_back returns them).
  subroutine lend(self, st)
    class(smalbe_t), intent(inout) :: self
    type(outer_state_t), intent(inout) :: st
    call move_alloc(self%gradient, st%g)
    call move_alloc(self%muhat, st%muhat)
    call move_alloc(self%b_lin, st%b_lin)
    call move_alloc(self%ct_mu, st%ct_mu)
    st%tol_gp = self%tol_gp
    st%per_component = self%per_component
    st%n_hessian = self%n_hessian
    st%max_hessian = self%settings%max_hessian
    st%n_preconditioner = self%n_preconditioner
  end subroutine lend

  !> The pair and counters back from the outer step's state.
  subroutine take_back(self, st)
    class(smalbe_t), intent(inout) :: self
    type(outer_state_t), intent(inout) :: st
    call move_alloc(st%g, self%gradient)
    call move_alloc(st%muhat, self%muhat)
    call move_alloc(st%b_lin, self%b_lin)
    call move_alloc(st%ct_mu, self%ct_mu)
    self%n_hessian = st%n_hessian
    self%n_preconditioner = st%n_preconditioner
  end subroutine take_back

  !> A warm start (a load history): the next solve starts from the multiplier
  !> muhat (eq%size() entries, else ignored) instead of 0, and the polish
  !> first from the face of the given x.
  subroutine warm_start(self, muhat)
    class(smalbe_t), intent(inout) :: self
    real(dp), intent(in) :: muhat(:)
    self%muhat_start = muhat
  end subroutine warm_start

  !> Keep the face CG directions of the polish's face solves for the later
  !> solves with the same Hessian (face_recycle; a load history), or not.
  subroutine recycle_directions(self, on)
    class(smalbe_t), intent(inout) :: self
    logical, intent(in) :: on
    self%polish%face%recycle%on = on
  end subroutine recycle_directions

  !> The kept face CG directions (to save in a checkpoint or to read one into).
  function kept_directions(self) result(kept)
    class(smalbe_t), intent(inout), target :: self
    type(face_recycle_t), pointer :: kept
    kept => self%polish%face%recycle
  end function kept_directions

  !> Of the last solve: face solves on the face before (its matrices reused)
  !> and kept directions the face solves' starts used.
  subroutine reuse_counts(self, faces_reused, recycled)
    class(smalbe_t), intent(in) :: self
    integer(ip), intent(out) :: faces_reused, recycled
    faces_reused = self%polish%n_faces_reused
    recycled = self%polish%n_recycled
  end subroutine reuse_counts

  !> A copy of the solver for a later report: all of it but the kept face CG
  !> directions (up to 192 MiB per rank, which no report reads).
  subroutine report_copy(self, copy)
    class(smalbe_t), intent(inout) :: self
    type(smalbe_t), intent(out) :: copy
    real(dp), allocatable :: w(:, :), q(:, :)
    call move_alloc(self%polish%face%recycle%w, w)
    call move_alloc(self%polish%face%recycle%q, q)
    copy = self
    call move_alloc(w, self%polish%face%recycle%w)
    call move_alloc(q, self%polish%face%recycle%q)
  end subroutine report_copy

  !> Work vectors, the penalty, the tolerances and M_0, muhat = 0, the inner
  !> stopping rule, the polish's state; x projected onto the bounds.
  subroutine prepare(self, problem, x, st)
    class(smalbe_t), intent(inout) :: self
    class(qp_problem_t), intent(inout) :: problem
    real(dp), intent(inout) :: x(:)
    type(outer_state_t), intent(inout) :: st
    real(dp) :: scale
    integer(ip) :: n, m
    n = problem%n
    m = problem%eq%size()
    call ensure_size(self%gradient, n)
    call ensure_size(self%b_lin, n)
    call ensure_size(self%ct_mu, n)
    call ensure_size(self%ct_new, n)
    call ensure_size(self%x_prev, n)
    call ensure_size(self%g_prev, n)
    call ensure_size(self%muhat, m)
    call ensure_size(self%rule%z, m)
    ! a warm start (muhat_start): the polish first starts from the face of x
    st%monitor = self%monitor
    st%warm = allocated(self%muhat_start)
    call self%polish%start(problem, st)

    self%rho = problem%eq%penalty()
    self%rho_initial = self%rho
    self%preconditioned = allocated(problem%prec)
    call self%inner%ritz%reset()
    call self%inner%norm_at_least(self%rho)
    call problem%project(x)
    self%norm_b = problem%norm(problem%b)
    scale = self%norm_b
    if (scale <= 0) scale = 1
    self%tol_abs = self%settings%tol*scale
    self%eta = self%settings%eta_scale*scale
    self%per_component = problem%per_component_stop()
    if (self%per_component) then
      ! both parts of the violation bounded per component: g^P directly, and the
      ! penalty part rho Q x of the gradient through max(w) ||C x|| >= ||W Q x||_inf
      self%tol_gp = problem%stop_scale
      if (self%tol_gp <= 0) self%tol_gp = problem%weighted_max(problem%b)
      if (self%tol_gp <= 0) self%tol_gp = 1
      self%tol_gp = self%settings%tol*self%tol_gp
      self%rule%w_max = problem%weighted_max(spread(1.0_dp, 1, problem%n))
      if (problem%eq%relative_measure) then
        self%tol_c = self%settings%tol
      else
        self%tol_c = self%tol_gp/max(self%rule%w_max, tiny(1.0_dp))
      end if
    else
      self%tol_gp = self%tol_abs
      self%tol_c = self%tol_abs
    end if
    self%m_initial = self%settings%m_scale*self%a_norm
    self%m_now = self%m_initial
    self%muhat = 0
    self%ct_mu = 0
    self%b_lin(1:n) = problem%b(1:n)
    if (allocated(self%muhat_start)) then
      ! a warm start (a load history): the multiplier of the previous solve
      if (size(self%muhat_start) == m) then
        self%muhat = self%muhat_start
        call problem%eq%apply_t(self%muhat, self%ct_mu)
        self%b_lin(1:n) = problem%b(1:n) - self%ct_mu(1:n)
      end if
      deallocate (self%muhat_start)
    end if
    self%rule%tol_gp = self%tol_gp
    self%rule%tol_c = self%tol_c
    self%rule%per_component = self%per_component
    self%rule%rho = self%rho
    self%rule%eta = self%eta
    self%rule%n_eq_residual = 0
    self%rule%cnorm = -1
    self%rule%monitor%on = self%monitor
    self%l_shift = 0
    self%n_idle = 0
    self%last_raise = 0
    self%after_polish = .false.
  end subroutine prepare

  !> Step 1: the inner solve of outer iteration `outer`, warm started from
  !> x_{k-1} with the gradient for mu_k, and its counters. False (status set)
  !> when the inner solver failed.
  logical function inner_step(self, problem, x, outer, gradient_given) result(ok)
    class(smalbe_t), intent(inout) :: self
    class(qp_problem_t), intent(inout) :: problem
    real(dp), intent(inout) :: x(:)
    integer(ip), intent(in) :: outer
    logical, intent(in) :: gradient_given
    integer(ip) :: n
    n = problem%n
    self%x_prev(1:n) = x(1:n)
    self%g_prev(1:n) = self%gradient(1:n)
    self%m_bound = self%m_now*self%settings%beta**self%n_idle
    self%rule%m_bound = self%m_bound
    self%rule%beta = self%settings%beta
    self%rule%n_forced_cuts = 0
    ! right after a polish (force_step): the inner solve takes a step unless the outer test holds
    self%rule%force_step = self%after_polish .and. self%settings%polish%force_step
    self%rule%monitor%base = self%n_hessian
    self%rule%monitor%outer = outer
    call self%inner%minimize(problem, self%b_lin, x, self%gradient, self%rule, &
                             self%settings%max_hessian - self%n_hessian, gradient_given)
    call self%rule%monitor%inner_flush()
    if (self%rule%n_forced_cuts > 0) then
      self%m_bound = self%rule%m_bound      ! the bound this inner solve used (monitor)
      self%polish%n_forced = self%polish%n_forced + 1
    end if
    self%n_outer = outer
    self%n_hessian = self%n_hessian + self%inner%n_hessian
    self%n_inner = self%n_inner + self%inner%n_iterations
    self%n_cg = self%n_cg + self%inner%n_cg
    self%n_expansion = self%n_expansion + self%inner%n_expansion
    self%n_proportioning = self%n_proportioning + self%inner%n_proportioning
    self%n_expansion_fallback = self%n_expansion_fallback + self%inner%n_expansion_fallback
    self%n_norm_updates = self%n_norm_updates + self%inner%n_norm_updates
    self%n_preconditioner = self%n_preconditioner + self%inner%n_preconditioner
    self%gp_norm = self%inner%gp_norm
    ok = self%inner%status == qp_status_converged .or. self%inner%status == qp_status_max_hessian
    if (.not. ok) then
      self%status = self%inner%status
      self%message = 'inner MPRGP: '//trim(self%inner%message)
    end if
  end function inner_step

  !> After the inner solve of outer iteration `outer`: z and ||C x|| at x,
  !> the histories, the outer criterion's measures, L(x_k, mu_k) and the
  !> decrease `change` = L(x_k, mu_k) - L(x_{k-1}, mu_k). False (status set)
  !> when ||C x|| or L is not finite.
  logical function outer_values(self, problem, x, outer, change) result(ok)
    class(smalbe_t), intent(inout) :: self
    class(qp_problem_t), intent(inout) :: problem
    real(dp), intent(in) :: x(:)
    integer(ip), intent(in) :: outer
    real(dp), intent(out) :: change
    real(dp) :: s(2), hi(2), lo(2), lagr
    integer(ip) :: i
    character(len=qp_message_len) :: buf
    ! z and ||C x|| at the final x: from the stopping rule when it stopped the loop
    if (.not. (self%inner%status == qp_status_converged .and. self%rule%evaluated)) then
      call problem%eq%residual(x, self%rule%z, self%rule%cnorm)
      self%rule%n_eq_residual = self%rule%n_eq_residual + 1
    end if
    self%cnorm = self%rule%cnorm
    self%cnorm_history = [self%cnorm_history, self%cnorm]
    self%hessian_history = [self%hessian_history, self%n_hessian]
    self%rho_history = [self%rho_history, self%rho]
    ! the outer criterion's measures at the final x: from the rule when its
    ! last evaluation belongs to this x and got that far, else now
    if (.not. (self%inner%status == qp_status_converged .and. self%rule%evaluated .and. &
               self%gp_norm > min(self%rule%m_bound*self%rule%cnorm, self%eta))) &
      call self%rule%outer_measures(problem, x, self%gradient, self%gp_norm)
    self%gp_measure = self%rule%gp_measure
    self%eq_measure = self%rule%eq_measure
    ! L(x_k, mu_k) and the decrease L(x_k, mu_k) - L(x_{k-1}, mu_k) of the inner
    ! quadratic, the latter as 1/2 (x_k - x_{k-1})^T (g(x_k) + g(x_{k-1})): exact for a
    ! quadratic and free of the cancellation of a difference of two L values
    hi = 0
    lo = 0
    do i = 1, problem%n
      call compensated_add(hi(1), lo(1), x(i)*(self%gradient(i) - self%b_lin(i)))
      call compensated_add(hi(2), lo(2), (x(i) - self%x_prev(i))*(self%gradient(i) + self%g_prev(i)))
    end do
    call problem%reduce_sums(hi, lo, s)
    lagr = 0.5_dp*s(1)
    change = 0.5_dp*s(2)
    self%lagrangian = lagr
    ok = ieee_is_finite(self%cnorm) .and. ieee_is_finite(lagr)
    if (.not. ok) then
      write (buf, '(a,i0)') 'not converged: non-finite ||C x|| or Lagrangian at outer iteration ', outer
      self%status = qp_status_not_finite
      self%message = buf
    end if
  end function outer_values

  !> Step 2: the outer criterion and the caps; true (status set) when the solve ends.
  logical function outer_stop(self, outer) result(done)
    class(smalbe_t), intent(inout) :: self
    integer(ip), intent(in) :: outer
    character(len=qp_message_len) :: buf
    done = .true.
    if (self%rule%outer_met()) then
      if (self%after_polish .and. self%inner%n_iterations == 0) self%polish%n_exact = self%polish%n_exact + 1
      write (buf, '(3a,es10.3,a,es10.3,3a,es10.3,a,es10.3)') 'converged: ', gp_name(self), ' = ', &
        self%gp_measure, ' <= ', self%tol_gp, ', ', eq_name(self), ' = ', self%eq_measure, ' <= ', self%tol_c
      self%status = qp_status_converged
      self%message = buf
    else if (self%inner%status == qp_status_max_hessian) then
      write (buf, '(a,i0,a,i0,a)') 'not converged: Hessian multiplication cap max_hessian = ', &
        self%settings%max_hessian, ' reached in outer iteration ', outer, '; '
      self%status = qp_status_max_hessian
      self%message = trim(buf)//' '//distance_to_tol(self)//stagnation_note(self)
    else if (outer == self%settings%max_outer) then
      write (buf, '(a,i0,a)') 'not converged: outer iteration cap max_outer = ', self%settings%max_outer, &
        ' reached; '
      self%status = qp_status_max_outer
      self%message = trim(buf)//' '//distance_to_tol(self)
    else
      done = .false.
    end if
  end function outer_stop

  !> Step 3: muhat <- muhat + rho z; the gradient follows without a Hessian product.
  subroutine update_multiplier(self, problem)
    class(smalbe_t), intent(inout) :: self
    class(qp_problem_t), intent(inout) :: problem
    integer(ip) :: i
    self%muhat = self%muhat + self%rho*self%rule%z
    call problem%eq%apply_t(self%muhat, self%ct_new)
    do i = 1, problem%n
      self%gradient(i) = self%gradient(i) + (self%ct_new(i) - self%ct_mu(i))
      self%ct_mu(i) = self%ct_new(i)
      self%b_lin(i) = problem%b(i) - self%ct_mu(i)
    end do
  end subroutine update_multiplier

  !> Step 4, semimonotonicity (see the module): L(x_k, mu_k) - L(x_{k-1}, mu_{k-1})
  !> = change + rho ||C x_{k-1}||^2 must be >= rho/2 ||C x_k||^2, else M <- beta M.
  !> An inner solve that made no step (its test was already met, because
  !> M ||C x|| exceeds ||g^P||) leaves x where it was: the Lagrangian test
  !> then passes, yet the next outer iteration may progress only by the
  !> slow growth of ||g^P|| through the multiplier. This happens in FETI when
  !> ||C x|| sits at its round-off floor. m_no_step = 'cut' treats it like a
  !> failed test (M <- beta M for good); 'temporary' lets only the next inner
  !> solve use beta M (beta^j M after j such solves in a row), so that the
  !> stall is broken while M itself follows the theory; 'keep' does nothing.
  !> (l_shift = rho ||C x_{k-1}||^2, plus the change of L(x_{k-1}, mu_k) by a
  !> raised rho, see step 5.)
  subroutine update_m(self, outer, change)
    class(smalbe_t), intent(inout) :: self
    integer(ip), intent(in) :: outer
    real(dp), intent(in) :: change
    logical :: failed
    failed = outer > 1 .and. .not. self%after_polish .and. &
             change + self%l_shift < 0.5_dp*self%rho*self%cnorm**2
    if (self%inner%n_iterations == 0) then
      self%n_no_step = self%n_no_step + 1
      self%n_idle = self%n_idle + 1
    else
      self%n_idle = 0
    end if
    if (self%m_no_step_kind == m_no_step_cut .and. self%inner%n_iterations == 0 .and. .not. self%after_polish) &
      failed = .true.
    if (self%m_no_step_kind /= m_no_step_temporary) self%n_idle = 0
    self%after_polish = .false.
    if (failed) then
      self%m_now = self%settings%beta*self%m_now
      self%n_m_updates = self%n_m_updates + 1
    end if
  end subroutine update_m

  !> Step 5, adaptive penalty: when ||C x|| shrank by less than rho_contraction
  !> per outer iteration over the last w = rho_window ones (||C x_k|| >
  !> rho_contraction^w ||C x_{k-w}||; w = 1: the last one), at least w outer
  !> iterations after the last raise and after an inner solve that made a
  !> step, rho <- rho_growth rho (at most smalbe_rho_cap rho_0). A gains (rho - rho_old) C^T C, so does the
  !> gradient at x_k (no Hessian product: C^T C x = eq%apply_t(z)); the
  !> inner ||A|| estimate becomes max(||A||, rho) (A_0 and C^T C act on
  !> complementary subspaces). L(x_k, mu_{k+1}) grows by
  !> (rho - rho_old)/2 ||C x_k||^2, which the next test of step 4 includes.
  !> rho_stall > 0: the first raise needs a stall (windowed test with
  !> rho_stall), the later ones the per-iteration test with rho_contraction.
  subroutine update_penalty(self, problem, outer)
    class(smalbe_t), intent(inout) :: self
    class(qp_problem_t), intent(inout) :: problem
    integer(ip), intent(in) :: outer
    real(dp) :: q, rho_old
    integer(ip) :: w, i
    logical :: raise
    self%l_shift = self%rho*self%cnorm**2
    q = self%settings%rho_contraction
    w = self%settings%rho_window
    if (self%settings%rho_stall > 0) then
      w = merge(self%settings%rho_window, 1_ip, self%n_rho_updates == 0)
      if (self%n_rho_updates == 0) q = self%settings%rho_stall
    end if
    raise = self%settings%rho_growth > 1 .and. outer > w .and. outer - self%last_raise >= w .and. &
            self%inner%n_iterations > 0 .and. &
            self%settings%rho_growth*self%rho <= smalbe_rho_cap*self%rho_initial*(1 + 1.0e-12_dp)
    if (raise) raise = self%cnorm > q**w*self%cnorm_history(outer - w)
    if (.not. raise) return
    rho_old = self%rho
    self%rho = self%settings%rho_growth*self%rho
    call problem%eq%set_penalty(self%rho)
    call problem%eq%apply_t(self%rule%z, self%ct_new)
    do i = 1, problem%n
      self%gradient(i) = self%gradient(i) + (self%rho - rho_old)*self%ct_new(i)
    end do
    self%l_shift = self%l_shift + 0.5_dp*(self%rho - rho_old)*self%cnorm**2
    self%rule%rho = self%rho
    call self%inner%norm_at_least(self%rho)
    self%n_rho_updates = self%n_rho_updates + 1
    self%last_raise = outer
  end subroutine update_penalty

  !> The solver's section of the run's report: status, counters, measures,
  !> the per-outer history, the inner solver's CG runs and the polish.
  subroutine smalbe_report(self, sink)
    class(smalbe_t), intent(in) :: self
    class(report_sink_t), intent(inout) :: sink
    call sink%put_logical('converged', self%converged())
    call sink%put_text('status', qp_status_name(self%status))
    call sink%put_text('message', trim(self%message))
    call sink%put_long('outer_iterations', int(self%n_outer, i8))
    call sink%put_long('inner_iterations', int(self%n_inner, i8))
    call sink%put_long('hessian_multiplications', int(self%n_hessian, i8))
    call sink%put_long('cg_steps', int(self%n_cg, i8))
    call sink%put_long('expansion_steps', int(self%n_expansion, i8))
    call sink%put_long('proportioning_steps', int(self%n_proportioning, i8))
    call sink%put_long('m_updates', int(self%n_m_updates, i8))
    call sink%put_real('projected_gradient', self%gp_norm)
    call sink%put_real('equality_residual', self%cnorm)
    call sink%put_real('norm_b', self%norm_b)
    call report_history(self, sink)
    call sink%put_long('preconditioner_applications', int(self%n_preconditioner, i8))
    call self%polish%report(sink)
    ! the inner solver's CG runs: the condition estimate of the operator they saw
    ! (Ritz values of the Lanczos matrices of the CG coefficients; null when no run had 2 steps)
    if (.not. allocated(self%inner)) return
    associate (rz => self%inner%ritz)
      if (rz%n_runs > 0) then
        call sink%put_real('face_condition_estimate', rz%max_ratio)
        call sink%put_real('face_ritz_min', rz%theta_min)
        call sink%put_real('face_ritz_max', rz%theta_max)
      else
        call sink%put_null('face_condition_estimate')
        call sink%put_null('face_ritz_min')
        call sink%put_null('face_ritz_max')
      end if
      call sink%put_long('cg_runs', int(rz%n_runs, i8))
      call sink%put_long('longest_cg_run', int(rz%longest, i8))
    end associate
  end subroutine smalbe_report

  !> The monitor's per-outer figures: ||C x_k|| (`cnorm_per_outer`), the
  !> Hessian multiplications after outer iteration k (`hessian_per_outer`,
  !> cumulative), the penalty (`rho_per_outer`), the contraction
  !> ||C x_k|| / ||C x_(k-1)|| for k >= 2 (`contraction_per_outer`), its
  !> median and its geometric mean over the second half of the outer
  !> iterations (`contraction_late`, the linear rate; null with fewer than 2
  !> outer iterations), and the Hessian multiplications per outer iteration
  !> (`hessian_per_outer_mean`).
  subroutine report_history(self, sink)
    class(smalbe_t), intent(in) :: self
    class(report_sink_t), intent(inout) :: sink
    real(dp), allocatable :: c(:), q(:), sorted(:)
    integer(ip), allocatable :: h(:)
    integer(ip) :: k, j, nq, first
    real(dp) :: t
    allocate (c(0), h(0))
    if (allocated(self%cnorm_history)) c = self%cnorm_history
    if (allocated(self%hessian_history)) h = self%hessian_history
    nq = max(size(c, kind=ip) - 1, 0_ip)
    allocate (q(nq))
    do k = 1, nq
      if (c(k) > 0) then
        q(k) = c(k + 1)/c(k)
      else
        q(k) = 0
      end if
    end do
    call sink%put_reals('cnorm_per_outer', c)
    call sink%put_longs('hessian_per_outer', int(h, i8))
    if (allocated(self%rho_history)) call sink%put_reals('rho_per_outer', self%rho_history)
    call sink%put_reals('contraction_per_outer', q)
    if (nq > 0) then
      sorted = q
      do k = 2, nq                            ! insertion sort: at most max_outer values
        t = sorted(k)
        j = k - 1
        do while (j >= 1)
          if (sorted(j) <= t) exit
          sorted(j + 1) = sorted(j)
          j = j - 1
        end do
        sorted(j + 1) = t
      end do
      call sink%put_real('contraction_median', 0.5_dp*(sorted((nq + 1)/2) + sorted(nq/2 + 1)))
      first = nq/2 + 1
      if (all(q(first:nq) > 0)) then
        call sink%put_real('contraction_late', exp(sum(log(q(first:nq)))/(nq - first + 1)))
      else
        call sink%put_real('contraction_late', 0.0_dp)
      end if
    else
      call sink%put_null('contraction_median')
      call sink%put_null('contraction_late')
    end if
    call sink%put_real('hessian_per_outer_mean', real(self%n_hessian, dp)/max(self%n_outer, 1_ip))
  end subroutine report_history

  !> 'tol not met: ||g^P|| = .. (must be <= ..), ||C x|| = .. (must be <= ..)'.
  function distance_to_tol(self) result(text)
    class(smalbe_t), intent(in) :: self
    character(len=:), allocatable :: text
    character(len=200) :: buf
    write (buf, '(3a,es9.2,a,es9.2,3a,es9.2,a,es9.2,a)') 'tol not met: ', gp_name(self), ' = ', self%gp_measure, &
      ' (must be <= ', self%tol_gp, '), ', eq_name(self), ' = ', self%eq_measure, ' (must be <= ', self%tol_c, ')'
    text = trim(buf)
  end function distance_to_tol

  !> The name of the stopping test's measure of g^P.
  function gp_name(self) result(name)
    class(smalbe_t), intent(in) :: self
    character(len=:), allocatable :: name
    if (self%per_component) then
      name = 'max w|(g - rho C^T C x)^P|'
    else
      name = '||g^P||'
    end if
  end function gp_name

  !> The name of the stopping test's measure of C x = 0.
  function eq_name(self) result(name)
    class(smalbe_t), intent(in) :: self
    character(len=:), allocatable :: name
    if (self%per_component .and. self%tol_c == self%settings%tol) then
      name = 'equality measure (relative)'
    else
      name = '||C x||'
    end if
  end function eq_name

  !> When the last inner solve ran long without improving its smallest ||g^P||
  !> in its second half, say so: more Hessian multiplications are unlikely to
  !> help (ill-conditioned dual, or contact rows with lambda ~ 0 and gap ~ 0).
  function stagnation_note(self) result(text)
    class(smalbe_t), intent(in) :: self
    character(len=:), allocatable :: text
    character(len=200) :: buf
    text = ''
    if (self%inner%n_iterations >= 100 .and. 2*self%inner%n_best < self%inner%n_iterations) then
      write (buf, '(a,i0,a,es9.2,a,i0,a)') '; the last inner MPRGP solve stagnated (', self%inner%n_iterations, &
        ' iterations, smallest ||g^P|| ', self%inner%best_gp_norm, ' at iteration ', self%inner%n_best, &
        '): ill-conditioned or degenerate dual problem'
      text = trim(buf)
    end if
  end function stagnation_note

  subroutine reset_counters(self)
    class(smalbe_t), intent(inout) :: self
    self%status = qp_status_not_run
    self%message = 'not run'
    self%gp_norm = 0
    self%cnorm = 0
    self%lagrangian = 0
    self%n_hessian = 0
    self%n_outer = 0
    self%n_inner = 0
    self%n_cg = 0
    self%n_expansion = 0
    self%n_proportioning = 0
    self%n_expansion_fallback = 0
    self%n_eq_residual = 0
    self%n_m_updates = 0
    self%n_no_step = 0
    self%n_rho_updates = 0
    self%n_norm_updates = 0
    self%n_active = 0
    self%n_preconditioner = 0
    call self%polish%reset()
    self%cnorm_history = [real(dp) ::]
    self%hessian_history = [integer(ip) ::]
    self%rho_history = [real(dp) ::]
  end subroutine reset_counters

  !> The monitor's head: the parameters, the stopping test, the column heads.
  subroutine monitor_header(self)
    class(smalbe_t), intent(in) :: self
    character(len=200) :: buf
    write (buf, '(a,es10.3,a,es10.3,a,es10.3,a,es10.3,2a)') 'SMALBE: rho = ', self%rho, &
      ', ||A|| = ', self%a_norm, ', M0 = ', self%m_initial, ', eta = ', self%eta, ', ', self%inner%variant()
    call log_message(buf)
    write (buf, '(3a,es10.3,3a,es10.3)') 'SMALBE: stop when ', gp_name(self), ' <= ', self%tol_gp, &
      ' and ', eq_name(self), ' <= ', self%tol_c
    call log_message(trim(buf))
    call self%rule%monitor%legend(gp_name(self), eq_name(self))
  end subroutine monitor_header

  !> The summary (written with the monitor off too): the counts, then the
  !> reason line, which says which criterion ended the solve and after how
  !> many outer iterations and Hessian multiplications.
  subroutine monitor_summary(self)
    class(smalbe_t), intent(in) :: self
    character(len=300) :: buf
    write (buf, '(a,i0,a,i0,a,i0,a,i0,a,i0,a)') '  inner MPRGP: ' // counted(self%n_inner, 'step') // ' (cg ', &
      self%n_cg, ', expansion ', self%n_expansion, ', proportioning ', self%n_proportioning, &
      ', expansion fallbacks ', self%n_expansion_fallback, '), ', self%n_hessian - self%polish%n_products, &
      ' Hessian multiplications'
    call log_message(trim(buf))
    write (buf, '(a,i0,3a,es10.3,a,es10.3,5a,i0)') '  ||C x|| evaluations ', self%n_eq_residual, &
      ', M cut ', counted(self%n_m_updates, 'time'), ' (', self%m_initial, ' -> ', self%m_bound, '; ', &
      counted(self%n_no_step, 'inner solve'), ' without a step, m_no_step = ', trim(self%settings%m_no_step), &
      '), rows at bound ', self%n_active
    call log_message(trim(buf))
    write (buf, '(a,es10.3,a,es10.3,3a)') '  rho ', self%rho_initial, ' -> ', self%rho, ' (raised ', &
      counted(self%n_rho_updates, 'time'), ')'
    call log_message(buf)
    if (self%inner%ritz%n_runs > 0) then
      write (buf, '(a,l1,a,i0,a,es10.3,a,es10.3,a,es10.3,a,i0,a,i0)') '  preconditioned ', self%preconditioned, &
        ' (applications ', self%n_preconditioner, '), face condition estimate ', self%inner%ritz%max_ratio, &
        ' (Ritz values ', self%inner%ritz%theta_min, ' .. ', self%inner%ritz%theta_max, '; CG runs ', &
        self%inner%ritz%n_runs, ', longest ', self%inner%ritz%longest
      call log_message(trim(buf)//')')
    end if
    call self%polish%summary()
    if (self%n_norm_updates > 0) then
      write (buf, '(a,es10.3,a,es10.3,a,i0,a)') '  ||A|| estimate raised from ', self%a_norm, ' to ', &
        self%inner%a_norm, ' by Rayleigh quotients of the search directions (', self%n_norm_updates, ' times)'
      call log_message(buf)
    end if
    call log_message('SMALBE reason: '//reason_code(self%status)//' after '// &
                     counted(self%n_outer, 'outer iteration')//' and '// &
                     counted(self%n_hessian, 'Hessian multiplication')//'; '//trim(self%message))
  end subroutine monitor_summary

  !> The reason's code word (as PETSc's KSPConvergedReason): CONVERGED_TOL,
  !> DIVERGED_MAX_HESSIAN, DIVERGED_MAX_OUTER, DIVERGED_NAN, DIVERGED_BREAKDOWN,
  !> DIVERGED_REFUSED.
  function reason_code(status) result(code)
    integer, intent(in) :: status
    character(len=:), allocatable :: code
    select case (status)
    case (qp_status_converged)
      code = 'CONVERGED_TOL'
    case (qp_status_max_hessian)
      code = 'DIVERGED_MAX_HESSIAN'
    case (qp_status_max_outer)
      code = 'DIVERGED_MAX_OUTER'
    case (qp_status_not_finite)
      code = 'DIVERGED_NAN'
    case (qp_status_incompatible)
      code = 'DIVERGED_REFUSED'
    case default
      code = 'DIVERGED_BREAKDOWN'
    end select
  end function reason_code


end module smalbe
