#include "assertions.h"
!> The values of good.nml are read on rank 0 and reach every rank; variables
!> the file does not set keep their documented defaults.
program test_params
  use kinds, only: dp, ip, path_len
  use assertions, only: assert_true, assert_equal, assert_close, test_finish
  use params, only: params_t, read_params, check_params, default_params, param_item_t, param_items, group_names
  use mpi_f08, only: MPI_Init, MPI_COMM_WORLD
  implicit none
  type(params_t) :: p, d
  type(param_item_t), allocatable :: items(:)
  character(len=path_len) :: file
  integer :: ierr, status
  character(len=1024) :: msg

  call MPI_Init(ierr)
  call get_command_argument(1, file)
  call read_params(file, MPI_COMM_WORLD, p)
  d = default_params()

  ! values set in good.nml (case of strings is folded to lower case)
  call assert_true(all(p%mesh%nsub == [3, 1, 2]), 'mesh nsub', HERE)
  call assert_true(all(p%mesh%nel == [5, 6, 7]), 'mesh nel', HERE)
  call assert_close(1.5_dp, p%mesh%lengths(2), 0.0_dp, 'mesh lengths(2)', HERE)
  call assert_true(p%mesh%decomposition == 'metis', 'mesh decomposition lower-cased', HERE)
  call assert_close(0.45_dp, p%material%poisson, 0.0_dp, 'material poisson', HERE)
  call assert_true(p%material%variation == 'checkerboard', 'material variation', HERE)
  call assert_close(1.0e4_dp, p%material%contrast, 0.0_dp, 'material contrast', HERE)
  call assert_close(12.5_dp, p%load%top_pressure, 0.0_dp, 'load top_pressure', HERE)
  call assert_true(.not. p%boundary%top_dirichlet, 'boundary top_dirichlet', HERE)
  call assert_true(p%boundary%symmetry_x0, 'boundary symmetry_x0', HERE)
  call assert_true(p%obstacle%shape == 'plane', 'obstacle shape', HERE)
  call assert_close(0.25_dp, p%obstacle%gap, 0.0_dp, 'obstacle gap', HERE)
  call assert_close(1.0e-8_dp, p%solver%tol, 0.0_dp, 'solver tol', HERE)
  call assert_equal(7_ip, p%solver%max_outer, 'solver max_outer', HERE)
  call assert_true(p%solver%expansion == 'optimal', 'solver expansion', HERE)
  call assert_true(p%reconstruction%method == 'new', 'reconstruction method', HERE)
  call assert_true(p%output%directory == 'elsewhere', 'output directory', HERE)
  call assert_true(p%output%run_name == 'good', 'output run_name', HERE)

  ! defaults of variables the file leaves alone (docs/CASES.md: E = 2.1e5, nu default 0.3)
  call assert_close(2.1e5_dp, p%material%young, 0.0_dp, 'default young', HERE)
  call assert_close(1.0_dp, p%mesh%lengths(3), 0.0_dp, 'default lengths(3)', HERE)
  call assert_true(p%mesh%mapping == 'block', 'default mapping', HERE)
  call assert_close(d%solver%gamma, p%solver%gamma, 0.0_dp, 'default gamma', HERE)
  call assert_true(trim(p%file) == trim(file), 'file name recorded', HERE)

  ! the checker accepts the defaults and rejects a change of each kind
  call check_params(d, status, msg)
  call assert_equal(0, status, 'defaults pass the checks', HERE)
  d%material%poisson = 0.5_dp
  call check_params(d, status, msg)
  call assert_true(status /= 0 .and. index(msg, 'variable poisson') > 0, 'poisson = 0.5 refused', HERE)

  ! the table behind the echo and report.json: names, kinds, values, also of
  ! a string with the characters the namelist syntax uses
  d = default_params()
  d%output%directory = 'out/a, b = "c" /d'
  call param_items(d, 'output', items)
  call assert_equal(4, size(items), 'output: 4 variables', HERE)
  call assert_true(items(1)%name == 'directory' .and. items(1)%kind == 's' .and. items(1)%n == 1 .and. &
                   items(1)%values(1) == 'out/a, b = "c" /d', 'directory read back whole', HERE)
  call assert_true(items(3)%name == 'write_hdf5' .and. items(3)%kind == 'l' .and. items(3)%values(1) == 'T', &
                   'write_hdf5 a logical', HERE)
  call param_items(d, 'mesh', items)
  call assert_true(items(1)%name == 'nsub' .and. items(1)%kind == 'i' .and. items(1)%n == 3, 'nsub: 3 integers', HERE)
  call assert_true(items(3)%name == 'lengths' .and. items(3)%kind == 'r' .and. items(3)%n == 3, &
                   'lengths: 3 reals (repeat count expanded)', HERE)
  call assert_equal(8, size(group_names), 'eight groups', HERE)
  call test_finish()
end program test_params
