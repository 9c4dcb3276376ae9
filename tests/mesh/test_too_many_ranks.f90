!> Run on 3 ranks with 2 subdomains: build_decomposition must stop every rank
!> with an input error naming &mesh nsub (exit status and message checked by
!> CTest, cmake/RunProgramTest.cmake). Should it return, this program says so
!> and exits with status 1, which the test rejects.
program test_too_many_ranks
  use, intrinsic :: iso_fortran_env, only: error_unit
  use kinds, only: ip
  use params, only: params_t, default_params
  use decomposition, only: decomposition_t, build_decomposition
  use mpi_f08, only: MPI_Init, MPI_COMM_WORLD
  implicit none
  type(params_t) :: p
  type(decomposition_t) :: dec
  integer :: ierr

  call MPI_Init(ierr)
  p = default_params()
  p%mesh%nsub = [2_ip, 1_ip, 1_ip]
  p%mesh%nel = [2_ip, 2_ip, 2_ip]
  call build_decomposition(p%mesh, MPI_COMM_WORLD, dec)
  write (error_unit, '(a)') 'FAIL: build_decomposition returned with more ranks than subdomains'
  error stop 1
end program test_too_many_ranks
