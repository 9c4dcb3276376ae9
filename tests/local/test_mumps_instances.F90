#include "assertions.h"
!> Many MUMPS instances alive at once on MPI_COMM_SELF (a rank owning
!> thousands of subdomains): create N (argument 1, default 3000) instances of a
!> tiny SPD system (n = 24, the size of one Q1 element), factorize all, solve
!> with each, free all. Prints the resident memory per live instance and what
!> is left after freeing them (a leak would show there).
program test_mumps_instances
  use, intrinsic :: iso_fortran_env, only: output_unit
  use kinds, only: dp, ip
  use tolerances, only: solve_tol
  use assertions, only: assert_true, assert_below, test_finish
  use mumps_wrapper, only: mumps_t
  use mpi_f08, only: MPI_Init, MPI_COMM_SELF, MPI_COMM_WORLD, MPI_Comm_rank, MPI_Wtime
  implicit none
  integer, parameter :: n = 24
  integer(ip) :: irn(2*n - 1), jcn(2*n - 1)
  real(dp) :: a(2*n - 1)
  integer :: ierr, rank, count, i, status
  integer(kind=8) :: rss0, rss1, rss2, first_peak, first_after, live
  real(dp) :: t0, t1, t2, t3, worst
  character(len=32) :: arg

  call MPI_Init(ierr)
  call MPI_Comm_rank(MPI_COMM_WORLD, rank, ierr)
  count = 3000
  call get_command_argument(1, arg, status=status)
  if (status == 0 .and. len_trim(arg) > 0) read (arg, *) count

  ! tridiagonal SPD: 2.5 on the diagonal, -1 off it (upper triangle)
  do i = 1, n
    irn(i) = i
    jcn(i) = i
    a(i) = 2.5_dp
  end do
  do i = 1, n - 1
    irn(n + i) = i
    jcn(n + i) = i + 1
    a(n + i) = -1
  end do

  ! Three rounds. Freed memory stays with the allocator and the first rounds
  ! fragment the heap, so the process grows a little in round 2 (measured:
  ! ~6 KiB per instance, then flat); a leak would grow it again in round 3.
  call one_round(count, rss0, rss1, rss2, t0, t1, t2, t3, worst)
  live = rss1 - rss0
  ! tridiagonal (-1, 2.5, -1): eigenvalues in (0.5, 4.5), cond < 9; a
  ! backward-stable solve is exact to c eps cond
  call assert_below(worst, solve_tol(9.0_dp), 'every instance solves its own system', HERE)
  if (rank == 0) then
    write (output_unit, '(a,i0,a)') 'instances: ', count, ' (n = 24 each, all alive at once)'
    write (output_unit, '(a,f8.1,a)') 'resident memory per live instance: ', real(rss1 - rss0, dp)/count, ' KiB'
    write (output_unit, '(a,f8.1,a)') 'init + analysis + factorization per instance: ', 1.0e6_dp*(t1 - t0)/count, ' us'
    write (output_unit, '(a,f8.1,a)') 'solve (one vector) per instance: ', 1.0e6_dp*(t2 - t1)/count, ' us'
    write (output_unit, '(a,f8.1,a)') 'free per instance: ', 1.0e6_dp*(t3 - t2)/count, ' us'
  end if
  call one_round(count, rss0, rss1, rss2, t0, t1, t2, t3, worst)
  first_peak = rss1
  first_after = rss2
  call one_round(count, rss0, rss1, rss2, t0, t1, t2, t3, worst)
  call assert_below(worst, solve_tol(9.0_dp), 'every instance solves its own system, third round', HERE)
  if (rank == 0) then
    write (output_unit, '(a,i0,a)') 'third round: peak ', rss1 - first_peak, ' KiB above the peak of the second'
    write (output_unit, '(a,i0,a)') 'third round: ', rss2 - first_after, ' KiB more left after freeing'
  end if
  call assert_true(live > 0, 'resident memory is readable (/proc/self/status) and grows with live instances', HERE)
  call assert_true(rss1 - first_peak < max(2048_8, live/20), &
                   'the third round reuses the memory of the second (no leak)', HERE)
  call test_finish()

contains

  !> Create, factorize, solve with and free `count` instances; resident
  !> memory before, with all alive, after; wall clock at each step.
  subroutine one_round(count, rss0, rss1, rss2, t0, t1, t2, t3, worst)
    integer, intent(in) :: count
    integer(kind=8), intent(out) :: rss0, rss1, rss2
    real(dp), intent(out) :: t0, t1, t2, t3, worst
    type(mumps_t), allocatable :: solvers(:)
    real(dp) :: x(n), b(n)
    integer :: s

    rss0 = resident_kb()
    t0 = MPI_Wtime()
    allocate (solvers(count))
    do s = 1, count
      call solvers(s)%init(MPI_COMM_SELF, .true.)
      call solvers(s)%set_centralized(int(n, ip), irn, jcn, a*(1 + 1.0e-3_dp*s))
      call solvers(s)%set_ordering('amd')
      call solvers(s)%factorize()
    end do
    t1 = MPI_Wtime()
    rss1 = resident_kb()
    worst = 0
    do s = 1, count
      x = [(sin(real(i*s, dp)), i = 1, n)]
      call tridiagonal_times(a*(1 + 1.0e-3_dp*s), x, b)
      call solvers(s)%solve(b)
      worst = max(worst, norm2(b - x)/norm2(x))
    end do
    t2 = MPI_Wtime()
    do s = 1, count
      call solvers(s)%free()
    end do
    deallocate (solvers)
    t3 = MPI_Wtime()
    rss2 = resident_kb()
  end subroutine one_round

  subroutine tridiagonal_times(v, x, y)
    real(dp), intent(in) :: v(:), x(:)
    real(dp), intent(out) :: y(:)
    integer :: k
    y = v(1:n)*x
    do k = 1, n - 1
      y(k) = y(k) + v(n + k)*x(k + 1)
      y(k + 1) = y(k + 1) + v(n + k)*x(k)
    end do
  end subroutine tridiagonal_times

  !> VmRSS of this process in KiB (Linux), 0 if unknown.
  integer(kind=8) function resident_kb()
    integer :: unit, ios
    character(len=256) :: line
    resident_kb = 0
    open (newunit=unit, file='/proc/self/status', action='read', iostat=ios)
    if (ios /= 0) return
    do
      read (unit, '(a)', iostat=ios) line
      if (ios /= 0) exit
      if (line(1:6) == 'VmRSS:') then
        read (line(7:), *) resident_kb
        exit
      end if
    end do
    close (unit)
  end function resident_kb
end program test_mumps_instances
