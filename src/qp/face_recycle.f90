!> Krylov recycling for the face solves of a sequence of QPs with the same
!> Hessian and new right-hand sides (a load history; FETI for multiple
!> right-hand sides). The directions p_j of earlier face CG runs are kept
!> with their images q_j = A p_j (plus a vector C^T c_j of the range of C^T
!> with a lazy face operator), W = [p_j], Q = [q_j], and the Gram matrix
!> W^T Q = W^T A W (the range terms drop out: C p = 0). A p_j vanishes on
!> the active rows of its run and has C p_j = 0, so it is a vector of every
!> face whose free rows contain those of its run (`usable`). On such a face:
!> - the Galerkin start x <- x + W a, (W^T A W) a = W^T r (r = -P_F g), costs
!>   no Hessian product (g <- g + Q a) and makes r orthogonal to span W;
!> - deflated CG: each preconditioned residual z loses its A-projection onto
!>   span W, z <- z - W (W^T A W)^{-1} Q^T z, so the CG directions stay
!>   A-orthogonal to W and r stays orthogonal to it; CG then works on the
!>   A-complement of the kept space (Saad, Yeung, Erhel, Guyomarc'h, SIAM J.
!>   Sci. Comput. 21, 2000).
!> The solution is that of the face problem either way: only the start and
!> the search space change. At most `capacity` pairs, the oldest replaced
!> first; a run on a face that does not contain the kept free rows (a
!> shrinking contact zone) empties the store first. Every routine that
!> takes the problem is collective.
module face_recycle
  use kinds, only: dp, ip
  use qp_problem, only: qp_problem_t, compensated_add, max_reduce_sums
  use mpi_f08, only: MPI_Allreduce, MPI_IN_PLACE, MPI_LAND, MPI_LOGICAL
  implicit none
  private

  !> pairs kept at most (memory: 2 capacity vectors of the local length)
  integer(ip), parameter, public :: recycle_capacity = 40

  type, public :: face_recycle_t
    logical :: on = .false.                     !< keep directions and use them (the caller's choice)
    integer(ip) :: k = 0                        !< pairs kept
    integer(ip) :: next = 1                     !< the slot the next pair goes to (1..capacity)
    integer(ip) :: n_used = 0                   !< pairs the last `start` used (0: none)
    real(dp), allocatable :: w(:, :), q(:, :)   !< p_j and q_j (local rows, capacity columns)
    real(dp), allocatable :: gram(:, :)         !< W^T Q over the kept slots
    logical, allocatable :: free(:)             !< union of the free rows of the kept pairs' runs
    real(dp), allocatable, private :: chol(:, :), c(:)
    logical, private :: ready = .false.         !< chol holds the Cholesky factor of gram
  contains
    procedure :: clear
    procedure :: usable
    procedure :: start
    procedure :: deflate
    procedure :: add
  end type face_recycle_t

contains

  !> Forget every pair.
  subroutine clear(self)
    class(face_recycle_t), intent(inout) :: self
    self%k = 0
    self%next = 1
    self%n_used = 0
    self%ready = .false.
    if (allocated(self%free)) self%free = .false.
  end subroutine clear

  !> The kept pairs are vectors of the face of `free` (their free rows are
  !> free there); otherwise the store is emptied. False without pairs.
  logical function usable(self, problem, free)
    class(face_recycle_t), intent(inout) :: self
    class(qp_problem_t), intent(inout) :: problem
    logical, intent(in) :: free(:)
    integer :: ierr
    usable = .false.
    self%n_used = 0
    if (.not. self%on) return
    call ensure_store(self, problem%n)
    if (self%k == 0) return
    usable = .not. any(self%free(1:problem%n) .and. .not. free(1:problem%n))
    call MPI_Allreduce(MPI_IN_PLACE, usable, 1, MPI_LOGICAL, MPI_LAND, problem%comm, ierr)
    if (usable) usable = factor(self)
    if (.not. usable) call self%clear()
  end function usable

  !> The Galerkin start on a face where the store is usable: a with
  !> (W^T A W) a = W^T r, x <- x + W a, g <- g + Q a. No Hessian product.
  subroutine start(self, problem, x, g, r)
    class(face_recycle_t), intent(inout) :: self
    class(qp_problem_t), intent(inout) :: problem
    real(dp), intent(inout) :: x(:), g(:)
    real(dp), intent(in) :: r(:)
    integer(ip) :: j, n
    n = problem%n
    call projections(self, problem, self%w, r, self%c)
    call solve_gram(self, self%c)
    do j = 1, self%k
      x(1:n) = x(1:n) + self%c(j)*self%w(1:n, j)
      g(1:n) = g(1:n) + self%c(j)*self%q(1:n, j)
    end do
    self%n_used = self%k
  end subroutine start

  !> z <- z - W (W^T A W)^{-1} Q^T z (z a vector of the face, C z = 0).
  subroutine deflate(self, problem, z)
    class(face_recycle_t), intent(inout) :: self
    class(qp_problem_t), intent(inout) :: problem
    real(dp), intent(inout) :: z(:)
    integer(ip) :: j, n
    n = problem%n
    call projections(self, problem, self%q, z, self%c)
    call solve_gram(self, self%c)
    do j = 1, self%k
      z(1:n) = z(1:n) - self%c(j)*self%w(1:n, j)
    end do
  end subroutine deflate

  !> Keep the direction p of a CG step on the face of `free` and q, its
  !> image by the face operator (the oldest pair makes room when full).
  subroutine add(self, problem, free, p, q)
    class(face_recycle_t), intent(inout) :: self
    class(qp_problem_t), intent(inout) :: problem
    logical, intent(in) :: free(:)
    real(dp), intent(in) :: p(:), q(:)
    integer(ip) :: j, s, n
    if (.not. self%on) return
    n = problem%n
    call ensure_store(self, n)
    s = self%next
    self%w(1:n, s) = p(1:n)
    self%q(1:n, s) = q(1:n)
    self%k = max(self%k, s)
    self%next = mod(s, recycle_capacity) + 1
    self%free(1:n) = self%free(1:n) .or. free(1:n)
    ! the new row and column of the Gram matrix: w_j^T q_s (= p_j^T A p_s)
    call projections(self, problem, self%w, self%q(:, s), self%c)
    do j = 1, self%k
      self%gram(j, s) = self%c(j)
      self%gram(s, j) = self%c(j)
    end do
    self%ready = .false.
  end subroutine add

  !> c(j) = v_j^T y for the kept columns v_j of `v` (global, compensated sums).
  subroutine projections(self, problem, v, y, c)
    class(face_recycle_t), intent(in) :: self
    class(qp_problem_t), intent(inout) :: problem
    real(dp), intent(in) :: v(:, :), y(:)
    real(dp), intent(out) :: c(:)
    real(dp) :: hi(max_reduce_sums), lo(max_reduce_sums), s(max_reduce_sums)
    integer(ip) :: j0, j, m, i
    do j0 = 1, self%k, max_reduce_sums
      m = min(int(max_reduce_sums, ip), self%k - j0 + 1)
      hi = 0
      lo = 0
      do j = 1, m
        do i = 1, problem%n
          call compensated_add(hi(j), lo(j), v(i, j0 + j - 1)*y(i))
        end do
      end do
      call problem%reduce_sums(hi(1:m), lo(1:m), s(1:m))
      c(j0:j0 + m - 1) = s(1:m)
    end do
  end subroutine projections

  !> The Cholesky factor of the Gram matrix; false (not positive definite
  !> to round-off: nearly dependent pairs) when it fails. The same on every
  !> rank (the Gram matrix is).
  logical function factor(self) result(ok)
    class(face_recycle_t), intent(inout) :: self
    integer(ip) :: i, j, k
    real(dp) :: d
    ok = .true.
    if (self%ready) return
    k = self%k
    self%chol(1:k, 1:k) = self%gram(1:k, 1:k)
    do j = 1, k
      d = self%chol(j, j) - sum(self%chol(j, 1:j - 1)**2)
      if (.not. d > 1.0e-14_dp*abs(self%gram(j, j))) then
        ok = .false.
        return
      end if
      self%chol(j, j) = sqrt(d)
      do i = j + 1, k
        self%chol(i, j) = (self%chol(i, j) - sum(self%chol(i, 1:j - 1)*self%chol(j, 1:j - 1)))/self%chol(j, j)
      end do
    end do
    self%ready = .true.
  end function factor

  !> c <- (W^T A W)^{-1} c by the Cholesky factor (L L^T).
  subroutine solve_gram(self, c)
    class(face_recycle_t), intent(in) :: self
    real(dp), intent(inout) :: c(:)
    integer(ip) :: j
    do j = 1, self%k
      c(j) = (c(j) - sum(self%chol(j, 1:j - 1)*c(1:j - 1)))/self%chol(j, j)
    end do
    do j = self%k, 1, -1
      c(j) = (c(j) - sum(self%chol(j + 1:self%k, j)*c(j + 1:self%k)))/self%chol(j, j)
    end do
  end subroutine solve_gram

  !> The arrays for n local rows (emptied when n changes).
  subroutine ensure_store(self, n)
    class(face_recycle_t), intent(inout) :: self
    integer(ip), intent(in) :: n
    if (allocated(self%w)) then
      if (size(self%w, 1) == n) return
      deallocate (self%w, self%q, self%gram, self%chol, self%c, self%free)
    end if
    allocate (self%w(n, recycle_capacity), self%q(n, recycle_capacity), &
              self%gram(recycle_capacity, recycle_capacity), self%chol(recycle_capacity, recycle_capacity), &
              self%c(recycle_capacity), self%free(n))
    self%free = .false.
    self%k = 0
    self%next = 1
    self%ready = .false.
  end subroutine ensure_store
end module face_recycle
