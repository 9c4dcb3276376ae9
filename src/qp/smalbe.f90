!> SMALBE-M: semimonotonic augmented Lagrangians for bound and equality
!> constraints (Dostal 2006; Dostal, "Optimal Quadratic Programming
!> Algorithms", 2009), with MPRGP for the inner problems, for
!>
!>     min 1/2 x^T A x - b^T x   s.t.  x >= l,  C x = 0,
!>
!> where A already contains the penalty rho C^T C (rho = problem%penalty()).
!> The augmented Lagrangian is therefore
!>
!>     L(x, mu) = 1/2 x^T A x - b^T x + mu^T C x
!>              = 1/2 x^T (g - b + C^T mu),   g = grad_x L = A x - b + C^T mu,
!>
!> and the inner problem of outer iteration k is the bound constrained QP
!> with Hessian A and linear term b - C^T mu_k. mu is carried in hat form
!> (see qp_problem): C^T mu = eq_apply_t(muhat), and mu <- mu + rho C x is
!> muhat <- muhat + rho z with z from eq_residual.
!>
!> Outer iteration k (M_0 = m_scale ||A||, eta = eta_scale ||b||):
!> 1. x_k: MPRGP from x_{k-1} (warm start, the gradient updated without a
!>    Hessian multiplication) until ||g^P(x, mu_k)|| <= min(M_k ||C x||, eta),
!>    or until the outer criterion below holds;
!> 2. stop if ||g^P(x_k, mu_k)|| <= tol ||b|| and ||C x_k|| <= tol ||b||;
!>    the pair (x_k, muhat_k) is returned (mu is not updated after the test).
!>    With a problem that asks for the per-component test (qp_problem,
!>    `stop_weight`): max_i w_i |g^P_i| <= tol S and max(w) ||C x_k|| <= tol S
!>    with S = problem%stop_scale or max_i w_i |b_i| instead (the M test and
!>    eta stay in the 2-norm);
!> 3. muhat_{k+1} = muhat_k + rho z_k;
!> 4. if k > 1 and L(x_k, mu_k) < L(x_{k-1}, mu_{k-1}) + rho/2 ||C x_k||^2,
!>    M_{k+1} = beta M_k (beta in (0,1)), else M_{k+1} = M_k.
!>    (`m_no_step`: what an inner solve without a step does to M, see step 4
!>    in smalbe_solve.)
!> 5. optional adaptive penalty (rho_growth > 1): rho <- rho_growth rho when
!>    ||C x_k|| > rho_contraction^w ||C x_{k-w}|| (w = rho_window, and at
!>    least w outer iterations after the last raise), at most smalbe_rho_cap rho_0;
!>    the problem's Hessian follows through problem%set_penalty (see step 5 in
!>    smalbe_solve). Off by default here (smalbe_settings_t); `&solver` turns
!>    it on behind a stall test (rho_stall), measured in docs/RESULTS.md
!>    "Outer loop with the preconditioner".
!>
!> The test of step 4 compares the Lagrangians of consecutive pairs (x_k, mu_k)
!> as PERMON's SMALXE does. Written with mu_{k+1} and mu_k instead,
!> L(x_k, mu_{k+1}) >= L(x_{k-1}, mu_k) + rho/2 ||C x_k||^2 fails even for
!> exact inner solves (no bounds) as soon as rho > 0.62 / lambda_max(C A_0^{-1}
!> C^T), A_0 = A - rho C^T C the Hessian without the penalty: always for the
!> FETI dual, where A_0 = P F P vanishes on Im C^T. M would be cut in nearly
!> every outer iteration (observed: 16 of 26 on the test problems).
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
!> ||C x|| costs one eq_residual (for FETI: one coarse problem solve). The
!> inner stopping rule evaluates it only when ||g^P|| <= max(eta, tol ||b||),
!> since otherwise neither inner criterion can hold (counted in n_eq_residual).
!>
!> Caps: max_outer outer iterations, max_hessian Hessian multiplications in
!> total (inner solves get the remaining budget); either ends the solve with a
!> "not converged" status and a message, as do NaN/Inf (qp_status_not_finite).
!>
!> 6. optional polish (polish_window > 0, a problem with a face solver,
!>    qp_problem; off in smalbe_settings_t, `&solver polish_window` is 1 by
!>    default, docs/RESULTS.md "Polish: the exact face solve"): once the active set (the x_i at their bound) has not
!>    changed for polish_window outer iterations whose inner solve made a
!>    step, the equality constrained QP
!>    on that face (x_A = l_A, C x = 0) is solved by PCPG (module face_solve)
!>    and (x, mu) replaced by its solution and face multiplier; the gradient
!>    follows (one more product if x had to be projected onto the bounds).
!>    Its products count in n_hessian. When the active set was the right one,
!>    the next outer iteration's test accepts the pair at once; otherwise
!>    SMALBE goes on from it (a feasible warm start: the L test of 4. is not
!>    applied to that step). At most once per distinct active set and
!>    smalbe_polish_max times per solve (each up to polish_rounds face
!>    solves: a face solve whose x leaves a bound on a free row is projected
!>    and the new face solved at once; with polish_release active rows whose
!>    gradient has the wrong sign are also freed, primal-dual active set
!>    rounds, see polish_step; with polish_loose > 0 a face solve that may be
!>    followed by another round stops at its loose check when the set would
!>    change, face_solve; with polish_predict > 0 a round that projected at
!>    least that many rows and released none also makes as many of the free
!>    rows nearest their bound active, predicted_rows; with polish_release_share
!>    > 0 the first round of a polish releases only the wrong-sign rows whose
!>    gradient is at least that share of the largest, released_rows).
!>    polish_settle > 0: an outer iteration counts as
!>    settled when the set changed on at most that fraction of the bounded
!>    rows; a polish given up at its first face then does not count toward
!>    smalbe_polish_max, and the next waits until the products have doubled.
!>    Each face solve at most smalbe_polish_steps and
!>    at most max(smalbe_polish_min_steps, the products spent so far)
!>    CG steps, to smalbe_polish_target times the outer test's bound; a
!>    face solve whose first steps are too slow for that budget is given up
!>    and the iterate restored (face_solve, `aborted`), unless a loose check
!>    has found no change on it (a trusted face: never given up, at most
!>    smalbe_polish_trusted_steps steps). With polish_force_step (default)
!>    the inner solve right after a polish takes at least one step unless
!>    the outer test accepts the polished pair (its bound beta^j M for that
!>    solve only, see inner_stop_test; docs/THEORY.md "Polish robustness").
!>    Timer 'polish' (a part of 'solve': the face matrix's assembly and
!>    factorization, the CG steps with their products).
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
  use kinds, only: dp, ip, i8, name_len, MPI_INT_IP, MPI_INT_I8
  use errors, only: fatal_error
  use logger, only: log_message
  use timers, only: timer_start, timer_stop
  use qp_problem, only: qp_problem_t, qp_solver_t, qp_message_len, compensated_add, qp_status_converged, &
                        no_lower_bound, qp_status_max_hessian, qp_status_max_outer, qp_status_not_finite, &
                        qp_status_incompatible, qp_status_not_run
  use mprgp, only: mprgp_t, mprgp_stop_t, ensure_size
  use face_solve, only: face_polish_t, free_rows, face_changes
  use mpi_f08, only: MPI_Allreduce, MPI_SUM, MPI_MAX, MPI_Comm_rank, MPI_DOUBLE_PRECISION, MPI_IN_PLACE
  implicit none
  private

  !> The inner stopping rule of SMALBE-M; keeps z and ||C x|| of the last
  !> evaluation for the multiplier update.
  type, extends(mprgp_stop_t) :: smalbe_inner_stop_t
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
  contains
    procedure :: test => inner_stop_test
    procedure :: outer_measures
    procedure :: outer_met
  end type smalbe_inner_stop_t

  !> The settings of SMALBE-M and its inner MPRGP, with the defaults of the
  !> literature (see smalbe_init for their ranges).
  type, public :: smalbe_settings_t
    real(dp) :: tol = 1.0e-6_dp                !< relative tolerance (of ||b||)
    integer(ip) :: max_outer = 200             !< cap of outer iterations
    integer(ip) :: max_hessian = 20000         !< cap of Hessian multiplications in total
    real(dp) :: gamma = 1                      !< MPRGP proportioning parameter
    real(dp) :: alpha_scale = 1.9_dp           !< MPRGP expansion step alpha_scale/||A||
    character(len=name_len) :: expansion = 'fixed'  !< 'fixed' | 'optimal'
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
    real(dp) :: rho_growth = 1
    real(dp) :: rho_contraction = 0.5_dp
    integer(ip) :: rho_window = 1
    !> > 0: a stall detector for the first raise only: ||C x_k|| >
    !> rho_stall^w ||C x_{k-w}||; after it the per-iteration test with
    !> rho_contraction (w = 1). 0: every raise uses rho_contraction and w
    real(dp) :: rho_stall = 0
    !> > 0: polish (exact face solve, step 6 of the module) once the active set
    !> has not changed for this many outer iterations; 0: never
    integer(ip) :: polish_window = 0
    !> polish: at most this many face solves per polish (rounds after a change of the active set)
    integer(ip) :: polish_rounds = 3
    !> polish: active rows whose gradient has the wrong sign are released (made free) and the face
    !> solved again within the polish (a primal-dual active set step), not left to SMALBE
    logical :: polish_release = .false.
    !> polish trigger: an outer iteration counts as settled when the active set changed on at most
    !> this fraction of the bounded rows (0: not at all)
    real(dp) :: polish_settle = 0
    !> > 0: a face solve of the polish that is not its last possible round pauses once its residual
    !> is this many times its start value and stops there when the active set would change (face_solve)
    real(dp) :: polish_loose = 0
    !> the inner solve right after a polish takes a step (with a bound beta^j M for that solve only)
    !> unless the outer test accepts the polished pair (docs/THEORY.md, session 8)
    logical :: polish_force_step = .true.
    !> > 0: predictive set update in the polish rounds (issue 14, session 9): after a round that
    !> projects k >= polish_predict free rows onto their bound and releases none, also the k other
    !> free rows with the smallest slack x_i - l_i (at most half of them) become active (the next
    !> round's release corrects them); 0: off
    integer(ip) :: polish_predict = 0
    !> in [0, 1): the first release of a polish (its first round) frees only the active rows whose
    !> wrong-sign weighted gradient is at least this share of the largest one (issue 14, session 16;
    !> released_rows); the later rounds release every wrong-sign row. 0: every one at once
    real(dp) :: polish_release_share = 0
    !> polish before the first outer iteration (issue 14, session 10): from x with every bounded
    !> row at its bound, the polish rounds (release, projection) on that face; only where the
    !> problem knows the equality rows alone to fix it (face_always_regular)
    logical :: polish_first = .false.
    logical :: monitor = .false.               !< one line per outer iteration and a summary
  end type smalbe_settings_t

  !> rho never exceeds rho_cap times its initial value (adaptive penalty)
  real(dp), parameter, public :: smalbe_rho_cap = 100
  !> polish: at most this many per solve, each at most smalbe_polish_steps CG
  !> steps, stopped at smalbe_polish_target times the outer test's bound of g^P
  integer(ip), parameter, public :: smalbe_polish_max = 3
  !> a polish whose x leaves the bounds on free rows solves the projected face at once, at most this many rounds
  integer(ip), parameter, public :: smalbe_polish_rounds = 3
  integer(ip), parameter, public :: smalbe_polish_steps = 500
  integer(ip), parameter, public :: smalbe_polish_min_steps = 30
  real(dp), parameter, public :: smalbe_polish_target = 0.5_dp
  !> a face solve whose loose check found no change (a trusted face) may take this many CG steps
  integer(ip), parameter, public :: smalbe_polish_trusted_steps = 500

  public :: polish_cycling, face_signature, predicted_rows, released_rows, revisit_of_cut_short

  !> The SMALBE-M solver with its inner MPRGP. All counters are totals of the
  !> last solve (components, for report.json).
  type, extends(qp_solver_t), public :: smalbe_t
    type(mprgp_t) :: inner                     !< inner solver (its counters: the last inner solve)
    real(dp) :: tol = 1.0e-6_dp                !< relative tolerance (of ||b||)
    real(dp) :: a_norm = 0                     !< ||A|| (penalty included)
    real(dp) :: m_scale = 100                  !< M_0 = m_scale ||A||
    real(dp) :: beta = 0.5_dp                  !< M <- beta M when the Lagrangian grows too little
    real(dp) :: eta_scale = 0.1_dp             !< eta = eta_scale ||b||
    character(len=name_len) :: m_no_step = 'cut'  !< 'cut' | 'temporary' | 'keep' (see smalbe_settings_t)
    real(dp) :: rho_growth = 1                 !< adaptive penalty factor (1: off; see smalbe_settings_t)
    real(dp) :: rho_contraction = 0.5_dp       !< raise rho when ||C x|| shrinks by less than this
    integer(ip) :: rho_window = 1              !< ... per outer iteration over this many (see smalbe_settings_t)
    real(dp) :: rho_stall = 0                  !< > 0: first raise on a stall only (see smalbe_settings_t)
    real(dp) :: rho_initial = 0                !< problem%penalty() at the start of the last solve
    integer(ip) :: n_rho_updates = 0           !< times rho was raised
    integer(ip) :: max_outer = 200             !< cap of outer iterations
    integer(ip) :: max_hessian = 20000         !< cap of Hessian multiplications in total
    integer(ip) :: polish_window = 0           !< polish after this many outer iterations of one active set (0: off)
    integer(ip) :: polish_rounds = 3           !< face solves per polish at most (see smalbe_settings_t)
    logical :: polish_release = .false.        !< release wrong-sign active rows within the polish
    real(dp) :: polish_settle = 0              !< settled: active set changes on <= this fraction of bounded rows
    real(dp) :: polish_loose = 0               !< loose check of the face solves (0: off)
    integer(ip) :: polish_predict = 0          !< predictive set update from this many projected rows (0: off)
    real(dp) :: polish_release_share = 0       !< first release of a polish: this share of the largest and up
    logical :: polish_first = .false.          !< polish before the first outer iteration (start face)
    logical :: polished_first = .false.        !< the last solve started with a polish that was not given up
    integer(ip) :: n_polish_predicted = 0      !< rows made active by the prediction in all
    logical :: force_polish_step = .true.      !< the inner solve after a polish takes a step (settings)
    integer(ip) :: n_forced = 0                !< inner solves whose bound was cut to force a step
    integer(ip) :: n_polish_released = 0       !< active rows released by the polish in all (polish_release)
    type(face_polish_t) :: polish              !< the face solve (its counters: the last polish)
    integer(ip) :: n_polish = 0                !< polish steps of the last solve
    integer(ip) :: n_polish_rounds = 0         !< face solves of those (rounds after projections included)
    integer(ip) :: n_polish_hessian = 0        !< Hessian products of those (included in n_hessian)
    integer(ip) :: n_polish_steps = 0          !< their CG steps
    integer(ip) :: n_polish_exact = 0          !< polishes after which the outer test held at once
    integer(ip) :: n_polish_aborted = 0        !< face solves given up (too slow), the iterate restored
    ! results of the last solve
    real(dp), allocatable :: muhat(:)          !< final multiplier, hat form (C^T mu = eq_apply_t(muhat))
    real(dp) :: cnorm = 0                      !< ||C x|| at the returned x
    real(dp) :: lagrangian = 0                 !< L(x, mu) at the returned pair
    real(dp) :: rho = 0                        !< problem%penalty()
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
    integer(ip) :: n_inner = 0                 !< inner MPRGP iterations in all
    integer(ip) :: n_cg = 0                    !< CG steps in all
    integer(ip) :: n_expansion = 0             !< expansion steps in all
    integer(ip) :: n_proportioning = 0         !< proportioning steps in all
    integer(ip) :: n_expansion_fallback = 0    !< 'optimal' expansions redone with alpha_bar
    integer(ip) :: n_eq_residual = 0           !< eq_residual calls (FETI: coarse solves for ||C x||)
    integer(ip) :: n_m_updates = 0             !< times M was reduced
    integer(ip) :: n_no_step = 0               !< inner solves that made no step
    integer(ip) :: n_norm_updates = 0          !< times the inner MPRGP raised its ||A|| estimate
    integer(ip) :: n_active = 0                !< components at their bound at the returned x
    integer(ip) :: n_preconditioner = 0        !< preconditioner applications in all (MPRGP in the face)
    logical :: preconditioned = .false.        !< the inner MPRGP used the problem's preconditioner
    !> per outer iteration k of the last solve: ||C x_k|| after the inner solve
    !> and the Hessian multiplications so far (report.json: the contraction
    !> ||C x_k|| / ||C x_(k-1)|| and the products per outer iteration)
    real(dp), allocatable :: cnorm_history(:)
    integer(ip), allocatable :: hessian_history(:)
    real(dp), allocatable :: rho_history(:)    !< the penalty of outer iteration k's inner solve
    real(dp), allocatable, private :: b_lin(:), ct_mu(:), ct_new(:), x_prev(:), g_prev(:)
    logical, allocatable, private :: free_now(:), free_prev(:)
    real(dp), allocatable, private :: muhat_prev(:)     !< the multiplier before a polish
    type(smalbe_inner_stop_t), private :: rule
  contains
    procedure :: init => smalbe_init
    procedure :: init_with => smalbe_init_with
    procedure :: free => smalbe_free
    procedure :: solve => smalbe_solve
    procedure :: is_compatible => smalbe_is_compatible
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
    call problem%eq_residual(x, self%z, self%cnorm)
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

  !> gp_measure and eq_measure at x (g the gradient there; z and cnorm of
  !> eq_residual at x already computed). Classical: ||g^P|| and ||C x||.
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
    call problem%eq_apply_t(self%z, self%work)
    self%work(1:n) = g(1:n) - self%rho*self%work(1:n)
    self%gp_measure = problem%projected_gradient_max(x, self%work)
    self%eq_measure = problem%eq_measure(x, self%cnorm)
  end subroutine outer_measures

  !> The outer criterion on the measures of the last evaluation.
  logical function outer_met(self)
    class(smalbe_inner_stop_t), intent(in) :: self
    outer_met = self%gp_measure <= self%tol_gp .and. self%eq_measure <= self%tol_c
  end function outer_met

  !> Set the parameters. a_norm: ||A|| > 0 (penalty included); tol in (0, 1);
  !> max_outer, max_hessian >= 1; gamma, alpha_scale, expansion as for MPRGP;
  !> m_scale > 0 (default 100), beta in (0, 1) (default 0.5), eta_scale > 0
  !> (default 0.1); monitor: one line per outer iteration and a summary.
  subroutine smalbe_init(self, a_norm, tol, max_outer, max_hessian, gamma, alpha_scale, expansion, &
                         m_scale, beta, eta_scale, monitor, m_no_step, rho_growth, rho_contraction, rho_window, &
                         rho_stall, polish_window, polish_rounds, polish_release, polish_settle, polish_loose, &
                         polish_force_step, polish_predict, polish_first, polish_release_share)
    class(smalbe_t), intent(inout) :: self
    real(dp), intent(in) :: a_norm, tol
    integer(ip), intent(in) :: max_outer, max_hessian
    real(dp), intent(in), optional :: gamma, alpha_scale, m_scale, beta, eta_scale, rho_growth, rho_contraction, &
                                      rho_stall, polish_settle, polish_loose, polish_release_share
    character(len=*), intent(in), optional :: expansion, m_no_step
    logical, intent(in), optional :: monitor, polish_release, polish_force_step, polish_first
    integer(ip), intent(in), optional :: rho_window, polish_window, polish_rounds, polish_predict

    call self%free()
    call self%inner%init(a_norm, tol, max_hessian, gamma, alpha_scale, expansion, monitor=.false.)
    self%a_norm = a_norm
    self%tol = tol
    self%max_outer = max_outer
    self%max_hessian = max_hessian
    self%m_scale = 100
    if (present(m_scale)) self%m_scale = m_scale
    self%beta = 0.5_dp
    if (present(beta)) self%beta = beta
    self%eta_scale = 0.1_dp
    if (present(eta_scale)) self%eta_scale = eta_scale
    self%monitor = .false.
    if (present(monitor)) self%monitor = monitor
    self%m_no_step = 'cut'
    if (present(m_no_step)) self%m_no_step = m_no_step
    self%rho_growth = 1
    if (present(rho_growth)) self%rho_growth = rho_growth
    self%rho_contraction = 0.5_dp
    if (present(rho_contraction)) self%rho_contraction = rho_contraction
    self%rho_window = 1
    if (present(rho_window)) self%rho_window = rho_window
    self%rho_stall = 0
    if (present(rho_stall)) self%rho_stall = rho_stall
    self%polish_window = 0
    if (present(polish_window)) self%polish_window = polish_window
    self%polish_rounds = smalbe_polish_rounds
    if (present(polish_rounds)) self%polish_rounds = polish_rounds
    self%polish_release = .false.
    if (present(polish_release)) self%polish_release = polish_release
    self%polish_settle = 0
    if (present(polish_settle)) self%polish_settle = polish_settle
    self%polish_loose = 0
    if (present(polish_loose)) self%polish_loose = polish_loose
    self%force_polish_step = .true.
    if (present(polish_force_step)) self%force_polish_step = polish_force_step
    self%polish_predict = 0
    if (present(polish_predict)) self%polish_predict = polish_predict
    self%polish_first = .false.
    if (present(polish_first)) self%polish_first = polish_first
    self%polish_release_share = 0
    if (present(polish_release_share)) self%polish_release_share = polish_release_share

    if (.not. (tol > 0 .and. tol < 1)) call fatal_error('smalbe: tol must be in (0, 1)')
    if (max_outer < 1) call fatal_error('smalbe: max_outer must be >= 1')
    if (max_hessian < 1) call fatal_error('smalbe: max_hessian must be >= 1')
    if (.not. (self%m_scale > 0)) call fatal_error('smalbe: m_scale must be > 0')
    if (.not. (self%beta > 0 .and. self%beta < 1)) call fatal_error('smalbe: beta must be in (0, 1)')
    if (.not. (self%eta_scale > 0)) call fatal_error('smalbe: eta_scale must be > 0')
    select case (self%m_no_step)
    case ('cut', 'temporary', 'keep')
    case default
      call fatal_error("smalbe: m_no_step must be 'cut', 'temporary' or 'keep'")
    end select
    if (.not. (self%rho_growth >= 1)) call fatal_error('smalbe: rho_growth must be >= 1')
    if (.not. (self%rho_contraction > 0 .and. self%rho_contraction < 1)) &
      call fatal_error('smalbe: rho_contraction must be in (0, 1)')
    if (self%rho_window < 1) call fatal_error('smalbe: rho_window must be >= 1')
    if (.not. (self%rho_stall >= 0 .and. self%rho_stall < 1)) call fatal_error('smalbe: rho_stall must be in [0, 1)')
    if (self%polish_window < 0) call fatal_error('smalbe: polish_window must be >= 0')
    if (self%polish_rounds < 1) call fatal_error('smalbe: polish_rounds must be >= 1')
    if (.not. (self%polish_settle >= 0 .and. self%polish_settle < 1)) &
      call fatal_error('smalbe: polish_settle must be in [0, 1)')
    if (.not. (self%polish_loose >= 0 .and. self%polish_loose < 1)) &
      call fatal_error('smalbe: polish_loose must be in [0, 1)')
    if (self%polish_predict < 0) call fatal_error('smalbe: polish_predict must be >= 0')
    if (.not. (self%polish_release_share >= 0 .and. self%polish_release_share < 1)) &
      call fatal_error('smalbe: polish_release_share must be in [0, 1)')
  end subroutine smalbe_init

  !> The settings `s` at once, with ||A|| = a_norm (penalty included).
  subroutine smalbe_init_with(self, s, a_norm)
    class(smalbe_t), intent(inout) :: self
    type(smalbe_settings_t), intent(in) :: s
    real(dp), intent(in) :: a_norm
    call self%init(a_norm, s%tol, s%max_outer, s%max_hessian, s%gamma, s%alpha_scale, s%expansion, &
                   s%m_scale, s%beta, s%eta_scale, s%monitor, s%m_no_step, s%rho_growth, s%rho_contraction, &
                   s%rho_window, s%rho_stall, s%polish_window, s%polish_rounds, s%polish_release, &
                   s%polish_settle, s%polish_loose, s%polish_force_step, s%polish_predict, s%polish_first, &
                   s%polish_release_share)
  end subroutine smalbe_init_with

  subroutine smalbe_free(self)
    class(smalbe_t), intent(inout) :: self
    call self%inner%free()
    if (allocated(self%muhat)) deallocate (self%muhat)
    if (allocated(self%gradient)) deallocate (self%gradient)
    if (allocated(self%b_lin)) deallocate (self%b_lin)
    if (allocated(self%ct_mu)) deallocate (self%ct_mu)
    if (allocated(self%ct_new)) deallocate (self%ct_new)
    if (allocated(self%x_prev)) deallocate (self%x_prev)
    if (allocated(self%g_prev)) deallocate (self%g_prev)
    if (allocated(self%rule%z)) deallocate (self%rule%z)
    if (allocated(self%free_now)) deallocate (self%free_now, self%free_prev)
    if (allocated(self%muhat_prev)) deallocate (self%muhat_prev)
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
    else if (.not. problem%has_equality) then
      reason = 'SMALBE needs the equality constraint C x = 0 (has_equality is false; use MPRGP)'
    else if (.not. (problem%penalty() > 0)) then
      write (buf, '(es10.3)') problem%penalty()
      reason = 'SMALBE needs a penalty rho > 0 in the Hessian (penalty() = '//trim(adjustl(buf))//')'
    else if (problem%eq_size() < 1) then
      reason = 'SMALBE needs at least one multiplier (eq_size() < 1)'
    else if (.not. (allocated(problem%b) .and. allocated(problem%lower))) then
      reason = 'the problem has no b or lower bounds (not initialized)'
    else if (size(problem%b) < problem%n .or. size(problem%lower) < problem%n) then
      reason = 'the problem has b or lower bounds shorter than its local length n'
    else
      smalbe_is_compatible = .true.
    end if
  end function smalbe_is_compatible

  !> Solve from x (projected onto the bounds first); muhat starts at 0.
  !> On return: x, muhat, gradient = A x - b + C^T mu, gp_norm, cnorm,
  !> lagrangian belong to the same pair (x_k, mu_k); status and message say
  !> whether tol was met.
  subroutine smalbe_solve(self, problem, x)
    class(smalbe_t), intent(inout) :: self
    class(qp_problem_t), intent(inout) :: problem
    real(dp), intent(inout) :: x(:)
    character(len=qp_message_len) :: reason, buf
    real(dp) :: scale, lagr, change, m_now, q, s(2), hi(2), lo(2), l_shift, rho_old
    integer(ip) :: n, m, outer, i, n_idle, last_raise, w, n_stable, changes, local, n_bounded, n_given_up, hessian_wait
    real(dp) :: settle_limit
    logical :: gradient_given, failed, raise, polishing, polished_set, after_polish, restored
    integer :: ierr

    call reset_counters(self)
    if (.not. self%is_compatible(problem, reason)) then
      self%status = qp_status_incompatible
      self%message = 'problem refused: '//trim(reason)
      if (self%monitor) call log_message('SMALBE: '//trim(self%message))
      return
    end if
    n = problem%n
    m = problem%eq_size()
    if (size(x) < n) call fatal_error('smalbe: x shorter than the local length of the problem')
    call ensure_size(self%gradient, n)
    call ensure_size(self%b_lin, n)
    call ensure_size(self%ct_mu, n)
    call ensure_size(self%ct_new, n)
    call ensure_size(self%x_prev, n)
    call ensure_size(self%g_prev, n)
    call ensure_size(self%muhat, m)
    call ensure_size(self%rule%z, m)
    call ensure_size(self%muhat_prev, m)
    polishing = self%polish_window > 0 .and. problem%has_face_solver()
    if (allocated(self%free_now)) deallocate (self%free_now, self%free_prev)
    allocate (self%free_now(n), self%free_prev(n))
    self%free_prev = .true.
    n_stable = 0
    polished_set = .false.
    after_polish = .false.
    n_given_up = 0
    hessian_wait = 0
    settle_limit = 0
    if (polishing .and. self%polish_settle > 0) then
      local = count(problem%lower(1:n) > no_lower_bound, kind=ip)
      call MPI_Allreduce(local, n_bounded, 1, MPI_INT_IP, MPI_SUM, problem%comm, ierr)
      settle_limit = self%polish_settle*n_bounded
    end if

    self%rho = problem%penalty()
    self%rho_initial = self%rho
    self%preconditioned = problem%has_preconditioner()
    call self%inner%ritz%reset()
    if (self%rho > self%inner%a_norm) then
      self%inner%a_norm = self%rho
      self%inner%alpha_bar = self%inner%alpha_scale/self%inner%a_norm
    end if
    call problem%project(x)
    self%norm_b = problem%norm(problem%b)
    scale = self%norm_b
    if (scale <= 0) scale = 1
    self%tol_abs = self%tol*scale
    self%eta = self%eta_scale*scale
    self%per_component = problem%per_component_stop()
    if (self%per_component) then
      ! both parts of the violation bounded per component: g^P directly, and the
      ! penalty part rho Q x of the gradient through max(w) ||C x|| >= ||W Q x||_inf
      self%tol_gp = problem%stop_scale
      if (self%tol_gp <= 0) self%tol_gp = problem%weighted_max(problem%b)
      if (self%tol_gp <= 0) self%tol_gp = 1
      self%tol_gp = self%tol*self%tol_gp
      self%rule%w_max = problem%weighted_max(spread(1.0_dp, 1, problem%n))
      if (problem%relative_eq_measure) then
        self%tol_c = self%tol
      else
        self%tol_c = self%tol_gp/max(self%rule%w_max, tiny(1.0_dp))
      end if
    else
      self%tol_gp = self%tol_abs
      self%tol_c = self%tol_abs
    end if
    self%m_initial = self%m_scale*self%a_norm
    m_now = self%m_initial
    self%muhat = 0
    self%ct_mu = 0
    self%b_lin(1:n) = problem%b(1:n)
    self%rule%tol_gp = self%tol_gp
    self%rule%tol_c = self%tol_c
    self%rule%per_component = self%per_component
    self%rule%rho = self%rho
    self%rule%eta = self%eta
    self%rule%n_eq_residual = 0
    l_shift = 0
    n_idle = 0
    last_raise = 0
    w = self%rho_window
    gradient_given = .false.
    if (self%monitor) call monitor_header(self)

    self%status = qp_status_not_run
    ! 0. polish first (polish_first): the polish rounds from the face on which every bounded row
    ! is at its bound (a primal-dual active set start: the first round releases the rows whose
    ! gradient has the wrong sign); only where the equality rows alone fix the problem
    ! (face_always_regular: C_E C_E^T regular), as for the polish of an all-active set below
    self%polished_first = .false.
    if (polishing .and. self%polish_first .and. problem%face_always_regular() .and. self%max_hessian > 2) then
      if (self%monitor) call log_message('polish first: the face with every contact row at its bound')
      self%free_now(1:n) = .not. problem%lower(1:n) > no_lower_bound
      x(1:n) = merge(x(1:n), problem%lower(1:n), self%free_now(1:n))
      self%gradient(1:n) = 0
      call polish_and_account(0_ip)
      ! given up in its first round: SMALBE from that x (MPRGP computes the gradient)
      gradient_given = .not. restored
      self%polished_first = .not. restored
    end if
    do outer = 1, self%max_outer
      ! 1. inner problem, warm started from x_{k-1} with the gradient for mu_k
      self%x_prev(1:n) = x(1:n)
      self%g_prev(1:n) = self%gradient(1:n)
      self%m_bound = m_now*self%beta**n_idle
      self%rule%m_bound = self%m_bound
      self%rule%beta = self%beta
      self%rule%n_forced_cuts = 0
      ! right after a polish (force_polish_step): the inner solve takes a step unless the outer test holds
      self%rule%force_step = after_polish .and. self%force_polish_step
      call self%inner%minimize(problem, self%b_lin, x, self%gradient, self%rule, &
                               self%max_hessian - self%n_hessian, gradient_given)
      gradient_given = .true.
      if (self%rule%n_forced_cuts > 0) then
        self%m_bound = self%rule%m_bound      ! the bound this inner solve used (monitor)
        self%n_forced = self%n_forced + 1
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
      if (self%inner%status /= qp_status_converged .and. self%inner%status /= qp_status_max_hessian) then
        self%status = self%inner%status
        self%message = 'inner MPRGP: '//trim(self%inner%message)
        exit
      end if
      ! z and ||C x|| at the final x: from the stopping rule when it stopped the loop
      if (.not. (self%inner%status == qp_status_converged .and. self%rule%evaluated)) then
        call problem%eq_residual(x, self%rule%z, self%rule%cnorm)
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
      do i = 1, n
        call compensated_add(hi(1), lo(1), x(i)*(self%gradient(i) - self%b_lin(i)))
        call compensated_add(hi(2), lo(2), (x(i) - self%x_prev(i))*(self%gradient(i) + self%g_prev(i)))
      end do
      call problem%reduce_sums(hi, lo, s)
      lagr = 0.5_dp*s(1)
      change = 0.5_dp*s(2)
      self%lagrangian = lagr
      if (.not. (ieee_is_finite(self%cnorm) .and. ieee_is_finite(lagr))) then
        write (buf, '(a,i0)') 'not converged: non-finite ||C x|| or Lagrangian at outer iteration ', outer
        self%status = qp_status_not_finite
        self%message = buf
        exit
      end if
      if (self%monitor) call monitor_line(self, problem, x, outer)
      ! the active set: unchanged for n_stable outer iterations (polish)
      if (polishing) then
        call free_rows(problem, x, self%free_now)
        local = count(self%free_now .neqv. self%free_prev, kind=ip)
        call MPI_Allreduce(local, changes, 1, MPI_INT_IP, MPI_SUM, problem%comm, ierr)
        ! polish_settle > 0: a change on at most settle_limit rows still counts as settled
        if (outer == 1 .or. changes > settle_limit) then
          n_stable = 0
          polished_set = .false.
        else
          if (changes > 0) polished_set = .false.
          if (self%inner%n_iterations > 0) n_stable = n_stable + 1      ! only outer iterations that moved x count
        end if
        self%free_prev = self%free_now
      end if

      ! 2. outer stopping criterion, caps
      if (self%rule%outer_met()) then
        if (after_polish .and. self%inner%n_iterations == 0) self%n_polish_exact = self%n_polish_exact + 1
        write (buf, '(3a,es10.3,a,es10.3,3a,es10.3,a,es10.3)') 'converged: ', gp_name(self), ' = ', &
          self%gp_measure, ' <= ', self%tol_gp, ', ', eq_name(self), ' = ', self%eq_measure, ' <= ', self%tol_c
        self%status = qp_status_converged
        self%message = buf
        exit
      end if
      if (self%inner%status == qp_status_max_hessian) then
        write (buf, '(a,i0,a,i0,a)') 'not converged: Hessian multiplication cap max_hessian = ', &
          self%max_hessian, ' reached in outer iteration ', outer, '; '
        self%status = qp_status_max_hessian
        self%message = trim(buf)//' '//distance_to_tol(self)//stagnation_note(self)
        exit
      end if
      if (outer == self%max_outer) then
        write (buf, '(a,i0,a)') 'not converged: outer iteration cap max_outer = ', self%max_outer, ' reached; '
        self%status = qp_status_max_outer
        self%message = trim(buf)//' '//distance_to_tol(self)
        exit
      end if

      ! 3. multiplier update; the gradient follows without a Hessian product
      self%muhat = self%muhat + self%rho*self%rule%z
      call problem%eq_apply_t(self%muhat, self%ct_new)
      do i = 1, n
        self%gradient(i) = self%gradient(i) + (self%ct_new(i) - self%ct_mu(i))
        self%ct_mu(i) = self%ct_new(i)
        self%b_lin(i) = problem%b(i) - self%ct_mu(i)
      end do

      ! 4. semimonotonicity (see the module): L(x_k, mu_k) - L(x_{k-1}, mu_{k-1})
      ! = change + rho ||C x_{k-1}||^2 must be >= rho/2 ||C x_k||^2, else M <- beta M
      ! An inner solve that made no step (its test was already met, because
      ! M ||C x|| exceeds ||g^P||) leaves x where it was: the Lagrangian test
      ! then passes, yet the next outer iteration may progress only by the
      ! slow growth of ||g^P|| through the multiplier. This happens in FETI when
      ! ||C x|| sits at its round-off floor. m_no_step = 'cut' treats it like a
      ! failed test (M <- beta M for good); 'temporary' lets only the next inner
      ! solve use beta M (beta^j M after j such solves in a row), so that the
      ! stall is broken while M itself follows the theory; 'keep' does nothing.
      ! (l_shift = rho ||C x_{k-1}||^2, plus the change of L(x_{k-1}, mu_k) by a
      ! raised rho, see 5.)
      failed = outer > 1 .and. .not. after_polish .and. change + l_shift < 0.5_dp*self%rho*self%cnorm**2
      if (self%inner%n_iterations == 0) then
        self%n_no_step = self%n_no_step + 1
        n_idle = n_idle + 1
      else
        n_idle = 0
      end if
      if (self%m_no_step == 'cut' .and. self%inner%n_iterations == 0 .and. .not. after_polish) failed = .true.
      if (self%m_no_step /= 'temporary') n_idle = 0
      after_polish = .false.
      if (failed) then
        m_now = self%beta*m_now
        self%n_m_updates = self%n_m_updates + 1
      end if

      ! 5. adaptive penalty: when ||C x|| shrank by less than rho_contraction
      ! per outer iteration over the last w = rho_window ones (||C x_k|| >
      ! rho_contraction^w ||C x_{k-w}||; w = 1: the last one), at least w outer
      ! iterations after the last raise and after an inner solve that made a
      ! step, rho <- rho_growth rho (at most smalbe_rho_cap rho_0). A gains (rho - rho_old) C^T C, so does the
      ! gradient at x_k (no Hessian product: C^T C x = eq_apply_t(z)); the
      ! inner ||A|| estimate becomes max(||A||, rho) (A_0 and C^T C act on
      ! complementary subspaces), and alpha_bar follows. L(x_k, mu_{k+1}) grows
      ! by (rho - rho_old)/2 ||C x_k||^2, which the next test of 4. includes.
      l_shift = self%rho*self%cnorm**2
      ! rho_stall > 0: the first raise needs a stall (windowed test with
      ! rho_stall), the later ones the per-iteration test with rho_contraction
      q = self%rho_contraction
      if (self%rho_stall > 0) then
        w = merge(self%rho_window, 1_ip, self%n_rho_updates == 0)
        if (self%n_rho_updates == 0) q = self%rho_stall
      end if
      raise = self%rho_growth > 1 .and. outer > w .and. outer - last_raise >= w .and. &
              self%inner%n_iterations > 0 .and. &
              self%rho_growth*self%rho <= smalbe_rho_cap*self%rho_initial*(1 + 1.0e-12_dp)
      if (raise) raise = self%cnorm > q**w*self%cnorm_history(outer - w)
      if (raise) then
        rho_old = self%rho
        self%rho = self%rho_growth*self%rho
        call problem%set_penalty(self%rho)
        call problem%eq_apply_t(self%rule%z, self%ct_new)
        do i = 1, n
          self%gradient(i) = self%gradient(i) + (self%rho - rho_old)*self%ct_new(i)
        end do
        l_shift = l_shift + 0.5_dp*(self%rho - rho_old)*self%cnorm**2
        self%rule%rho = self%rho
        if (self%rho > self%inner%a_norm) then
          self%inner%a_norm = self%rho
          self%inner%alpha_bar = self%inner%alpha_scale/self%inner%a_norm
        end if
        self%n_rho_updates = self%n_rho_updates + 1
        last_raise = outer
      end if

      ! 6. polish: the exact solve on a face that has not changed for polish_window outer iterations
      ! (not when every bounded row is at its bound, unless the problem knows the equality rows
      ! alone to give a regular C_E C_E^T: else C_F C_F^T may be singular, e.g. a body held by
      ! its contact only)
      if (polishing .and. n_stable >= self%polish_window .and. .not. polished_set .and. &
          self%n_polish - n_given_up < smalbe_polish_max .and. self%n_hessian >= hessian_wait .and. &
          self%max_hessian - self%n_hessian > 2) then
        local = count(self%free_now .and. problem%lower(1:n) > no_lower_bound, kind=ip)
        call MPI_Allreduce(local, changes, 1, MPI_INT_IP, MPI_SUM, problem%comm, ierr)
        if (changes == 0 .and. problem%count_at_bound(x) > 0) then
          if (.not. problem%face_always_regular()) polished_set = .true.
        end if
      end if
      if (polishing .and. n_stable >= self%polish_window .and. .not. polished_set .and. &
          self%n_polish - n_given_up < smalbe_polish_max .and. self%n_hessian >= hessian_wait .and. &
          self%max_hessian - self%n_hessian > 2) then
        call polish_and_account(outer)
      end if
    end do
    self%n_eq_residual = self%rule%n_eq_residual
    self%n_active = problem%count_at_bound(x)
    if (self%monitor) call monitor_summary(self)

  contains

    !> The polish after outer iteration k (k = 0: the polish first) and what
    !> the outer loop keeps of it.
    subroutine polish_and_account(k)
      integer(ip), intent(in) :: k
      call polish_step(self, problem, x, k, restored)
      self%free_prev = self%free_now
      n_stable = 0
      polished_set = .true.
      if (.not. restored) then
        after_polish = .true.
        l_shift = 0
      end if
      if (self%polish%aborted .and. self%polish_settle > 0) then
        ! with the early trigger a face given up (too slow for the budget of an early polish,
        ! ill-conditioned faces) does not use up a polish, and the same set may be polished
        ! again; the next polish waits until the products have doubled (its budget grows with
        ! them), which bounds the waste by the products spent
        n_given_up = n_given_up + 1
        hessian_wait = 2*self%n_hessian
        polished_set = .false.
      end if
    end subroutine polish_and_account
  end subroutine smalbe_solve

  !> Step 6 of the module: the face solve on the free rows free_now, then
  !> (x, muhat, gradient) handed back to the outer loop. When the face
  !> solution would change the active set, the new face is solved at once,
  !> at most polish_rounds face solves: free rows below their bound are
  !> projected onto it (made active; a primal active-set step) and, with
  !> polish_release, active rows whose gradient has the wrong sign are made
  !> free (a primal-dual active set step). Safeguard against cycling
  !> (polish_cycling): a round that would go back to the free set of an
  !> earlier round of this polish (compared by face_signature), or, from the
  !> third round on, a round with strictly more set changes than the previous
  !> one ends the polish (SMALBE goes on from the feasible pair). Equal change
  !> counts on new sets go on (session 8: cube_h4_n64 with polish_settle =
  !> 0.15 changed 24, 4, 4, ... rows on its way to the solution's face).
  !> With polish_predict > 0 a round that projected k >= polish_predict rows
  !> and released none also puts the k free rows of smallest slack onto their
  !> bound (predicted_rows; the next round's release corrects wrong ones).
  !> Collective.
  subroutine polish_step(self, problem, x, outer, restored)
    class(smalbe_t), intent(inout) :: self
    class(qp_problem_t), intent(inout) :: problem
    real(dp), intent(inout) :: x(:)
    integer(ip), intent(in) :: outer
    logical, intent(out) :: restored      !< the first face solve was given up: x, mu as before
    integer(ip) :: n, i, budget, budget_trusted, counts(2), rounds, n_changes, prev_changes, n_predicted, &
                   n_released
    real(dp) :: change_tol, loose, share
    logical :: again, cycling, revisited, g_known, revisit_used
    logical, allocatable :: cut_short(:)
    logical, allocatable :: release(:)
    integer(i8), allocatable :: signatures(:, :)
    character(len=400) :: buf
    call timer_start('polish')
    restored = .false.
    n = problem%n
    allocate (release(n))
    again = .true.
    self%n_polish = self%n_polish + 1
    rounds = 0
    prev_changes = huge(1_ip)
    allocate (signatures(2, self%polish_rounds + 1), cut_short(self%polish_rounds + 1))
    cut_short = .false.
    revisit_used = .false.
    signatures(:, 1) = face_signature(problem, self%free_now)
    ! without release, the wrong-sign active rows do not change the face (not counted by the loose check)
    change_tol = merge(self%tol_gp, huge(1.0_dp), self%polish_release)
    g_known = .false.
    do while (again)
      rounds = rounds + 1
      ! at most as many steps as the solve has spent so far (at least smalbe_polish_min_steps):
      ! a face that CG solves slowly (inner-bound cases) costs at most twice the products
      budget = min(smalbe_polish_steps, max(smalbe_polish_min_steps, self%n_hessian), &
                   self%max_hessian - self%n_hessian - 2)
      ! a face whose loose check found no change: the fixed cap (face_solve, `trusted`)
      budget_trusted = min(smalbe_polish_trusted_steps, self%max_hessian - self%n_hessian - 2)
      ! the pair to go back to when the face solve gives up (too slow for its budget)
      self%x_prev(1:n) = x(1:n)
      self%g_prev(1:n) = self%gradient(1:n)
      self%muhat_prev = self%muhat
      ! the loose check only where another round may follow
      loose = 0
      if (rounds < self%polish_rounds) loose = self%polish_loose
      call problem%face_init(self%free_now)
      ! after a round that only released rows, x is that round's face solution unchanged (on the new
      ! face too) and its gradient is known: the Lagrangian gradient without the multiplier term
      if (g_known) self%gradient(1:n) = self%gradient(1:n) - self%ct_mu(1:n)
      call self%polish%run(problem, self%free_now, x, self%gradient, self%muhat, &
                           smalbe_polish_target*self%tol_gp, self%per_component, budget, loose, change_tol, &
                           budget_trusted, g_known)
      call problem%face_free()
      cut_short(rounds) = self%polish%stopped_loose
      self%n_polish_rounds = self%n_polish_rounds + 1
      self%n_hessian = self%n_hessian + self%polish%n_hessian
      self%n_polish_hessian = self%n_polish_hessian + self%polish%n_hessian
      self%n_polish_steps = self%n_polish_steps + self%polish%n_steps
      self%n_preconditioner = self%n_preconditioner + self%polish%n_precondition
      if (self%polish%aborted) then
        x(1:n) = self%x_prev(1:n)
        self%gradient(1:n) = self%g_prev(1:n)
        self%muhat = self%muhat_prev
        call problem%track_reset()
        restored = rounds == 1
        if (rounds > 1) then
          ! x_prev is the previous round's x after the change of the face (projected): the
          ! gradient saved with it is that of the x before the projection, so recompute it
          ! (b_lin and ct_mu still belong to muhat_prev, the previous round's face multiplier)
          call fresh_gradient()
        end if
        self%n_polish_aborted = self%n_polish_aborted + 1
        if (self%monitor) then
          write (buf, '(a,i0,a,i0,a,i0,a,es9.2,a,es9.2,a)') 'polish after outer ', outer, ': given up after ', &
            self%polish%n_steps, ' CG steps (', self%polish%n_hessian, ' products; residual ', &
            self%polish%measure0, ' -> ', self%polish%measure, ' too slow for its budget), iterate restored'
          call log_message(trim(buf))
        end if
        exit
      end if
      ! the gradient of the Lagrangian with the face multiplier
      call problem%eq_apply_t(self%muhat, self%ct_mu)
      do i = 1, n
        self%b_lin(i) = problem%b(i) - self%ct_mu(i)
        self%gradient(i) = self%gradient(i) + self%ct_mu(i)
      end do
      ! free rows below their bound (projected: MPRGP needs a feasible x), and
      ! active rows whose gradient has the wrong sign (beyond the test's bound)
      counts = face_changes(problem, self%free_now, x, self%gradient, self%tol_gp)
      n_changes = counts(1)
      if (self%polish_release) n_changes = n_changes + counts(2)
      cycling = self%polish_release .and. polish_cycling(rounds, n_changes, prev_changes, .false.)
      prev_changes = n_changes
      if (self%monitor) then
        write (buf, '(a,i0,a,i0,a,i0,a,es9.2,a,es9.2,a,es9.2,a,l1,a,i0,a,i0,a)') 'polish after outer ', outer, &
          ': ', self%polish%n_steps, ' CG steps, ', self%polish%n_hessian, ' products, residual ', &
          self%polish%measure0, ' -> ', self%polish%measure, ' (target ', smalbe_polish_target*self%tol_gp, &
          ', reached ', self%polish%reached, '); ', counts(1), ' free rows projected onto their bound, ', &
          counts(2), ' active rows with a wrong-sign gradient'
        if (self%polish%stopped_loose) buf = trim(buf)//' (stopped at the loose check)'
        if (self%polish_release .and. counts(2) > 0 .and. .not. cycling .and. rounds < self%polish_rounds) &
          buf = trim(buf)//', released'
        if (cycling) buf = trim(buf)//'; more changes than the round before: back to SMALBE'
        call log_message(trim(buf))
      end if
      again = n_changes > 0 .and. rounds < self%polish_rounds .and. .not. cycling .and. &
              self%max_hessian - self%n_hessian > 2 .and. .not. self%polish%breakdown
      if (again) then
        ! the new face: projected rows active, released rows free
        release = .false.
        if (self%polish_release) then
          ! the first round: only the rows of the strongest wrong sign (polish_release_share)
          share = 0
          if (rounds == 1) share = self%polish_release_share
          n_released = released_rows(problem, self%free_now, self%gradient, self%tol_gp, share, release)
          self%n_polish_released = self%n_polish_released + n_released
          if (self%monitor .and. n_released < counts(2)) then
            write (buf, '(a,i0,a,i0,a,f4.2,a)') 'polish: ', n_released, ' of the ', counts(2), &
              ' wrong-sign rows released (those of at least ', share, ' times the largest wrong-sign gradient)'
            call log_message(trim(buf))
          end if
        end if
        ! predictive update (polish_predict): after a round that projected at least polish_predict
        ! rows and released none, as many more free rows, those nearest their bound, become active
        ! with them (the next round releases those whose gradient says otherwise)
        if (self%polish_predict > 0 .and. counts(1) >= self%polish_predict .and. counts(2) == 0) then
          n_predicted = predicted_rows(problem, self%free_now, x, counts(1), release)
          self%n_polish_predicted = self%n_polish_predicted + n_predicted
          if (self%monitor .and. n_predicted > 0) then
            write (buf, '(a,i0,a)') 'polish: ', n_predicted, ' more free rows nearest their bound made active'
            call log_message(trim(buf))
          end if
        end if
        if (counts(1) > 0) then
          call problem%project(x)
          call problem%track_reset()
        end if
        ! only released rows (x unchanged, already on the new face): the next round needs no new gradient
        g_known = counts(1) == 0
        call free_rows(problem, x, self%free_now)
        self%free_now(1:n) = self%free_now(1:n) .or. release
        ! a set of an earlier round again: a cycle, back to SMALBE from the projected x
        signatures(:, rounds + 1) = face_signature(problem, self%free_now)
        revisited = any(signatures(1, 1:rounds) == signatures(1, rounds + 1) .and. &
                        signatures(2, 1:rounds) == signatures(2, rounds + 1))
        ! a face whose earlier visit ended at a loose check (its solve cut short, the release made
        ! from an early iterate) may be visited once more in a polish, to be solved this time
        if (revisited .and. .not. revisit_used) then
          revisit_used = revisit_of_cut_short(signatures(:, 1:rounds), cut_short(1:rounds), signatures(:, rounds + 1))
          if (revisit_used) then
            revisited = .false.
            if (self%monitor) call log_message('polish: the next face is that of an earlier round cut short '// &
                                               'at a loose check: solved once more')
          end if
        end if
        ! (the growth test of polish_cycling was made above: here n_changes > 0, only the revisit is new)
        if (revisited) then
          if (self%monitor) call log_message('polish: the next face is that of an earlier round: back to SMALBE')
          if (counts(1) > 0) call fresh_gradient()
          exit
        end if
      else if (counts(1) > 0) then
        ! the gradient at the projected x for the inner MPRGP
        call problem%project(x)
        call problem%track_reset()
        call fresh_gradient()
      end if
    end do
    call timer_stop('polish')

  contains

    !> The gradient A x - b_lin at the current x (one product, counted as the polish's).
    subroutine fresh_gradient()
      call problem%hessian(x, self%gradient)
      call problem%track_last()
      self%gradient(1:n) = self%gradient(1:n) - self%b_lin(1:n)
      self%n_hessian = self%n_hessian + 1
      self%n_polish_hessian = self%n_polish_hessian + 1
    end subroutine fresh_gradient
  end subroutine polish_step

  !> The next face of a polish (signature `next`) is that of an earlier round
  !> (signatures(:, 1:r)) whose face solve was cut short at a loose check
  !> (cut_short(1:r)): its release or projection came from an early iterate,
  !> so the polish may visit that face once more (polish_step allows one such
  !> revisit per polish; any other revisit ends the polish).
  pure logical function revisit_of_cut_short(signatures, cut_short, next) result(yes)
    integer(i8), intent(in) :: signatures(:, :), next(2)
    logical, intent(in) :: cut_short(:)
    yes = any(signatures(1, :) == next(1) .and. signatures(2, :) == next(2) .and. cut_short)
  end function revisit_of_cut_short

  !> The rows the polish releases: the active bounded rows (not `free`) whose
  !> weighted gradient w_i g_i (w = stop_weight, 1 without) is below
  !> -max(tol, share * gmax), gmax the largest -w_i g_i over the active
  !> bounded rows of all ranks (share = 0: every row with w_i g_i < -tol, the
  !> primal-dual active set step). `release` (local rows) is set on those rows
  !> and left alone elsewhere; returns their count over all ranks. Why a share
  !> (docs/THEORY.md "Damped first release"): from the face of every contact
  !> row at its bound the wrong-sign rows are those the contact-free solution
  !> penetrates, a zone larger than the contact zone on smooth obstacles (a
  !> sphere: twice its area, Hertz); the rows of deepest penetration are in
  !> contact first. Collective.
  function released_rows(problem, free, gradient, tol, share, release) result(n_released)
    class(qp_problem_t), intent(in) :: problem
    logical, intent(in) :: free(:)
    real(dp), intent(in) :: gradient(:)
    real(dp), intent(in) :: tol, share
    logical, intent(inout) :: release(:)
    integer(ip) :: n_released, i, local
    real(dp) :: wi, gmax(1), bound
    integer :: ierr
    gmax = 0
    if (share > 0) then
      do i = 1, problem%n
        if (problem%lower(i) <= no_lower_bound .or. free(i)) cycle
        wi = 1
        if (allocated(problem%stop_weight)) wi = problem%stop_weight(i)
        gmax(1) = max(gmax(1), -wi*gradient(i))
      end do
      call MPI_Allreduce(MPI_IN_PLACE, gmax, 1, MPI_DOUBLE_PRECISION, MPI_MAX, problem%comm, ierr)
    end if
    bound = max(tol, share*gmax(1))
    local = 0
    do i = 1, problem%n
      if (problem%lower(i) <= no_lower_bound .or. free(i)) cycle
      wi = 1
      if (allocated(problem%stop_weight)) wi = problem%stop_weight(i)
      if (wi*gradient(i) < -bound) then
        release(i) = .true.
        local = local + 1
      end if
    end do
    call MPI_Allreduce(local, n_released, 1, MPI_INT_IP, MPI_SUM, problem%comm, ierr)
  end function released_rows

  !> The predictive set update of the polish (polish_predict): of the free
  !> bounded rows with x_i >= l_i (not released in this round: `skip`), the k
  !> with the smallest slack x_i - l_i (ties included) are put onto their
  !> bound (x_i = l_i), at most half of them (a face keeps free rows). The
  !> threshold is found by bisection on the slack with one MPI_Allreduce of a
  !> count per step. Returns the number of rows moved (global). Collective.
  function predicted_rows(problem, free, x, k, skip) result(n_moved)
    class(qp_problem_t), intent(in) :: problem
    logical, intent(in) :: free(:), skip(:)
    real(dp), intent(inout) :: x(:)
    integer(ip), intent(in) :: k
    integer(ip) :: n_moved
    logical, allocatable :: cand(:)
    real(dp) :: lo, hi, mid, local_max
    integer(ip) :: i, n_cand, local, cnt, want, it
    integer :: ierr
    n_moved = 0
    allocate (cand(problem%n))
    local_max = 0
    do i = 1, problem%n
      cand(i) = free(i) .and. .not. skip(i) .and. problem%lower(i) > no_lower_bound
      if (cand(i)) cand(i) = x(i) >= problem%lower(i)
      if (cand(i)) local_max = max(local_max, x(i) - problem%lower(i))
    end do
    local = count(cand, kind=ip)
    call MPI_Allreduce(local, n_cand, 1, MPI_INT_IP, MPI_SUM, problem%comm, ierr)
    call MPI_Allreduce(local_max, hi, 1, MPI_DOUBLE_PRECISION, MPI_MAX, problem%comm, ierr)
    want = min(k, n_cand/2)
    if (want <= 0) return
    ! the least threshold t (to a relative 2^-50 of the largest slack) with #{slack <= t} >= want
    lo = 0
    do it = 1, 60
      mid = 0.5_dp*(lo + hi)
      local = count(cand .and. x(1:problem%n) - problem%lower(1:problem%n) <= mid, kind=ip)
      call MPI_Allreduce(local, cnt, 1, MPI_INT_IP, MPI_SUM, problem%comm, ierr)
      if (cnt >= want) then
        hi = mid
      else
        lo = mid
      end if
      if (hi - lo <= epsilon(1.0_dp)*hi) exit
    end do
    local = 0
    do i = 1, problem%n
      if (cand(i) .and. x(i) - problem%lower(i) <= hi) then
        x(i) = problem%lower(i)
        local = local + 1
      end if
    end do
    call MPI_Allreduce(local, n_moved, 1, MPI_INT_IP, MPI_SUM, problem%comm, ierr)
  end function predicted_rows

  !> The polish's safeguard against cycling: with n_changes > 0 set changes
  !> after round `rounds` (prev_changes those of the round before, huge at the
  !> first), stop when the next set is one of an earlier round (`revisited`)
  !> or, from the third round on, when the changes grew strictly.
  pure logical function polish_cycling(rounds, n_changes, prev_changes, revisited)
    integer(ip), intent(in) :: rounds, n_changes, prev_changes
    logical, intent(in) :: revisited
    polish_cycling = n_changes > 0 .and. (revisited .or. (rounds >= 3 .and. n_changes > prev_changes))
  end function polish_cycling

  !> Two sums of hashes of (rank, local row) over the bounded free rows, summed
  !> over ranks: equal for equal sets (per rank); different sets collide only
  !> by chance (two independent 32-bit hash sums). Collective.
  function face_signature(problem, free) result(sig)
    class(qp_problem_t), intent(in) :: problem
    logical, intent(in) :: free(:)
    integer(i8) :: sig(2), local(2), v
    integer(ip) :: i
    integer :: rank, ierr, k
    integer(i8), parameter :: low32 = 4294967295_i8
    call MPI_Comm_rank(problem%comm, rank, ierr)
    local = 0
    do i = 1, problem%n
      if (problem%lower(i) <= no_lower_bound .or. .not. free(i)) cycle
      do k = 1, 2
        ! xorshift64 of the row and rank (bit operations only: no overflow)
        v = ior(ishft(int(rank, i8), 32), int(i, i8)) + k
        v = ieor(v, ishft(v, 13))
        v = ieor(v, ishft(v, -7))
        v = ieor(v, ishft(v, 17))
        v = ieor(v, ishft(v, 13))
        v = ieor(v, ishft(v, -7))
        v = ieor(v, ishft(v, 17))
        local(k) = local(k) + iand(v, low32)
      end do
    end do
    call MPI_Allreduce(local, sig, 2, MPI_INT_I8, MPI_SUM, problem%comm, ierr)
  end function face_signature

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
    if (self%per_component .and. self%tol_c == self%tol) then
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
    self%n_polish = 0
    self%n_polish_rounds = 0
    self%n_polish_hessian = 0
    self%n_polish_steps = 0
    self%n_polish_exact = 0
    self%n_polish_aborted = 0
    self%n_polish_released = 0
    self%n_polish_predicted = 0
    self%n_forced = 0
    self%cnorm_history = [real(dp) ::]
    self%hessian_history = [integer(ip) ::]
    self%rho_history = [real(dp) ::]
  end subroutine reset_counters

  subroutine monitor_header(self)
    class(smalbe_t), intent(in) :: self
    character(len=200) :: buf
    write (buf, '(a,es10.3,a,es10.3,a,es10.3,a,es10.3,2a)') 'SMALBE: rho = ', self%rho, &
      ', ||A|| = ', self%a_norm, ', M0 = ', self%m_initial, ', eta = ', self%eta, ', expansion ', &
      trim(self%inner%expansion)
    call log_message(buf)
    write (buf, '(3a,es10.3,3a,es10.3)') 'SMALBE: stop when ', gp_name(self), ' <= ', self%tol_gp, &
      ' and ', eq_name(self), ' <= ', self%tol_c
    call log_message(trim(buf))
    write (buf, '(a5,a7,a9,5a12,a9)') 'outer', 'inner', 'hessian', '||g^P||', '||Cx||', 'M', 'rho', &
      'L', 'active'
    call log_message(buf)
  end subroutine monitor_header

  subroutine monitor_line(self, problem, x, outer)
    class(smalbe_t), intent(in) :: self
    class(qp_problem_t), intent(inout) :: problem
    real(dp), intent(in) :: x(:)
    integer(ip), intent(in) :: outer
    character(len=200) :: buf
    integer(ip) :: active
    active = problem%count_at_bound(x)
    write (buf, '(i5,i7,i9,5es12.4,i9)') outer, self%inner%n_iterations, self%n_hessian, self%gp_norm, &
      self%cnorm, self%m_bound, self%rho, self%lagrangian, active
    call log_message(buf)
  end subroutine monitor_line

  subroutine monitor_summary(self)
    class(smalbe_t), intent(in) :: self
    character(len=300) :: buf
    call log_message('SMALBE: '//trim(self%message))
    write (buf, '(a,i0,a,i0,a,i0,a,i0,a,i0,a,i0,a)') '  outer iterations ', self%n_outer, &
      ', inner iterations ', self%n_inner, ' (cg ', self%n_cg, ', expansion ', self%n_expansion, &
      ', proportioning ', self%n_proportioning, ', expansion fallbacks ', self%n_expansion_fallback, ')'
    call log_message(buf)
    write (buf, '(a,i0,a,i0,a,i0,a,es10.3,a,i0,a,i0,3a)') '  Hessian multiplications ', self%n_hessian, &
      ', ||Cx|| evaluations ', self%n_eq_residual, ', M updates ', self%n_m_updates, ', final M ', &
      self%m_bound, ', active ', self%n_active, ', inner solves without a step ', self%n_no_step, &
      ' (m_no_step = ', trim(self%m_no_step), ')'
    call log_message(buf)
    write (buf, '(a,es10.3,a,es10.3,a,i0,a)') '  rho ', self%rho_initial, ' -> ', self%rho, ' (raised ', &
      self%n_rho_updates, ' times)'
    call log_message(buf)
    if (self%inner%ritz%n_runs > 0) then
      write (buf, '(a,l1,a,i0,a,es10.3,a,es10.3,a,es10.3,a,i0,a,i0)') '  preconditioned ', self%preconditioned, &
        ' (applications ', self%n_preconditioner, '), face condition estimate ', self%inner%ritz%max_ratio, &
        ' (Ritz values ', self%inner%ritz%theta_min, ' .. ', self%inner%ritz%theta_max, '; CG runs ', &
        self%inner%ritz%n_runs, ', longest ', self%inner%ritz%longest
      call log_message(trim(buf)//')')
    end if
    if (self%n_polish > 0) then
      write (buf, '(a,i0,a,i0,a,i0,a,i0,a,i0,a,i0,a)') '  polish ', self%n_polish, ' times (', self%n_polish_rounds, &
        ' face solves, ', self%n_polish_steps, &
        ' CG steps, ', self%n_polish_hessian, ' Hessian multiplications; accepted at once ', self%n_polish_exact, &
        ', given up ', self%n_polish_aborted, ')'
      if (self%polish_release) write (buf, '(a,a,i0,a)') trim(buf), ', released ', self%n_polish_released, &
        ' active rows'
      if (self%n_polish_predicted > 0) write (buf, '(a,a,i0,a)') trim(buf), ', predicted ', &
        self%n_polish_predicted, ' active rows'
      if (self%n_forced > 0) write (buf, '(a,a,i0,a)') trim(buf), '; ', self%n_forced, &
        ' inner solves after a polish made to take a step'
      call log_message(buf)
    end if
    if (self%n_norm_updates > 0) then
      write (buf, '(a,es10.3,a,es10.3,a,i0,a)') '  ||A|| estimate raised from ', self%a_norm, ' to ', &
        self%inner%a_norm, ' by Rayleigh quotients of the search directions (', self%n_norm_updates, ' times)'
      call log_message(buf)
    end if
  end subroutine monitor_summary

end module smalbe
