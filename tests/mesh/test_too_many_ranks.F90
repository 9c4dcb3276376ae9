#include "assertions.h"
!> Run on 3 ranks with 2 subdomains: build_decomposition must stop every rank
!> with an input error naming &mesh nsub (checked by CTest on the output).
program test_too_many_ranks
  use kinds, only: ip
  use params, only: params_t, default_params
  use decomposition, only: decomposition_t, build_decomposition
  use mpi_f08, only: MPI_Init, MPI_COMM_WORLD
  use assertions, only: assert_true, test_finish
  implicit none
  type(params_t) :: p
  type(decomposition_t) :: dec
  integer :: ierr

  call MPI_Init(ierr)
  p = default_params()
  p%mesh%nsub = [2_ip, 1_ip, 1_ip]
  p%mesh%nel = [2_ip, 2_ip, 2_ip]
  call build_decomposition(p, MPI_COMM_WORLD, dec)
  call assert_true(.false., 'build_decomposition should have stopped', HERE)
  call test_finish()
end program test_too_many_ranks
