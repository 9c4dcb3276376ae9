!> Integer arrays, the one place for their sorting: in place (heapsort,
!> O(n log n), no recursion; insertion sort up to insertion_max entries,
!> counting sort when the values span a range of a few times the length)
!> with duplicates removed on request, binary
!> search in a sorted array, stable sorting by keys (merge sort) returning a
!> permutation, and appending to a growing array (for adjacency lists).
module sorting
  use kinds, only: ip, i8
  implicit none
  private

  public :: sort_ints, sort_unique, binary_search, sort_permutation, append_int, append_unmarked

  !> Lists up to this length are sorted by insertion (fewer operations than a
  !> heap for the adjacency lists of a hexahedral mesh, at most 27 entries).
  integer(ip), parameter :: insertion_max = 32
  !> Longer lists whose values span fewer than counting_ratio times their
  !> length are sorted by counting.
  integer(i8), parameter :: counting_ratio = 4

  interface sort_permutation
    module procedure sort_permutation_i8, sort_permutation_ip
  end interface sort_permutation

contains

  !> append_int(v, n, x) unless marker(x) == tag, then marker(x) = tag: the
  !> distinct entries of one adjacency list (a new tag per list).
  pure subroutine append_unmarked(v, n, x, marker, tag)
    integer(ip), allocatable, intent(inout) :: v(:)
    integer(ip), intent(inout) :: n, marker(:)
    integer(ip), intent(in) :: x, tag
    if (marker(x) == tag) return
    marker(x) = tag
    call append_int(v, n, x)
  end subroutine append_unmarked

  !> v(n+1) = x, n = n + 1; v grows (doubles) when full.
  pure subroutine append_int(v, n, x)
    integer(ip), allocatable, intent(inout) :: v(:)
    integer(ip), intent(inout) :: n
    integer(ip), intent(in) :: x
    integer(ip), allocatable :: bigger(:)
    if (n == size(v)) then
      allocate (bigger(2*size(v) + 16))
      bigger(1:n) = v(1:n)
      call move_alloc(bigger, v)
    end if
    n = n + 1
    v(n) = x
  end subroutine append_int

  !> Sort a(:) ascending in place.
  pure subroutine sort_ints(a)
    integer(ip), intent(inout) :: a(:)
    integer(ip) :: n, i, j, t, lo, hi, v
    integer(ip), allocatable :: counts(:)
    n = size(a)
    if (n > insertion_max) then
      lo = minval(a)
      hi = maxval(a)
      if (int(hi, i8) - lo < counting_ratio*int(n, i8)) then
        ! counting sort: values in a range of fewer than counting_ratio*n
        ! (the dofs or nodes of one subdomain, often repeated), O(n + range)
        allocate (counts(lo:hi))
        counts = 0
        do i = 1, n
          counts(a(i)) = counts(a(i)) + 1
        end do
        j = 0
        do v = lo, hi
          a(j + 1:j + counts(v)) = v
          j = j + counts(v)
        end do
        return
      end if
    end if
    if (n <= insertion_max) then
      ! insertion sort: the short lists of the mesh (node adjacencies of at
      ! most 27 entries) sort several times faster than by heap sort
      do i = 2, n
        t = a(i)
        j = i                    ! a(j) <- t after shifting a(j:i-1) up by one
        do while (j > 1)
          if (a(j - 1) <= t) exit
          j = j - 1
        end do
        a(j + 1:i) = a(j:i - 1)
        a(j) = t
      end do
      return
    end if
    do i = n/2, 1, -1
      call sift_down(a, i, n)
    end do
    do i = n, 2, -1
      t = a(1)
      a(1) = a(i)
      a(i) = t
      call sift_down(a, 1, i - 1)
    end do
  end subroutine sort_ints

  pure subroutine sift_down(a, first, last)
    integer(ip), intent(inout) :: a(:)
    integer(ip), intent(in) :: first, last
    integer(ip) :: root, child, t
    root = first
    do
      child = 2*root
      if (child > last) exit
      if (child < last) then
        if (a(child + 1) > a(child)) child = child + 1
      end if
      if (a(root) >= a(child)) exit
      t = a(root)
      a(root) = a(child)
      a(child) = t
      root = child
    end do
  end subroutine sift_down

  !> Sort a(:) and move its distinct values to a(1:n).
  pure subroutine sort_unique(a, n)
    integer(ip), intent(inout) :: a(:)
    integer(ip), intent(out) :: n
    integer(ip) :: i
    n = 0
    if (size(a) == 0) return
    call sort_ints(a)
    n = 1
    do i = 2, size(a)
      if (a(i) /= a(n)) then
        n = n + 1
        a(n) = a(i)
      end if
    end do
  end subroutine sort_unique

  !> Position of `key` in the ascending array a(:), 0 if absent.
  pure integer(ip) function binary_search(a, key)
    integer(ip), intent(in) :: a(:), key
    integer(ip) :: lo, hi, mid
    binary_search = 0
    lo = 1
    hi = size(a)
    do while (lo <= hi)
      mid = (lo + hi)/2
      if (a(mid) == key) then
        binary_search = mid
        return
      else if (a(mid) < key) then
        lo = mid + 1
      else
        hi = mid - 1
      end if
    end do
  end function binary_search

  !> perm such that keys(perm) is ascending; equal keys keep their order.
  subroutine sort_permutation_i8(keys, perm)
    integer(i8), intent(in) :: keys(:)
    integer(ip), allocatable, intent(out) :: perm(:)
    integer(ip), allocatable :: work(:)
    integer(ip) :: n, width, lo, mid, hi, i, j, k

    n = size(keys, kind=ip)
    allocate (perm(n), work(n))
    perm = [(i, i = 1, n)]
    width = 1
    do while (width < n)
      lo = 1
      do while (lo <= n)
        mid = min(lo + width - 1, n)
        hi = min(lo + 2*width - 1, n)
        if (mid < hi) then
          i = lo
          j = mid + 1
          k = lo
          do while (i <= mid .and. j <= hi)
            if (keys(perm(j)) < keys(perm(i))) then
              work(k) = perm(j)
              j = j + 1
            else
              work(k) = perm(i)
              i = i + 1
            end if
            k = k + 1
          end do
          do while (i <= mid)
            work(k) = perm(i)
            i = i + 1
            k = k + 1
          end do
          do while (j <= hi)
            work(k) = perm(j)
            j = j + 1
            k = k + 1
          end do
          perm(lo:hi) = work(lo:hi)
        end if
        lo = lo + 2*width
      end do
      width = 2*width
    end do
  end subroutine sort_permutation_i8

  !> The same for default integer keys.
  subroutine sort_permutation_ip(keys, perm)
    integer(ip), intent(in) :: keys(:)
    integer(ip), allocatable, intent(out) :: perm(:)
    call sort_permutation_i8(int(keys, i8), perm)
  end subroutine sort_permutation_ip
end module sorting
