!> The active-set polish of SMALBE-M: an optional outer-step plug-in that
!> SMALBE holds (smalbe_t%polish). Once the active set (the x_i at their
!> bound) has not changed for `window` outer iterations whose inner solve
!> made a step, the equality constrained QP on that face (x_A = l_A, C x = 0)
!> is solved by PCPG (module face_solve) and SMALBE's pair (x, mu) replaced
!> by its solution and face multiplier; the gradient follows (one more
!> product if x had to be projected onto the bounds). Its products count in
!> SMALBE's n_hessian. When the active set was the right one, the next outer
!> iteration's test accepts the pair at once; otherwise SMALBE goes on from
!> it (a feasible warm start: SMALBE's Lagrangian test is not applied to that
!> step). Needs a problem with a face solver (qp_problem: the part `face`).
!>
!> One polish is up to `rounds` face solves (polish_step): a face solve whose
!> x leaves a bound on a free row is projected and the new face solved at
!> once; with `release` active rows whose gradient has the wrong sign are
!> also freed (primal-dual active set rounds); with `loose` > 0 a face solve
!> that may be followed by another round stops at its loose check when the
!> set would change beyond `loose_margin` times its residual (face_solve); with `predict` > 0 a round that projected
!> at least that many rows and released none also makes as many of the free
!> rows nearest their bound active (predicted_rows); with `release_share` > 0
!> the first round of a polish releases only the wrong-sign rows whose
!> gradient is at least that share of the largest (released_rows).
!> At most once per distinct active set and `max_count` times per solve.
!> `settle` > 0: an outer iteration counts as settled when the set changed on
!> at most that fraction of the bounded rows; a polish given up at its first
!> face then does not count toward max_count, and the next waits until the
!> products have doubled. Each face solve at most polish_steps and at most
!> max(polish_min_steps, the products spent so far) CG steps, to
!> polish_target times the outer test's bound; a face solve whose first
!> steps are too slow for that budget is given up and the iterate restored
!> (face_solve, `aborted`), unless a loose check has found no change on it
!> (a trusted face: never given up, at most polish_trusted_steps steps).
!> With `force_step` SMALBE's inner solve right after a polish takes at least
!> one step unless the outer test accepts the polished pair
!> (docs/THEORY.md "Polish robustness").
!> `first`: before SMALBE's first outer iteration, the polish rounds from the
!> face on which every bounded row is at its bound, where the problem knows
!> its equality rows alone to fix it (face%regular()).
!> Timer 'polish' (a part of 'solve').
module active_set_polish
  use kinds, only: dp, ip, i8, name_len, MPI_INT_IP, MPI_INT_I8
  use logger, only: log_message
  use text, only: counted
  use timers, only: timer_start, timer_stop
  use report_sink, only: report_sink_t
  use qp_problem, only: qp_problem_t, no_lower_bound, x_moved, moved_other, moved_to_argument
  use face_solve, only: face_polish_t, free_rows, face_changes
  use outer_step, only: outer_step_t, outer_state_t
  use mpi_f08, only: MPI_Allreduce, MPI_SUM, MPI_MAX, MPI_Comm_rank, MPI_DOUBLE_PRECISION, MPI_IN_PLACE
  use settings_base, only: settings_t
  implicit none
  private

  public :: polish_cycling, face_signature, predicted_rows, released_rows, revisit_of_cut_short

  !> each face solve at most polish_steps CG steps, stopped at polish_target times the outer
  !> test's bound of g^P
  integer(ip), parameter, public :: polish_steps = 500
  integer(ip), parameter, public :: polish_min_steps = 30
  real(dp), parameter, public :: polish_target = 0.5_dp
  !> a face solve whose loose check found no change (a trusted face) may take this many CG steps
  integer(ip), parameter, public :: polish_trusted_steps = 500

  !> The settings of the polish (`&solver` variables polish_*, docs/INPUT.md):
  !> the one home of their defaults (the program's), ranges and echo.
  type, extends(settings_t), public :: polish_settings_t
    !> > 0: polish once the active set has not changed for this many outer iterations; 0: never
    integer(ip) :: window = 1
    integer(ip) :: rounds = 8                  !< face solves per polish at most
    integer(ip) :: max_count = 3               !< polishes per solve at most (the polish first aside)
    logical :: release = .true.                !< release wrong-sign active rows within the polish
    !> settled: the active set changed on at most this fraction of the bounded rows (0: not at all)
    real(dp) :: settle = 0.15_dp
    !> > 0: a face solve that may be followed by another round pauses once its residual is this
    !> many times its start value and stops there when the active set would change
    real(dp) :: loose = 0.5_dp
    !> the inner solve right after a polish takes a step unless the outer test accepts the pair
    logical :: force_step = .true.
    !> > 0: after a round that projects k >= predict free rows and releases none, the k other free
    !> rows of smallest slack (at most half of them) become active too; 0: off
    integer(ip) :: predict = 100
    !> in [0, 1): the first release of a polish frees only the wrong-sign rows of at least this
    !> share of the largest wrong-sign weighted gradient; 0: every one at once
    real(dp) :: release_share = 0.5_dp
    !> polish before the first outer iteration from every bounded row at its bound
    logical :: first = .true.
    !> >= 0: a loose check counts a row only when its violation exceeds this many times the
    !> face residual's measure there (0: every violation)
    real(dp) :: loose_margin = 0.3_dp
  contains
    procedure :: check => polish_settings_check
    procedure :: group => polish_settings_group
    procedure :: variables => polish_settings_variables
    procedure :: read_namelist => polish_settings_read
    procedure :: write_namelist => polish_settings_write
  end type polish_settings_t

  !> The plug-in: its settings, its face solve, its counters (of the last
  !> SMALBE solve) and the state it keeps between outer iterations.
  type, extends(outer_step_t), public :: active_set_polish_t
    type(polish_settings_t) :: settings
    type(face_polish_t) :: face                !< the face solve (its counters: the last face solve)
    logical :: monitor = .false.               !< log each polish (SMALBE's monitor)
    logical :: active = .false.                !< the current solve polishes (window > 0, a face solver)
    integer(ip) :: n_polish = 0                !< polishes of the last solve
    integer(ip) :: n_rounds = 0                !< face solves of those (rounds after projections included)
    integer(ip) :: n_products = 0              !< Hessian products of those (included in SMALBE's n_hessian)
    integer(ip) :: n_steps = 0                 !< their CG steps
    integer(ip) :: n_exact = 0                 !< polishes after which the outer test held at once
    integer(ip) :: n_aborted = 0               !< face solves given up (too slow), the iterate restored
    integer(ip) :: n_released = 0              !< active rows released in all (release)
    integer(ip) :: n_predicted = 0             !< rows made active by the prediction in all
    integer(ip) :: n_forced = 0                !< SMALBE inner solves whose bound was cut to force a step
    integer(ip) :: n_faces_reused = 0          !< face solves on the face before, its matrices reused
    integer(ip) :: n_recycled = 0              !< kept CG directions of earlier runs their starts used
    logical :: polished_first = .false.        !< the last solve started with a polish that was not given up
    !> the next `first` starts from the face of the given x (its free rows: a warm start),
    !> not from every bounded row at its bound; `first` clears it
    logical :: warm_face = .false.
    logical, allocatable :: free_now(:)        !< the free rows of the current x
    logical, allocatable, private :: free_prev(:)
    real(dp), allocatable, private :: x_prev(:), g_prev(:), muhat_prev(:)   !< the pair to go back to
    integer(ip), private :: n_stable = 0       !< outer iterations with the same active set
    integer(ip), private :: n_given_up = 0     !< polishes given up at their first face (settle > 0)
    integer(ip), private :: hessian_wait = 0   !< the next polish waits for this many products
    real(dp), private :: settle_limit = 0      !< settle times the bounded rows
    logical, private :: polished_set = .false. !< the current active set was polished
  contains
    procedure :: reset => polish_reset
    procedure :: start
    procedure :: first
    procedure :: after_outer
    procedure :: due
    procedure :: step
    procedure :: summary
    procedure :: report
  end type active_set_polish_t

contains

  !> The first setting out of its range: `variable` its name ('' if none),
  !> `rule` the allowed values, `got` the value.
  subroutine polish_settings_check(self, variable, rule, got)
    class(polish_settings_t), intent(in) :: self
    character(len=:), allocatable, intent(out) :: variable, rule, got
    character(len=32) :: buf
    variable = ''
    rule = ''
    got = ''
    buf = ''
    if (self%window < 0) then
      variable = 'polish_window'
      rule = 'must be >= 0 (0: off)'
      write (buf, '(i0)') self%window
    else if (self%rounds < 1) then
      variable = 'polish_rounds'
      rule = 'must be >= 1'
      write (buf, '(i0)') self%rounds
    else if (self%max_count < 0) then
      variable = 'polish_max'
      rule = 'must be >= 0'
      write (buf, '(i0)') self%max_count
    else if (.not. (self%settle >= 0 .and. self%settle < 1)) then
      variable = 'polish_settle'
      rule = 'must be in [0, 1) (0: no change)'
      write (buf, '(g0.6)') self%settle
    else if (.not. (self%loose >= 0 .and. self%loose < 1)) then
      variable = 'polish_loose'
      rule = 'must be in [0, 1) (0: off)'
      write (buf, '(g0.6)') self%loose
    else if (self%predict < 0) then
      variable = 'polish_predict'
      rule = 'must be >= 0 (0: off)'
      write (buf, '(i0)') self%predict
    else if (.not. (self%loose_margin >= 0 .and. self%loose_margin <= huge(1.0_dp))) then
      variable = 'polish_loose_margin'
      rule = 'must be >= 0 (0: every violation counts)'
      write (buf, '(g0.6)') self%loose_margin
    else if (.not. (self%release_share >= 0 .and. self%release_share < 1)) then
      variable = 'polish_release_share'
      rule = 'must be in [0, 1) (0: release every wrong-sign row at once)'
      write (buf, '(g0.6)') self%release_share
    end if
    got = trim(adjustl(buf))
  end subroutine polish_settings_check

  !> The namelist group of these variables.
  function polish_settings_group(self) result(name)
    class(polish_settings_t), intent(in) :: self
    character(len=:), allocatable :: name
    name = 'solver'
  end function polish_settings_group

  !> The names of the namelist variables (those of read_namelist).
  subroutine polish_settings_variables(self, names)
    class(polish_settings_t), intent(in) :: self
    character(len=name_len), allocatable, intent(out) :: names(:)
    names = [character(len=name_len) :: 'polish_window', 'polish_rounds', 'polish_max', &
        'polish_release', 'polish_settle', 'polish_loose', 'polish_predict', 'polish_release_share', &
        'polish_first', 'polish_loose_margin']
  end subroutine polish_settings_variables

  !> Read the settings' variables from the namelist group text `group`
  !> ('&solver ... /', only this component's variables).
  subroutine polish_settings_read(self, group, status, msg)
    class(polish_settings_t), intent(inout) :: self
    character(len=*), intent(in) :: group
    integer, intent(out) :: status
    character(len=*), intent(out) :: msg
    integer(ip) :: polish_window, polish_rounds, polish_predict, polish_max
    real(dp) :: polish_settle, polish_loose, polish_release_share, polish_loose_margin
    logical :: polish_release, polish_first
    namelist /solver/ polish_window, polish_rounds, polish_max, polish_release, polish_settle, polish_loose, &
      polish_predict, polish_release_share, polish_first, polish_loose_margin
    polish_max = self%max_count
    polish_window = self%window; polish_rounds = self%rounds; polish_release = self%release
    polish_settle = self%settle; polish_loose = self%loose; polish_predict = self%predict
    polish_release_share = self%release_share; polish_first = self%first
    polish_loose_margin = self%loose_margin
    read (group, nml=solver, iostat=status, iomsg=msg)
    if (status /= 0) return
    self%max_count = polish_max
    self%window = polish_window; self%rounds = polish_rounds; self%release = polish_release
    self%settle = polish_settle; self%loose = polish_loose; self%predict = polish_predict
    self%release_share = polish_release_share; self%first = polish_first
    self%loose_margin = polish_loose_margin
  end subroutine polish_settings_read

  !> Write the settings as the namelist group '&solver ... /'.
  subroutine polish_settings_write(self, lines, status, msg)
    class(polish_settings_t), intent(in) :: self
    character(len=*), intent(out) :: lines(:)
    integer, intent(out) :: status
    character(len=*), intent(out) :: msg
    integer(ip) :: polish_window, polish_rounds, polish_predict, polish_max
    real(dp) :: polish_settle, polish_loose, polish_release_share, polish_loose_margin
    logical :: polish_release, polish_first
    namelist /solver/ polish_window, polish_rounds, polish_max, polish_release, polish_settle, polish_loose, &
      polish_predict, polish_release_share, polish_first, polish_loose_margin
    polish_max = self%max_count
    polish_window = self%window; polish_rounds = self%rounds; polish_release = self%release
    polish_settle = self%settle; polish_loose = self%loose; polish_predict = self%predict
    polish_release_share = self%release_share; polish_first = self%first
    polish_loose_margin = self%loose_margin
    lines = ''
    write (lines, nml=solver, delim='quote', iostat=status, iomsg=msg)
  end subroutine polish_settings_write

  !> Zero the counters of the last solve.
  subroutine polish_reset(self)
    class(active_set_polish_t), intent(inout) :: self
    self%n_polish = 0
    self%n_rounds = 0
    self%n_products = 0
    self%n_steps = 0
    self%n_exact = 0
    self%n_aborted = 0
    self%n_released = 0
    self%n_predicted = 0
    self%n_forced = 0
    self%n_faces_reused = 0
    self%n_recycled = 0
    self%polished_first = .false.
  end subroutine polish_reset

  !> Before a solve: zero the counters, decide whether this solve polishes,
  !> and set up the tracking of the active set; with st%warm the polish
  !> first starts from the face of the given x. Collective.
  subroutine start(self, problem, st)
    class(active_set_polish_t), intent(inout) :: self
    class(qp_problem_t), intent(inout) :: problem
    type(outer_state_t), intent(inout) :: st
    integer(ip) :: n, local, n_bounded
    integer :: ierr
    n = problem%n
    self%monitor = st%monitor
    self%face%monitor%on = st%monitor
    call self%reset()
    self%active = self%settings%window > 0 .and. allocated(problem%face)
    if (allocated(self%free_now)) deallocate (self%free_now, self%free_prev)
    allocate (self%free_now(n), self%free_prev(n))
    self%free_prev = .true.
    self%n_stable = 0
    self%polished_set = .false.
    self%n_given_up = 0
    self%hessian_wait = 0
    self%settle_limit = 0
    if (self%active .and. self%settings%settle > 0) then
      local = count(problem%lower(1:n) > no_lower_bound, kind=ip)
      call MPI_Allreduce(local, n_bounded, 1, MPI_INT_IP, MPI_SUM, problem%comm, ierr)
      self%settle_limit = self%settings%settle*n_bounded
    end if
    self%warm_face = st%warm
  end subroutine start

  !> The polish first (settings%first): from the face on which every bounded
  !> row is at its bound (x moved there, gradient unknown), the polish rounds
  !> (a primal-dual active set start: the first round releases the rows whose
  !> gradient has the wrong sign); only where the equality rows alone fix the
  !> problem (the face is regular). st%ran: it ran; st%restored: given up in
  !> its first round (x and g as before, SMALBE starts without a gradient).
  subroutine first(self, problem, x, st)
    class(active_set_polish_t), intent(inout) :: self
    class(qp_problem_t), intent(inout) :: problem
    real(dp), intent(inout) :: x(:)
    type(outer_state_t), intent(inout) :: st
    integer(ip) :: n
    st%restored = .false.
    st%ran = self%active .and. self%settings%first .and. st%max_hessian > 2
    if (st%ran) st%ran = problem%face%regular()
    if (.not. st%ran) then
      self%warm_face = .false.
      return
    end if
    n = problem%n
    if (self%warm_face) then
      ! a warm start: its own face (rows above their bound stay free)
      call self%face%monitor%note('polish first: from the face of the warm start')
      self%free_now(1:n) = .not. problem%lower(1:n) > no_lower_bound .or. x(1:n) > problem%lower(1:n)
    else
      call self%face%monitor%note('polish first: from the face with every contact row at its bound')
      self%free_now(1:n) = .not. problem%lower(1:n) > no_lower_bound
    end if
    self%warm_face = .false.
    x(1:n) = merge(x(1:n), problem%lower(1:n), self%free_now(1:n))
    st%g(1:n) = 0
    st%outer = 0
    call self%step(problem, x, st)
    self%polished_first = .not. st%restored
  end subroutine first

  !> After outer iteration st%outer (x its result, st%moved: its inner solve
  !> made a step): whether the active set changed (on more than settle_limit
  !> rows). Collective.
  subroutine after_outer(self, problem, x, st)
    class(active_set_polish_t), intent(inout) :: self
    class(qp_problem_t), intent(inout) :: problem
    real(dp), intent(inout) :: x(:)
    type(outer_state_t), intent(inout) :: st
    integer(ip) :: local, changes
    integer :: ierr
    if (.not. self%active) return
    call free_rows(problem, x, self%free_now)
    local = count(self%free_now .neqv. self%free_prev, kind=ip)
    call MPI_Allreduce(local, changes, 1, MPI_INT_IP, MPI_SUM, problem%comm, ierr)
    if (st%outer == 1 .or. changes > self%settle_limit) then
      self%n_stable = 0
      self%polished_set = .false.
    else
      if (changes > 0) self%polished_set = .false.
      if (st%moved) self%n_stable = self%n_stable + 1      ! only outer iterations that moved x count
    end if
    self%free_prev = self%free_now
  end subroutine after_outer

  !> A polish is due: the active set has been stable for `window` outer
  !> iterations, was not polished, and the budget allows one. Not when every
  !> bounded row is at its bound, unless the problem knows the equality rows
  !> alone to give a regular C_E C_E^T (else C_F C_F^T may be singular, e.g.
  !> a body held by its contact only). Collective.
  logical function due(self, problem, x, st)
    class(active_set_polish_t), intent(inout) :: self
    class(qp_problem_t), intent(inout) :: problem
    real(dp), intent(inout) :: x(:)
    type(outer_state_t), intent(inout) :: st
    integer(ip) :: local, n_free_bounded
    integer :: ierr
    due = .false.
    if (.not. self%active) return
    if (ready()) then
      local = count(self%free_now .and. problem%lower(1:problem%n) > no_lower_bound, kind=ip)
      call MPI_Allreduce(local, n_free_bounded, 1, MPI_INT_IP, MPI_SUM, problem%comm, ierr)
      if (n_free_bounded == 0 .and. problem%count_at_bound(x) > 0) then
        if (.not. problem%face%regular()) self%polished_set = .true.
      end if
    end if
    due = ready()
  contains
    logical function ready()
      ready = self%n_stable >= self%settings%window .and. .not. self%polished_set .and. &
              self%n_polish - self%n_given_up < self%settings%max_count .and. &
              st%n_hessian >= self%hessian_wait .and. st%max_hessian - st%n_hessian > 2
    end function ready
  end function due

  !> One polish after outer iteration st%outer (0: the polish first) of
  !> SMALBE's pair (x, st%muhat) with gradient st%g, linear term st%b_lin =
  !> b - C^T mu and st%ct_mu = C^T mu. st%restored: the first face solve was
  !> given up (x, g, muhat as before). Collective.
  subroutine step(self, problem, x, st)
    class(active_set_polish_t), intent(inout) :: self
    class(qp_problem_t), intent(inout) :: problem
    real(dp), intent(inout) :: x(:)
    type(outer_state_t), intent(inout) :: st
    call polish_step(self, problem, x, st)
    self%free_prev = self%free_now
    self%n_stable = 0
    self%polished_set = .true.
    if (self%face%aborted .and. self%settings%settle > 0) then
      ! with the early trigger a face given up (too slow for the budget of an early polish,
      ! ill-conditioned faces) does not use up a polish, and the same set may be polished
      ! again; the next polish waits until the products have doubled (its budget grows with
      ! them), which bounds the waste by the products spent
      self%n_given_up = self%n_given_up + 1
      self%hessian_wait = 2*st%n_hessian
      self%polished_set = .false.
    end if
  end subroutine step

  !> The polish's line of SMALBE's monitor summary (n_forced: SMALBE's inner
  !> solves made to take a step after a polish).
  subroutine summary(self)
    class(active_set_polish_t), intent(in) :: self
    character(len=300) :: buf
    if (self%n_polish == 0) return
    write (buf, '(9a,i0,a,i0,a)') '  polish: ', counted(self%n_polish, 'polish', 'polishes'), ' (', &
      counted(self%n_rounds, 'face solve'), ', ', counted(self%n_steps, 'CG step'), ', ', &
      counted(self%n_products, 'Hessian multiplication'), '; accepted at once ', self%n_exact, ', given up ', &
      self%n_aborted, ')'
    if (self%settings%release) buf = trim(buf)//', released '//counted(self%n_released, 'row')//' from their bound'
    if (self%n_predicted > 0) buf = trim(buf)//', predicted '//counted(self%n_predicted, 'row')//' at their bound'
    if (self%n_forced > 0) buf = trim(buf)//'; '//counted(self%n_forced, 'inner solve')// &
      ' after a polish made to take a step'
    if (self%n_faces_reused > 0) buf = trim(buf)//'; '//counted(self%n_faces_reused, 'face')// &
      ' of the face before (matrices reused)'
    if (self%n_recycled > 0) buf = trim(buf)//'; Galerkin starts on '// &
      counted(self%n_recycled, 'kept direction')
    call log_message(buf)
  end subroutine summary

  !> The polish's fields of the solver's report section (report.json, docs/OUTPUT.md).
  subroutine report(self, sink)
    class(active_set_polish_t), intent(in) :: self
    class(report_sink_t), intent(inout) :: sink
    call sink%put_long('polish_window', int(self%settings%window, i8))
    call sink%put_long('polish_count', int(self%n_polish, i8))
    call sink%put_long('polish_hessian', int(self%n_products, i8))
    call sink%put_long('polish_cg_steps', int(self%n_steps, i8))
    call sink%put_long('polish_accepted', int(self%n_exact, i8))
    call sink%put_long('polish_face_solves', int(self%n_rounds, i8))
    call sink%put_long('polish_released', int(self%n_released, i8))
    call sink%put_long('polish_predicted', int(self%n_predicted, i8))
    call sink%put_long('polish_faces_reused', int(self%n_faces_reused, i8))
    call sink%put_long('polish_recycled_directions', int(self%n_recycled, i8))
    ! whether the solve started with a polish that was not given up
    call sink%put_logical('polish_first_used', self%polished_first)
    ! the condition estimate of the face CG runs (null: none of 2 steps)
    if (self%face%ritz%n_runs > 0) then
      call sink%put_real('polish_condition_estimate', self%face%ritz%max_ratio)
    else
      call sink%put_null('polish_condition_estimate')
    end if
  end subroutine report

  !> The face solve on the free rows free_now, then (x, muhat, g) handed back
  !> to SMALBE. When the face solution would change the active set, the new
  !> face is solved at once, at most settings%rounds face solves: free rows
  !> below their bound are projected onto it (made active; a primal
  !> active-set step) and, with settings%release, active rows whose gradient
  !> has the wrong sign are made free (a primal-dual active set step; the
  !> next face: next_face). Safeguard against cycling (polish_cycling): a
  !> round that would go back to the free set of an earlier round of this
  !> polish (compared by face_signature), or, from the third round on, a
  !> round with strictly more set changes than the previous one ends the
  !> polish (SMALBE goes on from the feasible pair). Equal change counts on
  !> new sets go on (a polish may change 24, 4, 4, ... rows on its way to
  !> the solution's face). Collective.
  subroutine polish_step(self, problem, x, st)
    class(active_set_polish_t), intent(inout) :: self
    class(qp_problem_t), intent(inout) :: problem
    real(dp), intent(inout) :: x(:)
    type(outer_state_t), intent(inout) :: st
    integer(ip) :: n, i, budget, budget_trusted, counts(2), rounds, n_changes, prev_changes
    real(dp) :: change_tol, loose
    logical :: again, cycling, revisited, g_known, revisit_used, reused
    logical, allocatable :: cut_short(:)
    integer(i8), allocatable :: signatures(:, :)
    character(len=400) :: buf
    associate (outer => st%outer, g => st%g, muhat => st%muhat, b_lin => st%b_lin, ct_mu => st%ct_mu, &
               tol_gp => st%tol_gp, per_component => st%per_component, n_hessian => st%n_hessian, &
               max_hessian => st%max_hessian, n_preconditioner => st%n_preconditioner, restored => st%restored)
    call timer_start('polish')
    restored = .false.
    n = problem%n
    call grow(self%x_prev, n)
    call grow(self%g_prev, n)
    call grow(self%muhat_prev, size(muhat))
    again = .true.
    self%n_polish = self%n_polish + 1
    rounds = 0
    prev_changes = huge(1_ip)
    allocate (signatures(2, self%settings%rounds + 1), cut_short(self%settings%rounds + 1))
    cut_short = .false.
    revisit_used = .false.
    signatures(:, 1) = face_signature(problem, self%free_now)
    ! without release, the wrong-sign active rows do not change the face (not counted by the loose check)
    change_tol = merge(tol_gp, huge(1.0_dp), self%settings%release)
    g_known = .false.
    do while (again)
      rounds = rounds + 1
      ! at most as many steps as the solve has spent so far (at least polish_min_steps):
      ! a face that CG solves slowly (inner-bound cases) costs at most twice the products
      budget = min(polish_steps, max(polish_min_steps, n_hessian), max_hessian - n_hessian - 2)
      ! a face whose loose check found no change: the fixed cap (face_solve, `trusted`)
      budget_trusted = min(polish_trusted_steps, max_hessian - n_hessian - 2)
      ! the pair to go back to when the face solve gives up (too slow for its budget)
      self%x_prev(1:n) = x(1:n)
      self%g_prev(1:n) = g(1:n)
      self%muhat_prev = muhat
      ! the loose check only where another round may follow
      loose = 0
      if (rounds < self%settings%rounds) loose = self%settings%loose
      call problem%face%init(self%free_now, reused)
      if (reused) self%n_faces_reused = self%n_faces_reused + 1
      ! after a round that only released rows, x is that round's face solution unchanged (on the new
      ! face too) and its gradient is known: the Lagrangian gradient without the multiplier term
      if (g_known) g(1:n) = g(1:n) - ct_mu(1:n)
      self%face%monitor%base = n_hessian
      self%face%monitor%polish = self%n_polish
      self%face%monitor%round = rounds
      call self%face%run(problem, self%free_now, x, g, muhat, polish_target*tol_gp, per_component, budget, loose, &
                         change_tol, budget_trusted, g_known, self%settings%loose_margin)
      call problem%face%release()
      cut_short(rounds) = self%face%stopped_loose
      self%n_rounds = self%n_rounds + 1
      self%n_recycled = self%n_recycled + self%face%recycle%n_used
      n_hessian = n_hessian + self%face%n_hessian
      self%n_products = self%n_products + self%face%n_hessian
      self%n_steps = self%n_steps + self%face%n_steps
      n_preconditioner = n_preconditioner + self%face%n_precondition
      if (self%face%aborted) then
        x(1:n) = self%x_prev(1:n)
        g(1:n) = self%g_prev(1:n)
        muhat = self%muhat_prev
        call x_moved(problem, moved_other)
        restored = rounds == 1
        ! x_prev is the previous round's x after the change of the face (projected): the
        ! gradient saved with it is that of the x before the projection, so recompute it
        ! (b_lin and ct_mu still belong to muhat_prev, the previous round's face multiplier)
        if (rounds > 1) call fresh_gradient(self, problem, x, st)
        self%n_aborted = self%n_aborted + 1
        write (buf, '(a,i0,a,i0,a)') 'after outer ', outer, ': given up after ', self%face%n_steps, &
          ' CG steps (too slow for its budget), iterate restored'
        call self%face%monitor%round_line(self%n_polish, rounds, n_hessian, self%face%measure, &
                                          polish_target*tol_gp, trim(buf))
        exit
      end if
      ! the gradient of the Lagrangian with the face multiplier
      call problem%eq%apply_t(muhat, ct_mu)
      do i = 1, n
        b_lin(i) = problem%b(i) - ct_mu(i)
        g(i) = g(i) + ct_mu(i)
      end do
      ! free rows below their bound (projected: MPRGP needs a feasible x), and
      ! active rows whose gradient has the wrong sign (beyond the test's bound)
      counts = face_changes(problem, self%free_now, x, g, tol_gp)
      n_changes = counts(1)
      if (self%settings%release) n_changes = n_changes + counts(2)
      cycling = self%settings%release .and. polish_cycling(rounds, n_changes, prev_changes, .false.)
      prev_changes = n_changes
      if (self%monitor) call log_round(self, outer, counts, tol_gp, rounds, cycling, n_hessian)
      again = n_changes > 0 .and. rounds < self%settings%rounds .and. .not. cycling .and. &
              max_hessian - n_hessian > 2 .and. .not. self%face%breakdown
      if (again) then
        call next_face(self, problem, x, g, tol_gp, counts, rounds, signatures, cut_short, revisit_used, g_known, &
                       revisited)
        if (revisited) then
          call self%face%monitor%note('polish: the next face is that of an earlier round: back to SMALBE')
          if (counts(1) > 0) call fresh_gradient(self, problem, x, st)
          exit
        end if
      else if (counts(1) > 0) then
        ! the gradient at the projected x for the inner MPRGP
        call problem%project(x)
        call x_moved(problem, moved_other)
        call fresh_gradient(self, problem, x, st)
      end if
    end do
    call timer_stop('polish')
    end associate
  end subroutine polish_step

  !> The next face of a polish after round `rounds` (counts: face_changes of
  !> its solution): released rows free (the first round: only those of the
  !> strongest wrong sign, release_share), projected rows active, with the
  !> prediction (predict) as many more; free_now becomes the new face.
  !> `revisited`: that face is one of an earlier round (a cycle; one revisit
  !> of a face cut short at a loose check is allowed per polish). Collective.
  subroutine next_face(self, problem, x, g, tol_gp, counts, rounds, signatures, cut_short, revisit_used, g_known, &
                       revisited)
    class(active_set_polish_t), intent(inout) :: self
    class(qp_problem_t), intent(inout) :: problem
    real(dp), intent(inout) :: x(:)
    real(dp), intent(in) :: g(:), tol_gp
    integer(ip), intent(in) :: counts(2), rounds
    integer(i8), intent(inout) :: signatures(:, :)
    logical, intent(in) :: cut_short(:)
    logical, intent(inout) :: revisit_used
    logical, intent(out) :: g_known, revisited
    logical, allocatable :: release(:)
    integer(ip) :: n, n_released, n_predicted
    real(dp) :: share
    character(len=400) :: buf
    n = problem%n
    allocate (release(n))
    ! the new face: projected rows active, released rows free
    release = .false.
    if (self%settings%release) then
      ! the first round: only the rows of the strongest wrong sign (release_share)
      share = 0
      if (rounds == 1) share = self%settings%release_share
      n_released = released_rows(problem, self%free_now, g, tol_gp, share, release)
      self%n_released = self%n_released + n_released
      if (n_released < counts(2)) then
        write (buf, '(a,i0,a,i0,a,f4.2,a)') 'polish: ', n_released, ' of the ', counts(2), &
          ' wrong-sign rows released (those of at least ', share, ' times the largest wrong-sign gradient)'
        call self%face%monitor%note(trim(buf))
      end if
    end if
    ! predictive update: after a round that projected at least `predict` rows and released none, as
    ! many more free rows, those nearest their bound, become active with them (the next round
    ! releases those whose gradient says otherwise)
    if (self%settings%predict > 0 .and. counts(1) >= self%settings%predict .and. counts(2) == 0) then
      n_predicted = predicted_rows(problem, self%free_now, x, counts(1), release)
      self%n_predicted = self%n_predicted + n_predicted
      if (n_predicted > 0) then
        write (buf, '(a,i0,a)') 'polish: ', n_predicted, ' more free rows nearest their bound made active'
        call self%face%monitor%note(trim(buf))
      end if
    end if
    if (counts(1) > 0) then
      call problem%project(x)
      call x_moved(problem, moved_other)
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
        call self%face%monitor%note('polish: the next face is that of an earlier round cut short '// &
                                           'at a loose check: solved once more')
      end if
    end if
  end subroutine next_face

  !> The monitor line of one round of a polish (n_hessian: the products so far).
  subroutine log_round(self, outer, counts, tol_gp, rounds, cycling, n_hessian)
    class(active_set_polish_t), intent(in) :: self
    integer(ip), intent(in) :: outer, counts(2), rounds, n_hessian
    real(dp), intent(in) :: tol_gp
    logical, intent(in) :: cycling
    character(len=400) :: buf
    write (buf, '(a,i0,3a)') 'after outer ', outer, ': ', counted(self%face%n_steps, 'CG step'), ', '
    if (self%face%stopped_loose) buf = trim(buf)//' stopped at the loose check,'
    buf = trim(buf)//' '//counted(counts(1), 'free row')//' projected, '//counted(counts(2), 'wrong-sign row')
    if (self%settings%release .and. counts(2) > 0 .and. .not. cycling .and. rounds < self%settings%rounds) &
      buf = trim(buf)//' released'
    if (cycling) buf = trim(buf)//'; more changes than the round before: back to SMALBE'
    call self%face%monitor%round_line(self%n_polish, rounds, n_hessian, self%face%measure, polish_target*tol_gp, &
                                      trim(buf))
  end subroutine log_round

  !> The gradient A x - b_lin at the current x (one product, counted as the polish's).
  subroutine fresh_gradient(self, problem, x, st)
    class(active_set_polish_t), intent(inout) :: self
    class(qp_problem_t), intent(inout) :: problem
    real(dp), intent(in) :: x(:)
    type(outer_state_t), intent(inout) :: st
    integer(ip) :: n
    n = problem%n
    call problem%hessian(x, st%g)
    call x_moved(problem, moved_to_argument)
    st%g(1:n) = st%g(1:n) - st%b_lin(1:n)
    st%n_hessian = st%n_hessian + 1
    self%n_products = self%n_products + 1
  end subroutine fresh_gradient

  !> v allocated with at least n entries (kept across calls).
  subroutine grow(v, n)
    real(dp), allocatable, intent(inout) :: v(:)
    integer(ip), intent(in) :: n
    if (allocated(v)) then
      if (size(v) == n) return
      deallocate (v)
    end if
    allocate (v(n))
  end subroutine grow

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

end module active_set_polish
