!> A STREAM-like triad a = b + s c on every rank at once, to measure the
!> memory bandwidth the local solves can hope for. Prints the aggregate
!> bandwidth over all ranks (best of the repetitions, 24 bytes per index:
!> two reads and one write; write-allocate traffic not counted, as in STREAM).
!>   mpirun -n P stream_triad [megabytes per array, default 256] [repetitions, default 10]
program stream_triad
  use kinds, only: dp, i8
  use mpi_f08, only: MPI_Init, MPI_Finalize, MPI_COMM_WORLD, MPI_Comm_rank, MPI_Comm_size, MPI_Wtime, &
                     MPI_Barrier, MPI_Allreduce, MPI_MAX, MPI_DOUBLE_PRECISION
  implicit none
  real(dp), allocatable :: a(:), b(:), c(:)
  real(dp) :: t0, t, tmax, best, s
  integer(i8) :: n, i
  integer :: rank, nranks, ierr, rep, reps, mb
  character(len=32) :: arg

  call MPI_Init(ierr)
  call MPI_Comm_rank(MPI_COMM_WORLD, rank, ierr)
  call MPI_Comm_size(MPI_COMM_WORLD, nranks, ierr)
  mb = 256
  reps = 10
  if (command_argument_count() >= 1) then
    call get_command_argument(1, arg)
    read (arg, *) mb
  end if
  if (command_argument_count() >= 2) then
    call get_command_argument(2, arg)
    read (arg, *) reps
  end if
  n = int(mb, i8)*1024*1024/8
  allocate (a(n), b(n), c(n))
  do i = 1, n
    a(i) = 0
    b(i) = 1
    c(i) = 2
  end do
  s = 3
  best = huge(1.0_dp)
  do rep = 1, reps
    call MPI_Barrier(MPI_COMM_WORLD, ierr)
    t0 = MPI_Wtime()
    do i = 1, n
      a(i) = b(i) + s*c(i)
    end do
    t = MPI_Wtime() - t0
    call MPI_Allreduce(t, tmax, 1, MPI_DOUBLE_PRECISION, MPI_MAX, MPI_COMM_WORLD, ierr)
    best = min(best, tmax)
    s = s + a(n/2)*1.0e-30_dp
  end do
  if (rank == 0) write (*, '(a,i0,a,i0,a,f10.3,a)') 'triad: ', nranks, ' ranks, ', mb, ' MB per array, ', &
    24.0_dp*n*nranks/best/1.0e9_dp, ' GB/s'
  call MPI_Finalize(ierr)
end program stream_triad
