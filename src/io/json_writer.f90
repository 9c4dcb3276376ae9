!> A small builder of JSON text (RFC 8259) for report.json.
!>
!>     type(json_writer_t) :: w
!>     call w%begin_object()
!>     call w%add('tol', 1.0e-6_dp)               ! object member: key and value
!>     call w%begin_array('residuals')
!>     call w%append(0.5_dp)                      ! array element: value only
!>     call w%end_array()
!>     call w%add_raw('params', params_json(p))   ! a fragment that is already JSON
!>     call w%end_object()
!>     call w%write_file('out/report.json', comm) ! rank 0 of comm writes
!>
!> Reals are written with 17 significant digits (they read back to the same
!> double); NaN and infinities, which JSON cannot represent, are written as
!> null. Strings are escaped. Misuse (a member without a key, a key inside an
!> array, unbalanced begin/end) is a programming error and stops the run.
!> Members of objects go on their own indented lines; arrays stay on one line.
module json_writer
  use, intrinsic :: ieee_arithmetic, only: ieee_is_finite
  use kinds, only: dp, ip, i8
  use text, only: str
  use errors, only: fatal_error
  use file_system, only: rename_file
  use mpi_f08, only: MPI_Comm, MPI_Comm_rank
  use report_sink, only: report_sink_t
  implicit none
  private

  public :: json_string, json_real, json_integer, json_logical

  integer, parameter :: max_depth = 32

  !> JSON text under construction.
  type, extends(report_sink_t), public :: json_writer_t
    private
    character(len=:), allocatable :: buffer
    integer :: length = 0                          !< characters used in buffer
    integer :: depth = 0                           !< open objects and arrays
    character :: closer(max_depth) = ' '           !< '}' or ']' of each open level
    logical :: has_items(0:max_depth) = .false.    !< a value was written at this level
  contains
    procedure :: begin_object
    procedure :: end_object
    procedure :: begin_array
    procedure :: end_array
    procedure, private :: add_real, add_integer, add_long, add_logical, add_string, add_reals, &
                          add_integers
    generic :: add => add_real, add_integer, add_long, add_logical, add_string, add_reals, add_integers
    procedure, private :: append_real, append_integer, append_long, append_logical, append_string
    generic :: append => append_real, append_integer, append_long, append_logical, append_string
    procedure, private :: add_each_real, add_each_long
    generic :: add_each => add_each_real, add_each_long
    procedure :: add_raw
    procedure :: append_raw
    procedure :: add_null
    procedure :: text
    procedure :: write_file
    procedure :: reset
    ! the report_sink_t interface (sections written by the solvers)
    procedure :: put_long => add_long
    procedure :: put_real => add_real
    procedure :: put_logical => add_logical
    procedure :: put_text => add_string
    procedure :: put_null => add_null
    procedure :: put_reals => add_reals
    procedure :: put_longs => add_longs
  end type json_writer_t

contains

  ! ---- value formatting (usable on their own) ----

  !> `s` as a JSON string: quoted, with '"', '\' and control characters escaped.
  !> Bytes >= 128 pass unchanged (the text is taken to be UTF-8).
  pure function json_string(s) result(json)
    character(len=*), intent(in) :: s
    character(len=:), allocatable :: json
    character(len=*), parameter :: hex = '0123456789abcdef'
    integer :: i, c

    json = '"'
    do i = 1, len(s)
      c = iachar(s(i:i))
      select case (c)
      case (34)
        json = json//'\"'
      case (92)
        json = json//'\\'
      case (8)
        json = json//'\b'
      case (9)
        json = json//'\t'
      case (10)
        json = json//'\n'
      case (12)
        json = json//'\f'
      case (13)
        json = json//'\r'
      case (0:7, 11, 14:31)
        json = json//'\u00'//hex(c/16+1:c/16+1)//hex(mod(c, 16)+1:mod(c, 16)+1)
      case default
        json = json//s(i:i)
      end select
    end do
    json = json//'"'
  end function json_string

  !> `x` with 17 significant digits, or null when it is NaN or infinite.
  pure function json_real(x) result(json)
    real(dp), intent(in) :: x
    character(len=:), allocatable :: json
    character(len=32) :: buf
    if (.not. ieee_is_finite(x)) then
      json = 'null'
      return
    end if
    write (buf, '(es24.16e3)') x
    json = trim(adjustl(buf))
  end function json_real

  !> `n` in decimal.
  pure function json_integer(n) result(json)
    integer(i8), intent(in) :: n
    character(len=:), allocatable :: json
    json = str(n)
  end function json_integer

  !> true or false.
  pure function json_logical(v) result(json)
    logical, intent(in) :: v
    character(len=:), allocatable :: json
    if (v) then
      json = 'true'
    else
      json = 'false'
    end if
  end function json_logical

  ! ---- the builder ----

  !> Forget everything written so far.
  subroutine reset(self)
    class(json_writer_t), intent(inout) :: self
    if (allocated(self%buffer)) deallocate (self%buffer)
    self%length = 0
    self%depth = 0
    self%closer = ' '
    self%has_items = .false.
  end subroutine reset

  subroutine put(self, piece)
    class(json_writer_t), intent(inout) :: self
    character(len=*), intent(in) :: piece
    character(len=:), allocatable :: grown
    integer :: need

    need = self%length + len(piece)
    if (.not. allocated(self%buffer)) allocate (character(len=max(256, need)) :: self%buffer)
    if (need > len(self%buffer)) then
      allocate (character(len=max(2*len(self%buffer), need)) :: grown)
      grown(1:self%length) = self%buffer(1:self%length)
      call move_alloc(grown, self%buffer)
    end if
    self%buffer(self%length+1:need) = piece
    self%length = need
  end subroutine put

  !> Start a value: the separator, the newline and indentation of an object
  !> member, and the key. Checks that a key is given exactly inside objects.
  subroutine start_value(self, key)
    class(json_writer_t), intent(inout) :: self
    character(len=*), intent(in), optional :: key
    logical :: in_object

    if (self%depth == 0) then
      if (self%has_items(0)) call fatal_error('json_writer: a second value at the top level')
      if (present(key)) call fatal_error('json_writer: key "'//key//'" outside an object')
      self%has_items(0) = .true.
      return
    end if
    in_object = self%closer(self%depth) == '}'
    if (in_object .and. .not. present(key)) &
      call fatal_error('json_writer: an object member needs a key')
    if (.not. in_object .and. present(key)) &
      call fatal_error('json_writer: key "'//key//'" inside an array')
    if (self%has_items(self%depth)) call put(self, ',')
    if (in_object) then
      call put(self, new_line('a')//repeat('  ', self%depth))
      call put(self, json_string(key)//': ')
    else if (self%has_items(self%depth)) then
      call put(self, ' ')
    end if
    self%has_items(self%depth) = .true.
  end subroutine start_value

  subroutine open_level(self, closer, key)
    class(json_writer_t), intent(inout) :: self
    character, intent(in) :: closer
    character(len=*), intent(in), optional :: key
    call start_value(self, key)
    if (self%depth == max_depth) call fatal_error('json_writer: nesting deeper than 32 levels')
    self%depth = self%depth + 1
    self%closer(self%depth) = closer
    self%has_items(self%depth) = .false.
    if (closer == '}') then
      call put(self, '{')
    else
      call put(self, '[')
    end if
  end subroutine open_level

  subroutine close_level(self, closer)
    class(json_writer_t), intent(inout) :: self
    character, intent(in) :: closer
    if (self%depth == 0) call fatal_error('json_writer: end_object/end_array without a begin')
    if (self%closer(self%depth) /= closer) &
      call fatal_error('json_writer: end_'//merge('object', 'array ', closer == '}')//' closes an '// &
                       merge('array ', 'object', closer == '}'))
    self%depth = self%depth - 1
    if (closer == '}' .and. self%has_items(self%depth + 1)) &
      call put(self, new_line('a')//repeat('  ', self%depth))
    call put(self, closer)
  end subroutine close_level

  !> Open an object; `key` is required inside an object and not allowed elsewhere.
  subroutine begin_object(self, key)
    class(json_writer_t), intent(inout) :: self
    character(len=*), intent(in), optional :: key
    call open_level(self, '}', key)
  end subroutine begin_object

  !> Close the innermost object.
  subroutine end_object(self)
    class(json_writer_t), intent(inout) :: self
    call close_level(self, '}')
  end subroutine end_object

  !> Open an array; `key` is required inside an object and not allowed elsewhere.
  subroutine begin_array(self, key)
    class(json_writer_t), intent(inout) :: self
    character(len=*), intent(in), optional :: key
    call open_level(self, ']', key)
  end subroutine begin_array

  !> Close the innermost array.
  subroutine end_array(self)
    class(json_writer_t), intent(inout) :: self
    call close_level(self, ']')
  end subroutine end_array

  !> Member `key` whose value is `json`, text that is already valid JSON
  !> (for example `params_json(p)`); it is inserted unchanged except that its
  !> line breaks are indented to the current level.
  subroutine add_raw(self, key, json)
    class(json_writer_t), intent(inout) :: self
    character(len=*), intent(in) :: key, json
    call start_value(self, key)
    call put_indented(self, json)
  end subroutine add_raw

  !> Array element `json`, text that is already valid JSON.
  subroutine append_raw(self, json)
    class(json_writer_t), intent(inout) :: self
    character(len=*), intent(in) :: json
    call start_value(self)
    call put_indented(self, json)
  end subroutine append_raw

  !> `json` with each line break followed by the indentation of the current
  !> level (safe: a line break in valid JSON is never inside a string).
  subroutine put_indented(self, json)
    class(json_writer_t), intent(inout) :: self
    character(len=*), intent(in) :: json
    integer :: start, i
    start = 1
    do i = 1, len(json)
      if (json(i:i) /= new_line('a')) cycle
      call put(self, json(start:i)//repeat('  ', self%depth))
      start = i + 1
    end do
    call put(self, json(start:))
  end subroutine put_indented

  !> Member `key` with the value null.
  subroutine add_null(self, key)
    class(json_writer_t), intent(inout) :: self
    character(len=*), intent(in) :: key
    call add_raw(self, key, 'null')
  end subroutine add_null

  !> One member per key: keys(k) with values(k) (a table of figures).
  subroutine add_each_real(self, keys, values)
    class(json_writer_t), intent(inout) :: self
    character(len=*), intent(in) :: keys(:)
    real(dp), intent(in) :: values(:)
    integer :: k
    do k = 1, size(keys)
      call add_raw(self, trim(keys(k)), json_real(values(k)))
    end do
  end subroutine add_each_real

  subroutine add_each_long(self, keys, values)
    class(json_writer_t), intent(inout) :: self
    character(len=*), intent(in) :: keys(:)
    integer(i8), intent(in) :: values(:)
    integer :: k
    do k = 1, size(keys)
      call add_raw(self, trim(keys(k)), json_integer(values(k)))
    end do
  end subroutine add_each_long

  subroutine add_real(self, key, value)
    class(json_writer_t), intent(inout) :: self
    character(len=*), intent(in) :: key
    real(dp), intent(in) :: value
    call add_raw(self, key, json_real(value))
  end subroutine add_real

  subroutine add_integer(self, key, value)
    class(json_writer_t), intent(inout) :: self
    character(len=*), intent(in) :: key
    integer(ip), intent(in) :: value
    call add_raw(self, key, json_integer(int(value, i8)))
  end subroutine add_integer

  subroutine add_long(self, key, value)
    class(json_writer_t), intent(inout) :: self
    character(len=*), intent(in) :: key
    integer(i8), intent(in) :: value
    call add_raw(self, key, json_integer(value))
  end subroutine add_long

  subroutine add_logical(self, key, value)
    class(json_writer_t), intent(inout) :: self
    character(len=*), intent(in) :: key
    logical, intent(in) :: value
    call add_raw(self, key, json_logical(value))
  end subroutine add_logical

  subroutine add_string(self, key, value)
    class(json_writer_t), intent(inout) :: self
    character(len=*), intent(in) :: key, value
    call add_raw(self, key, json_string(value))
  end subroutine add_string

  subroutine add_reals(self, key, values)
    class(json_writer_t), intent(inout) :: self
    character(len=*), intent(in) :: key
    real(dp), intent(in) :: values(:)
    integer :: i
    call begin_array(self, key)
    do i = 1, size(values)
      call append_real(self, values(i))
    end do
    call end_array(self)
  end subroutine add_reals

  subroutine add_longs(self, key, values)
    class(json_writer_t), intent(inout) :: self
    character(len=*), intent(in) :: key
    integer(i8), intent(in) :: values(:)
    integer :: i
    call begin_array(self, key)
    do i = 1, size(values)
      call append_long(self, values(i))
    end do
    call end_array(self)
  end subroutine add_longs

  subroutine add_integers(self, key, values)
    class(json_writer_t), intent(inout) :: self
    character(len=*), intent(in) :: key
    integer(ip), intent(in) :: values(:)
    integer :: i
    call begin_array(self, key)
    do i = 1, size(values)
      call append_integer(self, values(i))
    end do
    call end_array(self)
  end subroutine add_integers

  subroutine append_real(self, value)
    class(json_writer_t), intent(inout) :: self
    real(dp), intent(in) :: value
    call append_raw(self, json_real(value))
  end subroutine append_real

  subroutine append_integer(self, value)
    class(json_writer_t), intent(inout) :: self
    integer(ip), intent(in) :: value
    call append_raw(self, json_integer(int(value, i8)))
  end subroutine append_integer

  subroutine append_long(self, value)
    class(json_writer_t), intent(inout) :: self
    integer(i8), intent(in) :: value
    call append_raw(self, json_integer(value))
  end subroutine append_long

  subroutine append_logical(self, value)
    class(json_writer_t), intent(inout) :: self
    logical, intent(in) :: value
    call append_raw(self, json_logical(value))
  end subroutine append_logical

  subroutine append_string(self, value)
    class(json_writer_t), intent(inout) :: self
    character(len=*), intent(in) :: value
    call append_raw(self, json_string(value))
  end subroutine append_string

  !> The finished JSON text. Every object and array must be closed.
  function text(self) result(json)
    class(json_writer_t), intent(in) :: self
    character(len=:), allocatable :: json
    if (self%depth /= 0) call fatal_error('json_writer: text requested with an object or array still open')
    if (self%length == 0) then
      json = ''
    else
      json = self%buffer(1:self%length)
    end if
  end function text

  !> Write the text and a final newline to `path` (under a temporary name,
  !> renamed when complete). With `comm`, only its rank 0 writes and the
  !> other ranks return at once; without it, the calling rank writes.
  subroutine write_file(self, path, comm)
    class(json_writer_t), intent(in) :: self
    character(len=*), intent(in) :: path
    type(MPI_Comm), intent(in), optional :: comm
    character(len=:), allocatable :: tmp
    character(len=512) :: msg
    integer :: rank, ierr, unit, status

    if (present(comm)) then
      call MPI_Comm_rank(comm, rank, ierr)
      if (rank /= 0) return
    end if
    tmp = trim(path)//'.tmp'
    open (newunit=unit, file=tmp, status='replace', action='write', access='stream', &
          form='unformatted', iostat=status, iomsg=msg)
    if (status /= 0) call fatal_error('json_writer: cannot open '//tmp//' for writing: '//trim(msg))
    write (unit, iostat=status, iomsg=msg) self%text()//new_line('a')
    if (status /= 0) call fatal_error('json_writer: cannot write '//tmp//': '//trim(msg))
    close (unit, iostat=status, iomsg=msg)
    if (status /= 0) call fatal_error('json_writer: cannot close '//tmp//': '//trim(msg))
    call rename_file(tmp, path, status)
    if (status /= 0) call fatal_error('json_writer: cannot rename '//tmp//' to '//trim(path))
  end subroutine write_file
end module json_writer
