!> The abstract quadratic programme the QP solvers work on, and the solver base type.
!>
!>     min 1/2 x^T A x - b^T x   s.t.  x >= l  (componentwise)  [and C x = 0]
!>
!> Vectors x, b, l (and every work vector of the solvers) are distributed: each
!> rank of `comm` holds its own slice of length `n`; dot products are a local
!> sum plus one MPI_Allreduce on `comm`. A lower bound l_i = `no_lower_bound`
!> (= -huge(1.0_dp)) means that x_i is unbounded below; any other bound must be
!> of moderate size (x_i - l_i is formed without overflow checks).
!>
!> The equality constraint C x = 0 (C with orthonormal rows) is never seen as a
!> matrix. A problem with `has_equality` provides it in "hat" form, so that the
!> FETI dual (C = L^{-1} G with G G^T = L L^T) never needs the factor L:
!> - `eq_size()`: length m of the multiplier vector (replicated on every rank);
!> - `eq_residual(x, z, cnorm)`: cnorm = ||C x|| and z (length m, replicated)
!>   such that the multiplier update mu <- mu + rho C x reads
!>   muhat <- muhat + rho z. Orthonormal explicit C: z = C x. FETI:
!>   z = (G G^T)^{-1} G x and cnorm^2 = (G x)^T z;
!> - `eq_apply_t(muhat, y)`: y = C^T mu, the local slice (FETI: y = G^T muhat).
!> With an equality constraint the Hessian A applied by `hessian` already
!> contains the penalty rho C^T C (FETI: A = P F P + rho Q, Q = C^T C), and
!> `penalty()` returns that rho (> 0).
!>
!> Every type-bound procedure is collective over `comm` unless stated otherwise.
!>
!> Preconditioner (optional): a problem whose `has_preconditioner()` is true
!> provides `precondition(r, z)`, z = M_A^{-1} r with M_A^{-1} symmetric
!> positive definite (an approximate inverse of A); MPRGP then uses it in the
!> face (its CG steps; mprgp). The QP layer knows nothing else of it.
!> A problem may change its preconditioner during a solve (an adaptive
!> choice, `&solver preconditioner = 'auto'`): while `watches_condition()`
!> is true, MPRGP hands it after every preconditioned CG step the running
!> condition estimate of the preconditioned face operator (the Ritz values
!> of the CG coefficients, the same on every rank: ritz_values), through
!> `condition_estimate(kappa, switched)`; switched = .true. says that the
!> preconditioner changed, and MPRGP restarts its CG direction (as on a
!> change of the face). By default nobody watches and nothing changes.
!>
!> Face solver (optional, SMALBE's polish step): a problem with an equality
!> constraint whose `has_face_solver()` is true can restrict C to the free
!> rows F of an active set: `face_init(free, reused)` prepares C_F C_F^T (free:
!> the local mask of F; `reused`: the last face's matrices were those and are
!> kept), `face_coefficient(y, c)` gives the multiplier-form
!> coefficients c (length eq_size, the form eq_apply_t takes) of the least
!> squares fit (C_F C_F^T)^{-1} C y, so that the face projector onto
!> {y : y_A = 0, C y = 0} reads P_F y = y_F - (eq_apply_t(c))_F for c of y_F
!> (see face_solve), and `face_free()` releases it. Problems without it never
!> polish. Two optional shortcuts for vectors of the face (C p = 0, p_A = 0),
!> `face_operator(p, q)`, q = A p for p on the face (default: the Hessian;
!> a problem may save work there) and `face_precondition(r, z)`, used only
!> as P_F z, an SPD preconditioner on the face (default: precondition).
!> A third one: a problem whose `face_lazy()` is true gives by
!> `face_operator_lazy(p, q)` A p plus some vector C^T c of the range of C^T
!> (cheaper: the FETI dual skips its projector), and by
!> `eq_range_coefficient(y, c)` the coefficients of the orthogonal projection
!> of y onto that range, (C C^T)^{-1} C y in the form eq_apply_t takes; the
!> face solve then carries the extra terms in its gradient (P_F removes them)
!> and takes them out every few steps and at the end (face_solve's fold).
!>
!> Stopping test (what the solvers compare with tol): by default the classical
!> ||g^P|| <= tol ||b|| and ||C x|| <= tol ||b|| in the 2-norm. A problem that
!> allocates `stop_weight` (w_i > 0, local slice) asks instead for a test per
!> component: max_i w_i |v^P_i| <= tol S, v = g - rho C^T C x the gradient
!> without its penalty part, S = `stop_scale` if the problem sets it, else
!> max_i w_i |b_i|; and C x = 0 measured by `eq_measure`: by default
!> max(w) ||C x|| <= tol S, or, for a problem with `relative_eq_measure`, its
!> own dimensionless measure <= tol (the FETI dual: the largest relative force
!> imbalance of a subdomain). The FETI dual sets w = 1/(row scale), so that the
!> test bounds the largest constraint violation of the reconstructed
!> displacements (jump between copies, Dirichlet error, penetration) by tol
!> times the largest one of the start, in displacement units, whatever the
!> scaling of the rows and the material contrast (docs/THEORY.md).
!>
!> Global sums (dot products, norms, the solvers' fused reductions) are
!> compensated: each rank sums its terms with Neumaier's algorithm
!> (`compensated_add`) and the (sum, error) pairs are combined across ranks
!> by a double-double MPI reduction (`reduce_sums`). The result is the
!> correctly rounded sum of the (rounded) terms except in rare near-tie
!> cases, so it does not depend on how a vector is split over the ranks:
!> given a Hessian whose result does not depend on it either, the solvers
!> take the same steps on any number of ranks. The solvers fuse their dot
!> products through `reduce_sums` instead of calling `dot`: the inner
!> product is always the Euclidean one of the distributed vector.
module qp_problem
  use, intrinsic :: iso_c_binding, only: c_ptr, c_f_pointer
  use kinds, only: dp, ip, MPI_REAL_DP, MPI_INT_IP
  use errors, only: fatal_error
  use mpi_f08, only: MPI_Comm, MPI_COMM_NULL, MPI_Allreduce, MPI_SUM, MPI_MIN, MPI_MAX, MPI_Datatype, MPI_Op, &
                     MPI_Type_contiguous, MPI_Type_commit, MPI_Op_create
  implicit none
  private

  public :: qp_status_name, compensated_add

  real(dp), parameter, public :: no_lower_bound = -huge(1.0_dp)  !< l_i of an unbounded x_i

  integer, parameter, public :: qp_message_len = 512
  integer, parameter, public :: max_reduce_sums = 8   !< most sums reduce_sums combines at once

  ! the double-double reduction, created on first use (MPI_Finalize frees it)
  logical, save :: dd_ready = .false.
  type(MPI_Datatype), save :: dd_type
  type(MPI_Op), save :: dd_op

  !> Solver status codes (component `status` of every qp_solver_t).
  integer, parameter, public :: qp_status_not_run = -1      !< solve not called yet
  integer, parameter, public :: qp_status_converged = 0     !< stopping criterion met
  integer, parameter, public :: qp_status_max_hessian = 1   !< Hessian multiplication cap reached
  integer, parameter, public :: qp_status_max_outer = 2     !< outer iteration cap reached
  integer, parameter, public :: qp_status_not_finite = 3    !< NaN or Inf detected in a norm or step length
  integer, parameter, public :: qp_status_breakdown = 4     !< p^T A p <= 0 (A not positive definite)
  integer, parameter, public :: qp_status_incompatible = 5  !< the solver refused the problem

  !> A distributed QP with lower bounds and optionally C x = 0 (see the module).
  !> Extensions must override `hessian`; problems with an equality constraint
  !> also override `penalty`, `eq_size`, `eq_residual` and `eq_apply_t`.
  type, abstract, public :: qp_problem_t
    type(MPI_Comm) :: comm = MPI_COMM_NULL     !< communicator of the distributed vectors
    integer(ip) :: n = 0                       !< local length of x, b, lower on this rank
    real(dp), allocatable :: b(:)              !< linear term (local slice)
    real(dp), allocatable :: lower(:)          !< lower bounds l (local slice), no_lower_bound if none
    logical :: has_equality = .false.          !< the constraint C x = 0 is present
    !> weights of the per-component stopping test (see the module); not
    !> allocated: the classical 2-norm test
    real(dp), allocatable :: stop_weight(:)
    !> the scale that per-component test compares with; 0: max_i w_i |b_i|
    real(dp) :: stop_scale = 0
    !> eq_measure is relative (compared with tol itself), not ||C x||
    logical :: relative_eq_measure = .false.
  contains
    procedure(hessian_iface), deferred :: hessian
    procedure :: penalty => default_penalty
    procedure :: set_penalty => default_set_penalty
    procedure :: eq_size => default_eq_size
    procedure :: eq_residual => default_eq_residual
    procedure :: eq_apply_t => default_eq_apply_t
    procedure :: track_last => default_track
    procedure :: track_step => default_track_step
    procedure :: track_reset => default_track
    procedure :: eq_measure => default_eq_measure
    procedure :: has_preconditioner => default_has_preconditioner
    procedure :: refined_norm => default_refined_norm
    procedure :: precondition => default_precondition
    procedure :: watches_condition => default_watches_condition
    procedure :: condition_estimate => default_condition_estimate
    procedure :: has_face_solver => default_has_face_solver
    procedure :: face_always_regular => default_face_always_regular
    procedure :: face_init => default_face_init
    procedure :: face_coefficient => default_face_coefficient
    procedure :: face_free => default_face_free
    procedure :: face_operator => default_face_operator
    procedure :: face_lazy => default_face_lazy
    procedure :: face_operator_lazy => default_face_operator_lazy
    procedure :: eq_range_coefficient => default_eq_range_coefficient
    procedure :: face_precondition => default_face_precondition
    procedure :: init_base
    procedure :: free_base
    procedure :: dot
    procedure :: norm
    procedure :: per_component_stop
    procedure :: weighted_max
    procedure :: projected_gradient_max
    procedure :: reduce_sums
    procedure :: global_min
    procedure :: count_at_bound
    procedure :: project
  end type qp_problem_t

  abstract interface
    !> y = A x (local slices; collective).
    subroutine hessian_iface(self, x, y)
      import :: qp_problem_t, dp
      class(qp_problem_t), intent(inout) :: self
      real(dp), intent(in) :: x(:)
      real(dp), intent(out) :: y(:)
    end subroutine hessian_iface
  end interface

  !> What every QP solver has: a status with a message, the final norm of the
  !> projected gradient, the Hessian multiplications and the final gradient.
  type, abstract, public :: qp_solver_t
    integer :: status = qp_status_not_run            !< one of qp_status_*
    character(len=qp_message_len) :: message = 'not run'  !< why the solver stopped
    logical :: monitor = .false.                     !< print progress through module logger
    real(dp) :: gp_norm = 0                          !< ||g^P|| at the returned x
    integer(ip) :: n_hessian = 0                     !< Hessian multiplications of the last solve
    real(dp), allocatable :: gradient(:)             !< gradient (of the Lagrangian) at the returned x
  contains
    procedure(solve_iface), deferred :: solve
    procedure(compatible_iface), deferred :: is_compatible
    procedure :: converged => solver_converged
  end type qp_solver_t

  abstract interface
    !> Solve `problem` from the initial guess `x` (projected onto the bounds
    !> first); on return `x` is the last iterate and `status`/`message` say
    !> whether it meets the stopping criterion. Collective.
    subroutine solve_iface(self, problem, x)
      import :: qp_solver_t, qp_problem_t, dp
      class(qp_solver_t), intent(inout) :: self
      class(qp_problem_t), intent(inout) :: problem
      real(dp), intent(inout) :: x(:)
    end subroutine solve_iface

    !> True when the solver can handle `problem`; otherwise `reason` says why.
    logical function compatible_iface(self, problem, reason)
      import :: qp_solver_t, qp_problem_t
      class(qp_solver_t), intent(in) :: self
      class(qp_problem_t), intent(inout) :: problem
      character(len=*), intent(out) :: reason
    end function compatible_iface
  end interface

contains

  !> Set the communicator and the local length; allocate b = 0 and
  !> lower = no_lower_bound; no equality. Extensions call this in their init.
  subroutine init_base(self, comm, n)
    class(qp_problem_t), intent(inout) :: self
    type(MPI_Comm), intent(in) :: comm
    integer(ip), intent(in) :: n
    call self%free_base()
    if (n < 0) call fatal_error('qp_problem: negative local length')
    self%comm = comm
    self%n = n
    allocate (self%b(n), self%lower(n))
    self%b = 0
    self%lower = no_lower_bound
  end subroutine init_base

  !> Release what init_base allocated.
  subroutine free_base(self)
    class(qp_problem_t), intent(inout) :: self
    if (allocated(self%b)) deallocate (self%b)
    if (allocated(self%lower)) deallocate (self%lower)
    if (allocated(self%stop_weight)) deallocate (self%stop_weight)
    self%stop_scale = 0
    self%n = 0
    self%has_equality = .false.
    self%comm = MPI_COMM_NULL
  end subroutine free_base

  !> Penalty rho contained in the Hessian: 0 without equality constraint; a
  !> problem with one must override this.
  real(dp) function default_penalty(self)
    class(qp_problem_t), intent(in) :: self
    default_penalty = 0
    if (self%has_equality) call fatal_error('qp_problem: has_equality but penalty() not provided')
  end function default_penalty

  !> Change the penalty rho in the Hessian (A <- A + (rho - penalty()) C^T C);
  !> needed only by a solver that raises rho (SMALBE with rho_growth > 1).
  !> Not local-only: problems may communicate.
  subroutine default_set_penalty(self, rho)
    class(qp_problem_t), intent(inout) :: self
    real(dp), intent(in) :: rho
    if (rho /= self%penalty()) call fatal_error('qp_problem: this problem cannot change its penalty (set_penalty)')
  end subroutine default_set_penalty

  !> Length of the multiplier vector: 0 without equality constraint; a
  !> problem with one must override this.
  integer(ip) function default_eq_size(self)
    class(qp_problem_t), intent(in) :: self
    default_eq_size = 0
    if (self%has_equality) call fatal_error('qp_problem: has_equality but eq_size() not provided')
  end function default_eq_size

  subroutine default_eq_residual(self, x, z, cnorm)
    class(qp_problem_t), intent(inout) :: self
    real(dp), intent(in) :: x(:)
    real(dp), intent(out) :: z(:)
    real(dp), intent(out) :: cnorm
    character(len=80) :: sizes
    write (sizes, '(3(a,i0))') 'n = ', self%n, ', size(x) = ', size(x), ', size(z) = ', size(z)
    call fatal_error('qp_problem: eq_residual not provided by this problem ('//trim(sizes)//')')
    z = 0
    cnorm = 0
  end subroutine default_eq_residual

  subroutine default_eq_apply_t(self, muhat, y)
    class(qp_problem_t), intent(inout) :: self
    real(dp), intent(in) :: muhat(:)
    real(dp), intent(out) :: y(:)
    call not_provided(self, 'eq_apply_t', 'muhat', size(muhat))
    y = 0
  end subroutine default_eq_apply_t

  !> The per-component stopping test's measure of C x = 0 at x, where
  !> eq_residual(x) gave cnorm = ||C x|| (and was the last call of it):
  !> ||C x|| by default.
  real(dp) function default_eq_measure(self, x, cnorm)
    class(qp_problem_t), intent(inout) :: self
    real(dp), intent(in) :: x(:)
    real(dp), intent(in) :: cnorm
    default_eq_measure = cnorm
  end function default_eq_measure

  !> ||A|| from an estimate made more accurate now, for MPRGP's step length
  !> when it is first needed (a problem that defers its norm estimate, as
  !> dual_problem does, overrides it); 0: nothing better than the norm given
  !> at MPRGP's init. Collective in the overrides.
  real(dp) function default_refined_norm(self)
    class(qp_problem_t), intent(inout) :: self
    default_refined_norm = 0
    if (self%n < 0) default_refined_norm = -1   ! never: keeps self referenced
  end function default_refined_norm

  !> False: no preconditioner (MPRGP's CG steps use the free gradient).
  !> Local, no communication.
  logical function default_has_preconditioner(self)
    class(qp_problem_t), intent(in) :: self
    default_has_preconditioner = .false.
    if (self%n < 0) default_has_preconditioner = .true.   ! never: keeps self referenced
  end function default_has_preconditioner

  !> z = M_A^{-1} r (local slices; collective): the identity by default.
  subroutine default_precondition(self, r, z)
    class(qp_problem_t), intent(inout) :: self
    real(dp), intent(in) :: r(:)
    real(dp), intent(out) :: z(:)
    z(1:self%n) = r(1:self%n)
  end subroutine default_precondition

  !> False: the preconditioner never changes. Local, no communication.
  logical function default_watches_condition(self)
    class(qp_problem_t), intent(in) :: self
    default_watches_condition = .false.
    if (self%n < 0) default_watches_condition = .true.   ! never: keeps self referenced
  end function default_watches_condition

  !> The running condition estimate kappa of the preconditioned face
  !> operator (globally reduced); switched = .true. when the problem changed
  !> its preconditioner in response. Never by default. Collective when
  !> watches_condition() is true.
  subroutine default_condition_estimate(self, kappa, switched)
    class(qp_problem_t), intent(inout) :: self
    real(dp), intent(in) :: kappa
    logical, intent(out) :: switched
    switched = .false.
    if (self%n < 0 .and. kappa < 0) switched = .true.   ! never: keeps the arguments referenced
  end subroutine default_condition_estimate

  !> False: no face solver (SMALBE never polishes). Local, no communication.
  logical function default_has_face_solver(self)
    class(qp_problem_t), intent(in) :: self
    default_has_face_solver = .false.
    if (self%n < 0) default_has_face_solver = .true.   ! never: keeps self referenced
  end function default_has_face_solver

  !> False: C_F C_F^T may be singular when every bounded row is at its bound
  !> (the equality rows alone need not determine the multipliers), so SMALBE
  !> does not polish that face. True where the problem knows that the
  !> equality rows alone give a regular C_E C_E^T (then every C_F C_F^T is
  !> regular). Local, no communication.
  logical function default_face_always_regular(self)
    class(qp_problem_t), intent(in) :: self
    default_face_always_regular = .false.
    if (self%n < 0) default_face_always_regular = .true.   ! never: keeps self referenced
  end function default_face_always_regular

  !> Prepare C_F C_F^T for the free rows `free` (local mask). Collective.
  subroutine default_face_init(self, free, reused)
    class(qp_problem_t), intent(inout) :: self
    logical, intent(in) :: free(:)
    logical, intent(out), optional :: reused
    if (present(reused)) reused = .false.
    call not_provided(self, 'face_init', 'free', size(free))
  end subroutine default_face_init

  !> c = (C_F C_F^T)^{-1} C y in the form eq_apply_t takes. Collective.
  subroutine default_face_coefficient(self, y, c)
    class(qp_problem_t), intent(inout) :: self
    real(dp), intent(in) :: y(:)
    real(dp), intent(out) :: c(:)
    call not_provided(self, 'face_coefficient', 'y', size(y))
    c = 0
  end subroutine default_face_coefficient

  !> q = A p for p on the face (C p = 0): the Hessian by default.
  subroutine default_face_operator(self, p, q)
    class(qp_problem_t), intent(inout) :: self
    real(dp), intent(in) :: p(:)
    real(dp), intent(out) :: q(:)
    call self%hessian(p, q)
  end subroutine default_face_operator

  !> face_operator_lazy leaves a term in the range of C^T: not by default.
  logical function default_face_lazy(self)
    class(qp_problem_t), intent(in) :: self
    default_face_lazy = .false.
    if (self%n < 0) default_face_lazy = .true.   ! never: keeps self referenced
  end function default_face_lazy

  !> q = A p (+ a term C^T c) for p on the face: face_operator by default.
  subroutine default_face_operator_lazy(self, p, q)
    class(qp_problem_t), intent(inout) :: self
    real(dp), intent(in) :: p(:)
    real(dp), intent(out) :: q(:)
    call self%face_operator(p, q)
  end subroutine default_face_operator_lazy

  !> c = (C C^T)^{-1} C y: needed only by a problem whose face_lazy() is true.
  subroutine default_eq_range_coefficient(self, y, c)
    class(qp_problem_t), intent(inout) :: self
    real(dp), intent(in) :: y(:)
    real(dp), intent(out) :: c(:)
    call not_provided(self, 'eq_range_coefficient', 'y', size(y))
    c = 0
  end subroutine default_eq_range_coefficient

  !> Stop with the message of a default binding that the problem had to override:
  !> `what` not provided, with n and the size m of the argument `arg`.
  subroutine not_provided(self, what, arg, m)
    class(qp_problem_t), intent(in) :: self
    character(len=*), intent(in) :: what, arg
    integer, intent(in) :: m
    character(len=80) :: sizes
    write (sizes, '(a,i0,a,i0)') 'n = ', self%n, ', size('//arg//') = ', m
    call fatal_error('qp_problem: '//what//' not provided by this problem ('//trim(sizes)//')')
  end subroutine not_provided

  !> The face's preconditioner before P_F: precondition by default.
  subroutine default_face_precondition(self, r, z)
    class(qp_problem_t), intent(inout) :: self
    real(dp), intent(in) :: r(:)
    real(dp), intent(out) :: z(:)
    call self%precondition(r, z)
  end subroutine default_face_precondition

  !> Release what face_init prepared (nothing by default).
  subroutine default_face_free(self)
    class(qp_problem_t), intent(inout) :: self
  end subroutine default_face_free

  !> Optional bookkeeping of C x that a problem may keep so that eq_residual
  !> needs no new work: the solver calls track_last when x has become the
  !> argument v of the last `hessian` call, track_step(alpha) when x moved to
  !> x - alpha v, and track_reset when x changed otherwise. No-ops by default.
  subroutine default_track(self)
    class(qp_problem_t), intent(inout) :: self
  end subroutine default_track

  subroutine default_track_step(self, alpha)
    class(qp_problem_t), intent(inout) :: self
    real(dp), intent(in) :: alpha
  end subroutine default_track_step

  !> Global x^T y (compensated, independent of the distribution).
  real(dp) function dot(self, x, y)
    class(qp_problem_t), intent(in) :: self
    real(dp), intent(in) :: x(:), y(:)
    real(dp) :: hi(1), lo(1), s(1)
    integer(ip) :: i
    hi = 0
    lo = 0
    do i = 1, self%n
      call compensated_add(hi(1), lo(1), x(i)*y(i))
    end do
    call self%reduce_sums(hi, lo, s)
    dot = s(1)
  end function dot

  !> Global ||x||_2.
  real(dp) function norm(self, x)
    class(qp_problem_t), intent(in) :: self
    real(dp), intent(in) :: x(:)
    norm = sqrt(self%dot(x, x))
  end function norm

  !> True when the problem asks for the per-component stopping test.
  logical function per_component_stop(self)
    class(qp_problem_t), intent(in) :: self
    per_component_stop = allocated(self%stop_weight)
  end function per_component_stop

  !> max_i w_i |v_i| over all ranks (w = 1 without stop_weight).
  real(dp) function weighted_max(self, v)
    class(qp_problem_t), intent(in) :: self
    real(dp), intent(in) :: v(:)
    real(dp) :: mine
    integer :: ierr
    mine = 0
    if (self%n > 0) then
      if (allocated(self%stop_weight)) then
        mine = maxval(abs(self%stop_weight(1:self%n)*v(1:self%n)))
      else
        mine = maxval(abs(v(1:self%n)))
      end if
    end if
    call MPI_Allreduce(mine, weighted_max, 1, MPI_REAL_DP, MPI_MAX, self%comm, ierr)
  end function weighted_max

  !> max_i w_i |g^P_i| over all ranks, g^P the projected gradient at x
  !> (g^P_i = g_i where x_i > l_i, min(g_i, 0) where x_i is at its bound).
  real(dp) function projected_gradient_max(self, x, g)
    class(qp_problem_t), intent(in) :: self
    real(dp), intent(in) :: x(:), g(:)
    real(dp) :: mine, gp
    integer(ip) :: i
    integer :: ierr
    mine = 0
    do i = 1, self%n
      gp = g(i)
      if (x(i) <= self%lower(i) .and. self%lower(i) > no_lower_bound) gp = min(gp, 0.0_dp)
      if (allocated(self%stop_weight)) gp = self%stop_weight(i)*gp
      mine = max(mine, abs(gp))
    end do
    call MPI_Allreduce(mine, projected_gradient_max, 1, MPI_REAL_DP, MPI_MAX, self%comm, ierr)
  end function projected_gradient_max

  !> One step of Neumaier's compensated summation: s + c <- s + c + p
  !> (s the running sum, c the accumulated rounding errors; start both at 0).
  elemental subroutine compensated_add(s, c, p)
    real(dp), intent(inout) :: s, c
    real(dp), intent(in) :: p
    real(dp) :: t
    t = s + p
    if (abs(s) >= abs(p)) then
      c = c + ((s - t) + p)
    else
      c = c + ((p - t) + s)
    end if
    s = t
  end subroutine compensated_add

  !> total(k) = global sum of the local compensated sums hi(k) + lo(k), in
  !> one MPI_Allreduce with a double-double reduction (at most
  !> max_reduce_sums entries).
  subroutine reduce_sums(self, hi, lo, total)
    class(qp_problem_t), intent(in) :: self
    real(dp), intent(in) :: hi(:), lo(:)
    real(dp), intent(out) :: total(:)
    real(dp) :: send(2, max_reduce_sums), recv(2, max_reduce_sums)
    integer :: k, ierr
    k = size(hi)
    if (k > max_reduce_sums .or. size(lo) /= k .or. size(total) /= k) &
      call fatal_error('qp_problem: reduce_sums: bad sizes')
    if (.not. dd_ready) call create_dd_reduction()
    send(1, 1:k) = hi
    send(2, 1:k) = lo
    call MPI_Allreduce(send, recv, k, dd_type, dd_op, self%comm, ierr)
    total = recv(1, 1:k) + recv(2, 1:k)
  end subroutine reduce_sums

  !> The MPI datatype (two doubles) and operation of the double-double sum.
  subroutine create_dd_reduction()
    integer :: ierr
    call MPI_Type_contiguous(2, MPI_REAL_DP, dd_type, ierr)
    call MPI_Type_commit(dd_type, ierr)
    call MPI_Op_create(dd_sum, .true., dd_op, ierr)
    dd_ready = .true.
  end subroutine create_dd_reduction

  !> inout <- in + inout for `len` double-double pairs (hi, lo): the hi parts
  !> are added with their exact rounding error (TwoSum) carried in lo.
  subroutine dd_sum(invec, inoutvec, len, datatype)
    type(c_ptr), value :: invec, inoutvec
    integer :: len
    type(MPI_Datatype) :: datatype   ! always dd_type
    real(dp), pointer :: a(:, :), b(:, :)
    real(dp) :: t, v, e
    integer :: k
    call c_f_pointer(invec, a, [2, len])
    call c_f_pointer(inoutvec, b, [2, len])
    do k = 1, len
      t = a(1, k) + b(1, k)
      v = t - a(1, k)
      e = (a(1, k) - (t - v)) + (b(1, k) - v)
      b(2, k) = (a(2, k) + b(2, k)) + e
      b(1, k) = t
    end do
  end subroutine dd_sum

  !> Minimum of `a` over the ranks of comm.
  real(dp) function global_min(self, a)
    class(qp_problem_t), intent(in) :: self
    real(dp), intent(in) :: a
    integer :: ierr
    call MPI_Allreduce(a, global_min, 1, MPI_REAL_DP, MPI_MIN, self%comm, ierr)
  end function global_min

  !> Global number of components with x_i <= l_i (x_i at its bound).
  integer(ip) function count_at_bound(self, x)
    class(qp_problem_t), intent(in) :: self
    real(dp), intent(in) :: x(:)
    integer(ip) :: local
    integer :: ierr
    local = int(count(x(1:self%n) <= self%lower(1:self%n) .and. self%lower(1:self%n) > no_lower_bound), ip)
    call MPI_Allreduce(local, count_at_bound, 1, MPI_INT_IP, MPI_SUM, self%comm, ierr)
  end function count_at_bound

  !> x <- max(x, l), the projection onto the bounds (local, no communication).
  subroutine project(self, x)
    class(qp_problem_t), intent(in) :: self
    real(dp), intent(inout) :: x(:)
    x(1:self%n) = max(x(1:self%n), self%lower(1:self%n))
  end subroutine project

  !> True when the last solve met its stopping criterion.
  logical function solver_converged(self)
    class(qp_solver_t), intent(in) :: self
    solver_converged = self%status == qp_status_converged
  end function solver_converged

  !> A short name of a status code, for reports.
  function qp_status_name(status) result(name)
    integer, intent(in) :: status
    character(len=:), allocatable :: name
    select case (status)
    case (qp_status_not_run)
      name = 'not run'
    case (qp_status_converged)
      name = 'converged'
    case (qp_status_max_hessian)
      name = 'max_hessian reached'
    case (qp_status_max_outer)
      name = 'max_outer reached'
    case (qp_status_not_finite)
      name = 'non-finite value'
    case (qp_status_breakdown)
      name = 'breakdown'
    case (qp_status_incompatible)
      name = 'problem refused'
    case default
      name = 'unknown status'
    end select
  end function qp_status_name
end module qp_problem
