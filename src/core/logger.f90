!> A logger that only rank 0 of its communicator writes.
module logger
  use, intrinsic :: iso_fortran_env, only: output_unit
  use mpi_f08, only: MPI_Comm, MPI_COMM_WORLD, MPI_Comm_rank
  implicit none
  private

  public :: logger_init, log_section, log_message, log_is_root, log_unit, log_open_file, log_file_unit, log_to_file

  integer :: rank = 0
  integer :: unit = output_unit
  !> the log file (log_open_file) and, before it is open, the lines it will start with
  integer :: file_unit = 0
  logical :: file_open = .false.
  integer :: screen_unit = output_unit   !< the unit while log_to_file is on
  type :: line_t
    character(len=:), allocatable :: text
  end type line_t
  type(line_t), allocatable :: held(:)
  integer :: nheld = 0

contains

  !> Set the communicator whose rank 0 writes (default MPI_COMM_WORLD).
  subroutine logger_init(comm, to_unit)
    type(MPI_Comm), intent(in), optional :: comm
    integer, intent(in), optional :: to_unit
    integer :: ierr
    if (present(comm)) then
      call MPI_Comm_rank(comm, rank, ierr)
    else
      call MPI_Comm_rank(MPI_COMM_WORLD, rank, ierr)
    end if
    if (present(to_unit)) unit = to_unit
  end subroutine logger_init

  !> True on the rank that writes.
  logical function log_is_root()
    log_is_root = rank == 0
  end function log_is_root

  !> The unit rank 0 writes to (for tables written with explicit formats).
  integer function log_unit()
    log_unit = unit
  end function log_unit

  !> The log file's unit (-1 when none is open; newunit's are negative too, never -1): what a table written to
  !> log_unit() is written to once more.
  integer function log_file_unit()
    log_file_unit = -1
    if (file_open) log_file_unit = file_unit
  end function log_file_unit

  !> On: log_unit() is the log file (a table written to log_unit() is written
  !> once more with it on); off: the unit again.
  subroutine log_to_file(on)
    logical, intent(in) :: on
    if (.not. file_open) return
    if (on .and. unit /= file_unit) then
      screen_unit = unit
      unit = file_unit
    else if (.not. on .and. unit == file_unit) then
      unit = screen_unit
    end if
  end subroutine log_to_file

  !> From now on, every line also goes to the file `path` (rank 0), which
  !> starts with the lines logged so far (those of log_message, log_section
  !> and log_held_line). On an error opening it, the log stays on the unit.
  subroutine log_open_file(path)
    character(len=*), intent(in) :: path
    integer :: i, ios
    if (rank /= 0 .or. file_open) return
    open (newunit=file_unit, file=path, status='replace', action='write', iostat=ios)
    if (ios /= 0) return
    file_open = .true.
    do i = 1, nheld
      write (file_unit, '(a)') held(i)%text
    end do
    deallocate (held)
    nheld = 0
    flush (file_unit)
  end subroutine log_open_file

  !> Keep `text` for the log file (written now when it is open).
  subroutine to_file(text)
    character(len=*), intent(in) :: text
    type(line_t), allocatable :: more(:)
    if (file_open) then
      write (file_unit, '(a)') text
      flush (file_unit)
      return
    end if
    if (.not. allocated(held)) allocate (held(64))
    if (nheld == size(held)) then
      allocate (more(2*size(held)))
      more(1:nheld) = held
      call move_alloc(more, held)
    end if
    nheld = nheld + 1
    held(nheld)%text = text
  end subroutine to_file

  !> Start a section: a blank line and an underlined title.
  subroutine log_section(title)
    character(len=*), intent(in) :: title
    if (rank /= 0) return
    write (unit, '(/,a)') trim(title)
    write (unit, '(a)') repeat('-', len_trim(title))
    flush (unit)
    call to_file('')
    call to_file(trim(title))
    call to_file(repeat('-', len_trim(title)))
  end subroutine log_section

  !> One line of text.
  subroutine log_message(text)
    character(len=*), intent(in) :: text
    if (rank /= 0) return
    write (unit, '(a)') trim(text)
    flush (unit)
    call to_file(trim(text))
  end subroutine log_message
end module logger
