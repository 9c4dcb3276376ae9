!> Krylov recycling for the face solves of a sequence of QPs with the same
!> Hessian and new right-hand sides (a load history; FETI for multiple
!> right-hand sides). The directions p_j of earlier face CG runs are kept
!> with their images q_j = A p_j (plus a vector C^T c_j of the range of C^T
!> with a lazy face operator), W = [p_j], Q = [q_j], and the Gram matrix
!> W^T Q = W^T A W (the range terms drop out: C p_j = 0). A p_j vanishes on
!> the rows that were active in its run. A new run on the face of `free`
!> (`begin_run`) uses the kept pairs that are vectors of its face (those
!> that vanish on its active rows; the others, after a contact zone shrank,
!> are dropped):
!> - the Galerkin start x <- x + W a, (W^T A W) a = W^T r (r = -P_F g), costs
!>   no Hessian product (g <- g + Q a) and makes r orthogonal to span W;
!> - deflated CG: each preconditioned residual z loses its A-projection onto
!>   span W, z <- z - W (W^T A W)^{-1} Q^T z, so the new directions stay
!>   A-orthogonal to W and r orthogonal to it: CG works on the A-complement
!>   of the kept space (Saad, Yeung, Erhel, Guyomarc'h, SIAM J. Sci. Comput.
!>   21, 2000), where the modes the earlier runs resolved are gone.
!> The solution is that of the face problem either way: only the start and
!> the search space change. The run's own directions are added after the
!> kept ones (the deflation basis of a run is the set kept at its start); at
!> most `capacity` pairs (recycle_pairs, fewer on large problems:
!> recycle_bytes per rank), the oldest dropped first, the kept ones at most
!> two thirds of them at the start of a run. Every routine that takes the
!> problem is collective.
module face_recycle
  use kinds, only: dp, ip, MPI_INT_IP
  use qp_problem, only: qp_problem_t, compensated_add, max_reduce_sums
  use mpi_f08, only: MPI_Allreduce, MPI_IN_PLACE, MPI_LAND, MPI_LOGICAL, MPI_MAX
  implicit none
  private

  !> pairs kept at most: recycle_pairs, fewer where their 2 vectors per pair of the largest local
  !> length would take more than recycle_bytes per rank (at least recycle_min_pairs)
  integer(ip), parameter, public :: recycle_pairs = 96, recycle_min_pairs = 8
  real(dp), parameter, public :: recycle_bytes = 192.0_dp*2**20

  type, public :: face_recycle_t
    logical :: on = .false.                     !< keep directions and use them (the caller's choice)
    integer(ip) :: k = 0                        !< pairs kept (columns 1..k, oldest first)
    integer(ip) :: n_used = 0                   !< pairs the current (last) run started from (its deflation basis)
    integer(ip) :: capacity = 0                 !< pairs kept at most (set by the first begin_run; 0: not yet)
    real(dp), allocatable :: w(:, :), q(:, :)   !< p_j and q_j (local rows, capacity columns)
    real(dp), allocatable :: gram(:, :)         !< W^T Q over the kept columns
    logical, allocatable :: free(:)             !< union of the free rows of the kept pairs' runs
    real(dp), allocatable, private :: chol(:, :), c(:)
  contains
    procedure :: clear
    procedure :: begin_run
    procedure :: start
    procedure :: deflate
    procedure :: add
    procedure :: write_state
    procedure :: read_state
  end type face_recycle_t

contains

  !> Forget every pair.
  subroutine clear(self)
    class(face_recycle_t), intent(inout) :: self
    self%k = 0
    self%n_used = 0
    if (allocated(self%free)) self%free = .false.
  end subroutine clear

  !> Before a run on the face of `free`: the kept pairs restricted to that
  !> face (the module), room for the run's own pairs, the Cholesky factor of
  !> their Gram matrix. True when the run starts from n_used > 0 pairs.
  logical function begin_run(self, problem, free) result(usable)
    class(face_recycle_t), intent(inout) :: self
    class(qp_problem_t), intent(inout) :: problem
    logical, intent(in) :: free(:)
    integer(ip) :: n_max, keep
    integer :: ierr
    usable = .false.
    self%n_used = 0
    if (.not. self%on) return
    if (self%capacity == 0) then
      call MPI_Allreduce(problem%n, n_max, 1, MPI_INT_IP, MPI_MAX, problem%comm, ierr)
      self%capacity = int(min(real(recycle_pairs, dp), recycle_bytes/(16.0_dp*max(n_max, 1_ip))), ip)
      self%capacity = max(self%capacity, recycle_min_pairs)
    end if
    call ensure_store(self, problem%n)
    if (self%k > 0) call restrict(self, problem, free)
    ! room for this run's pairs: the kept ones at most two thirds of the store (the oldest dropped)
    keep = (2*self%capacity)/3
    if (self%k > keep) call drop_oldest(self, self%k - keep)
    self%free(1:problem%n) = self%free(1:problem%n) .and. free(1:problem%n)
    if (self%k == 0) return
    usable = factor(self)
    if (.not. usable) then
      call self%clear()
      return
    end if
    self%n_used = self%k
  end function begin_run

  !> The Galerkin start over the run's basis: a with (W^T A W) a = W^T r,
  !> x <- x + W a, g <- g + Q a. No Hessian product.
  subroutine start(self, problem, x, g, r)
    class(face_recycle_t), intent(inout) :: self
    class(qp_problem_t), intent(inout) :: problem
    real(dp), intent(inout) :: x(:), g(:)
    real(dp), intent(in) :: r(:)
    integer(ip) :: j, n
    n = problem%n
    call projections(self, problem, self%w, r, self%c)
    call solve_gram(self, self%c)
    do j = 1, self%n_used
      x(1:n) = x(1:n) + self%c(j)*self%w(1:n, j)
      g(1:n) = g(1:n) + self%c(j)*self%q(1:n, j)
    end do
  end subroutine start

  !> z <- z - W (W^T A W)^{-1} Q^T z over the run's basis (z a vector of
  !> the face, C z = 0); nothing without one.
  subroutine deflate(self, problem, z)
    class(face_recycle_t), intent(inout) :: self
    class(qp_problem_t), intent(inout) :: problem
    real(dp), intent(inout) :: z(:)
    integer(ip) :: j, n
    if (self%n_used == 0) return
    n = problem%n
    call projections(self, problem, self%q, z, self%c)
    call solve_gram(self, self%c)
    do j = 1, self%n_used
      z(1:n) = z(1:n) - self%c(j)*self%w(1:n, j)
    end do
  end subroutine deflate

  !> Keep the direction p of a CG step on the face of `free` and q, its
  !> image by the face operator (while there is room).
  subroutine add(self, problem, free, p, q)
    class(face_recycle_t), intent(inout) :: self
    class(qp_problem_t), intent(inout) :: problem
    logical, intent(in) :: free(:)
    real(dp), intent(in) :: p(:), q(:)
    integer(ip) :: s, n, nu
    if (.not. self%on) return
    n = problem%n
    call ensure_store(self, n)
    if (self%k >= self%capacity) return
    s = self%k + 1
    self%w(1:n, s) = p(1:n)
    self%q(1:n, s) = q(1:n)
    self%free(1:n) = self%free(1:n) .or. free(1:n)
    ! the new row and column of the Gram matrix: w_j^T q_s (= p_j^T A p_s); projections and
    ! solve_gram work on the first n_used columns, so count s in for the dot products only
    nu = self%n_used
    self%n_used = s
    call projections(self, problem, self%w, self%q(:, s), self%c)
    self%n_used = nu
    self%gram(1:s, s) = self%c(1:s)
    self%gram(s, 1:s) = self%c(1:s)
    self%k = s
  end subroutine add

  !> Drop the kept pairs that are not vectors of the face of `free`: those
  !> that do not vanish on a row active there (a contact zone that shrinks;
  !> a pair is exactly 0 on the rows active in its run). Collective.
  subroutine restrict(self, problem, free)
    class(face_recycle_t), intent(inout) :: self
    class(qp_problem_t), intent(inout) :: problem
    logical, intent(in) :: free(:)
    logical, allocatable :: keep(:), rows(:)
    integer(ip) :: j
    integer :: ierr
    rows = self%free(1:problem%n) .and. .not. free(1:problem%n)
    allocate (keep(self%k))
    do j = 1, self%k
      keep(j) = .not. any(rows .and. self%w(1:problem%n, j) /= 0)
    end do
    call MPI_Allreduce(MPI_IN_PLACE, keep, int(self%k), MPI_LOGICAL, MPI_LAND, problem%comm, ierr)
    do j = self%k, 1, -1
      if (.not. keep(j)) call drop_column(self, j)
    end do
  end subroutine restrict

  !> Drop the `m` oldest pairs.
  subroutine drop_oldest(self, m)
    class(face_recycle_t), intent(inout) :: self
    integer(ip), intent(in) :: m
    integer(ip) :: k
    k = self%k - m
    self%w(:, 1:k) = self%w(:, m + 1:self%k)
    self%q(:, 1:k) = self%q(:, m + 1:self%k)
    self%gram(1:k, 1:k) = self%gram(m + 1:self%k, m + 1:self%k)
    self%k = k
  end subroutine drop_oldest

  !> c(j) = v_j^T y for the columns 1..n_used of `v` (global, compensated sums).
  subroutine projections(self, problem, v, y, c)
    class(face_recycle_t), intent(in) :: self
    class(qp_problem_t), intent(inout) :: problem
    real(dp), intent(in) :: v(:, :), y(:)
    real(dp), intent(out) :: c(:)
    real(dp) :: hi(max_reduce_sums), lo(max_reduce_sums), s(max_reduce_sums)
    integer(ip) :: j0, j, m, i
    do j0 = 1, self%n_used, max_reduce_sums
      m = min(int(max_reduce_sums, ip), self%n_used - j0 + 1)
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

  !> The Cholesky factor of the Gram matrix of the k kept pairs; a pair
  !> whose A-orthogonal part (to the pairs before it) has less than
  !> `dependent` times its energy is dropped first (nearly dependent pairs
  !> would make the Galerkin coefficients round-off). False when no pair
  !> is left. The same on every rank (the Gram matrix is).
  logical function factor(self) result(ok)
    class(face_recycle_t), intent(inout) :: self
    real(dp), parameter :: dependent = 1.0e-8_dp
    integer(ip) :: i, j
    real(dp) :: d
    j = 1
    do while (j <= self%k)
      self%chol(j, 1:j) = self%gram(j, 1:j)
      do i = 1, j - 1
        self%chol(j, i) = (self%chol(j, i) - sum(self%chol(j, 1:i - 1)*self%chol(i, 1:i - 1)))/self%chol(i, i)
      end do
      d = self%gram(j, j) - sum(self%chol(j, 1:j - 1)**2)
      if (d > dependent*abs(self%gram(j, j))) then
        self%chol(j, j) = sqrt(d)
        j = j + 1
      else
        call drop_column(self, j)
      end if
    end do
    ok = self%k > 0
  end function factor

  !> Remove pair j (the later ones move up).
  subroutine drop_column(self, j)
    class(face_recycle_t), intent(inout) :: self
    integer(ip), intent(in) :: j
    integer(ip) :: k
    k = self%k
    self%w(:, j:k - 1) = self%w(:, j + 1:k)
    self%q(:, j:k - 1) = self%q(:, j + 1:k)
    self%gram(j:k - 1, 1:k) = self%gram(j + 1:k, 1:k)
    self%gram(1:k - 1, j:k - 1) = self%gram(1:k - 1, j + 1:k)
    self%k = k - 1
  end subroutine drop_column

  !> c <- (W^T A W)^{-1} c over the run's basis (the Cholesky factor L L^T).
  subroutine solve_gram(self, c)
    class(face_recycle_t), intent(in) :: self
    real(dp), intent(inout) :: c(:)
    integer(ip) :: j, k
    k = self%n_used
    do j = 1, k
      c(j) = (c(j) - sum(self%chol(j, 1:j - 1)*c(1:j - 1)))/self%chol(j, j)
    end do
    do j = k, 1, -1
      c(j) = (c(j) - sum(self%chol(j + 1:k, j)*c(j + 1:k)))/self%chol(j, j)
    end do
  end subroutine solve_gram

  !> The kept pairs to the open unformatted stream unit `u` (a checkpoint:
  !> a restarted history starts its face solves as the uninterrupted one).
  subroutine write_state(self, u, status, msg)
    class(face_recycle_t), intent(in) :: self
    integer, intent(in) :: u
    integer, intent(out) :: status
    character(len=*), intent(inout) :: msg
    integer(ip) :: k
    k = self%k
    write (u, iostat=status, iomsg=msg) self%capacity, k
    if (status /= 0 .or. k == 0) return
    write (u, iostat=status, iomsg=msg) size(self%w, 1, kind=ip), self%w(:, 1:k), self%q(:, 1:k), &
      self%gram(1:k, 1:k), merge(1_ip, 0_ip, self%free)
  end subroutine write_state

  !> The pairs of write_state from unit `u` for n local rows; status /= 0
  !> when unreadable or of other sizes.
  subroutine read_state(self, u, n, status)
    class(face_recycle_t), intent(inout) :: self
    integer, intent(in) :: u
    integer(ip), intent(in) :: n
    integer, intent(out) :: status
    integer(ip) :: k, rows, capacity
    integer(ip), allocatable :: flags(:)
    read (u, iostat=status) capacity, k
    if (status /= 0) return
    status = 1
    if (capacity < 0 .or. k < 0 .or. k > capacity .or. (capacity == 0 .and. k > 0)) return
    status = 0
    self%capacity = capacity
    self%k = 0
    self%n_used = 0
    if (k == 0) return
    call ensure_store(self, n)
    allocate (flags(n))
    read (u, iostat=status) rows
    if (status /= 0) return
    if (rows /= n) then
      status = 1
      return
    end if
    read (u, iostat=status) self%w(:, 1:k), self%q(:, 1:k), self%gram(1:k, 1:k), flags
    if (status /= 0) return
    self%free = flags == 1
    self%k = k
  end subroutine read_state

  !> The arrays for n local rows and `capacity` pairs (emptied when either changes).
  subroutine ensure_store(self, n)
    class(face_recycle_t), intent(inout) :: self
    integer(ip), intent(in) :: n
    if (allocated(self%w)) then
      if (size(self%w, 1) == n .and. size(self%w, 2) == self%capacity) return
      deallocate (self%w, self%q, self%gram, self%chol, self%c, self%free)
    end if
    allocate (self%w(n, self%capacity), self%q(n, self%capacity), &
              self%gram(self%capacity, self%capacity), self%chol(self%capacity, self%capacity), &
              self%c(self%capacity), self%free(n))
    self%free = .false.
    self%k = 0
    self%n_used = 0
  end subroutine ensure_store
end module face_recycle
