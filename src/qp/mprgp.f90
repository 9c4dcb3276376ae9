!> MPRGP: modified proportioning with reduced gradient projections, for
!>
!>     min 1/2 x^T A x - c^T x   s.t.  x >= l,
!>
!> after Dostal and Schoeberl (2005) and Dostal, "Optimal Quadratic
!> Programming Algorithms" (2009). With g = A x - c, the free gradient phi,
!> the chopped gradient beta and the projected gradient g^P are
!>
!>     phi_i  = g_i            if x_i > l_i, else 0
!>     beta_i = min(g_i, 0)    if x_i = l_i, else 0
!>     g^P    = phi + beta,
!>
!> and the reduced free gradient is phit_i = min((x_i - l_i)/alpha_bar, phi_i).
!> An iterate is proportional when ||beta||^2 <= Gamma^2 phit^T phi. Each
!> iteration makes one of three steps:
!> - CG step (proportional, the CG step length alpha_cg = g^T p / p^T A p is at
!>   most the largest feasible step alpha_f): x <- x - alpha_cg p, p conjugate;
!> - expansion step (proportional, alpha_cg > alpha_f): the half step
!>   x <- x - alpha_f p to the boundary, then x <- P(x - alpha_e phi(x)) with P
!>   the projection onto the bounds, the gradient recomputed, p <- phi;
!> - proportioning step (not proportional): exact line search along beta
!>   (feasible: beta <= 0 lives on the active set), p <- phi.
!>
!> Expansion step length alpha_e:
!> - 'fixed': alpha_e = alpha_bar = alpha_scale / ||A|| (||A|| from the
!>   caller, e.g. Lanczos or a power method); alpha_scale in (0, 2] keeps the cost
!>   decreasing when ||A|| is not underestimated;
!> - 'optimal': alpha_e = phi^T g / phi^T A phi, the minimizer of the cost
!>   along -phi without bounds, then projected. The cost f = 1/2 x^T (g - c)
!>   of the projected point is compared with that of the half step; if it did
!>   not decrease, the step is redone with alpha_bar (counted in
!>   n_expansion_fallback). It costs one more Hessian multiplication than
!>   'fixed' (two more on a fallback).
!>
!> The norm estimate ||A|| (a_norm) only has to bound the spectrum from above
!> for 'fixed' to be safe, yet callers estimate it by Lanczos (FETI) or a power
!> method, which approach ||A|| from below. Every CG, proportioning and optimal expansion
!> direction d gives a Rayleigh quotient d^T A d / d^T d <= ||A|| for one more
!> local dot product in a reduction that is made anyway; when it exceeds
!> a_norm, a_norm is raised to it and alpha_bar = alpha_scale/a_norm follows
!> (counted in n_norm_updates, kept across calls). It restores
!> alpha_bar <= 2/||A|| when the caller's estimate is low; with the power
!> method (within 0.4% of ||A||) it does not trigger.
!>
!> The stopping rule is an object (`inner_stop_t`, module inner_solver) asked every iteration with
!> the current x and ||g^P||, so that SMALBE can stop the inner loop on
!> ||g^P|| <= min(M ||C x||, eta). The stand-alone `solve` stops on
!> ||g^P|| <= tol ||b|| (`mprgp_abs_stop_t`; always the 2-norm test: the
!> per-component test of qp_problem is SMALBE's). The core, `minimize`, takes the
!> linear term c as an argument (SMALBE passes b - C^T mu).
!>
!> Safeguards: every iterate is kept feasible (x <- max(x, l) after each
!> update, which only removes round-off); ||g^P|| and every step length are
!> checked for NaN/Inf each iteration, before they are used, and the solver
!> stops with qp_status_not_finite; p^T A p <= 0 stops with
!> qp_status_breakdown; the Hessian multiplications of one call never exceed
!> its budget (qp_status_max_hessian). x is never left non-finite.
!>
!> Communication per CG step: one MPI_Allreduce for the gradient split
!> (||phi||^2, ||beta||^2, phit^T phi and phi^T A p fused), one for p^T A p
!> with g^T p and p^T p, one MIN for alpha_f, plus the Hessian. The sums are
!> compensated (qp_problem: compensated_add, reduce_sums), so the iterates do
!> not depend on the number of ranks when the Hessian's result does not.
!>
!> Preconditioning in the face (Dostal, "Optimal Quadratic Programming
!> Algorithms", 2009, Sec. 5.11): when the problem has a preconditioner
!> (qp_problem: the part `prec`), the CG steps use
!> z = R_F M_A^{-1} R_F g, the preconditioned free gradient restricted to
!> the free set (0 on the active set), instead of phi: a run of CG steps
!> starts with p = z, conjugates with beta_cg = z^T A p / p^T A p and
!> p <- z - beta_cg p. The step length g^T p / p^T A p, the test of
!> proportionality (phi, beta, phit), the expansion step (along phi, length
!> alpha_bar) and the proportioning step (along beta), and the stopping test
!> keep their unpreconditioned forms, so the bounds stay simple. z is
!> computed only when the iterate is proportional and not converged, i.e.
!> when its direction is used: after a CG step the conjugation
!> (z, beta_cg = z^T A p / p^T A p with the A p and p^T A p of that step, one
!> more reduction) waits for the next iteration's stopping and
!> proportionality tests, so no application (two projections, two coarse
!> solves, and M^{-1}) is spent on the iterate where an inner solve stops or
!> a proportioning step follows. The iterates are those of the eager form.
!>
!> Face condition estimate: the step lengths and conjugation coefficients
!> of every run of consecutive CG steps (between two restarts of p) are a
!> Lanczos process on the face; `ritz` (ritz_values) keeps the extreme Ritz
!> values and the largest ratio theta_max/theta_min of a run, over the
!> calls since the caller reset it (SMALBE: one solve). Without
!> preconditioner the operator is A on the face, with it R_F M_A^{-1} R_F A.
!> A problem that watches it (qp_preconditioner: watches; the FETI dual
!> with `&solver preconditioner = 'auto'`) is handed the running estimate
!> after every preconditioned CG step and may change its preconditioner;
!> then the next CG step starts a new run (p = z), as after a face change.
!>
!> Work vectors (5 of the local length) are allocated on the first call and
!> kept (no allocation in the iteration).
module mprgp
  use, intrinsic :: ieee_arithmetic, only: ieee_is_finite, ieee_is_nan
  use kinds, only: dp, ip, name_len
  use errors, only: fatal_error
  use logger, only: log_message
  use text, only: lower_case
  use qp_problem, only: qp_problem_t, no_lower_bound, compensated_add, qp_status_converged, &
                        qp_status_max_hessian, qp_status_not_finite, qp_status_breakdown, &
                        qp_status_incompatible, qp_status_not_run, qp_message_len, x_moved, &
                        moved_other, moved_to_argument, moved_along_argument
  use inner_solver, only: inner_solver_t, inner_stop_t
  use solver_monitor, only: step_none, step_cg, step_expansion, step_proportioning
  use settings_base, only: settings_t
  implicit none
  private

  public :: ensure_size, preconditioned_free_gradient

  !> The settings of MPRGP (`&solver` variables gamma, alpha_scale, expansion;
  !> docs/INPUT.md): the one home of their defaults, ranges and echo.
  type, extends(settings_t), public :: mprgp_settings_t
    real(dp) :: gamma = 1                      !< proportioning parameter Gamma > 0
    real(dp) :: alpha_scale = 1.9_dp           !< expansion step alpha_bar = alpha_scale/||A||, in (0, 2]
    character(len=name_len) :: expansion = 'fixed'  !< 'fixed' | 'optimal'
  contains
    procedure :: check => mprgp_settings_check
    procedure :: group => mprgp_settings_group
    procedure :: variables => mprgp_settings_variables
    procedure :: read_namelist => mprgp_settings_read
    procedure :: write_namelist => mprgp_settings_write
  end type mprgp_settings_t

  !> The expansion step lengths (chosen once in init).
  integer, parameter :: expansion_fixed = 1, expansion_optimal = 2

  !> Stop when ||g^P|| <= tol_abs.
  type, extends(inner_stop_t), public :: mprgp_abs_stop_t
    real(dp) :: tol_abs = 0
  contains
    procedure :: test => abs_stop_test
  end type mprgp_abs_stop_t

  !> The MPRGP solver. Counters and gp_norm describe the last call of
  !> `solve` or `minimize` (SMALBE sums them over its inner solves).
  type, extends(inner_solver_t), public :: mprgp_t
    real(dp) :: gamma = 1                      !< proportioning parameter Gamma > 0
    real(dp) :: alpha_scale = 1.9_dp           !< alpha_bar = alpha_scale / a_norm
    real(dp) :: alpha_bar = 0                  !< fixed expansion step length
    character(len=name_len) :: expansion = 'fixed'  !< 'fixed' | 'optimal'
    integer, private :: expansion_kind = expansion_fixed
    real(dp) :: tol = 1.0e-6_dp                !< stand-alone solve: stop at ||g^P|| <= tol ||b||
    integer(ip) :: max_hessian = 20000         !< stand-alone solve: Hessian multiplication cap
    real(dp) :: tol_abs = 0                    !< absolute tolerance used by the last solve
    logical :: norm_refined = .false.          !< the problem's refined_norm was asked (once after init)
    logical :: preconditioned = .false.        !< the last call used the problem's preconditioner
    integer(ip) :: n_switches = 0              !< times the problem changed its preconditioner (all calls)
    real(dp), allocatable, private :: p(:), ap(:), w_phi(:), w_x(:), w_g(:)
  contains
    procedure :: init => mprgp_init
    procedure :: init_with => mprgp_init_with
    procedure :: free => mprgp_free
    procedure :: solve => mprgp_solve
    procedure :: is_compatible => mprgp_is_compatible
    procedure :: minimize
    procedure :: norm_at_least => mprgp_norm_at_least
    procedure :: variant => mprgp_variant
  end type mprgp_t

contains

  subroutine abs_stop_test(self, problem, x, g, gp_norm, stop)
    class(mprgp_abs_stop_t), intent(inout) :: self
    class(qp_problem_t), intent(inout) :: problem
    real(dp), intent(in) :: x(:), g(:)
    real(dp), intent(in) :: gp_norm
    logical, intent(out) :: stop
    stop = gp_norm <= self%tol_abs
  end subroutine abs_stop_test

  !> Set the parameters. a_norm: ||A|| > 0; tol: relative tolerance of the
  !> stand-alone solve; max_hessian >= 0; gamma, alpha_scale, expansion as in
  !> mprgp_settings_t (its defaults when absent).
  subroutine mprgp_init(self, a_norm, tol, max_hessian, gamma, alpha_scale, expansion, monitor)
    class(mprgp_t), intent(inout) :: self
    real(dp), intent(in) :: a_norm, tol
    integer(ip), intent(in) :: max_hessian
    real(dp), intent(in), optional :: gamma, alpha_scale
    character(len=*), intent(in), optional :: expansion
    logical, intent(in), optional :: monitor
    type(mprgp_settings_t) :: s
    if (present(gamma)) s%gamma = gamma
    if (present(alpha_scale)) s%alpha_scale = alpha_scale
    if (present(expansion)) s%expansion = expansion
    call self%init_with(s, a_norm, tol, max_hessian, monitor)
  end subroutine mprgp_init

  !> The settings `s` at once (see mprgp_init for the other arguments).
  subroutine mprgp_init_with(self, s, a_norm, tol, max_hessian, monitor)
    class(mprgp_t), intent(inout) :: self
    type(mprgp_settings_t), intent(in) :: s
    real(dp), intent(in) :: a_norm, tol
    integer(ip), intent(in) :: max_hessian
    logical, intent(in), optional :: monitor
    character(len=160) :: buf
    character(len=:), allocatable :: variable, rule, got

    call self%free()
    self%a_norm = a_norm
    self%tol = tol
    self%max_hessian = max_hessian
    self%gamma = s%gamma
    self%alpha_scale = s%alpha_scale
    self%expansion = s%expansion
    self%monitor = .false.
    if (present(monitor)) self%monitor = monitor

    if (.not. (a_norm > 0 .and. a_norm <= huge(a_norm))) then
      write (buf, '(a,es10.3,a)') 'mprgp: the Hessian norm estimate ||A|| = ', a_norm, ' must be finite and > 0 '// &
        '(the operator over- or underflowed: data out of the range of double precision?)'
      call fatal_error(trim(buf))
    end if
    if (.not. (tol >= 0 .and. tol < 1)) call fatal_error('mprgp: tol must be in [0, 1)')
    if (max_hessian < 0) call fatal_error('mprgp: max_hessian must be >= 0')
    call s%check(variable, rule, got)
    if (len(variable) > 0) call fatal_error('mprgp: '//variable//' '//rule//' (got '//got//')')
    self%expansion_kind = merge(expansion_optimal, expansion_fixed, self%expansion == 'optimal')
    self%alpha_bar = self%alpha_scale/self%a_norm
    self%norm_refined = .false.
  end subroutine mprgp_init_with

  !> The first setting out of its range: `variable` its name ('' if none),
  !> `rule` the allowed values, `got` the value.
  subroutine mprgp_settings_check(self, variable, rule, got)
    class(mprgp_settings_t), intent(in) :: self
    character(len=:), allocatable, intent(out) :: variable, rule, got
    character(len=32) :: buf
    variable = ''
    rule = ''
    got = ''
    if (.not. (self%gamma > 0)) then
      variable = 'gamma'
      rule = 'must be > 0'
      write (buf, '(g0)') self%gamma
    else if (.not. (self%alpha_scale > 0 .and. self%alpha_scale <= 2)) then
      variable = 'alpha_scale'
      rule = 'must be in (0, 2]'
      write (buf, '(g0)') self%alpha_scale
    else if (self%expansion /= 'fixed' .and. self%expansion /= 'optimal') then
      variable = 'expansion'
      rule = "must be 'fixed' or 'optimal'"
      buf = self%expansion
    else
      return
    end if
    got = trim(adjustl(buf))
  end subroutine mprgp_settings_check

  !> The namelist group of these variables.
  function mprgp_settings_group(self) result(name)
    class(mprgp_settings_t), intent(in) :: self
    character(len=:), allocatable :: name
    name = 'solver'
  end function mprgp_settings_group

  !> The names of the namelist variables (those of read_namelist).
  subroutine mprgp_settings_variables(self, names)
    class(mprgp_settings_t), intent(in) :: self
    character(len=name_len), allocatable, intent(out) :: names(:)
    names = [character(len=name_len) :: 'gamma', 'alpha_scale', 'expansion']
  end subroutine mprgp_settings_variables

  !> Read the settings' variables from the namelist group text `group`
  !> ('&solver ... /', only this component's variables); strings lower case.
  subroutine mprgp_settings_read(self, group, status, msg)
    class(mprgp_settings_t), intent(inout) :: self
    character(len=*), intent(in) :: group
    integer, intent(out) :: status
    character(len=*), intent(out) :: msg
    real(dp) :: gamma, alpha_scale
    character(len=name_len) :: expansion
    namelist /solver/ gamma, alpha_scale, expansion
    gamma = self%gamma
    alpha_scale = self%alpha_scale
    expansion = self%expansion
    read (group, nml=solver, iostat=status, iomsg=msg)
    if (status /= 0) return
    self%gamma = gamma
    self%alpha_scale = alpha_scale
    self%expansion = lower_case(expansion)
  end subroutine mprgp_settings_read

  !> Write the settings as the namelist group '&solver ... /' (strings quoted).
  subroutine mprgp_settings_write(self, lines, status, msg)
    class(mprgp_settings_t), intent(in) :: self
    character(len=*), intent(out) :: lines(:)
    integer, intent(out) :: status
    character(len=*), intent(out) :: msg
    real(dp) :: gamma, alpha_scale
    character(len=name_len) :: expansion
    namelist /solver/ gamma, alpha_scale, expansion
    gamma = self%gamma
    alpha_scale = self%alpha_scale
    expansion = self%expansion
    lines = ''
    write (lines, nml=solver, delim='quote', iostat=status, iomsg=msg)
  end subroutine mprgp_settings_write

  !> Raise the norm estimate to at least `bound`; alpha_bar follows.
  subroutine mprgp_norm_at_least(self, bound)
    class(mprgp_t), intent(inout) :: self
    real(dp), intent(in) :: bound
    if (bound > self%a_norm) then
      self%a_norm = bound
      self%alpha_bar = self%alpha_scale/self%a_norm
    end if
  end subroutine mprgp_norm_at_least

  function mprgp_variant(self) result(text)
    class(mprgp_t), intent(in) :: self
    character(len=:), allocatable :: text
    text = 'expansion '//trim(self%expansion)
  end function mprgp_variant

  subroutine mprgp_free(self)
    class(mprgp_t), intent(inout) :: self
    if (allocated(self%p)) deallocate (self%p)
    if (allocated(self%ap)) deallocate (self%ap)
    if (allocated(self%w_phi)) deallocate (self%w_phi)
    if (allocated(self%w_x)) deallocate (self%w_x)
    if (allocated(self%w_g)) deallocate (self%w_g)
    if (allocated(self%gradient)) deallocate (self%gradient)
    self%status = qp_status_not_run
    self%message = 'not run'
  end subroutine mprgp_free

  !> MPRGP handles bound constraints only.
  logical function mprgp_is_compatible(self, problem, reason)
    class(mprgp_t), intent(in) :: self
    class(qp_problem_t), intent(inout) :: problem
    character(len=*), intent(out) :: reason
    reason = ''
    mprgp_is_compatible = .false.
    if (self%a_norm <= 0) then
      reason = 'MPRGP is not initialized (call init first)'
    else if (allocated(problem%eq)) then
      reason = 'MPRGP handles bound constraints only; this problem has the equality constraint C x = 0 '// &
               '(use SMALBE)'
    else if (.not. (allocated(problem%b) .and. allocated(problem%lower))) then
      reason = 'the problem has no b or lower bounds (not initialized)'
    else if (size(problem%b) < problem%n .or. size(problem%lower) < problem%n) then
      reason = 'the problem has b or lower bounds shorter than its local length n'
    else
      mprgp_is_compatible = .true.
    end if
  end function mprgp_is_compatible

  !> Stand-alone solve: x <- P(x), then MPRGP until ||g^P|| <= tol ||b||
  !> (tol itself when b = 0) or max_hessian multiplications.
  subroutine mprgp_solve(self, problem, x)
    class(mprgp_t), intent(inout) :: self
    class(qp_problem_t), intent(inout) :: problem
    real(dp), intent(inout) :: x(:)
    character(len=qp_message_len) :: reason
    type(mprgp_abs_stop_t) :: rule
    real(dp) :: norm_b
    character(len=200) :: buf

    if (.not. self%is_compatible(problem, reason)) then
      self%status = qp_status_incompatible
      self%message = 'problem refused: '//trim(reason)
      if (self%monitor) call log_message('MPRGP: '//trim(self%message))
      return
    end if
    if (size(x) < problem%n) call fatal_error('mprgp: x shorter than the local length of the problem')
    call ensure_size(self%gradient, problem%n)
    call problem%project(x)
    norm_b = problem%norm(problem%b)
    self%tol_abs = self%tol*norm_b
    if (norm_b <= 0) self%tol_abs = self%tol
    rule%tol_abs = self%tol_abs
    call self%ritz%reset()
    call self%minimize(problem, problem%b, x, self%gradient, rule, self%max_hessian, .false.)
    if (self%status == qp_status_converged) then
      write (buf, '(a,es10.3,a,es10.3,a)') 'converged: ||g^P|| = ', self%gp_norm, ' <= ', self%tol_abs, &
        ' (tol ||b||)'
      self%message = buf
    end if
    if (self%monitor) call mprgp_summary(self)
  end subroutine mprgp_solve

  !> Work arrays sized for `problem`, counters and status of a new minimize run.
  subroutine reset_run(self, problem)
    class(mprgp_t), intent(inout) :: self
    class(qp_problem_t), intent(in) :: problem
    integer(ip) :: n
    n = problem%n
    call ensure_size(self%p, n)
    call ensure_size(self%ap, n)
    call ensure_size(self%w_phi, n)
    call ensure_size(self%w_x, n)
    call ensure_size(self%w_g, n)
    self%n_hessian = 0
    self%n_iterations = 0
    self%n_cg = 0
    self%n_expansion = 0
    self%n_proportioning = 0
    self%n_expansion_fallback = 0
    self%gp_norm = huge(1.0_dp)
    self%best_gp_norm = huge(1.0_dp)
    self%n_best = 0
    self%n_norm_updates = 0
    self%n_preconditioner = 0
    self%preconditioned = allocated(problem%prec)
    self%status = qp_status_not_run
    self%message = ''
  end subroutine reset_run

  !> The MPRGP iteration from a feasible x with linear term c (= b_lin).
  !> On entry x >= l (not checked; callers project). With gradient_given,
  !> g must hold A x - c on entry; otherwise it is computed (one Hessian
  !> multiplication). On return x is the last iterate, g = A x - c,
  !> gp_norm = ||g^P(x)||, status/message say why the loop stopped, and the
  !> counters describe this call. At most max_hessian multiplications.
  subroutine minimize(self, problem, b_lin, x, g, stop_rule, max_hessian, gradient_given)
    class(mprgp_t), intent(inout) :: self
    class(qp_problem_t), intent(inout) :: problem
    real(dp), intent(in) :: b_lin(:)
    real(dp), intent(inout) :: x(:)
    real(dp), intent(inout) :: g(:)
    class(inner_stop_t), intent(inout) :: stop_rule
    integer(ip), intent(in) :: max_hessian
    logical, intent(in) :: gradient_given
    real(dp) :: stats(4), alpha_f, alpha_cg, pap
    logical :: restart, conjugate_pending
    integer(ip) :: n
    integer :: last_kind                   ! the kind of the last step (the rule's monitor)

    n = problem%n
    call reset_run(self, problem)

    if (.not. gradient_given) then
      call x_moved(problem, moved_other)
      if (max_hessian < 1) then
        call set_status(self, qp_status_max_hessian, 'Hessian multiplication cap reached', max_hessian)
        return
      end if
      call apply_hessian(self, problem, x, g)
      call x_moved(problem, moved_to_argument)
      g(1:n) = g(1:n) - b_lin(1:n)
    end if
    call gradient_part(problem, x, g, .false., self%p)
    call split_stats(self, problem, x, g, stats)
    restart = .true.
    conjugate_pending = .false.
    last_kind = step_none

    do
      if (stops_here(self, problem, x, g, stats, stop_rule, last_kind, max_hessian)) exit
      if (.not. self%norm_refined) call refine_norm(self, problem, x, g, stats)
      if (stats(2) <= self%gamma**2*stats(3)) then
        ! proportional iterate: try a CG step along p (a new run: p = phi, or z)
        if (restart) then
          if (self%preconditioned) call free_direction(self, problem, x, g, self%p)
          call self%ritz%begin_run()
          restart = .false.
        else if (conjugate_pending) then
          ! after a CG step (preconditioned): z, beta_cg = z^T A p / p^T A p with
          ! A p and p^T A p of that step, p <- z - beta_cg p
          call free_direction(self, problem, x, g, self%w_phi)
          if (.not. conjugated(self, problem, x, self%w_phi, free_dot(problem, x, self%w_phi, self%ap)/pap)) exit
        end if
        conjugate_pending = .false.
        alpha_f = feasible_step(problem, x, self%p)
        if (.not. step_along_p(self, problem, g, .not. ieee_is_nan(alpha_f), 'p', &
                               'p^T A p, g^T p or the feasible step', 'CG', pap, alpha_cg)) exit
        call self%ritz%add_alpha(alpha_cg)

        if (alpha_cg <= alpha_f) then
          ! CG step, then p <- phi - beta_cg p with beta_cg = phi^T A p / p^T A p
          ! (preconditioned: p <- z - beta_cg p, beta_cg = z^T A p / p^T A p)
          call take_step(problem, x, g, alpha_cg, self%p, self%ap)
          call x_moved(problem, moved_along_argument, alpha_cg)
          self%n_cg = self%n_cg + 1
          last_kind = step_cg
          if (self%preconditioned) then
            ! z and the conjugation wait until a CG step follows (see the module)
            call split_stats(self, problem, x, g, stats)
            conjugate_pending = .true.
            if (preconditioner_switched(self, problem)) then
              ! a new preconditioner: the next CG step starts a new run (p = z)
              conjugate_pending = .false.
              restart = .true.
              call self%ritz%end_run()
            end if
          else
            call split_stats(self, problem, x, g, stats, self%ap)
            if (.not. conjugated(self, problem, x, g, stats(4)/pap)) exit
          end if
        else
          restart = .true.
          call self%ritz%end_run()
          ! expansion step: half step to the boundary, then the projected gradient step
          call take_step(problem, x, g, alpha_f, self%p, self%ap)
          call x_moved(problem, moved_along_argument, alpha_f)
          self%n_expansion = self%n_expansion + 1
          last_kind = step_expansion
          call expand(self, problem, b_lin, x, g, max_hessian)
          if (self%status /= qp_status_not_run) exit
          call gradient_part(problem, x, g, .false., self%p)
          call split_stats(self, problem, x, g, stats)
        end if
      else
        ! proportioning step along beta
        restart = .true.
        conjugate_pending = .false.
        call self%ritz%end_run()
        call gradient_part(problem, x, g, .true., self%p)
        if (.not. step_along_p(self, problem, g, .true., 'beta', 'beta^T A beta or g^T beta', 'proportioning', &
                               pap, alpha_cg)) exit
        call take_step(problem, x, g, alpha_cg, self%p, self%ap)
        call x_moved(problem, moved_along_argument, alpha_cg)
        self%n_proportioning = self%n_proportioning + 1
        last_kind = step_proportioning
        call gradient_part(problem, x, g, .false., self%p)
        call split_stats(self, problem, x, g, stats)
      end if
      self%n_iterations = self%n_iterations + 1
    end do
    call self%ritz%end_run()
  end subroutine minimize

  !> At the top of an iteration of minimize (stats: split_stats at x): ||g^P||
  !> recorded, then true (status set) when it is not finite, when the
  !> caller's stopping rule holds or when the product cap is reached.
  logical function stops_here(self, problem, x, g, stats, stop_rule, last_kind, max_hessian) result(done)
    class(mprgp_t), intent(inout) :: self
    class(qp_problem_t), intent(inout) :: problem
    real(dp), intent(in) :: x(:), g(:), stats(4)
    class(inner_stop_t), intent(inout) :: stop_rule
    integer, intent(in) :: last_kind
    integer(ip), intent(in) :: max_hessian
    real(dp) :: gp
    logical :: stop
    done = .true.
    gp = sqrt(stats(1) + stats(2))
    self%gp_norm = gp
    if (.not. all(ieee_is_finite(stats))) then
      call set_status(self, qp_status_not_finite, 'non-finite value in ||g^P||', self%n_iterations)
      return
    end if
    if (gp < self%best_gp_norm) then
      self%best_gp_norm = gp
      self%n_best = self%n_iterations
    end if
    call stop_rule%observe(last_kind, self%n_hessian, gp)
    call stop_rule%test(problem, x, g, gp, stop)
    if (stop) then
      call set_status(self, qp_status_converged, 'converged (stopping rule met)', self%n_iterations)
      return
    end if
    if (self%n_hessian >= max_hessian) then
      call set_status(self, qp_status_max_hessian, 'Hessian multiplication cap reached', max_hessian)
      return
    end if
    done = .false.
  end function stops_here

  !> The first step of this MPRGP: the problem's better ||A|| (deferred
  !> Lanczos, dual_problem%refined_norm) before alpha_bar is used; stats
  !> again with the new alpha_bar.
  subroutine refine_norm(self, problem, x, g, stats)
    class(mprgp_t), intent(inout) :: self
    class(qp_problem_t), intent(inout) :: problem
    real(dp), intent(in) :: x(:), g(:)
    real(dp), intent(inout) :: stats(4)
    real(dp) :: a_refined
    self%norm_refined = .true.
    a_refined = problem%refined_norm()
    if (a_refined > self%a_norm) then
      self%a_norm = a_refined
      self%alpha_bar = self%alpha_scale/self%a_norm
      call split_stats(self, problem, x, g, stats)
    end if
  end subroutine refine_norm

  !> After a CG step: p <- d - beta_cg p on the free set (d = phi, or z when
  !> preconditioned), beta_cg recorded for the Ritz values. .false. (status
  !> set) when beta_cg is not finite.
  logical function conjugated(self, problem, x, d, beta_cg)
    class(mprgp_t), intent(inout) :: self
    class(qp_problem_t), intent(in) :: problem
    real(dp), intent(in) :: x(:), d(:), beta_cg
    conjugated = ieee_is_finite(beta_cg)
    if (.not. conjugated) then
      call set_status(self, qp_status_not_finite, 'non-finite CG orthogonalization coefficient', self%n_iterations)
      return
    end if
    call self%ritz%add_beta(-beta_cg)
    call conjugate(problem, x, d, beta_cg, self%p)
  end function conjugated

  !> After a preconditioned CG step: when the problem watches the condition
  !> of its preconditioned face operator, hand it the running estimate
  !> (the largest theta_max/theta_min of this solve's closed runs and of the
  !> open one); .true. when it changed its preconditioner (the caller
  !> restarts the CG direction). Collective while the problem watches.
  logical function preconditioner_switched(self, problem) result(switched)
    class(mprgp_t), intent(inout) :: self
    class(qp_problem_t), intent(inout) :: problem
    switched = .false.
    if (.not. problem%prec%watches()) return
    call problem%prec%condition(max(self%ritz%max_ratio, self%ritz%current_ratio()), switched)
    if (switched) self%n_switches = self%n_switches + 1
  end function preconditioner_switched

  !> v = R_F M_A^{-1} R_F g: the problem's preconditioner applied to the free
  !> gradient phi, restricted to the free set (0 where x_i is at its bound).
  subroutine free_direction(self, problem, x, g, v)
    class(mprgp_t), intent(inout) :: self
    class(qp_problem_t), intent(inout) :: problem
    real(dp), intent(in) :: x(:), g(:)
    real(dp), intent(inout) :: v(:)
    call preconditioned_free_gradient(problem, x, g, self%w_g, v)
    self%n_preconditioner = self%n_preconditioner + 1
  end subroutine free_direction

  !> z = R_F M_A^{-1} R_F g at x: phi (into `work`), the problem's
  !> preconditioner applied to it, and z_i = 0 where x_i is at its bound.
  !> Collective.
  subroutine preconditioned_free_gradient(problem, x, g, work, z)
    class(qp_problem_t), intent(inout) :: problem
    real(dp), intent(in) :: x(:), g(:)
    real(dp), intent(inout) :: work(:), z(:)
    integer(ip) :: i
    call gradient_part(problem, x, g, .false., work)
    call problem%prec%apply(work, z)
    do i = 1, problem%n
      if (.not. x(i) > problem%lower(i)) z(i) = 0
    end do
  end subroutine preconditioned_free_gradient

  !> Second half of an expansion step, from the half step x (at the
  !> boundary) with gradient g: x <- P(x - alpha_e phi(x)), g recomputed.
  !> Sets a status only when a step length is not finite. When the budget
  !> allows no multiplication, x stays at the half step.
  subroutine expand(self, problem, b_lin, x, g, max_hessian)
    class(mprgp_t), intent(inout) :: self
    class(qp_problem_t), intent(inout) :: problem
    real(dp), intent(in) :: b_lin(:)
    real(dp), intent(inout) :: x(:), g(:)
    integer(ip), intent(in) :: max_hessian
    real(dp) :: s(4), hi(4), lo(4), alpha_e, f_half, f_new
    integer(ip) :: n, budget

    n = problem%n
    budget = max_hessian - self%n_hessian
    if (budget < 1) return
    call gradient_part(problem, x, g, .false., self%w_phi)

    if (self%expansion_kind == expansion_optimal .and. budget >= 2) then
      call apply_hessian(self, problem, self%w_phi, self%ap)
      hi = 0
      lo = 0
      call add_dot(hi(1), lo(1), n, self%w_phi, g)
      call add_dot(hi(2), lo(2), n, self%w_phi, self%ap)
      call add_twice_cost(hi(3), lo(3), n, x, g, b_lin)
      call add_dot(hi(4), lo(4), n, self%w_phi, self%w_phi)
      call problem%reduce_sums(hi, lo, s)
      if (.not. all(ieee_is_finite(s))) then
        call set_status(self, qp_status_not_finite, 'non-finite value in the optimal expansion step', &
                        self%n_iterations)
        return
      end if
      call raise_norm(self, s(2), s(4))
      f_half = 0.5_dp*s(3)
      alpha_e = self%alpha_bar
      if (s(2) > 0) alpha_e = s(1)/s(2)
      if (.not. ieee_is_finite(alpha_e)) then
        call set_status(self, qp_status_not_finite, 'non-finite optimal expansion step length', &
                        self%n_iterations)
        return
      end if
      self%w_x(1:n) = x(1:n)
      self%w_g(1:n) = g(1:n)
      call projected_step(problem, self%w_x, alpha_e, self%w_phi, x)
      call apply_hessian(self, problem, x, g)
      call x_moved(problem, moved_to_argument)
      g(1:n) = g(1:n) - b_lin(1:n)
      hi = 0
      lo = 0
      call add_twice_cost(hi(1), lo(1), n, x, g, b_lin)
      call problem%reduce_sums(hi(1:1), lo(1:1), s(1:1))
      f_new = 0.5_dp*s(1)
      if (.not. (f_new <= f_half)) then
        ! the projected optimal step did not decrease the cost (or is NaN): use alpha_bar
        self%n_expansion_fallback = self%n_expansion_fallback + 1
        if (max_hessian - self%n_hessian >= 1) then
          call projected_step(problem, self%w_x, self%alpha_bar, self%w_phi, x)
          call apply_hessian(self, problem, x, g)
          call x_moved(problem, moved_to_argument)
          g(1:n) = g(1:n) - b_lin(1:n)
        else
          x(1:n) = self%w_x(1:n)
          g(1:n) = self%w_g(1:n)
          call x_moved(problem, moved_other)
        end if
      end if
    else
      self%w_x(1:n) = x(1:n)
      call projected_step(problem, self%w_x, self%alpha_bar, self%w_phi, x)
      call apply_hessian(self, problem, x, g)
      call x_moved(problem, moved_to_argument)
      g(1:n) = g(1:n) - b_lin(1:n)
    end if
  end subroutine expand

  !> (hi, lo) += local x^T (g - c) = 2 f(x) for g = A x - c (compensated).
  pure subroutine add_twice_cost(hi, lo, n, x, g, c)
    real(dp), intent(inout) :: hi, lo
    integer(ip), intent(in) :: n
    real(dp), intent(in) :: x(:), g(:), c(:)
    integer(ip) :: i
    do i = 1, n
      call compensated_add(hi, lo, x(i)*(g(i) - c(i)))
    end do
  end subroutine add_twice_cost

  !> (hi, lo) += local u^T v (compensated).
  pure subroutine add_dot(hi, lo, n, u, v)
    real(dp), intent(inout) :: hi, lo
    integer(ip), intent(in) :: n
    real(dp), intent(in) :: u(:), v(:)
    integer(ip) :: i
    do i = 1, n
      call compensated_add(hi, lo, u(i)*v(i))
    end do
  end subroutine add_dot

  !> res = [d^T (A d), g^T d, d^T d], global, in one reduction.
  subroutine direction_dots(problem, d, ad, g, res)
    class(qp_problem_t), intent(in) :: problem
    real(dp), intent(in) :: d(:), ad(:), g(:)
    real(dp), intent(out) :: res(3)
    real(dp) :: hi(3), lo(3)
    hi = 0
    lo = 0
    call add_dot(hi(1), lo(1), problem%n, d, ad)
    call add_dot(hi(2), lo(2), problem%n, g, d)
    call add_dot(hi(3), lo(3), problem%n, d, d)
    call problem%reduce_sums(hi, lo, res)
  end subroutine direction_dots

  !> Every search direction d gives a Rayleigh quotient d^T A d / d^T d <= ||A||
  !> for free. When one exceeds a_norm, the estimate from the caller (Lanczos
  !> or a power method, which approach ||A|| from below) was too small and the fixed
  !> expansion step alpha_bar = alpha_scale/a_norm could exceed 2/||A||, where
  !> the expansion no longer decreases the cost: raise a_norm to it. The
  !> estimate only grows, and never beyond ||A||.
  subroutine raise_norm(self, dad, dd)
    class(mprgp_t), intent(inout) :: self
    real(dp), intent(in) :: dad, dd
    real(dp) :: quotient
    if (.not. (dd > 0 .and. dad > 0)) return
    quotient = dad/dd
    if (ieee_is_finite(quotient) .and. quotient > self%a_norm) then
      self%a_norm = quotient
      self%alpha_bar = self%alpha_scale/self%a_norm
      self%n_norm_updates = self%n_norm_updates + 1
    end if
  end subroutine raise_norm

  !> y = A v, counted.
  subroutine apply_hessian(self, problem, v, y)
    class(mprgp_t), intent(inout) :: self
    class(qp_problem_t), intent(inout) :: problem
    real(dp), intent(in) :: v(:)
    real(dp), intent(out) :: y(:)
    call problem%hessian(v, y)
    self%n_hessian = self%n_hessian + 1
  end subroutine apply_hessian

  !> x <- max(x - alpha d, l), g <- g - alpha A d.
  subroutine take_step(problem, x, g, alpha, d, ad)
    class(qp_problem_t), intent(in) :: problem
    real(dp), intent(inout) :: x(:), g(:)
    real(dp), intent(in) :: alpha, d(:), ad(:)
    integer(ip) :: i
    do i = 1, problem%n
      x(i) = max(x(i) - alpha*d(i), problem%lower(i))
      g(i) = g(i) - alpha*ad(i)
    end do
  end subroutine take_step

  !> y <- max(x - alpha d, l).
  subroutine projected_step(problem, x, alpha, d, y)
    class(qp_problem_t), intent(in) :: problem
    real(dp), intent(in) :: x(:), alpha, d(:)
    real(dp), intent(inout) :: y(:)
    integer(ip) :: i
    do i = 1, problem%n
      y(i) = max(x(i) - alpha*d(i), problem%lower(i))
    end do
  end subroutine projected_step

  !> The free gradient phi(x) (`chopped` false: g where x_i > l_i) or the
  !> chopped gradient beta(x) (`chopped` true: min(g, 0) where x_i <= l_i)
  !> into v, 0 elsewhere.
  subroutine gradient_part(problem, x, g, chopped, v)
    class(qp_problem_t), intent(in) :: problem
    real(dp), intent(in) :: x(:), g(:)
    logical, intent(in) :: chopped
    real(dp), intent(inout) :: v(:)
    integer(ip) :: i
    do i = 1, problem%n
      v(i) = 0
      if (chopped) then
        if (x(i) <= problem%lower(i)) v(i) = min(g(i), 0.0_dp)
      else
        if (x(i) > problem%lower(i)) v(i) = g(i)
      end if
    end do
  end subroutine gradient_part

  !> p <- phi(x) - beta_cg p (g the gradient; or z - beta_cg p with z the
  !> restricted preconditioned gradient in place of g).
  subroutine conjugate(problem, x, g, beta_cg, p)
    class(qp_problem_t), intent(in) :: problem
    real(dp), intent(in) :: x(:), g(:), beta_cg
    real(dp), intent(inout) :: p(:)
    integer(ip) :: i
    do i = 1, problem%n
      if (x(i) > problem%lower(i)) then
        p(i) = g(i) - beta_cg*p(i)
      else
        p(i) = -beta_cg*p(i)
      end if
    end do
  end subroutine conjugate

  !> Global [phi^T phi, beta^T beta, phit^T phi, phi^T v] in one reduction
  !> (the last entry 0 without v).
  !> phit uses alpha_bar; it is formed without dividing by alpha_bar unless
  !> the result is below phi_i (no overflow).
  subroutine split_stats(self, problem, x, g, stats, v)
    class(mprgp_t), intent(in) :: self
    class(qp_problem_t), intent(in) :: problem
    real(dp), intent(in) :: x(:), g(:)
    real(dp), intent(out) :: stats(4)
    real(dp), intent(in), optional :: v(:)
    real(dp) :: gi, d, abar, hi(4), lo(4)
    integer(ip) :: i

    abar = self%alpha_bar
    hi = 0
    lo = 0
    do i = 1, problem%n
      gi = g(i)
      if (x(i) > problem%lower(i)) then
        call compensated_add(hi(1), lo(1), gi*gi)
        if (gi > 0 .and. problem%lower(i) > no_lower_bound) then
          d = x(i) - problem%lower(i)
          if (d < abar*gi) then
            call compensated_add(hi(3), lo(3), (d/abar)*gi)
          else
            call compensated_add(hi(3), lo(3), gi*gi)
          end if
        else
          call compensated_add(hi(3), lo(3), gi*gi)
        end if
      else if (gi < 0) then
        call compensated_add(hi(2), lo(2), gi*gi)
      end if
    end do
    if (present(v)) then
      do i = 1, problem%n
        if (x(i) > problem%lower(i)) call compensated_add(hi(4), lo(4), g(i)*v(i))
      end do
    end if
    call problem%reduce_sums(hi, lo, stats)
  end subroutine split_stats

  !> Global z^T v over the free set (x_i > l_i), one reduction (compensated).
  real(dp) function free_dot(problem, x, z, v)
    class(qp_problem_t), intent(in) :: problem
    real(dp), intent(in) :: x(:), z(:), v(:)
    real(dp) :: hi(1), lo(1), res(1)
    integer(ip) :: i
    hi = 0
    lo = 0
    do i = 1, problem%n
      if (x(i) > problem%lower(i)) call compensated_add(hi(1), lo(1), z(i)*v(i))
    end do
    call problem%reduce_sums(hi, lo, res)
    free_dot = res(1)
  end function free_dot

  !> The largest alpha with x - alpha p >= l (global); huge(1.0_dp) when no
  !> bound limits the step.
  real(dp) function feasible_step(problem, x, p)
    class(qp_problem_t), intent(in) :: problem
    real(dp), intent(in) :: x(:), p(:)
    real(dp) :: a, d
    integer(ip) :: i
    a = huge(1.0_dp)
    do i = 1, problem%n
      if (p(i) > 0 .and. problem%lower(i) > no_lower_bound) then
        d = x(i) - problem%lower(i)
        if (d <= 0) then
          a = 0
        else if (p(i) >= 1) then
          a = min(a, d/p(i))
        else if (d < huge(1.0_dp)*p(i)) then
          a = min(a, d/p(i))       ! p(i) < 1: the test above cannot overflow, nor can d/p(i)
        end if
      end if
    end do
    feasible_step = problem%global_min(a)
  end function feasible_step

  subroutine set_status(self, status, what, number)
    class(mprgp_t), intent(inout) :: self
    integer, intent(in) :: status
    character(len=*), intent(in) :: what
    integer(ip), intent(in) :: number
    character(len=qp_message_len) :: buf
    select case (status)
    case (qp_status_converged)
      write (buf, '(a,a,i0,a)') what, ' after ', number, ' iterations'
    case (qp_status_max_hessian)
      write (buf, '(3a,i0,a,es10.3,a,es10.3,a,i0,a,i0)') 'not converged: ', what, ' (max_hessian = ', number, &
        '), ||g^P|| = ', self%gp_norm, ', smallest ', self%best_gp_norm, ' at iteration ', self%n_best, ' of ', &
        self%n_iterations
    case default
      write (buf, '(3a,i0)') 'not converged: ', what, ' at iteration ', number
    end select
    self%status = status
    self%message = buf
  end subroutine set_status

  subroutine mprgp_summary(self)
    class(mprgp_t), intent(in) :: self
    character(len=300) :: buf
    call log_message('MPRGP: '//trim(self%message))
    write (buf, '(a,i0,a,i0,a,i0,a,i0,a,i0,a,i0,a,es10.3)') '  iterations ', self%n_iterations, ' (cg ', &
      self%n_cg, ', expansion ', self%n_expansion, ', proportioning ', self%n_proportioning, &
      ', expansion fallbacks ', self%n_expansion_fallback, '), Hessian multiplications ', self%n_hessian, &
      ', ||g^P|| = ', self%gp_norm
    call log_message(buf)
    if (self%n_norm_updates > 0) then
      write (buf, '(a,es10.3,a,i0,a)') '  ||A|| estimate raised to ', self%a_norm, ' by Rayleigh quotients (', &
        self%n_norm_updates, ' times)'
      call log_message(buf)
    end if
  end subroutine mprgp_summary

  !> ap = A p for the direction p (`dir` in messages), p^T A p and the step
  !> length alpha = g^T p / p^T A p of a CG or proportioning step; false,
  !> with the status set, when p^T A p or g^T p is not finite (or `finite` is
  !> false), when p^T A p <= 0, or when alpha is not finite. `dots` names the
  !> values of the first test, `step` the step in the last message.
  logical function step_along_p(self, problem, g, finite, dir, dots, step, pap, alpha) result(ok)
    class(mprgp_t), intent(inout) :: self
    class(qp_problem_t), intent(inout) :: problem
    real(dp), intent(in) :: g(:)
    logical, intent(in) :: finite
    character(len=*), intent(in) :: dir, dots, step
    real(dp), intent(out) :: pap, alpha
    real(dp) :: pair(3)
    ok = .false.
    alpha = 0
    call apply_hessian(self, problem, self%p, self%ap)
    call direction_dots(problem, self%p, self%ap, g, pair)
    pap = pair(1)
    if (.not. (ieee_is_finite(pap) .and. ieee_is_finite(pair(2)) .and. finite)) then
      call set_status(self, qp_status_not_finite, 'non-finite value in '//dots, self%n_iterations)
      return
    end if
    if (pap <= 0) then
      call set_status(self, qp_status_breakdown, dir//'^T A '//dir//' <= 0 (Hessian not positive definite?)', &
                      self%n_iterations)
      return
    end if
    alpha = pair(2)/pap
    if (.not. ieee_is_finite(alpha)) then
      call set_status(self, qp_status_not_finite, 'non-finite '//step//' step length', self%n_iterations)
      return
    end if
    call raise_norm(self, pap, pair(3))
    ok = .true.
  end function step_along_p

  !> Allocate v with length n unless it already has it (no work inside loops);
  !> also SMALBE's work vectors.
  subroutine ensure_size(v, n)
    real(dp), allocatable, intent(inout) :: v(:)
    integer(ip), intent(in) :: n
    if (allocated(v)) then
      if (size(v) == n) return
      deallocate (v)
    end if
    allocate (v(n))
    v = 0
  end subroutine ensure_size
end module mprgp
