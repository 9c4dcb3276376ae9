!> Memory at phase boundaries: `memory_mark(name)` records this process's
!> peak resident set (VmHWM) and resident set (VmRSS) at that moment (local,
!> no communication); report.json's `memory.phases` gives them reduced over
!> the ranks (report%memory_json). The growth of VmHWM from one mark to the
!> next is what the phase in between added to the peak.
module memory_marks
  use kinds, only: i8, name_len
  use proc_status, only: proc_status_bytes
  implicit none
  private

  public :: memory_mark, memory_mark_count, memory_mark_get, memory_marks_clear

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

  !> Forget every mark.
  subroutine memory_marks_clear()
    nmarks = 0
  end subroutine memory_marks_clear
end module memory_marks
