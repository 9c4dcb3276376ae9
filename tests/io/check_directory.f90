!> check_output_directory on the directory given as the argument: prints
!> 'output directory ok' and exits 0, or exits through collective_error
!> (run by RunDirectoryCheck.cmake, which judges the status and message).
program check_directory
  use kinds, only: path_len
  use logger, only: logger_init, log_message
  use hdf5_output, only: check_output_directory
  use mpi_f08, only: MPI_Init, MPI_Finalize, MPI_COMM_WORLD
  implicit none
  character(len=path_len) :: directory
  integer :: ierr

  call MPI_Init(ierr)
  call logger_init(MPI_COMM_WORLD)
  call get_command_argument(1, directory)
  call check_output_directory(MPI_COMM_WORLD, trim(directory))
  call log_message('output directory ok: '//trim(directory))
  call MPI_Finalize(ierr)
end program check_directory
