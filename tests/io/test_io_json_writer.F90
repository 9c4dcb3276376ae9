#include "assertions.h"
!> json_writer: the formatting of single values, and a document with nested
!> objects and arrays, awkward strings, extreme reals, NaN/Inf, integers of
!> both kinds, logicals and a raw fragment (params_json). Rank 0 of the
!> communicator writes <argument>/writer_np<ranks>.json, which check_json.py
!> parses and compares value by value.
program test_io_json_writer
  use, intrinsic :: ieee_arithmetic, only: ieee_value, ieee_quiet_nan, ieee_positive_inf, ieee_negative_inf
  use kinds, only: dp, ip, i8, path_len
  use assertions, only: assert_true, test_finish
  use json_writer, only: json_writer_t, json_string, json_real, json_integer, json_logical
  use params, only: default_params
  use report, only: params_json
  use mpi_f08, only: MPI_Init, MPI_COMM_WORLD, MPI_Comm_rank, MPI_Comm_size, MPI_Barrier
  implicit none

  type(json_writer_t) :: w, empty
  character(len=path_len) :: dir
  character(len=:), allocatable :: path, s
  real(dp) :: nan, inf
  integer :: rank, nranks, ierr, i
  logical :: there

  call MPI_Init(ierr)
  call MPI_Comm_rank(MPI_COMM_WORLD, rank, ierr)
  call MPI_Comm_size(MPI_COMM_WORLD, nranks, ierr)
  call get_command_argument(1, dir)
  nan = ieee_value(1.0_dp, ieee_quiet_nan)
  inf = ieee_value(1.0_dp, ieee_positive_inf)

  ! single values
  call assert_true(json_string('a"b\c') == '"a\"b\\c"', 'quote and backslash escaped', HERE)
  call assert_true(json_string('x'//achar(10)//achar(9)//achar(1)) == '"x\n\t\u0001"', 'control characters', HERE)
  call assert_true(json_string('') == '""', 'empty string', HERE)
  call assert_true(json_real(nan) == 'null', 'NaN is null', HERE)
  call assert_true(json_real(inf) == 'null', '+Inf is null', HERE)
  call assert_true(json_real(ieee_value(1.0_dp, ieee_negative_inf)) == 'null', '-Inf is null', HERE)
  call assert_true(json_real(1.5_dp) == '1.5000000000000000E+000', '1.5 with 17 digits', HERE)
  call assert_true(json_real(-2.0_dp**(-1000)) == '-9.3326361850321888E-302', 'three-digit exponent', HERE)
  call assert_true(json_integer(-9007199254740993_i8) == '-9007199254740993', 'int64', HERE)
  call assert_true(json_logical(.true.) == 'true' .and. json_logical(.false.) == 'false', 'logicals', HERE)

  ! a document; check_json.py holds the same values
  call w%begin_object()
  call w%add('name', 'feti "contact" \ test'//achar(10)//'line 2'//achar(9)//'tab'//achar(27)//'esc')
  call w%add('utf8', 'μ = 0.3, σ_vm')
  call w%add('empty_string', '')
  call w%add('tenth', 0.1_dp)
  call w%add('third', 1.0_dp/3.0_dp)
  call w%add('negative', -2.5_dp)
  call w%add('negative_zero', -0.0_dp)
  call w%add('big', huge(1.0_dp))
  call w%add('small', tiny(1.0_dp))
  call w%add('subnormal', 4.9406564584124654e-324_dp)
  call w%add('avogadro', 6.02214076e23_dp)
  call w%add('nan', nan)
  call w%add('inf', inf)
  call w%add('int', -2147483647_ip)
  call w%add('long', 9007199254740993_i8)
  call w%add('yes', .true.)
  call w%add('no', .false.)
  call w%add_null('nothing')
  call w%add('reals', [1.0_dp, -1.0e-10_dp, nan])
  call w%add('ints', [1_ip, 2_ip, 3_ip])
  call w%add('no_ints', [integer(ip) ::])
  call w%begin_object('nested')
  call w%begin_object('deeper')
  call w%add('level', 3_ip)
  call w%end_object()
  call w%begin_object('empty_object')
  call w%end_object()
  call w%begin_array('mixed')
  call w%append(1_ip)
  call w%append(2.5_dp)
  call w%append('three')
  call w%append(.true.)
  call w%append(4_i8)
  call w%append_raw('null')
  call w%begin_array()
  call w%append(1_ip)
  call w%begin_array()
  call w%end_array()
  call w%end_array()
  call w%begin_object()
  call w%add('in_array', 1_ip)
  call w%end_object()
  call w%end_array()
  call w%end_object()
  call w%add_raw('params', params_json(default_params()))
  call w%begin_array('objects')
  do i = 1, 3
    call w%begin_object()
    call w%add('i', int(i, ip))
    call w%add('square', real(i*i, dp))
    call w%end_object()
  end do
  call w%end_array()
  call w%end_object()

  s = w%text()
  call assert_true(s(1:1) == '{' .and. s(len(s):len(s)) == '}', 'text is one object', HERE)
  call assert_true(index(s, '"tenth": 1.0000000000000001E-001') > 0, 'member text', HERE)
  call assert_true(empty%text() == '', 'an empty writer gives empty text', HERE)

  path = trim(dir)//'/writer_np'//achar(iachar('0') + nranks)//'.json'
  call w%write_file(path, MPI_COMM_WORLD)
  call MPI_Barrier(MPI_COMM_WORLD, ierr)
  inquire (file=path, exist=there)
  call assert_true(there, 'the file exists', HERE)
  inquire (file=path//'.tmp', exist=there)
  call assert_true(.not. there, 'no temporary file left', HERE)

  ! the writer can be reused after reset
  call w%reset()
  call w%begin_array()
  call w%end_array()
  call assert_true(w%text() == '[]', 'reset, then an empty array', HERE)
  call test_finish()
end program test_io_json_writer
