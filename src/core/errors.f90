!> The one way a run stops on an error.
!>
!> `fatal_error` is for an error seen by one rank while others may be waiting
!> in a collective: it prints on that rank and calls MPI_Abort, so no rank hangs.
!> `collective_error` is for an error every rank knows about (for example after a
!> broadcast of an input check): rank 0 prints, every rank finalizes MPI and the
!> process exits with a non-zero status, without Open MPI's abort banner.
!> An input error found after the input was read (a refusal at run time:
!> the output folder, ranks against subdomains) names the input file too:
!> `set_input_file` records it once, and every input error message that
!> starts with 'group &' is prefixed with 'file <name>, '.
module errors
  use, intrinsic :: iso_fortran_env, only: error_unit, output_unit
  use, intrinsic :: iso_c_binding, only: c_int
  use mpi_f08, only: MPI_Comm, MPI_COMM_WORLD, MPI_Abort, MPI_Comm_rank, MPI_Finalize, &
                     MPI_Initialized, MPI_Finalized
  implicit none
  private

  public :: fatal_error, collective_error, exit_process, set_input_file

  interface
    !> The C library's exit: ends the process with a status and no Fortran
    !> runtime message (gfortran's ERROR STOP prints a backtrace with -fbacktrace).
    subroutine c_exit(status) bind(C, name='exit')
      import :: c_int
      integer(c_int), value :: status
    end subroutine c_exit
  end interface

  integer, parameter, public :: exit_input_error = 2    !< bad input
  integer, parameter, public :: exit_not_converged = 3  !< a solver did not converge
  integer, parameter, public :: exit_kkt_failed = 4     !< the KKT check failed
  integer, parameter, public :: exit_internal = 5       !< anything else

  !> the input file of the run ('' until set_input_file)
  character(len=:), allocatable, save :: input_file

contains

  !> Print `message` (prefixed with the rank) and abort all ranks of `comm`.
  subroutine fatal_error(message, comm, code)
    character(len=*), intent(in) :: message
    type(MPI_Comm), intent(in), optional :: comm
    integer, intent(in), optional :: code
    type(MPI_Comm) :: c
    integer :: rank, ierr, status
    logical :: up, down

    c = MPI_COMM_WORLD
    if (present(comm)) c = comm
    status = exit_internal
    if (present(code)) status = code
    call MPI_Initialized(up, ierr)
    call MPI_Finalized(down, ierr)
    rank = 0
    if (up .and. .not. down) call MPI_Comm_rank(MPI_COMM_WORLD, rank, ierr)
    flush (output_unit)
    write (error_unit, '(a,i0,2a)') 'feticontact: ERROR (rank ', rank, '): ', trim(message)
    flush (error_unit)
    if (up .and. .not. down) call MPI_Abort(c, status, ierr)
    error stop status, quiet=.true.
  end subroutine fatal_error

  !> The input file that input error messages name (see the module).
  subroutine set_input_file(file)
    character(len=*), intent(in) :: file
    input_file = trim(file)
  end subroutine set_input_file

  !> Every rank of `comm` calls this together: rank 0 prints, all finalize, exit.
  !> An input error about a group names the input file (set_input_file).
  subroutine collective_error(message, comm, code)
    character(len=*), intent(in) :: message
    type(MPI_Comm), intent(in) :: comm
    integer, intent(in) :: code
    integer :: rank, ierr
    character(len=:), allocatable :: prefix

    call MPI_Comm_rank(comm, rank, ierr)
    flush (output_unit)
    prefix = ''
    if (code == exit_input_error .and. allocated(input_file)) then
      if (len(input_file) > 0 .and. index(message, 'group &') == 1) prefix = 'file '//input_file//', '
    end if
    if (rank == 0) then
      write (error_unit, '(3a)') 'feticontact: ERROR: ', prefix, trim(message)
      flush (error_unit)
    end if
    call MPI_Finalize(ierr)
    call exit_process(code)
  end subroutine collective_error

  !> End the process with `status` (after MPI_Finalize), without any message.
  subroutine exit_process(status)
    integer, intent(in) :: status
    flush (output_unit)
    flush (error_unit)
    call c_exit(int(status, c_int))
  end subroutine exit_process

end module errors
