!> Run on 2 ranks: rank 1 stops with fatal_error and a given exit code while
!> rank 0 waits in a barrier. MPI_Abort must end both ranks with that code
!> (exit status and message checked by CTest, cmake/RunProgramTest.cmake):
!> the exit statuses of docs/INPUT.md (2 input, 3 not converged, 4 KKT, 5
!> internal) reach the caller whichever rank finds the error.
program test_fatal_status
  use errors, only: fatal_error, exit_kkt_failed
  use mpi_f08, only: MPI_Init, MPI_Comm_rank, MPI_Barrier, MPI_COMM_WORLD
  implicit none
  integer :: rank, ierr

  call MPI_Init(ierr)
  call MPI_Comm_rank(MPI_COMM_WORLD, rank, ierr)
  if (rank == 1) call fatal_error('deliberate error on one rank', code=exit_kkt_failed)
  call MPI_Barrier(MPI_COMM_WORLD, ierr)
  error stop 1
end program test_fatal_status
