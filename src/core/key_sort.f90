!> Stable sorting by keys (merge sort), returning a permutation.
module key_sort
  use kinds, only: ip, i8
  implicit none
  private

  public :: sort_permutation

  interface sort_permutation
    module procedure sort_permutation_i8, sort_permutation_ip
  end interface sort_permutation

contains

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
end module key_sort
