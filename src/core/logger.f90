!> A logger that only rank 0 of its communicator writes.
module logger
  use, intrinsic :: iso_fortran_env, only: output_unit
  use mpi_f08, only: MPI_Comm, MPI_COMM_WORLD, MPI_Comm_rank
  implicit none
  private

  public :: logger_init, log_section, log_message, log_is_root, log_unit

  integer :: rank = 0
  integer :: unit = output_unit

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

  !> Start a section: a blank line and an underlined title.
  subroutine log_section(title)
    character(len=*), intent(in) :: title
    if (rank /= 0) return
    write (unit, '(/,a)') trim(title)
    write (unit, '(a)') repeat('-', len_trim(title))
    flush (unit)
  end subroutine log_section

  !> One line of text.
  subroutine log_message(text)
    character(len=*), intent(in) :: text
    if (rank /= 0) return
    write (unit, '(a)') trim(text)
    flush (unit)
  end subroutine log_message
end module logger
