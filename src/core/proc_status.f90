!> The one reader of /proc/self/status (Linux): one "Vm..." memory field of
!> this process, in bytes.
module proc_status
  use kinds, only: i8
  implicit none
  private

  public :: proc_status_bytes

contains

  !> The field `name` of /proc/self/status ('VmHWM' peak resident set,
  !> 'VmRSS' resident set, ...) in bytes, or -1 where it is not available.
  function proc_status_bytes(name) result(bytes)
    character(len=*), intent(in) :: name
    integer(i8) :: bytes
    character(len=256) :: line
    integer :: u, status, n
    integer(i8) :: kib

    bytes = -1
    open (newunit=u, file='/proc/self/status', status='old', action='read', iostat=status)
    if (status /= 0) return
    n = len(name) + 1
    do
      read (u, '(a)', iostat=status) line
      if (status /= 0) exit
      if (line(1:n) /= name//':') cycle
      read (line(n + 1:), *, iostat=status) kib
      if (status == 0 .and. index(line, 'kB') > 0) bytes = 1024*kib
      exit
    end do
    close (u)
  end function proc_status_bytes
end module proc_status
