!> Memory at phase boundaries: `memory_mark(name)` records this process's
!> peak resident set (VmHWM) and resident set (VmRSS) at that moment (local,
!> no communication); report.json's `memory.phases` gives them reduced over
!> the ranks (report%memory_json), the log's memory table too
!> (memory_marks_reduce through timers_reduce). The growth of VmHWM from one
!> mark to the next is what the phase in between added to the peak.
module memory_marks
  use kinds, only: i8, name_len, MPI_INT_I8
  use proc_status, only: proc_status_bytes
  use mpi_f08, only: MPI_Comm, MPI_Allreduce, MPI_MAX, MPI_MIN, MPI_INTEGER
  implicit none
  private

  public :: memory_mark, memory_mark_count, memory_mark_get, memory_marks_clear, memory_marks_reduce

  integer, parameter :: max_marks = 32

  type :: mark_t
    character(len=name_len) :: name = ''
    integer(i8) :: peak = -1, resident = -1
  end type mark_t

  type(mark_t), save :: marks(max_marks)
  integer, save :: nmarks = 0

contains

  !> Record VmHWM and VmRSS now under `name` (a repeated name overwrites its
  !> earlier mark; more than max_marks distinct names are ignored).
  subroutine memory_mark(name)
    character(len=*), intent(in) :: name
    integer :: i
    do i = 1, nmarks
      if (marks(i)%name == name) exit
    end do
    if (i > nmarks) then
      if (nmarks == max_marks) return
      nmarks = nmarks + 1
      i = nmarks
    end if
    marks(i)%name = name
    ! VmRSS first: the peak read after it includes it (reading the file
    ! allocates, so the other order could give a resident set above the peak)
    marks(i)%resident = proc_status_bytes('VmRSS')
    marks(i)%peak = proc_status_bytes('VmHWM')
  end subroutine memory_mark

  !> Number of marks recorded.
  integer function memory_mark_count()
    memory_mark_count = nmarks
  end function memory_mark_count

  !> The i-th mark, in the order of recording: its name, VmHWM and VmRSS in
  !> bytes (-1 where /proc/self/status cannot tell).
  subroutine memory_mark_get(i, name, peak, resident)
    integer, intent(in) :: i
    character(len=name_len), intent(out) :: name
    integer(i8), intent(out) :: peak, resident
    name = marks(i)%name
    peak = marks(i)%peak
    resident = marks(i)%resident
  end subroutine memory_mark_get

  !> Every mark over the ranks of `comm`, in the order of recording: its name
  !> and the max over the ranks of VmHWM at the mark, of its growth since the
  !> mark before (since the start for the first) and of VmRSS (bytes; -1
  !> where some rank cannot tell). Collective; the ranks record the same marks
  !> (the first marks common to all are reduced).
  subroutine memory_marks_reduce(comm, names, peak, added, resident)
    type(MPI_Comm), intent(in) :: comm
    character(len=name_len), allocatable, intent(out) :: names(:)
    integer(i8), allocatable, intent(out) :: peak(:), added(:), resident(:)
    integer(i8), allocatable :: local(:, :), hi(:, :), lo(:, :)
    integer :: n, i, ierr
    call MPI_Allreduce(nmarks, n, 1, MPI_INTEGER, MPI_MIN, comm, ierr)
    allocate (local(3, max(n, 1)), hi(3, max(n, 1)), lo(3, max(n, 1)))
    local = 0
    do i = 1, n
      local(:, i) = [marks(i)%peak, marks(i)%peak, marks(i)%resident]
    end do
    do i = 2, n
      local(2, i) = -1
      if (marks(i)%peak >= 0 .and. marks(i - 1)%peak >= 0) local(2, i) = marks(i)%peak - marks(i - 1)%peak
    end do
    call MPI_Allreduce(local, hi, size(local), MPI_INT_I8, MPI_MAX, comm, ierr)
    call MPI_Allreduce(local, lo, size(local), MPI_INT_I8, MPI_MIN, comm, ierr)
    where (lo < 0) hi = -1
    allocate (names(n), peak(n), added(n), resident(n))
    do i = 1, n
      names(i) = marks(i)%name
    end do
    peak = hi(1, 1:n)
    added = hi(2, 1:n)
    resident = hi(3, 1:n)
  end subroutine memory_marks_reduce

  !> Forget every mark.
  subroutine memory_marks_clear()
    nmarks = 0
  end subroutine memory_marks_clear
end module memory_marks
