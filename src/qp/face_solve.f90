!> The exact solve on a face of the feasible set (SMALBE's polish step):
!>
!>     min 1/2 x^T A x - b^T x   s.t.  x_A = l_A,  C x = 0,
!>
!> A the active rows (at their bound), F the free rows (the others, and every
!> row without a bound). With the face projector
!>
!>     P_F y = y_F - C_F^T (C_F C_F^T)^{-1} C_F y_F      (zero on A)
!>
!> onto {y : y_A = 0, C y = 0} (C_F the columns of C on F), the problem is a
!> linear one on Im P_F, solved by projected preconditioned CG (PCPG):
!> 1. start: x_A := l_A, then x_F -= C_F^T (C_F C_F^T)^{-1} C x (C x = 0);
!> 2. r = -P_F g, g = A x - b, z = P_F M_F^{-1} r (M^{-1} the problem's
!>    face%precondition on the rows F, or none), standard CG recurrences; the
!>    gradient g follows each step (g <- g + alpha q, q = face%apply(p)
!>    = A p), r is projected anew. A face with lazy() gives instead
!>    q = face%apply_lazy(p) = A p + C^T c: g then carries terms of the
!>    range of C^T, which P_F removes from r and which cancel in the
!>    Lagrangian gradient g + C^T mu of the loose checks (mu follows g); every
!>    lazy_fold steps and at the end they leave g (`fold`: one
!>    face%range_coefficient of the change of g since the last fold);
!> 3. stop when the stopping measure of r (the problem's weighted maximum
!>    with a per-component test, else ||r||) is <= target, or after max_steps
!>    steps, or (`aborted`) after abort_check steps or more when the mean
!>    reduction per step so far would not reach target within abort_factor
!>    times max_steps (CG usually speeds up; a run stopped by max_steps
!>    keeps its iterate, an aborted one is given up).
!> With g_valid (SMALBE's round after one that only released rows), x is
!> already on the face and g = A x - b is given: step 1 and the product of
!> step 2 are skipped.
!> The multiplier that makes the face's KKT conditions hold in the least
!> squares sense is mu = -(C_F C_F^T)^{-1} C_F g_F (returned in the form
!> eq%apply_t takes, `muhat`), so that g + C^T mu = P_F g on F.
!> On Im P_F, C p = 0, so A p = A_0 p (the penalty rho C^T C drops out) and
!> P_F A_0 = P_F F for the FETI dual (P_F kills Im G^T): the face problem is
!> the same with or without the penalty and the FETI projector P.
!> With a loose target (`loose` times the start measure of r, above target:
!> SMALBE's polish rounds), the run pauses once the measure of r first drops below it and
!> counts the rows whose status the face solution would change (face_changes:
!> free rows below their bound, active rows whose Lagrangian gradient
!> g + C^T mu has the wrong sign; with `margin` > 0 only rows beyond margin
!> times the current measure of r count: an iterate's error is at least
!> about its residual, ||A|| ~ 1, so a smaller violation is not yet
!> decided); if there are any it stops there
!> (`stopped_loose`: x, g, muhat a face iterate, not the face solution),
!> else the same CG run goes on (no restart, no Krylov space lost) and checks
!> again each time the measure has dropped by another factor `loose`.
!> The give-up rule of 3. with loose checks: before the
!> first loose check the extrapolation aims at the loose target (the run's
!> next decision point), not at target; once a loose check has found no
!> change the face is trusted (`trusted`): no give-up any more, and the run
!> may go on to max_steps_trusted steps (the caller's budget for a face that
!> looks right). A wrong face is stopped by its loose check instead.
!> With `recycle%on` (a load history: the same A, new right-hand sides) the
!> run keeps its directions and starts from those of earlier runs when they
!> lie in its face: a Galerkin start after step 1, deflated CG in step 2
!> (module face_recycle; no Hessian products).
!> The problem provides C_F C_F^T through qp_problem's face hooks
!> (face%init, face%coefficient). Every routine is collective.
module face_solve
  use kinds, only: dp, ip, MPI_INT_IP
  use qp_problem, only: qp_problem_t, no_lower_bound, x_moved, moved_other
  use mprgp, only: ensure_size
  use ritz_values, only: cg_ritz_t
  use solver_monitor, only: solver_monitor_t
  use face_recycle, only: face_recycle_t
  use mpi_f08, only: MPI_Allreduce, MPI_SUM
  implicit none
  private

  public :: face_project, free_rows, face_changes

  !> steps after which a run that would not reach its target within max_steps stops
  integer(ip), parameter, public :: abort_check = 10
  !> ... would need more than abort_factor * max_steps at its mean rate so far (CG speeds up later)
  real(dp), parameter, public :: abort_factor = 2
  !> with face_lazy: CG steps between two folds of the range terms out of g
  integer(ip), parameter, public :: lazy_fold = 20

  !> Counters and outcome of the last polish.
  type, public :: face_polish_t
    integer(ip) :: n_hessian = 0       !< Hessian products of the last run
    integer(ip) :: n_steps = 0         !< CG steps of the last run
    integer(ip) :: n_precondition = 0  !< preconditioner applications of the last run
    !> Ritz values of the CG runs (all runs since the object was made): the running estimate
    !> a problem that watches its face condition (qp_problem) is handed after every step
    type(cg_ritz_t) :: ritz
    real(dp) :: measure0 = 0           !< stopping measure of r at the start
    real(dp) :: measure = 0            !< ... at the end
    logical :: reached = .false.       !< measure <= target
    logical :: breakdown = .false.     !< p^T A p <= 0 or not finite
    !> stopped early: the rate of the first steps would not reach target within max_steps (x, g, muhat
    !> are then not a face solution; the caller restores its iterate)
    logical :: aborted = .false.
    !> stopped at the loose target because the face solution would change the active set there
    logical :: stopped_loose = .false.
    !> a loose check found no change: not given up any more, budget max_steps_trusted
    logical :: trusted = .false.
    integer(ip) :: loose_counts(2) = 0   !< face_changes at the loose check (0 when not checked)
    real(dp) :: margin = 0               !< the loose checks' margin of the last run (times the measure of r)
    type(solver_monitor_t) :: monitor    !< the caller's monitor: one line per CG step
    !> the directions of earlier runs (when `recycle%on`): a Galerkin start on a face that holds them
    type(face_recycle_t) :: recycle
    real(dp), allocatable, private :: r(:), z(:), p(:), q(:), w(:)
    real(dp), allocatable, private :: g0(:)   !< g at the start (problems with face_lazy)
    real(dp), allocatable, private :: cz(:)   !< coefficients of P_F z (muhat keeps those of g)
  contains
    procedure :: run
  end type face_polish_t

contains

  !> free(i): x_i is not at a finite lower bound (local, no communication).
  subroutine free_rows(problem, x, free)
    class(qp_problem_t), intent(in) :: problem
    real(dp), intent(in) :: x(:)
    logical, intent(out) :: free(:)
    integer(ip) :: i
    do i = 1, problem%n
      free(i) = .true.
      if (problem%lower(i) > no_lower_bound) free(i) = x(i) > problem%lower(i)
    end do
  end subroutine free_rows

  !> The rows whose status a face iterate would change, summed over ranks:
  !> counts(1) free rows (bounded) with x_i < l_i, counts(2) active rows whose
  !> gradient glag (of the Lagrangian, face multiplier included) has the wrong
  !> sign beyond tol: w_i glag_i < -tol (w = stop_weight, 1 without). With
  !> margin (optional, >= 0) a row counts only beyond it: w_i (l_i - x_i) >
  !> margin, w_i glag_i < -max(tol, margin). Collective.
  function face_changes(problem, free, x, glag, tol, margin) result(counts)
    class(qp_problem_t), intent(in) :: problem
    logical, intent(in) :: free(:)
    real(dp), intent(in) :: x(:), glag(:)
    real(dp), intent(in) :: tol
    real(dp), intent(in), optional :: margin
    integer(ip) :: counts(2), local(2), i
    integer :: ierr
    real(dp) :: wi, m
    m = 0
    if (present(margin)) m = margin
    local = 0
    do i = 1, problem%n
      if (problem%lower(i) <= no_lower_bound) cycle
      if (free(i)) then
        if (m > 0) then
          wi = 1
          if (allocated(problem%stop_weight)) wi = problem%stop_weight(i)
          if (wi*(problem%lower(i) - x(i)) > m) local(1) = local(1) + 1
        else
          if (x(i) < problem%lower(i)) local(1) = local(1) + 1
        end if
      else
        wi = 1
        if (allocated(problem%stop_weight)) wi = problem%stop_weight(i)
        if (wi*glag(i) < -max(tol, m)) local(2) = local(2) + 1
      end if
    end do
    call MPI_Allreduce(local, counts, 2, MPI_INT_IP, MPI_SUM, problem%comm, ierr)
  end function face_changes

  !> py = P_F y (y restricted to F first; py may not be y); c: the
  !> coefficients of C_F^T (C_F C_F^T)^{-1} C_F y_F (eq%size()). Collective.
  subroutine face_project(problem, free, y, py, c)
    class(qp_problem_t), intent(inout) :: problem
    logical, intent(in) :: free(:)
    real(dp), intent(in) :: y(:)
    real(dp), intent(inout) :: py(:)
    real(dp), intent(out) :: c(:)
    real(dp), allocatable :: w(:)
    integer(ip) :: n
    n = problem%n
    allocate (w(n))
    w = merge(y(1:n), 0.0_dp, free(1:n))
    call problem%face%coefficient(w, c)
    call problem%eq%apply_t(c, py)
    py(1:n) = merge(w - py(1:n), 0.0_dp, free(1:n))
  end subroutine face_project

  !> PCPG on the face of `free` (face%init(free) already called) from x;
  !> on return x is on the face (x_A = l_A, C x = 0 up to the coarse solves),
  !> g = A x - b (without multiplier) and muhat the face multiplier (see the
  !> module). per_component: measure r by problem%weighted_max, else ||r||.
  !> loose in (0, 1) (optional): the loose check of the module once the
  !> measure of r is <= loose times its start value, then at every further
  !> factor loose (while still > target),
  !> face_changes with tolerance change_tol (default 0). max_steps_trusted
  !> (optional, default max_steps): the step cap once a loose check has found
  !> no change (then never given up). margin (optional, default 0): the loose
  !> checks count a row only beyond margin times the current measure of r.
  subroutine run(self, problem, free, x, g, muhat, target, per_component, max_steps, loose, change_tol, &
                 max_steps_trusted, g_valid, margin)
    class(face_polish_t), intent(inout) :: self
    class(qp_problem_t), intent(inout) :: problem
    logical, intent(in) :: free(:)
    real(dp), intent(inout) :: x(:)
    real(dp), intent(out) :: g(:), muhat(:)
    real(dp), intent(in) :: target
    logical, intent(in) :: per_component
    integer(ip), intent(in) :: max_steps
    real(dp), intent(in), optional :: loose, change_tol
    integer(ip), intent(in), optional :: max_steps_trusted
    !> x is on the face of `free` already (x_A = l_A, C x = 0) and g = A x - b on entry: no
    !> start correction, no product (SMALBE's polish round after a round that only released rows)
    logical, intent(in), optional :: g_valid
    real(dp), intent(in), optional :: margin
    real(dp) :: rz, rz_new, pq, alpha, loose_at, ctol
    integer(ip) :: n, cap, unfolded
    logical :: prec, check, switched, lazy, known

    n = problem%n
    call reset_run(self, n, size(muhat, kind=ip))
    cap = max_steps
    prec = allocated(problem%prec)
    lazy = problem%face%lazy()
    loose_at = target
    ctol = 0
    if (present(change_tol)) ctol = change_tol
    if (present(margin)) self%margin = margin

    known = .false.
    if (present(g_valid)) known = g_valid
    ! 1. onto the face (unless known), then 2. PCPG
    call onto_face(self, problem, free, x, g, muhat, known)
    call face_project(problem, free, g, self%r, muhat)
    self%r = -self%r
    unfolded = 0          ! updates of g since g0 (face_lazy: the range terms in g come from them)
    if (lazy) then
      call ensure_size(self%g0, n)
      self%g0(1:n) = g(1:n)
    end if
    ! the directions of earlier runs (face_recycle): the Galerkin start (no product), then deflated CG
    if (galerkin_start(self, problem, free, x, g, muhat)) unfolded = 1
    self%measure0 = measure(problem, self%r, per_component)
    self%measure = self%measure0
    self%reached = self%measure <= target
    if (present(loose)) loose_at = max(loose*self%measure0, target)
    check = loose_at > target
    if (.not. self%reached) then
      call precondition(self, problem, free, prec)
      call self%recycle%deflate(problem, self%z)
      self%p = self%z
      rz = problem%dot(self%r, self%z)
      call self%ritz%begin_run()
      do while (self%n_steps < cap)
        if (lazy) then
          ! q = A p + C^T c: g carries the C^T c terms, P_F removes them from r (step 4. takes them out of g)
          call problem%face%apply_lazy(self%p, self%q)
        else
          call problem%face%apply(self%p, self%q)
        end if
        self%n_hessian = self%n_hessian + 1
        self%n_steps = self%n_steps + 1
        pq = problem%dot(self%p, self%q)
        if (.not. (pq > 0 .and. pq < huge(1.0_dp))) then
          self%breakdown = .true.
          exit
        end if
        alpha = rz/pq
        call self%recycle%add(problem, free, self%p, self%q)
        call self%ritz%add_alpha(alpha)
        x(1:n) = x(1:n) + alpha*self%p
        g(1:n) = g(1:n) + alpha*self%q
        unfolded = unfolded + 1
        call face_project(problem, free, g, self%r, muhat)
        self%r = -self%r
        ! every lazy_fold steps the range terms leave g (step 4.), so that they do not grow
        ! against the residual of a long run
        if (lazy .and. unfolded == lazy_fold) then
          call fold(self, problem, g, muhat)
          unfolded = 0
        end if
        self%measure = measure(problem, self%r, per_component)
        call self%monitor%face_step(self%n_steps, self%n_hessian, self%measure, target)
        if (self%measure <= target) then
          self%reached = .true.
          exit
        end if
        if (stop_after_step(self, problem, free, x, g, muhat, target, max_steps, loose, ctol, max_steps_trusted, &
                            loose_at, check, cap)) exit
        ! a problem that watches its face condition may change its preconditioner
        ! here (qp_problem; &solver preconditioner = 'auto'): then CG restarts, p = z
        switched = .false.
        if (prec) then
          if (problem%prec%watches()) &
            call problem%prec%condition(max(self%ritz%max_ratio, self%ritz%current_ratio()), switched)
        end if
        call precondition(self, problem, free, prec)
        call self%recycle%deflate(problem, self%z)
        rz_new = problem%dot(self%r, self%z)
        if (switched) then
          self%p = self%z
          call self%ritz%begin_run()
        else
          call self%ritz%add_beta(rz_new/rz)
          self%p = self%z + (rz_new/rz)*self%p
        end if
        rz = rz_new
      end do
      call self%ritz%end_run()
    end if
    ! 3. the face multiplier mu = -(C_F C_F^T)^{-1} C_F g_F: muhat holds the coefficients of
    ! the last projection of g, made after g last changed (the preconditioner's go to cz)
    call x_moved(problem, moved_other)
    if (self%aborted) return
    ! 4. (face_lazy) the range terms out of g (fold)
    if (lazy .and. unfolded > 0) call fold(self, problem, g, muhat)
    muhat = -muhat

  end subroutine run

  !> The Galerkin start from the kept directions of earlier runs, when
  !> face_recycle has some for this face: x, g and r = -P_F g move (no
  !> product); true when it did.
  logical function galerkin_start(self, problem, free, x, g, muhat) result(moved)
    class(face_polish_t), intent(inout) :: self
    class(qp_problem_t), intent(inout) :: problem
    logical, intent(in) :: free(:)
    real(dp), intent(inout) :: x(:), g(:), muhat(:)
    moved = self%recycle%begin_run(problem, free)
    if (.not. moved) return
    call self%recycle%start(problem, x, g, self%r)
    call face_project(problem, free, g, self%r, muhat)
    self%r = -self%r
  end function galerkin_start

  !> The run's work vectors (n, and m for the coefficients) and counters.
  subroutine reset_run(self, n, m)
    class(face_polish_t), intent(inout) :: self
    integer(ip), intent(in) :: n, m
    call ensure_size(self%r, n)
    call ensure_size(self%z, n)
    call ensure_size(self%p, n)
    call ensure_size(self%q, n)
    call ensure_size(self%w, n)
    call ensure_size(self%cz, m)
    self%n_hessian = 0
    self%n_steps = 0
    self%n_precondition = 0
    self%reached = .false.
    self%breakdown = .false.
    self%aborted = .false.
    self%stopped_loose = .false.
    self%loose_counts = 0
    self%margin = 0
    self%trusted = .false.
  end subroutine reset_run

  !> Unless `known`: x onto the face (x_A = l_A, then C x = 0 by the least
  !> squares correction on F) and g = A x - b there (one product).
  subroutine onto_face(self, problem, free, x, g, muhat, known)
    class(face_polish_t), intent(inout) :: self
    class(qp_problem_t), intent(inout) :: problem
    logical, intent(in) :: free(:)
    real(dp), intent(inout) :: x(:), g(:), muhat(:)
    logical, intent(in) :: known
    integer(ip) :: n
    n = problem%n
    if (.not. known) then
      x(1:n) = merge(x(1:n), problem%lower(1:n), free(1:n))
      call problem%face%coefficient(x, muhat)
      call problem%eq%apply_t(muhat, self%w)
      x(1:n) = x(1:n) - merge(self%w, 0.0_dp, free(1:n))
    end if
    call x_moved(problem, moved_other)
    if (.not. known) then
      call problem%hessian(x, g)
      self%n_hessian = 1
      g(1:n) = g(1:n) - problem%b(1:n)
    end if
  end subroutine onto_face

  !> The decisions after a CG step of `run` that did not reach target: the
  !> loose check (when the measure is <= loose_at: stop if the face would
  !> change, else trust the face and aim at the next factor `loose`), and the
  !> give-up rule (after abort_check steps, not on a trusted face: the mean
  !> rate so far, extrapolated, must reach the next decision point, the first
  !> loose check, else target, within max_steps). True: stop the run.
  logical function stop_after_step(self, problem, free, x, g, muhat, target, max_steps, loose, ctol, &
                                   max_steps_trusted, loose_at, check, cap) result(stop)
    class(face_polish_t), intent(inout) :: self
    class(qp_problem_t), intent(inout) :: problem
    logical, intent(in) :: free(:)
    real(dp), intent(in) :: x(:), g(:), muhat(:)
    real(dp), intent(in) :: target, ctol
    integer(ip), intent(in) :: max_steps
    real(dp), intent(in), optional :: loose
    integer(ip), intent(in), optional :: max_steps_trusted
    real(dp), intent(inout) :: loose_at
    logical, intent(inout) :: check
    integer(ip), intent(inout) :: cap
    real(dp) :: aim
    stop = .false.
    if (check .and. self%measure <= loose_at) then
      if (loose_check(self, problem, free, x, g, muhat, ctol)) then
        self%stopped_loose = .true.
        stop = .true.
        return
      end if
      ! no change: the face is trusted (no give-up, the larger step cap)
      if (.not. self%trusted) then
        self%trusted = .true.
        if (present(max_steps_trusted)) cap = max(max_steps, max_steps_trusted)
      end if
      ! the next check once the measure has dropped by another factor loose
      loose_at = loose*self%measure
      check = loose_at > target
    end if
    if (self%n_steps >= abort_check .and. .not. self%trusted) then
      aim = target
      if (check) aim = loose_at
      if (self%measure >= self%measure0) then
        self%aborted = .true.
      else
        self%aborted = self%n_steps*log(aim/self%measure0)/log(self%measure/self%measure0) > &
                       abort_factor*max_steps
      end if
      stop = self%aborted
    end if
  end function stop_after_step

  !> (face_lazy) g - g0 = A (x - x0) + C^T c: the C^T c terms out of g, c = (C C^T)^{-1} C (g - g0)
  !> (A (x - x0) lies in Ker C: x - x0 is a sum of face directions); the coefficients of the last
  !> projection of g, muhat, drop by the same c (those of C^T c on the face are c). One coarse solve.
  subroutine fold(self, problem, g, muhat)
    class(face_polish_t), intent(inout) :: self
    class(qp_problem_t), intent(inout) :: problem
    real(dp), intent(inout) :: g(:), muhat(:)
    integer(ip) :: n
    n = problem%n
    self%w(1:n) = g(1:n) - self%g0(1:n)
    call problem%face%range_coefficient(self%w, self%cz)
    call problem%eq%apply_t(self%cz, self%w)
    g(1:n) = g(1:n) - self%w(1:n)
    muhat = muhat - self%cz
    self%g0(1:n) = g(1:n)
  end subroutine fold

  !> face_changes at the current iterate (mu = -muhat of the last projection of g): any?
  logical function loose_check(self, problem, free, x, g, muhat, ctol)
    class(face_polish_t), intent(inout) :: self
    class(qp_problem_t), intent(inout) :: problem
    logical, intent(in) :: free(:)
    real(dp), intent(in) :: x(:), g(:), muhat(:), ctol
    integer(ip) :: n
    n = problem%n
    call problem%eq%apply_t(muhat, self%w)
    self%w(1:n) = g(1:n) - self%w(1:n)
    self%loose_counts = face_changes(problem, free, x, self%w, ctol, self%margin*self%measure)
    loose_check = sum(self%loose_counts) > 0
  end function loose_check

  !> The stopping measure of r: the problem's weighted maximum (per-component test) or ||r||.
  real(dp) function measure(problem, v, per_component)
    class(qp_problem_t), intent(inout) :: problem
    real(dp), intent(in) :: v(:)
    logical, intent(in) :: per_component
    if (per_component) then
      measure = problem%weighted_max(v)
    else
      measure = problem%norm(v)
    end if
  end function measure

  !> self%z = P_F M_F^{-1} r (r itself without preconditioner, prec false).
  subroutine precondition(self, problem, free, prec)
    class(face_polish_t), intent(inout) :: self
    class(qp_problem_t), intent(inout) :: problem
    logical, intent(in) :: free(:)
    logical, intent(in) :: prec
    integer(ip) :: n
    if (.not. prec) then
      self%z = self%r
      return
    end if
    n = problem%n
    self%w = merge(self%r, 0.0_dp, free(1:n))
    call problem%face%precondition(problem%prec, self%w, self%q)
    self%n_precondition = self%n_precondition + 1
    call face_project(problem, free, self%q, self%z, self%cz)
  end subroutine precondition

end module face_solve
