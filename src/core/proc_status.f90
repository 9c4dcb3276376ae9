!> The one reader of /proc/self/status and /proc/meminfo (Linux): one
!> "Vm..." memory field of this process, or one field of the machine's
!> memory, in bytes.
module proc_status
  use kinds, only: i8
  implicit none
  private

  public :: proc_status_bytes, meminfo_bytes

contains

  !> The field `name` of /proc/self/status ('VmHWM' peak resident set,
  !> 'VmRSS' resident set, ...) in bytes, or -1 where it is not available.
  function proc_status_bytes(name) result(bytes)
    character(len=*), intent(in) :: name
    integer(i8) :: bytes
    bytes = kib_field('/proc/self/status', name)
  end function proc_status_bytes

  !> The field `name` of /proc/meminfo ('MemAvailable', 'MemTotal', ...) in
  !> bytes, or -1 where it is not available.
  function meminfo_bytes(name) result(bytes)
    character(len=*), intent(in) :: name
    integer(i8) :: bytes
    bytes = kib_field('/proc/meminfo', name)
  end function meminfo_bytes

  !> The line 'name: value kB' of `file`, in bytes; -1 when absent.
  function kib_field(file, name) result(bytes)
    character(len=*), intent(in) :: file, name
    integer(i8) :: bytes
    character(len=256) :: line
    integer :: u, status, n
    integer(i8) :: kib

    bytes = -1
    open (newunit=u, file=file, status='old', action='read', iostat=status)
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
  end function kib_field
end module proc_status
