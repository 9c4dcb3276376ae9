!> report.json of one run: the case, the sizes, the solver's counters, the KKT
!> residuals, the reconstruction, the timings, the contact summary, memory,
!> BLAS and the F action's bandwidth (docs/OUTPUT.md). Rank 0 of the
!> dualization's communicator writes.
module run_report
  use kinds, only: dp, ip, i8, MPI_INT_I8, MPI_REAL_DP
  use timers, only: timer_stat_t
  use logger, only: log_message
  use output_settings, only: output_settings_t
  use reconstruction_settings, only: reconstruction_settings_t
  use feti_operators, only: feti_t, feti_sizes_t
  use coarse_problem, only: coarse_problem_t
  use smalbe, only: smalbe_t
  use tfeti_dualization, only: tfeti_dualization_t, dual_solution_t
  use contact_summary, only: contact_summary_t
  use json_writer, only: json_writer_t
  use report, only: timings_json, memory_json, blas_json
  use blas_threads, only: blas_in_use
  use build_info, only: fc_source_dir
  use file_system, only: absolute_path, path_exists
  use mpi_f08, only: MPI_Comm_size, MPI_Allreduce, MPI_SUM
  implicit none
  private

  public :: write_run_report, log_where_to_look

  !> What the input layer says about the run's input: the "case" object of
  !> report.json (the settings of every group), the warnings about the input,
  !> and the solver variant ('name=value' of the &solver settings that differ
  !> from their defaults, or 'default').
  type, public :: run_case_t
    character(len=:), allocatable :: case_json
    character(len=1024), allocatable :: warnings(:)
    character(len=:), allocatable :: variant
  end type run_case_t

contains

  !> Write <output%directory>/report.json. `run_case`: the input's part;
  !> `seconds`: the solve and, within it, the F actions and the coarse solves
  !> (tfeti_dualization%solve); `stats`: the reduced timers. Collective.
  subroutine write_run_report(run_case, output, reconstruction, dual, solver, sol, contact, stats, seconds, history, &
                              step)
    type(run_case_t), intent(in) :: run_case
    type(output_settings_t), intent(in) :: output
    type(reconstruction_settings_t), intent(in) :: reconstruction
    type(tfeti_dualization_t), intent(inout), target :: dual
    type(smalbe_t), intent(in) :: solver
    type(dual_solution_t), intent(in) :: sol
    type(contact_summary_t), intent(in) :: contact
    type(timer_stat_t), intent(in) :: stats(:)
    real(dp), intent(in) :: seconds(3)
    !> a load history: its step records (a JSON array), report.json's `history`;
    !> the other sections are those of the step `step` (the peak), named in report.json's `step`
    character(len=*), intent(in), optional :: history
    integer(ip), intent(in), optional :: step
    type(json_writer_t) :: js
    type(feti_t), pointer :: op
    type(feti_sizes_t) :: n
    character(len=:), allocatable :: memory
    integer(i8) :: f_bytes
    real(dp) :: f_seconds, flops(2), f_flops, switch_estimate
    integer :: switch_at
    integer :: nranks, ierr, k

    op => dual%operators()
    n = op%sizes()
    call MPI_Comm_size(op%comm(), nranks, ierr)
    memory = memory_json(op%comm())
    ! bytes one F action reads on all ranks, and the time of one F action
    call MPI_Allreduce(op%bytes_per_f_action(), f_bytes, 1, MPI_INT_I8, MPI_SUM, op%comm(), ierr)
    call MPI_Allreduce(op%setup_flops(), flops, 2, MPI_REAL_DP, MPI_SUM, op%comm(), ierr)
    call MPI_Allreduce(op%flops_per_f_action(), f_flops, 1, MPI_REAL_DP, MPI_SUM, op%comm(), ierr)
    f_seconds = stat_max(stats, 'F action', 0.0_dp)/max(op%f_applications(), 1_i8)

    call js%begin_object()
    call js%add_raw('case', run_case%case_json)
    call js%begin_array('warnings')
    do k = 1, size(run_case%warnings)
      call js%append(trim(run_case%warnings(k)))
    end do
    call js%end_array()
    call js%begin_object('sizes')
    call js%add_each([character(len=16) :: 'subdomains', 'ranks', 'primal_dofs', 'dual_dofs', 'coarse_dim', &
                      'contact_rows', 'active_contact', 'gluing_rows', 'dirichlet_rows'], &
                     int([n%nsubdomains, nranks, int(n%primal_dofs, ip), n%dual_dofs, n%coarse_dim, n%contact_rows, &
                          contact%active_nodes, n%gluing_rows, n%dirichlet_rows], i8))
    call js%end_object()
    call js%begin_object('solver')
    ! the solver's own section, then what the dual problem adds to it
    call solver%report(js)
    call js%add_each([character(len=8) :: 'rho', 'norm_pfp'], [dual%rho(), op%norm_pfp()])
    call js%add_each([character(len=16) :: 'f_applications', 'coarse_solves'], [op%f_applications(), op%coarse_solves()])
    call js%add('variant', run_case%variant)
    call js%add('preconditioner', dual%preconditioner_name())
    ! 'auto': the Hessian count at the switch to 'dirichlet' and the estimate that made it (null: none)
    call dual%preconditioner_switch(switch_at, switch_estimate)
    if (switch_at >= 0) then
      call js%add('preconditioner_switch_at', int(switch_at, i8))
      call js%add('preconditioner_switch_estimate', switch_estimate)
    else
      call js%add_null('preconditioner_switch_at')
      call js%add_null('preconditioner_switch_estimate')
    end if
    call js%end_object()
    call add_kkt(js, sol, reconstruction%kkt_tol)
    call js%begin_object('reconstruction')
    call js%add('method', trim(reconstruction%method))
    if (sol%alpha_difference >= 0) then
      call js%add('alpha_difference', sol%alpha_difference)
    else
      call js%add_null('alpha_difference')
    end if
    call js%begin_object('new')
    call add_stat_max('seconds', 'rec new')
    call js%end_object()
    call js%begin_object('standard')
    call add_stat_max('seconds', 'rec standard')
    call js%add_each([character(len=16) :: 'assembly', 'factorization', 'solve'], &
                     [sol%standard_cost%assembly, sol%standard_cost%factorization, sol%standard_cost%solve])
    call js%add('active_contact_rows', sol%standard_cost%active_rows)
    call js%end_object()
    call js%end_object()
    call js%add_raw('timings', timings_json(stats))
    call js%begin_object('contact')
    call js%add_each([character(len=16) :: 'total_force', 'max_pressure'], [contact%total_force, contact%max_pressure])
    call js%add('active_nodes', contact%active_nodes)
    call js%add('contact_radius', contact%contact_radius)
    call js%end_object()
    call js%add_raw('memory', memory)
    if (present(step)) call js%add('step', int(step, i8))
    if (present(history)) call js%add_raw('history', history)
    call add_coarse(js, op)
    associate (b => blas_in_use())                 ! set up by the main program
      call js%add_raw('blas', blas_json(trim(b%library), trim(b%path), b%threads, trim(b%source), b%settable, &
                                         trim(b%core), trim(b%core_before)))
    end associate
    call add_performance(js, op, f_bytes, flops, f_flops, f_seconds, seconds)
    call js%end_object()
    call js%write_file(trim(output%directory)//'/report.json', op%comm())

  contains

    !> The max over ranks of timer `name` (the time the run waited for it),
    !> null if it never ran.
    subroutine add_stat_max(key, name)
      character(len=*), intent(in) :: key, name
      real(dp) :: t
      t = stat_max(stats, name, -1.0_dp)
      if (t >= 0) then
        call js%add(key, t)
      else
        call js%add_null(key)
      end if
    end subroutine add_stat_max
  end subroutine write_run_report

  !> report.json's `kkt`: the residuals of the primal KKT check and its verdict.
  subroutine add_kkt(js, sol, kkt_tol)
    type(json_writer_t), intent(inout) :: js
    type(dual_solution_t), intent(in) :: sol
    real(dp), intent(in) :: kkt_tol
    call js%begin_object('kkt')
    call js%add_each([character(len=16) :: 'equilibrium', 'gluing', 'dirichlet', 'penetration', 'equality', &
                      'feasibility', 'dual_feasibility', 'complementarity'], &
                     [sol%kkt%equilibrium, sol%kkt%gluing, sol%kkt%dirichlet, sol%kkt%penetration, sol%kkt%equality, &
                      sol%kkt%feasibility, sol%kkt%dual_feasibility, sol%kkt%complementarity])
    call js%add('passed', sol%kkt%worst() <= kkt_tol)
    call js%end_object()
  end subroutine add_kkt

  !> report.json's `coarse`: the coarse factorization of the run.
  subroutine add_coarse(js, op)
    type(json_writer_t), intent(inout) :: js
    type(feti_t), intent(inout), target :: op
    type(coarse_problem_t), pointer :: cp
    cp => op%coarse_factor()
    call js%begin_object('coarse')
    call js%add_each([character(len=32) :: 'ranks_per_group', 'groups', 'factor_entries', &
                      'factor_entries_effective', 'mumps_memory_mb_max_rank', 'mumps_memory_mb_group'], &
                     [int(cp%ranks_per_group(), i8), int(cp%groups(), i8), cp%factor_entries(), &
                      cp%factor_entries_effective(), cp%mumps_memory_mb()])
    call js%add('factorization_seconds', cp%factorization_seconds())
    call js%add('dense', cp%is_dense())
    call js%end_object()
  end subroutine add_coarse

  !> report.json's `performance`: the F action's bytes, flops and time
  !> (sums over the ranks), the variants the run resolved, the solve's times.
  subroutine add_performance(js, op, f_bytes, flops, f_flops, f_seconds, seconds)
    type(json_writer_t), intent(inout) :: js
    type(feti_t), intent(inout) :: op
    integer(i8), intent(in) :: f_bytes
    real(dp), intent(in) :: flops(2), f_flops, f_seconds, seconds(3)
    call js%begin_object('performance')
    call js%add('f_bytes_per_action_sum', f_bytes)
    call js%add('f_action', trim(merge('explicit', 'implicit', op%f_explicit())))
    ! the ordering of the subdomain factorizations (&solver local_ordering = 'auto' resolved)
    call js%add('local_ordering', trim(op%local_ordering()))
    call js%add('local_solver', trim(op%local_solver()))
    ! f_action = 'auto''s deferred build: the F actions made before it (-1: none made or pending)
    call js%add('f_explicit_after', merge(op%f_explicit_after(), -1_i8, op%f_explicit()))
    call js%add('f_shared', op%f_shared())
    call js%add('f_flops_per_action_sum', f_flops)
    call js%add_each([character(len=32) :: 'factorization_flops_sum', 'explicit_f_flops_sum'], flops)
    call js%add_each([character(len=32) :: 'f_action_seconds_per_call', 'f_bandwidth_bytes_per_second', &
                      'solve_seconds', 'solve_f_action_seconds', 'solve_coarse_seconds', 'solve_coarse_share'], &
                     [f_seconds, real(f_bytes, dp)/max(f_seconds, tiny(1.0_dp)), seconds(1), seconds(2), seconds(3), &
                      seconds(3)/max(seconds(1), tiny(1.0_dp))])
    call js%end_object()
  end subroutine add_performance

  !> Where the output is and how to look at it (a user's first question), with
  !> absolute paths: the hints work from any folder (the plotting tool of the
  !> sources the program was built from; relative to them when they moved).
  !> `hertz`: the obstacle is a sphere (the contact pressure compares with Hertz's).
  subroutine log_where_to_look(output, hertz)
    type(output_settings_t), intent(in) :: output
    logical, intent(in) :: hertz
    character(len=:), allocatable :: dir, tool
    dir = absolute_path(output%directory)
    tool = fc_source_dir//'/tools/plots.py'
    if (.not. path_exists(tool)) tool = 'tools/plots.py (in the feticontact sources)'
    if (output%write_hdf5) then
      call log_message('output: '//dir//'/'//trim(output%run_name)//'.xdmf (fields for ParaView; '// &
                       'its grid "contact" holds the contact pressure and gap)')
      if (hertz) call log_message('contact pressure against Hertz: '// &
        '/usr/bin/python3 '//tool//' hertz '//dir//' --figures '//dir)
    end if
    if (output%write_report) call log_message('report: '//dir//'/report.json (settings, iterations, '// &
                                                'KKT residuals, timings)')
  end subroutine log_where_to_look

  !> The max over ranks of timer `name`, `absent` if there is no such timer.
  real(dp) function stat_max(stats, name, absent)
    type(timer_stat_t), intent(in) :: stats(:)
    character(len=*), intent(in) :: name
    real(dp), intent(in) :: absent
    integer :: k
    stat_max = absent
    do k = 1, size(stats)
      if (stats(k)%name == name) stat_max = stats(k)%max
    end do
  end function stat_max
end module run_report
