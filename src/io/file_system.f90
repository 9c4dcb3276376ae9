!> The few POSIX file system calls the output needs (Fortran has none of them):
!> directory test, mkdir -p, atomic rename, the process id, the absolute path.
!>
!> The C library is called through `bind(c)` interfaces; paths are passed as
!> NUL-terminated copies of the trimmed Fortran strings.
module file_system
  use, intrinsic :: iso_c_binding, only: c_int, c_char, c_null_char, c_ptr, c_null_ptr, c_associated
  implicit none
  private

  public :: is_directory, path_exists, make_directories, rename_file, process_id, absolute_path, could_create

  integer(c_int), parameter :: f_ok = 0                !< access(): existence test
  integer(c_int), parameter :: wx_ok = 3               !< access(): write and search permission
  integer(c_int), parameter :: mode_all = 511_c_int    !< 0777, reduced by the umask

  interface
    integer(c_int) function c_access(path, mode) bind(c, name='access')
      import :: c_int, c_char
      character(kind=c_char), intent(in) :: path(*)
      integer(c_int), value :: mode
    end function c_access

    integer(c_int) function c_mkdir(path, mode) bind(c, name='mkdir')
      import :: c_int, c_char
      character(kind=c_char), intent(in) :: path(*)
      integer(c_int), value :: mode          ! mode_t is a 32-bit unsigned int on Linux
    end function c_mkdir

    integer(c_int) function c_rename(from, to) bind(c, name='rename')
      import :: c_int, c_char
      character(kind=c_char), intent(in) :: from(*), to(*)
    end function c_rename

    integer(c_int) function c_getpid() bind(c, name='getpid')
      import :: c_int
    end function c_getpid

    type(c_ptr) function c_realpath(path, resolved) bind(c, name='realpath')
      import :: c_ptr, c_char
      character(kind=c_char), intent(in) :: path(*)
      character(kind=c_char), intent(out) :: resolved(*)
    end function c_realpath
  end interface

contains

  !> True if `path` exists (file, directory or anything else).
  logical function path_exists(path)
    character(len=*), intent(in) :: path
    path_exists = c_access(trim(path)//c_null_char, f_ok) == 0
  end function path_exists

  !> True if `path` is a directory (or a link to one) that can be searched.
  logical function is_directory(path)
    character(len=*), intent(in) :: path
    is_directory = c_access(trim(path)//'/.'//c_null_char, f_ok) == 0
  end function is_directory

  !> Whether make_directories(path) would succeed and the directory be
  !> writable, without creating anything (`--check`): the deepest existing
  !> prefix of `path` must be a writable directory. `reason` says why not.
  subroutine could_create(path, status, reason)
    character(len=*), intent(in) :: path
    integer, intent(out) :: status
    character(len=:), allocatable, intent(out) :: reason
    character(len=:), allocatable :: prefix
    integer :: n
    status = 0
    reason = ''
    prefix = trim(path)
    do while (len(prefix) > 0 .and. .not. path_exists(prefix))
      n = index(prefix, '/', back=.true.)
      if (n <= 1) then
        prefix = merge('/', '.', n == 1)
        exit
      end if
      prefix = prefix(1:n - 1)
    end do
    if (.not. is_directory(prefix)) then
      status = 1
      reason = "'"//prefix//"' exists and is not a directory"
    else if (c_access(prefix//c_null_char, wx_ok) /= 0) then
      status = 1
      reason = "'"//prefix//"' is not writable"
    end if
  end subroutine could_create

  !> Create `path` and its missing parents (mkdir -p). On failure `status` is
  !> non-zero and `reason` says which component could not be created and why.
  subroutine make_directories(path, status, reason)
    character(len=*), intent(in) :: path
    integer, intent(out) :: status
    character(len=:), allocatable, intent(out) :: reason
    integer :: i, n
    integer(c_int) :: ignored

    status = 0
    reason = ''
    n = len_trim(path)
    do while (n > 1 .and. path(n:n) == '/')
      n = n - 1
    end do
    if (n == 0) then
      status = 1
      reason = 'the path is empty'
      return
    end if
    ! each prefix that ends before a '/', then the whole path
    do i = 2, n + 1
      if (i <= n) then
        if (path(i:i) /= '/' .or. path(i-1:i-1) == '/') cycle
      end if
      associate (prefix => path(1:i-1))
        if (is_directory(prefix)) cycle
        if (path_exists(prefix)) then
          status = 1
          reason = "'"//prefix//"' exists and is not a directory"
          return
        end if
        ignored = c_mkdir(prefix//c_null_char, mode_all)
        if (.not. is_directory(prefix)) then
          status = 1
          reason = "mkdir of '"//prefix//"' failed"
          return
        end if
      end associate
    end do
  end subroutine make_directories

  !> Rename `from` to `to`, replacing `to` atomically if it exists (POSIX
  !> rename). `status` is 0 on success.
  subroutine rename_file(from, to, status)
    character(len=*), intent(in) :: from, to
    integer, intent(out) :: status
    status = int(c_rename(trim(from)//c_null_char, trim(to)//c_null_char))
  end subroutine rename_file

  !> The absolute, resolved form of the existing `path` (POSIX realpath); `path`
  !> itself when it cannot be resolved (it does not exist, or is too long).
  function absolute_path(path) result(full)
    character(len=*), intent(in) :: path
    character(len=:), allocatable :: full
    integer, parameter :: path_max = 4096       ! PATH_MAX on Linux
    character(kind=c_char, len=path_max + 1) :: buf
    integer :: n
    full = trim(path)
    buf = ''
    if (.not. c_associated(c_realpath(trim(path)//c_null_char, buf))) return
    n = index(buf, c_null_char) - 1
    if (n > 0) full = buf(1:n)
  end function absolute_path

  !> The id of this process (to make scratch file names unique).
  integer function process_id()
    process_id = int(c_getpid())
  end function process_id
end module file_system
