#include "assertions.h"
!> report: the timing table printed through the logger (captured in a file
!> and read back), timings_json and memory_json in a report written with
!> json_writer to <argument>/report_np<ranks>.json (check_json.py parses it),
!> and peak_rss_bytes growing when 80 MiB are touched.
program test_io_report
  use, intrinsic :: iso_fortran_env, only: output_unit
  use kinds, only: dp, i8, path_len
  use assertions, only: assert_true, assert_close, test_finish
  use timers, only: timer_stat_t, timer_start, timer_stop, timers_reduce
  use logger, only: logger_init
  use report, only: print_timing_table, timings_json, memory_json, params_json
  use proc_status, only: proc_status_bytes
  use json_writer, only: json_writer_t
  use params, only: default_params
  use mpi_f08, only: MPI_Init, MPI_COMM_WORLD, MPI_Comm_rank, MPI_Comm_size, MPI_Barrier
  implicit none

  type(timer_stat_t) :: stats(3)
  type(timer_stat_t), allocatable :: measured(:)
  type(json_writer_t) :: w
  character(len=path_len) :: dir
  character(len=:), allocatable :: table_file, json
  character(len=200) :: lines(5)
  real(dp), allocatable :: big(:)
  integer(i8) :: before, after
  integer :: rank, nranks, ierr, u, i, status
  real(dp) :: share

  call MPI_Init(ierr)
  call MPI_Comm_rank(MPI_COMM_WORLD, rank, ierr)
  call MPI_Comm_size(MPI_COMM_WORLD, nranks, ierr)
  call get_command_argument(1, dir)

  stats(1) = timer_stat_t('assemble', 0.5_dp, 1.5_dp, 1.0_dp)
  stats(2) = timer_stat_t('solve', 2.0_dp, 3.0_dp, 2.5_dp)
  stats(3) = timer_stat_t('output', 0.25_dp, 0.75_dp, 0.5_dp)

  ! the table, captured on rank 0
  table_file = trim(dir)//'/table_np'//achar(iachar('0') + nranks)//'.txt'
  if (rank == 0) open (newunit=u, file=table_file, status='replace', action='readwrite')
  if (rank /= 0) u = output_unit
  call logger_init(MPI_COMM_WORLD, u)
  call print_timing_table(stats)
  call logger_init(MPI_COMM_WORLD, output_unit)
  if (rank == 0) then
    rewind (u)
    lines = ''
    do i = 1, 5
      read (u, '(a)', iostat=status) lines(i)
      if (status /= 0) exit
    end do
    close (u, status='delete')
    call assert_true(index(lines(1), 'phase') == 1 .and. index(lines(1), 'mean [s]') > 0 .and. &
                     index(lines(1), 'share') > 0, 'table header', HERE)
    call assert_true(index(lines(2), 'assemble') == 1, 'first phase first', HERE)
    call assert_true(index(lines(3), 'solve') == 1, 'second phase second', HERE)
    call assert_true(index(lines(4), 'output') == 1, 'third phase third', HERE)
    call assert_true(len_trim(lines(5)) == 0, 'one line per phase', HERE)
    ! solve: 2.5 of 4.0 s = 62.5 %
    read (lines(3)(len_trim(lines(3))-11:len_trim(lines(3))-1), *) share
    call assert_close(62.5_dp, share, 0.0_dp, 'share of solve', HERE, atol=0.05_dp)
    call assert_true(index(lines(3), '2.000000') > 0 .and. index(lines(3), '3.000000') > 0 .and. &
                     index(lines(3), '2.500000') > 0, 'min, max, mean of solve', HERE)
  end if
  ! an explicit total, a phase named total, and no phases at all do not fail
  call print_timing_table(stats, total=8.0_dp)
  call print_timing_table([stats, timer_stat_t('total', 4.0_dp, 5.0_dp, 4.5_dp)])
  call print_timing_table(stats(1:0))
  call print_timing_table([timer_stat_t('idle', 0.0_dp, 0.0_dp, 0.0_dp)])

  json = timings_json(stats)
  call assert_true(index(json, '"solve": {') > 0, 'timings_json has the phases', HERE)
  call assert_true(timings_json(stats(1:0)) == '{}', 'no phases: {}', HERE)

  ! the peak grows when memory is touched
  before = proc_status_bytes('VmHWM')
  call assert_true(before > 0, 'VmHWM is known on Linux', HERE)
  allocate (big(10*2**20))               ! 80 MiB
  big = 1
  after = proc_status_bytes('VmHWM')
  call assert_true(after - before > 70*2_i8**20, 'peak rss grows by the 80 MiB touched', HERE)
  call assert_close(10.0_dp*2**20, sum(big), 0.0_dp, 'the memory is used', HERE)

  ! measured timers
  call timer_start('busy')
  big = big*2
  call timer_stop('busy')
  if (rank == 0) then
    call timer_start('idle')
    call timer_stop('idle')
  end if
  call timers_reduce(MPI_COMM_WORLD, measured)
  call print_timing_table(measured)

  ! the report, as the application will write it
  call w%begin_object()
  call w%add_raw('params', params_json(default_params()))
  call w%add_raw('timings', timings_json(stats))
  call w%add_raw('measured_timings', timings_json(measured))
  call w%add_raw('memory', memory_json(MPI_COMM_WORLD))
  call w%end_object()
  call w%write_file(trim(dir)//'/report_np'//achar(iachar('0') + nranks)//'.json', MPI_COMM_WORLD)
  call MPI_Barrier(MPI_COMM_WORLD, ierr)
  call test_finish()
end program test_io_report
