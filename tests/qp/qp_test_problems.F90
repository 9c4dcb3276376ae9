!> Small QPs with a solution known by construction, and a dense distributed
!> qp_problem_t to hand them to the solvers.
!>
!> A case is built on every rank from the same seed (identical data):
!> - A0 = Q diag(e) Q^T, Q a random orthogonal matrix, e log-spaced in
!>   [1, cond] (so ||A0|| = cond and kappa(A0) = cond);
!> - without equality: A = A0; with m equality rows: C (random rows, or
!>   orthonormalized rows), U an orthonormal basis of its rows, Q_C = U^T U,
!>   P = I - Q_C and A = P A0 P + rho Q_C with rho = rho_scale ||A0||, the
!>   structure of the FETI dual (A = P F P + rho Q);
!> - x* = P y for a random y (so C x* = 0), a random active set with
!>   multipliers s > 0 (s = 0 on `n_degenerate` of them), l_i = x*_i on the
!>   active set, l_i = no_lower_bound on `n_unbounded` others and
!>   l_i = x*_i - (0.1 + u) on the rest;
!> - muhat* random, and b = A x* + C^T muhat* - s, so that the KKT conditions
!>   A x* - b + C^T muhat* = s >= 0, s_i (x*_i - l_i) = 0, C x* = 0 hold.
!> With general rows the hat form is used: z = (C C^T)^{-1} C x,
!> ||C~ x||^2 = (C x)^T z, C~^T mu = C^T muhat.
module qp_test_problems
  use, intrinsic :: ieee_arithmetic, only: ieee_value, ieee_quiet_nan
  use kinds, only: dp, ip, MPI_REAL_DP
  use errors, only: fatal_error
  use qp_problem, only: qp_problem_t, no_lower_bound
  use qp_equality, only: qp_equality_t
  use qp_face, only: qp_face_t
  use smalbe, only: smalbe_settings_t
  use mpi_f08, only: MPI_Comm, MPI_Comm_rank, MPI_Comm_size, MPI_Allgatherv
  implicit none
  private

  public :: make_case, count_slack, plain_smalbe

  !> The global (replicated) data of one test QP and its exact solution.
  type, public :: qp_case_t
    integer(ip) :: n = 0, m = 0
    real(dp), allocatable :: a(:, :), b(:), lower(:), x_star(:), s_star(:)
    real(dp), allocatable :: c(:, :), muhat_star(:)
    real(dp) :: rho = 0, a_norm = 0
    logical :: orthonormal = .false.
  end type qp_case_t

  !> A dense QP whose rows are split over the ranks of comm; A x and C x
  !> gather x with MPI_Allgatherv and sum in a fixed order, so that their
  !> results do not depend on the number of ranks. Counts Hessian calls; after `poison_after` calls
  !> (if >= 0) the Hessian returns NaN (to test the safeguards).
  type, extends(qp_problem_t), public :: dense_qp_t
    integer(ip) :: n_global = 0, offset = 0, m = 0
    real(dp), allocatable :: a_rows(:, :)      !< (n, n_global)
    real(dp), allocatable :: c_cols(:, :)      !< (m, n) local columns of C
    real(dp), allocatable :: c_full(:, :)      !< (m, n_global) all of C
    real(dp), allocatable :: cct_chol(:, :)    !< lower Cholesky factor of C C^T
    real(dp), allocatable :: q_rows(:, :)      !< (n, n_global) local rows of Q = C^T (C C^T)^{-1} C
    logical :: orthonormal = .false.
    real(dp) :: rho = 0
    integer, allocatable :: counts(:), displs(:)
    real(dp), allocatable :: x_global(:)
    integer(ip) :: n_hessian_calls = 0
    integer(ip) :: poison_after = -1
    real(dp), allocatable :: face_chol(:, :)   !< lower Cholesky factor of C_F C_F^T
  contains
    procedure :: create
    procedure :: gather
    procedure :: enable_face
    procedure :: hessian => dense_hessian
  end type dense_qp_t

  !> The parts of the dense QP (qp_problem): C from its matrix, and the face
  !> solver by a dense Cholesky factorization of C_F C_F^T; each works on its
  !> owner's data (the owner must stay where it is while they live).
  type, extends(qp_equality_t) :: dense_equality_t
    class(dense_qp_t), pointer :: owner => null()
  contains
    procedure :: size => dense_eq_size
    procedure :: residual => dense_eq_residual
    procedure :: apply_t => dense_eq_apply_t
    procedure :: penalty => dense_penalty
    procedure :: set_penalty => dense_set_penalty
  end type dense_equality_t

  type, extends(qp_face_t) :: dense_face_t
    class(dense_qp_t), pointer :: owner => null()
  contains
    procedure :: init => dense_face_init
    procedure :: coefficient => dense_face_coefficient
    procedure :: apply => dense_face_apply
    procedure :: release => dense_face_free
    procedure :: regular => dense_face_regular
  end type dense_face_t

contains

  !> SMALBE-M as in the literature, the solver these tests were written for
  !> (the library's defaults are the program's: polish, adaptive rho and the
  !> monitor on): no polish, rho constant, no monitor; tol and the caps given,
  !> the inner MPRGP's expansion and the monitor optional.
  function plain_smalbe(tol, max_outer, max_hessian, expansion, monitor) result(s)
    real(dp), intent(in) :: tol
    integer(ip), intent(in) :: max_outer, max_hessian
    character(len=*), intent(in), optional :: expansion
    logical, intent(in), optional :: monitor
    type(smalbe_settings_t) :: s
    s%tol = tol
    s%max_outer = max_outer
    s%max_hessian = max_hessian
    s%rho_growth = 1
    s%rho_window = 1
    s%rho_stall = 0
    s%monitor = .false.
    if (present(monitor)) s%monitor = monitor
    if (present(expansion)) s%inner%expansion = expansion
    s%polish%window = 0
    s%polish%rounds = 3
    s%polish%release = .false.
    s%polish%settle = 0
    s%polish%loose = 0
    s%polish%predict = 0
    s%polish%release_share = 0
    s%polish%first = .false.
  end function plain_smalbe

  !> Build a case (see the module). m = 0: no equality constraint.
  subroutine make_case(cs, n, m, cond, n_active, n_degenerate, n_unbounded, orthonormal, seed, rho_scale)
    type(qp_case_t), intent(out) :: cs
    integer(ip), intent(in) :: n, m, n_active, n_degenerate, n_unbounded, seed
    real(dp), intent(in) :: cond
    logical, intent(in) :: orthonormal
    real(dp), intent(in), optional :: rho_scale
    real(dp), allocatable :: q(:, :), a0(:, :), u(:, :), p(:, :), y(:), e(:)
    integer(ip), allocatable :: perm(:)
    integer(ip) :: i, j, k
    real(dp) :: r

    if (n_active + n_unbounded > n .or. n_degenerate > n_active) call fatal_error('make_case: bad sizes')
    call seed_random(seed)
    cs%n = n
    cs%m = m
    cs%orthonormal = orthonormal
    allocate (q(n, n), a0(n, n), e(n), y(n), p(n, n), perm(n))
    call random_orthogonal(q)
    do i = 1, n
      e(i) = cond**(real(i - 1, dp)/real(max(n - 1, 1), dp))
    end do
    do j = 1, n
      do i = 1, n
        a0(i, j) = sum(q(i, :)*e*q(j, :))
      end do
    end do
    a0 = 0.5_dp*(a0 + transpose(a0))

    p = 0
    do i = 1, n
      p(i, i) = 1
    end do
    allocate (cs%a(n, n), cs%muhat_star(m), cs%c(m, n))
    if (m > 0) then
      call random_normal_matrix(cs%c)
      allocate (u(m, n))
      u = cs%c
      call orthonormalize_rows(u)
      if (orthonormal) cs%c = u
      p = p - matmul(transpose(u), u)
      cs%rho = cond
      if (present(rho_scale)) cs%rho = rho_scale*cond
      cs%a = matmul(p, matmul(a0, p)) + cs%rho*matmul(transpose(u), u)
      cs%a = 0.5_dp*(cs%a + transpose(cs%a))
      call random_normal_vector(cs%muhat_star)
      cs%a_norm = max(cond, cs%rho)
    else
      cs%a = a0
      cs%a_norm = cond
    end if

    call random_normal_vector(y)
    cs%x_star = matmul(p, y)
    call random_permutation(perm)
    allocate (cs%lower(n), cs%s_star(n))
    cs%s_star = 0
    do k = 1, n
      i = perm(k)
      if (k <= n_active) then
        cs%lower(i) = cs%x_star(i)
        if (k > n_degenerate) then
          call random_number(r)
          cs%s_star(i) = 0.5_dp + r
        end if
      else if (k <= n_active + n_unbounded) then
        cs%lower(i) = no_lower_bound
      else
        call random_number(r)
        cs%lower(i) = cs%x_star(i) - (0.1_dp + r)
      end if
    end do
    cs%b = matmul(cs%a, cs%x_star) - cs%s_star
    if (m > 0) cs%b = cs%b + matmul(transpose(cs%c), cs%muhat_star)
  end subroutine make_case

  !> The slice of `cs` owned by this rank of comm (rows split as evenly as
  !> possible, the first ranks get one more). with_equality = .false. drops C.
  subroutine create(self, comm, cs, with_equality)
    class(dense_qp_t), intent(inout), target :: self
    type(MPI_Comm), intent(in) :: comm
    type(qp_case_t), intent(in) :: cs
    logical, intent(in) :: with_equality
    integer :: rank, nranks, ierr, r
    integer(ip) :: n, j
    real(dp), allocatable :: cct(:, :)

    call MPI_Comm_rank(comm, rank, ierr)
    call MPI_Comm_size(comm, nranks, ierr)
    if (allocated(self%counts)) deallocate (self%counts, self%displs)
    allocate (self%counts(nranks), self%displs(nranks))
    do r = 0, nranks - 1
      self%counts(r + 1) = cs%n/nranks
      if (r < mod(cs%n, nranks)) self%counts(r + 1) = self%counts(r + 1) + 1
    end do
    self%displs(1) = 0
    do r = 2, nranks
      self%displs(r) = self%displs(r - 1) + self%counts(r - 1)
    end do
    n = self%counts(rank + 1)
    self%offset = self%displs(rank + 1)
    self%n_global = cs%n
    call self%init_base(comm, n)
    self%b = cs%b(self%offset + 1:self%offset + n)
    self%lower = cs%lower(self%offset + 1:self%offset + n)
    self%a_rows = cs%a(self%offset + 1:self%offset + n, :)
    self%x_global = cs%b
    self%n_hessian_calls = 0
    self%poison_after = -1
    self%m = 0
    self%rho = 0
    if (with_equality .and. cs%m > 0) then
      allocate (dense_equality_t :: self%eq)
      select type (part => self%eq)
      type is (dense_equality_t)
        part%owner => self
      end select
      self%m = cs%m
      self%rho = cs%rho
      self%orthonormal = cs%orthonormal
      self%c_cols = cs%c(:, self%offset + 1:self%offset + n)
      self%c_full = cs%c
      cct = matmul(cs%c, transpose(cs%c))
      call cholesky(cct)
      self%cct_chol = cct
      do j = 1, cs%m
        self%cct_chol(1:j - 1, j) = 0
      end do
      ! the rows of the projector Q onto Im C^T owned here (the penalty's C^T C)
      if (allocated(self%q_rows)) deallocate (self%q_rows)
      allocate (self%q_rows(n, cs%n))
      do j = 1, cs%n
        self%q_rows(:, j) = matmul(transpose(self%c_cols), cholesky_solve(self%cct_chol, cs%c(:, j)))
      end do
    end if
  end subroutine create

  !> The full vector from the local slices.
  subroutine gather(self, x, x_full)
    class(dense_qp_t), intent(in) :: self
    real(dp), intent(in) :: x(:)
    real(dp), intent(out) :: x_full(:)
    integer :: ierr
    call MPI_Allgatherv(x, int(self%n), MPI_REAL_DP, x_full, self%counts, self%displs, MPI_REAL_DP, &
                        self%comm, ierr)
  end subroutine gather

  subroutine dense_hessian(self, x, y)
    class(dense_qp_t), intent(inout) :: self
    real(dp), intent(in) :: x(:)
    real(dp), intent(out) :: y(:)
    integer :: ierr
    integer(ip) :: i
    self%n_hessian_calls = self%n_hessian_calls + 1
    call MPI_Allgatherv(x, int(self%n), MPI_REAL_DP, self%x_global, self%counts, self%displs, MPI_REAL_DP, &
                        self%comm, ierr)
    ! row by row in a fixed order: the result does not depend on the distribution
    do i = 1, self%n
      y(i) = dot_product(self%a_rows(i, :), self%x_global)
    end do
    if (self%poison_after >= 0 .and. self%n_hessian_calls > self%poison_after) &
      y(1:self%n) = ieee_value(1.0_dp, ieee_quiet_nan)
  end subroutine dense_hessian

  !> The face solver (SMALBE's polish) on or off: C_F C_F^T by a dense
  !> Cholesky factorization (the test cases keep m well below the free rows:
  !> every C_F has full row rank, the face is regular).
  subroutine enable_face(self, on)
    class(dense_qp_t), intent(inout), target :: self
    logical, intent(in) :: on
    if (allocated(self%face)) deallocate (self%face)
    if (.not. (on .and. allocated(self%eq))) return
    allocate (dense_face_t :: self%face)
    select type (part => self%face)
    type is (dense_face_t)
      part%owner => self
    end select
  end subroutine enable_face

  real(dp) function dense_penalty(self)
    class(dense_equality_t), intent(in) :: self
    dense_penalty = self%owner%rho
  end function dense_penalty

  !> A <- A + (rho - penalty()) Q: the penalty raised (or lowered) to rho.
  subroutine dense_set_penalty(self, rho)
    class(dense_equality_t), intent(inout) :: self
    real(dp), intent(in) :: rho
    associate (o => self%owner)
      o%a_rows = o%a_rows + (rho - o%rho)*o%q_rows
      o%rho = rho
    end associate
  end subroutine dense_set_penalty

  integer(ip) function dense_eq_size(self)
    class(dense_equality_t), intent(in) :: self
    dense_eq_size = self%owner%m
  end function dense_eq_size

  !> cnorm = ||C~ x||, z = C x (orthonormal rows) or (C C^T)^{-1} C x.
  subroutine dense_eq_residual(self, x, z, cnorm)
    class(dense_equality_t), intent(inout) :: self
    real(dp), intent(in) :: x(:)
    real(dp), intent(out) :: z(:)
    real(dp), intent(out) :: cnorm
    real(dp) :: cx(self%owner%m)
    integer :: ierr
    integer(ip) :: k
    associate (o => self%owner)
      ! C x from the gathered x (a fixed summation order on every rank count)
      call MPI_Allgatherv(x, int(o%n), MPI_REAL_DP, o%x_global, o%counts, o%displs, MPI_REAL_DP, &
                          o%comm, ierr)
      do k = 1, o%m
        cx(k) = dot_product(o%c_full(k, :), o%x_global)
      end do
      if (o%orthonormal) then
        z(1:o%m) = cx
      else
        z(1:o%m) = cholesky_solve(o%cct_chol, cx)
      end if
      cnorm = sqrt(max(dot_product(cx, z(1:o%m)), 0.0_dp))
    end associate
  end subroutine dense_eq_residual

  !> y = C^T muhat (local rows).
  subroutine dense_eq_apply_t(self, muhat, y)
    class(dense_equality_t), intent(inout) :: self
    real(dp), intent(in) :: muhat(:)
    real(dp), intent(out) :: y(:)
    associate (o => self%owner)
      y(1:o%n) = matmul(transpose(o%c_cols), muhat(1:o%m))
    end associate
  end subroutine dense_eq_apply_t

  !> Regular: see enable_face.
  logical function dense_face_regular(self)
    class(dense_face_t), intent(in) :: self
    dense_face_regular = associated(self%owner)
  end function dense_face_regular

  !> C_F C_F^T of the free rows (local mask `free`, gathered), factorized.
  subroutine dense_face_init(self, free, reused)
    class(dense_face_t), intent(inout) :: self
    logical, intent(in) :: free(:)
    logical, intent(out), optional :: reused
    real(dp), allocatable :: mask(:), cf(:, :)
    integer(ip) :: j
    if (present(reused)) reused = .false.
    associate (o => self%owner)
      allocate (mask(o%n_global))
      call o%gather(merge(1.0_dp, 0.0_dp, free(1:o%n)), mask)
      cf = o%c_full
      do j = 1, o%n_global
        cf(:, j) = mask(j)*cf(:, j)
      end do
      o%face_chol = matmul(cf, transpose(cf))
      call cholesky(o%face_chol)
      do j = 1, o%m
        o%face_chol(1:j - 1, j) = 0
      end do
    end associate
  end subroutine dense_face_init

  !> c = (C_F C_F^T)^{-1} C y (y the whole local slice), the form apply_t takes.
  subroutine dense_face_coefficient(self, x, y)
    class(dense_face_t), intent(inout) :: self
    real(dp), intent(in) :: x(:)
    real(dp), intent(out) :: y(:)
    real(dp) :: cy(self%owner%m)
    integer(ip) :: k
    associate (o => self%owner)
      call o%gather(x(1:o%n), o%x_global)
      do k = 1, o%m
        cy(k) = dot_product(o%c_full(k, :), o%x_global)
      end do
      y(1:o%m) = cholesky_solve(o%face_chol, cy)
    end associate
  end subroutine dense_face_coefficient

  !> q = A p: the Hessian.
  subroutine dense_face_apply(self, x, y)
    class(dense_face_t), intent(inout) :: self
    real(dp), intent(in) :: x(:)
    real(dp), intent(out) :: y(:)
    call self%owner%hessian(x, y)
  end subroutine dense_face_apply

  subroutine dense_face_free(self)
    class(dense_face_t), intent(inout) :: self
    if (allocated(self%owner%face_chol)) deallocate (self%owner%face_chol)
  end subroutine dense_face_free

  ! ---- small dense helpers -------------------------------------------------

  subroutine seed_random(seed)
    integer(ip), intent(in) :: seed
    integer, allocatable :: s(:)
    integer :: k, i
    call random_seed(size=k)
    allocate (s(k))
    do i = 1, k
      s(i) = 104729*i + 7919*seed + 13
    end do
    call random_seed(put=s)
  end subroutine seed_random

  subroutine random_normal_vector(v)
    real(dp), intent(out) :: v(:)
    real(dp) :: u1, u2
    integer :: i
    do i = 1, size(v)
      call random_number(u1)
      call random_number(u2)
      v(i) = sqrt(-2*log(1 - u1))*cos(8*atan(1.0_dp)*u2)
    end do
  end subroutine random_normal_vector

  subroutine random_normal_matrix(a)
    real(dp), intent(out) :: a(:, :)
    integer :: j
    do j = 1, size(a, 2)
      call random_normal_vector(a(:, j))
    end do
  end subroutine random_normal_matrix

  !> Columns of a random normal matrix, orthonormalized (Gram-Schmidt twice).
  subroutine random_orthogonal(q)
    real(dp), intent(out) :: q(:, :)
    real(dp), allocatable :: t(:, :)
    call random_normal_matrix(q)
    t = transpose(q)
    call orthonormalize_rows(t)
    q = transpose(t)
  end subroutine random_orthogonal

  !> Modified Gram-Schmidt on the rows, twice.
  subroutine orthonormalize_rows(u)
    real(dp), intent(inout) :: u(:, :)
    integer :: i, j, pass
    do pass = 1, 2
      do i = 1, size(u, 1)
        do j = 1, i - 1
          u(i, :) = u(i, :) - dot_product(u(j, :), u(i, :))*u(j, :)
        end do
        u(i, :) = u(i, :)/norm2(u(i, :))
      end do
    end do
  end subroutine orthonormalize_rows

  subroutine random_permutation(perm)
    integer(ip), intent(out) :: perm(:)
    integer(ip) :: i, j, t
    real(dp) :: r
    perm = [(i, i=1, size(perm))]
    do i = size(perm), 2, -1
      call random_number(r)
      j = 1 + int(r*i, ip)
      j = min(j, i)
      t = perm(i)
      perm(i) = perm(j)
      perm(j) = t
    end do
  end subroutine random_permutation

  !> In place: lower triangle of a <- L with a = L L^T.
  subroutine cholesky(a)
    real(dp), intent(inout) :: a(:, :)
    integer :: j, i
    do j = 1, size(a, 1)
      a(j, j) = sqrt(a(j, j) - dot_product(a(j, 1:j - 1), a(j, 1:j - 1)))
      do i = j + 1, size(a, 1)
        a(i, j) = (a(i, j) - dot_product(a(i, 1:j - 1), a(j, 1:j - 1)))/a(j, j)
      end do
    end do
  end subroutine cholesky

  function cholesky_solve(l, r) result(x)
    real(dp), intent(in) :: l(:, :), r(:)
    real(dp) :: x(size(r))
    integer :: i
    do i = 1, size(r)
      x(i) = (r(i) - dot_product(l(i, 1:i - 1), x(1:i - 1)))/l(i, i)
    end do
    do i = size(r), 1, -1
      x(i) = (x(i) - dot_product(l(i + 1:, i), x(i + 1:)))/l(i, i)
    end do
  end function cholesky_solve

  !> How far the step counts of the serial and the distributed run may be
  !> apart: 0 when the iterates are the same bits; otherwise a rounding
  !> difference may move one decision (a step type, the stopping iteration),
  !> so they may differ by 10% + 2 (more would mean another algorithm, not
  !> another rounding).
  pure integer function count_slack(serial, identical)
    integer(ip), intent(in) :: serial
    logical, intent(in) :: identical
    if (identical) then
      count_slack = 0
    else
      count_slack = 2 + serial/10
    end if
  end function count_slack
end module qp_test_problems
