!> Named wall-clock timers per phase, reported as min / max / mean over ranks.
!>
!> Timers accumulate: start/stop pairs with the same name add up. Every rank
!> must call `timers_reduce` together; a timer a rank never used counts as 0 s.
module timers
  use kinds, only: dp, name_len, MPI_REAL_DP
  use errors, only: fatal_error
  use mpi_f08, only: MPI_Comm, MPI_Wtime, MPI_Allreduce, MPI_Bcast, MPI_Comm_size, MPI_MIN, MPI_MAX, &
    MPI_SUM, MPI_CHARACTER, MPI_INTEGER
  implicit none
  private

  public :: timer_start, timer_stop, timer_seconds, timers_reduce

  integer, parameter :: max_timers = 64

  !> Reduced statistics of one timer.
  type, public :: timer_stat_t
    character(len=name_len) :: name = ''
    real(dp) :: min = 0, max = 0, mean = 0
  end type timer_stat_t

  character(len=name_len) :: names(max_timers) = ''
  real(dp) :: total(max_timers) = 0, started(max_timers) = -1
  integer :: count = 0

contains

  integer function find(name, create)
    character(len=*), intent(in) :: name
    logical, intent(in) :: create
    integer :: i
    do i = 1, count
      if (names(i) == name) then
        find = i
        return
      end if
    end do
    find = 0
    if (.not. create) return
    if (count == max_timers) call fatal_error('timers: too many timers (max 64)')
    count = count + 1
    names(count) = name
    find = count
  end function find

  !> Start (or resume) the timer `name`.
  subroutine timer_start(name)
    character(len=*), intent(in) :: name
    integer :: i
    i = find(name, .true.)
    started(i) = MPI_Wtime()
  end subroutine timer_start

  !> Stop the timer `name` and add the elapsed time to its total.
  subroutine timer_stop(name)
    character(len=*), intent(in) :: name
    integer :: i
    i = find(name, .false.)
    if (i == 0) call fatal_error('timers: stop of a timer never started: '//trim(name))
    if (started(i) < 0) call fatal_error('timers: stop of a timer not running: '//trim(name))
    total(i) = total(i) + (MPI_Wtime() - started(i))
    started(i) = -1
  end subroutine timer_stop

  !> Accumulated seconds of `name` on this rank (0 if never used).
  real(dp) function timer_seconds(name)
    character(len=*), intent(in) :: name
    integer :: i
    i = find(name, .false.)
    timer_seconds = 0
    if (i > 0) timer_seconds = total(i)
  end function timer_seconds

  !> Min / max / mean over the ranks of `comm` of every timer rank 0 knows,
  !> in the order rank 0 first started them. Collective.
  subroutine timers_reduce(comm, stats)
    type(MPI_Comm), intent(in) :: comm
    type(timer_stat_t), allocatable, intent(out) :: stats(:)
    integer :: n, i, ierr, nranks
    character(len=name_len) :: root_names(max_timers)
    real(dp) :: mine(max_timers), lo(max_timers), hi(max_timers), sum(max_timers)

    n = count
    call MPI_Bcast(n, 1, MPI_INTEGER, 0, comm, ierr)
    root_names = names
    call MPI_Bcast(root_names, name_len*max_timers, MPI_CHARACTER, 0, comm, ierr)
    call MPI_Comm_size(comm, nranks, ierr)
    do i = 1, n
      mine(i) = timer_seconds(root_names(i))
    end do
    call MPI_Allreduce(mine, lo, n, MPI_REAL_DP, MPI_MIN, comm, ierr)
    call MPI_Allreduce(mine, hi, n, MPI_REAL_DP, MPI_MAX, comm, ierr)
    call MPI_Allreduce(mine, sum, n, MPI_REAL_DP, MPI_SUM, comm, ierr)
    allocate (stats(n))
    do i = 1, n
      stats(i) = timer_stat_t(root_names(i), lo(i), hi(i), sum(i)/nranks)
    end do
  end subroutine timers_reduce
end module timers
