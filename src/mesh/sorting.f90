!> Sorting of integer arrays (heapsort: in place, O(n log n), no recursion).
module sorting
  use kinds, only: ip
  implicit none
  private

  public :: sort_ints, sort_unique, binary_search

contains

  !> Sort a(:) ascending in place.
  pure subroutine sort_ints(a)
    integer(ip), intent(inout) :: a(:)
    integer(ip) :: n, i, t
    n = size(a)
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
end module sorting
