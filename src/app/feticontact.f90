!> feticontact: frictionless contact of 3D linear elasticity by TFETI.
!>
!> Usage: mpirun -n P feticontact [--check] input.nml
!>   --check  read and check the input, echo the settings, make the checks a
!>            run makes before its set-up (output folder, ranks against
!>            subdomains, coarse groups), print a memory estimate, and exit.
!>        feticontact --version: the version and the git commit of the build.
!> Environment: FETICONTACT_BLAS_THREADS = BLAS threads per rank (default 1;
!> see blas_threads and docs/INPUT.md).
program feticontact
  use, intrinsic :: iso_fortran_env, only: output_unit
  use, intrinsic :: ieee_exceptions, only: ieee_get_halting_mode, ieee_set_halting_mode, ieee_set_flag, ieee_usual
  use kinds, only: path_len
  use errors, only: collective_error, exit_input_error, exit_process
  use build_info, only: fc_version, fc_commit
  use logger, only: logger_init, log_section, log_message, log_is_root
  use params, only: params_t, read_params, echo_params, input_warnings
  use contact_run, only: run_contact_case
  use run_checks, only: check_run
  use blas_threads, only: blas_threads_setup, blas_log_line
  use memory_marks, only: memory_mark
  use mpi_f08, only: MPI_Init, MPI_Finalize, MPI_COMM_WORLD, MPI_Comm_size
  implicit none

  type(params_t) :: p
  character(len=path_len) :: arg, file
  character(len=300) :: line
  logical :: check_only
  character(len=1024), allocatable :: warnings(:)
  integer :: i, ierr, nranks, status
  logical :: halting(size(ieee_usual))

  ! MPI_Init runs the launcher's and the MPI library's own start-up code (PMIx
  ! under srun, hwloc), which may divide by zero on purpose: floating point
  ! traps (the Debug build's -ffpe-trap) are for this program's arithmetic,
  ! so they are off during MPI_Init and restored after it
  call ieee_get_halting_mode(ieee_usual, halting)
  call ieee_set_halting_mode(ieee_usual, .false.)
  call MPI_Init(ierr)
  call ieee_set_flag(ieee_usual, .false.)
  call ieee_set_halting_mode(ieee_usual, halting)
  call logger_init(MPI_COMM_WORLD)
  call MPI_Comm_size(MPI_COMM_WORLD, nranks, ierr)
  ! before any BLAS work: one BLAS thread per rank unless the user says otherwise
  call blas_threads_setup(MPI_COMM_WORLD)
  call memory_mark('MPI_Init')

  check_only = .false.
  status = 0
  file = ''
  do i = 1, command_argument_count()
    call get_command_argument(i, arg)
    select case (arg)
    case ('--check')
      check_only = .true.
    case ('--version')
      call log_message('feticontact '//fc_version//' (commit '//fc_commit//')')
      call MPI_Finalize(ierr)
      call exit_process(0)
    case ('-h', '--help')
      call log_message('usage: mpirun -n P feticontact [--check] input.nml; feticontact --version')
      call MPI_Finalize(ierr)
      call exit_process(0)
    case default
      if (len_trim(file) > 0) call collective_error('more than one input file given; usage: '// &
        'mpirun -n P feticontact [--check] input.nml', MPI_COMM_WORLD, exit_input_error)
      file = arg
    end select
  end do
  if (len_trim(file) == 0) call collective_error('no input file given; usage: '// &
    'mpirun -n P feticontact [--check] input.nml', MPI_COMM_WORLD, exit_input_error)

  call log_message('feticontact '//fc_version//' (commit '//fc_commit//')')
  call read_params(file, MPI_COMM_WORLD, p)
  call log_section('feticontact: settings used')
  call log_echo(p)
  if (p%mesh%cluster_auto) then
    write (line, '(a,3(1x,i0),a)') '&mesh cluster (automatic):', p%mesh%cluster, ' -- '//trim(p%mesh%cluster_choice)
    call log_message(line)
  end if
  call log_message(blas_log_line())
  warnings = input_warnings(p)
  do i = 1, size(warnings)
    call log_message('feticontact: WARNING: '//trim(warnings(i)))
  end do

  if (.not. check_only) call run_contact_case(p, MPI_COMM_WORLD, status)
  if (check_only) then
    call check_run(p, MPI_COMM_WORLD, dry_run=.true.)
    call log_message('input checked: OK')
  end if
  call MPI_Finalize(ierr)
  if (status /= 0) call exit_process(status)

contains

  !> The settings echo (echo_params) through the logger: on the screen and in
  !> the log file the run writes beside report.json.
  subroutine log_echo(p)
    type(params_t), intent(in) :: p
    integer :: u, ios
    character(len=4096) :: text
    if (.not. log_is_root()) return
    open (newunit=u, status='scratch', action='readwrite', form='formatted', iostat=ios)
    if (ios /= 0) then
      call echo_params(p, output_unit)
      return
    end if
    call echo_params(p, u)
    rewind (u)
    do
      read (u, '(a)', iostat=ios) text
      if (ios /= 0) exit
      call log_message(trim(text))
    end do
    close (u)
    if (.not. p%boundary%top_dirichlet) call log_message('(&boundary top_displacement is not used: '// &
      'top_dirichlet = F leaves the top face free, loaded by &load top_pressure)')
  end subroutine log_echo
end program feticontact
