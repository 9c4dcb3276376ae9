!> Condition estimates from the coefficients of conjugate gradient runs.
!>
!> A (preconditioned) CG run with step lengths alpha_1..alpha_m and
!> conjugation coefficients beta_1..beta_{m-1} (the standard ones,
!> beta_k = r_{k+1}^T z_{k+1} / r_k^T z_k >= 0) is a Lanczos process for the
!> (preconditioned) operator; its tridiagonal matrix T_m has
!>
!>     T(1,1)   = 1/alpha_1
!>     T(k,k)   = 1/alpha_k + beta_{k-1}/alpha_{k-1}     (k >= 2)
!>     T(k,k+1) = sqrt(beta_k)/alpha_k,
!>
!> and its eigenvalues (Ritz values) approach the extreme eigenvalues of the
!> operator from inside: theta_max/theta_min is a lower bound of its
!> condition number that grows towards it with m (Golub and Van Loan,
!> "Matrix Computations", 4th ed., Sec. 11.3.5). `cg_ritz_t` collects the
!> coefficients of one run at a time (`begin_run`, `add_alpha`, `add_beta`,
!> `end_run`) and keeps, over all runs since `reset`: the number of runs of
!> at least 2 steps, the longest run, the largest ratio theta_max/theta_min
!> of a run and the extreme Ritz values. The extreme eigenvalues of T are
!> found by bisection on Sturm counts (no LAPACK), 2 x 60 counts of O(m).
!> A run whose coefficients are not positive and finite (round-off, or a
!> step that changed the face) is cut there.
module ritz_values
  use, intrinsic :: ieee_arithmetic, only: ieee_is_finite
  use kinds, only: dp, ip
  implicit none
  private

  public :: tridiagonal_extremes

  type, public :: cg_ritz_t
    integer(ip) :: n_runs = 0                  !< runs of >= 2 steps since reset
    integer(ip) :: longest = 0                 !< steps of the longest run
    real(dp) :: max_ratio = 0                  !< largest theta_max/theta_min of a run (0: none)
    real(dp) :: theta_min = huge(1.0_dp)       !< smallest Ritz value of all runs
    real(dp) :: theta_max = 0                  !< largest Ritz value of all runs
    integer(ip) :: m = 0                       !< steps of the current run
    logical :: open = .false.                  !< a run is being collected
    real(dp), allocatable :: alpha(:), beta(:) !< coefficients of the current run
  contains
    procedure :: reset
    procedure :: begin_run
    procedure :: add_alpha
    procedure :: add_beta
    procedure :: end_run
    procedure :: current_ratio
    procedure :: merge
  end type cg_ritz_t

contains

  !> Forget all runs.
  subroutine reset(self)
    class(cg_ritz_t), intent(inout) :: self
    self%n_runs = 0
    self%longest = 0
    self%max_ratio = 0
    self%theta_min = huge(1.0_dp)
    self%theta_max = 0
    self%m = 0
    self%open = .false.
  end subroutine reset

  !> Start a new run (ends the current one).
  subroutine begin_run(self)
    class(cg_ritz_t), intent(inout) :: self
    call self%end_run()
    self%m = 0
    self%open = .true.
  end subroutine begin_run

  !> The step length of the next step of the run.
  subroutine add_alpha(self, alpha)
    class(cg_ritz_t), intent(inout) :: self
    real(dp), intent(in) :: alpha
    if (.not. self%open) return
    if (.not. (alpha > 0 .and. ieee_is_finite(alpha) .and. ieee_is_finite(1/alpha))) then
      call self%end_run()
      return
    end if
    call grow(self, self%m + 1)
    self%m = self%m + 1
    self%alpha(self%m) = alpha
  end subroutine add_alpha

  !> The conjugation coefficient that follows the last step length.
  subroutine add_beta(self, beta)
    class(cg_ritz_t), intent(inout) :: self
    real(dp), intent(in) :: beta
    if (.not. self%open) return
    if (.not. (beta >= 0 .and. ieee_is_finite(beta))) then
      call self%end_run()
      return
    end if
    call grow(self, self%m)
    self%beta(self%m) = beta
  end subroutine add_beta

  !> Close the current run: its Ritz values enter the statistics.
  subroutine end_run(self)
    class(cg_ritz_t), intent(inout) :: self
    real(dp), allocatable :: d(:), e(:)
    real(dp) :: lo, hi
    integer(ip) :: k, m
    if (.not. self%open) return
    self%open = .false.
    m = self%m
    self%m = 0
    if (m < 2) return
    allocate (d(m), e(max(m - 1, 1)))
    d(1) = 1/self%alpha(1)
    do k = 2, m
      d(k) = 1/self%alpha(k) + self%beta(k - 1)/self%alpha(k - 1)
      e(k - 1) = sqrt(self%beta(k - 1))/self%alpha(k - 1)
    end do
    call tridiagonal_extremes(d, e(1:m - 1), lo, hi)
    if (.not. (lo > 0 .and. hi >= lo .and. ieee_is_finite(hi))) return
    self%n_runs = self%n_runs + 1
    self%longest = max(self%longest, m)
    self%max_ratio = max(self%max_ratio, hi/lo)
    self%theta_min = min(self%theta_min, lo)
    self%theta_max = max(self%theta_max, hi)
  end subroutine end_run

  !> theta_max/theta_min of the run being collected, from its m step lengths
  !> and m-1 conjugation coefficients (0 when it has fewer than 2 steps or
  !> its Ritz values are not positive and finite). The run stays open; this
  !> is the running condition estimate `&solver preconditioner = 'auto'`
  !> watches after every CG step, so it bisects to 2^-28 of the Gershgorin
  !> interval only (2 x 28 Sturm counts of O(m): relative error of
  !> theta_min below 1e-5 for ratios up to 1e3, enough for a threshold test;
  !> measured 16 -> 7 us at m = 25).
  real(dp) function current_ratio(self) result(ratio)
    class(cg_ritz_t), intent(in) :: self
    real(dp) :: d(self%m), e(max(self%m - 1, 0))   ! automatic: no heap allocation per CG step
    real(dp) :: lo, hi
    integer(ip) :: k, m
    ratio = 0
    m = self%m
    if (.not. self%open .or. m < 2) return
    d(1) = 1/self%alpha(1)
    do k = 2, m
      d(k) = 1/self%alpha(k) + self%beta(k - 1)/self%alpha(k - 1)
      e(k - 1) = sqrt(self%beta(k - 1))/self%alpha(k - 1)
    end do
    call tridiagonal_extremes(d, e, lo, hi, 28)
    if (lo > 0 .and. hi >= lo .and. ieee_is_finite(hi)) ratio = hi/lo
  end function current_ratio

  !> Add the statistics of `other` (closed runs only) to these.
  subroutine merge(self, other)
    class(cg_ritz_t), intent(inout) :: self
    type(cg_ritz_t), intent(in) :: other
    if (other%n_runs == 0) return
    self%n_runs = self%n_runs + other%n_runs
    self%longest = max(self%longest, other%longest)
    self%max_ratio = max(self%max_ratio, other%max_ratio)
    self%theta_min = min(self%theta_min, other%theta_min)
    self%theta_max = max(self%theta_max, other%theta_max)
  end subroutine merge

  !> Capacity for n coefficients (doubling; no allocation in most steps).
  subroutine grow(self, n)
    type(cg_ritz_t), intent(inout) :: self
    integer(ip), intent(in) :: n
    real(dp), allocatable :: t(:)
    integer(ip) :: cap
    if (.not. allocated(self%alpha)) allocate (self%alpha(64), self%beta(64))
    if (n <= size(self%alpha)) return
    cap = max(n, 2*size(self%alpha, kind=ip))
    allocate (t(cap))
    t(1:size(self%alpha)) = self%alpha
    call move_alloc(t, self%alpha)
    allocate (t(cap))
    t(1:size(self%beta)) = self%beta
    call move_alloc(t, self%beta)
  end subroutine grow

  !> Smallest and largest eigenvalue of the symmetric tridiagonal matrix with
  !> diagonal d(1:m) and off-diagonal e(1:m-1), by bisection on the Sturm
  !> count (number of eigenvalues below x = negative pivots of T - x I) from
  !> the Gershgorin interval, to about 1e-14 of its width (60 halvings, or
  !> `halvings`).
  subroutine tridiagonal_extremes(d, e, lo, hi, halvings)
    real(dp), intent(in) :: d(:), e(:)
    real(dp), intent(out) :: lo, hi
    integer, intent(in), optional :: halvings
    real(dp) :: a, b, x, r
    integer(ip) :: m, k, it, nh
    m = size(d, kind=ip)
    if (m == 0) then
      lo = 0
      hi = 0
      return
    end if
    a = huge(1.0_dp)
    b = -huge(1.0_dp)
    do k = 1, m
      r = 0
      if (k > 1) r = r + abs(e(k - 1))
      if (k < m) r = r + abs(e(k))
      a = min(a, d(k) - r)
      b = max(b, d(k) + r)
    end do
    nh = 60
    if (present(halvings)) nh = halvings
    ! smallest: the largest x with count(x) = 0
    lo = a
    hi = b
    do it = 1, nh
      x = 0.5_dp*(lo + hi)
      if (sturm_count(x) >= 1) then
        hi = x
      else
        lo = x
      end if
    end do
    x = 0.5_dp*(lo + hi)
    ! largest: the smallest x with count(x) = m
    lo = a
    hi = b
    do it = 1, nh
      r = 0.5_dp*(lo + hi)
      if (sturm_count(r) >= m) then
        hi = r
      else
        lo = r
      end if
    end do
    hi = 0.5_dp*(lo + hi)
    lo = x
  contains
    integer(ip) function sturm_count(s)
      real(dp), intent(in) :: s
      real(dp) :: q
      integer(ip) :: j
      sturm_count = 0
      q = d(1) - s
      do j = 1, m
        if (j > 1) then
          if (q == 0) q = tiny(1.0_dp)
          q = d(j) - s - e(j - 1)**2/q
        end if
        if (q < 0) sturm_count = sturm_count + 1
      end do
    end function sturm_count
  end subroutine tridiagonal_extremes
end module ritz_values
