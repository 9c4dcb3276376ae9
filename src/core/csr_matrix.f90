!> Sparse matrices in compressed sparse row (CSR) form, 1-based.
!>
!> General (full) storage: a symmetric matrix keeps both triangles. Column
!> indices are ascending and unique within each row when the matrix comes
!> from `csr_from_coo` (the builders of other modules keep that too).
module csr_matrix
  use kinds, only: dp, ip
  use errors, only: fatal_error
  implicit none
  private

  public :: csr_from_coo

  !> A sparse matrix, square or rectangular.
  type, public :: csr_t
    integer(ip) :: nrows = 0, ncols = 0
    integer(ip), allocatable :: rowptr(:)   !< (nrows+1), rowptr(1) = 1
    integer(ip), allocatable :: colind(:)   !< (nnz) column of each stored entry
    real(dp), allocatable :: values(:)      !< (nnz) its value
  contains
    procedure :: matvec
    procedure :: matvec_add
    procedure :: nnz
    procedure :: position
    procedure :: get
    procedure :: diagonal
    procedure :: to_dense
    procedure :: upper_coo
    procedure :: free
  end type csr_t

contains

  !> The entries with column >= row (the upper triangle of a symmetric
  !> matrix) in coordinate form, row by row; `extra` > 0 leaves that many
  !> slots at the end of the arrays for the caller to fill.
  subroutine upper_coo(this, irn, jcn, a, extra)
    class(csr_t), intent(in) :: this
    integer(ip), allocatable, intent(out) :: irn(:), jcn(:)
    real(dp), allocatable, intent(out) :: a(:)
    integer(ip), intent(in), optional :: extra
    integer(ip) :: i, k, nz, more
    more = 0
    if (present(extra)) more = extra
    nz = 0
    do i = 1, this%nrows
      do k = this%rowptr(i), this%rowptr(i + 1) - 1
        if (this%colind(k) >= i) nz = nz + 1
      end do
    end do
    allocate (irn(nz + more), jcn(nz + more), a(nz + more))
    nz = 0
    do i = 1, this%nrows
      do k = this%rowptr(i), this%rowptr(i + 1) - 1
        if (this%colind(k) < i) cycle
        nz = nz + 1
        irn(nz) = i
        jcn(nz) = this%colind(k)
        a(nz) = this%values(k)
      end do
    end do
  end subroutine upper_coo

  !> y = A x.
  subroutine matvec(this, x, y)
    class(csr_t), intent(in) :: this
    real(dp), intent(in) :: x(:)
    real(dp), intent(out) :: y(:)
    integer(ip) :: i, k
    real(dp) :: s

    if (size(x) < this%ncols .or. size(y) < this%nrows) &
      call fatal_error('csr_t%matvec: x or y shorter than the matrix')
    do i = 1, this%nrows
      s = 0
      do k = this%rowptr(i), this%rowptr(i + 1) - 1
        s = s + this%values(k)*x(this%colind(k))
      end do
      y(i) = s
    end do
  end subroutine matvec

  !> y = y + alpha A x.
  subroutine matvec_add(this, alpha, x, y)
    class(csr_t), intent(in) :: this
    real(dp), intent(in) :: alpha
    real(dp), intent(in) :: x(:)
    real(dp), intent(inout) :: y(:)
    integer(ip) :: i, k
    real(dp) :: s

    if (size(x) < this%ncols .or. size(y) < this%nrows) &
      call fatal_error('csr_t%matvec_add: x or y shorter than the matrix')
    do i = 1, this%nrows
      s = 0
      do k = this%rowptr(i), this%rowptr(i + 1) - 1
        s = s + this%values(k)*x(this%colind(k))
      end do
      y(i) = y(i) + alpha*s
    end do
  end subroutine matvec_add

  !> Number of stored entries.
  integer(ip) function nnz(this)
    class(csr_t), intent(in) :: this
    nnz = 0
    if (allocated(this%rowptr)) nnz = this%rowptr(this%nrows + 1) - 1
  end function nnz

  !> Index k of entry (i, j) in colind/values (binary search, columns
  !> ascending), 0 when (i, j) is not stored.
  integer(ip) function position(this, i, j)
    class(csr_t), intent(in) :: this
    integer(ip), intent(in) :: i, j
    integer(ip) :: lo, hi, mid

    position = 0
    if (i < 1 .or. i > this%nrows) return
    lo = this%rowptr(i)
    hi = this%rowptr(i + 1) - 1
    do while (lo <= hi)
      mid = (lo + hi)/2
      if (this%colind(mid) == j) then
        position = mid
        return
      else if (this%colind(mid) < j) then
        lo = mid + 1
      else
        hi = mid - 1
      end if
    end do
  end function position

  !> Value of entry (i, j); 0 when it is not stored.
  real(dp) function get(this, i, j)
    class(csr_t), intent(in) :: this
    integer(ip), intent(in) :: i, j
    integer(ip) :: k
    k = this%position(i, j)
    get = 0
    if (k > 0) get = this%values(k)
  end function get

  !> The diagonal d(min(nrows, ncols)) (0 where not stored).
  subroutine diagonal(this, d)
    class(csr_t), intent(in) :: this
    real(dp), intent(out) :: d(:)
    integer(ip) :: i
    do i = 1, min(this%nrows, this%ncols)
      d(i) = this%get(i, i)
    end do
  end subroutine diagonal

  !> The matrix as a dense (nrows, ncols) array (for tests and small matrices).
  subroutine to_dense(this, a)
    class(csr_t), intent(in) :: this
    real(dp), allocatable, intent(out) :: a(:, :)
    integer(ip) :: i, k
    allocate (a(this%nrows, this%ncols))
    a = 0
    do i = 1, this%nrows
      do k = this%rowptr(i), this%rowptr(i + 1) - 1
        a(i, this%colind(k)) = a(i, this%colind(k)) + this%values(k)
      end do
    end do
  end subroutine to_dense

  !> Release the storage.
  subroutine free(this)
    class(csr_t), intent(inout) :: this
    if (allocated(this%rowptr)) deallocate (this%rowptr)
    if (allocated(this%colind)) deallocate (this%colind)
    if (allocated(this%values)) deallocate (this%values)
    this%nrows = 0
    this%ncols = 0
  end subroutine free

  !> Build `a` (nrows x ncols) from coordinate triplets (rows(k), cols(k), vals(k)),
  !> summing duplicates. Columns come out ascending in every row. Two stable
  !> counting sorts (by column, then by row): O(n + nrows + ncols), no comparisons.
  subroutine csr_from_coo(nrows, ncols, rows, cols, vals, a)
    integer(ip), intent(in) :: nrows, ncols
    integer(ip), intent(in) :: rows(:), cols(:)
    real(dp), intent(in) :: vals(:)
    type(csr_t), intent(out) :: a
    integer(ip), allocatable :: bycol(:), byrow(:), start(:)
    integer(ip) :: n, k, m, i, j, last, count
    real(dp) :: v

    n = size(rows)
    if (size(cols) /= n .or. size(vals) /= n) &
      call fatal_error('csr_from_coo: rows, cols and vals differ in length')
    if (n > 0) then
      if (minval(rows) < 1 .or. maxval(rows) > nrows .or. minval(cols) < 1 .or. maxval(cols) > ncols) &
        call fatal_error('csr_from_coo: an index is out of range')
    end if
    ! stable sort by column
    allocate (start(max(nrows, ncols) + 1), bycol(n), byrow(n))
    start = 0
    do k = 1, n
      start(cols(k) + 1) = start(cols(k) + 1) + 1
    end do
    start(1) = 1
    do j = 2, ncols + 1
      start(j) = start(j) + start(j - 1)
    end do
    do k = 1, n
      bycol(start(cols(k))) = k
      start(cols(k)) = start(cols(k)) + 1
    end do
    ! stable sort of that order by row
    start = 0
    do k = 1, n
      start(rows(k) + 1) = start(rows(k) + 1) + 1
    end do
    start(1) = 1
    do i = 2, nrows + 1
      start(i) = start(i) + start(i - 1)
    end do
    do m = 1, n
      k = bycol(m)
      byrow(start(rows(k))) = k
      start(rows(k)) = start(rows(k)) + 1
    end do
    deallocate (bycol)
    ! compress duplicates (adjacent now)
    a%nrows = nrows
    a%ncols = ncols
    allocate (a%rowptr(nrows + 1))
    count = 0
    last = 0
    i = 0
    do m = 1, n
      k = byrow(m)
      if (rows(k) /= i .or. cols(k) /= last) then
        count = count + 1
        i = rows(k)
        last = cols(k)
      end if
    end do
    allocate (a%colind(count), a%values(count))
    a%rowptr = 0
    count = 0
    i = 0
    last = 0
    do m = 1, n
      k = byrow(m)
      v = vals(k)
      if (rows(k) /= i .or. cols(k) /= last) then
        count = count + 1
        i = rows(k)
        last = cols(k)
        a%colind(count) = last
        a%values(count) = v
        a%rowptr(i + 1) = a%rowptr(i + 1) + 1
      else
        a%values(count) = a%values(count) + v
      end if
    end do
    a%rowptr(1) = 1
    do i = 2, nrows + 1
      a%rowptr(i) = a%rowptr(i) + a%rowptr(i - 1)
    end do
  end subroutine csr_from_coo
end module csr_matrix
