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
!> Optional parts, each its own small type held as a component (not
!> allocated: the problem has no such part); the solvers use only the parts
!> they need:
!> - `eq` (qp_equality_t): the equality constraint C x = 0 (C with
!>   orthonormal rows, in hat form), the penalty rho C^T C that the Hessian
!>   then contains, and the equality measure of the stopping test; SMALBE
!>   needs it, MPRGP ignores it (it only tells it how x moved);
!> - `prec` (qp_preconditioner_t): M_A^{-1}, which MPRGP and the face solve
!>   use in their CG steps (and its condition watch);
!> - `face` (qp_face_t): the face solver of SMALBE's polish (C restricted to
!>   the free rows of an active set); problems without it never polish.
!> `refined_norm` (||A|| estimated more accurately when first needed) is the
!> one optional binding of the problem itself.
!>
!> Stopping test (what the solvers compare with tol): by default the classical
!> ||g^P|| <= tol ||b|| and ||C x|| <= tol ||b|| in the 2-norm. A problem that
!> allocates `stop_weight` (w_i > 0, local slice) asks instead for a test per
!> component: max_i w_i |v^P_i| <= tol S, v = g - rho C^T C x the gradient
!> without its penalty part, S = `stop_scale` if the problem sets it, else
!> max_i w_i |b_i|; and C x = 0 measured by `eq%measure`: by default
!> max(w) ||C x|| <= tol S, or, for a constraint with `relative_measure`, its
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
  use qp_equality, only: qp_equality_t, moved_other, moved_to_argument, moved_along_argument
  use qp_preconditioner, only: qp_preconditioner_t
  use qp_face, only: qp_face_t
  use mpi_f08, only: MPI_Comm, MPI_COMM_NULL, MPI_Allreduce, MPI_SUM, MPI_MIN, MPI_MAX, MPI_Datatype, MPI_Op, &
                     MPI_Type_contiguous, MPI_Type_commit, MPI_Op_create
  implicit none
  private

  public :: qp_status_name, compensated_add, x_moved
  public :: moved_other, moved_to_argument, moved_along_argument

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
  !> Extensions override `hessian` and allocate the parts they have.
  type, abstract, public :: qp_problem_t
    type(MPI_Comm) :: comm = MPI_COMM_NULL     !< communicator of the distributed vectors
    integer(ip) :: n = 0                       !< local length of x, b, lower on this rank
    real(dp), allocatable :: b(:)              !< linear term (local slice)
    real(dp), allocatable :: lower(:)          !< lower bounds l (local slice), no_lower_bound if none
    !> weights of the per-component stopping test (see the module); not
    !> allocated: the classical 2-norm test
    real(dp), allocatable :: stop_weight(:)
    !> the scale that per-component test compares with; 0: max_i w_i |b_i|
    real(dp) :: stop_scale = 0
    class(qp_equality_t), allocatable :: eq          !< C x = 0 and the penalty (optional)
    class(qp_preconditioner_t), allocatable :: prec  !< M_A^{-1} (optional)
    class(qp_face_t), allocatable :: face            !< the face solver of the polish (optional)
  contains
    procedure(hessian_iface), deferred :: hessian
    procedure :: refined_norm => default_refined_norm
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
  !> lower = no_lower_bound; no parts. Extensions call this in their init.
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
    if (allocated(self%eq)) deallocate (self%eq)
    if (allocated(self%prec)) deallocate (self%prec)
    if (allocated(self%face)) deallocate (self%face)
    self%stop_scale = 0
    self%n = 0
    self%comm = MPI_COMM_NULL
  end subroutine free_base

  !> ||A|| from an estimate made more accurate now, for MPRGP's step length
  !> when it is first needed (a problem that defers its norm estimate, as
  !> dual_problem does, overrides it); 0: nothing better than the norm given
  !> at MPRGP's init. Collective in the overrides.
  real(dp) function default_refined_norm(self)
    class(qp_problem_t), intent(inout) :: self
    default_refined_norm = 0
  end function default_refined_norm

  !> The solvers' notice to the equality constraint (if any) of how x
  !> changed (qp_equality: moved; alpha with moved_along_argument).
  subroutine x_moved(problem, how, alpha)
    class(qp_problem_t), intent(inout) :: problem
    integer, intent(in) :: how
    real(dp), intent(in), optional :: alpha
    if (allocated(problem%eq)) call problem%eq%moved(how, alpha)
  end subroutine x_moved

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
