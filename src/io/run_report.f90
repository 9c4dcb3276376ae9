!> report.json of one run: the case, the sizes, the solver's counters, the KKT
!> residuals, the reconstruction, the timings, the contact summary, memory,
!> BLAS and the F action's bandwidth (docs/OUTPUT.md). Rank 0 of the
!> dualization's communicator writes.
module run_report
  use kinds, only: dp, ip, i8, MPI_INT_I8
  use timers, only: timer_stat_t
  use logger, only: log_message
  use params, only: params_t
  use feti_operators, only: feti_t, feti_sizes_t
  use qp_problem, only: qp_status_name
  use smalbe, only: smalbe_t
  use tfeti_dualization, only: tfeti_dualization_t, dual_solution_t
  use contact_summary, only: contact_summary_t
  use json_writer, only: json_writer_t
  use report, only: timings_json, memory_json, blas_json, params_json
  use blas_threads, only: blas_in_use
  use mpi_f08, only: MPI_Comm_size, MPI_Allreduce, MPI_SUM
  implicit none
  private

  public :: write_run_report, log_where_to_look

contains

  !> Write <p%output%directory>/report.json. `seconds`: the solve and, within
  !> it, the F actions and the coarse solves (tfeti_dualization%solve);
  !> `stats`: the reduced timers. Collective.
  subroutine write_run_report(p, dual, solver, sol, contact, stats, seconds)
    type(params_t), intent(in) :: p
    type(tfeti_dualization_t), intent(inout), target :: dual
    type(smalbe_t), intent(in) :: solver
    type(dual_solution_t), intent(in) :: sol
    type(contact_summary_t), intent(in) :: contact
    type(timer_stat_t), intent(in) :: stats(:)
    real(dp), intent(in) :: seconds(3)
    type(json_writer_t) :: js
    type(feti_t), pointer :: op
    type(feti_sizes_t) :: n
    character(len=:), allocatable :: memory
    integer(i8) :: f_bytes
    real(dp) :: f_seconds
    integer :: nranks, ierr

    op => dual%operators()
    n = op%sizes()
    call MPI_Comm_size(op%comm(), nranks, ierr)
    memory = memory_json(op%comm())
    ! bytes one F action reads on all ranks, and the time of one F action
    call MPI_Allreduce(op%bytes_per_f_action(), f_bytes, 1, MPI_INT_I8, MPI_SUM, op%comm(), ierr)
    f_seconds = stat_max(stats, 'F action', 0.0_dp)/max(op%f_applications(), 1_i8)

    call js%begin_object()
    call js%add_raw('case', params_json(p))
    call js%begin_object('sizes')
    call js%add('subdomains', n%nsubdomains)
    call js%add('ranks', int(nranks, ip))
    call js%add('primal_dofs', n%primal_dofs)
    call js%add('dual_dofs', n%dual_dofs)
    call js%add('coarse_dim', n%coarse_dim)
    call js%add('contact_rows', n%contact_rows)
    call js%add('active_contact', contact%active_nodes)
    call js%add('gluing_rows', n%gluing_rows)
    call js%add('dirichlet_rows', n%dirichlet_rows)
    call js%end_object()
    call js%begin_object('solver')
    call js%add('converged', solver%converged())
    call js%add('status', qp_status_name(solver%status))
    call js%add('message', trim(solver%message))
    call js%add('outer_iterations', solver%n_outer)
    call js%add('inner_iterations', solver%n_inner)
    call js%add('hessian_multiplications', solver%n_hessian)
    call js%add('cg_steps', solver%n_cg)
    call js%add('expansion_steps', solver%n_expansion)
    call js%add('proportioning_steps', solver%n_proportioning)
    call js%add('m_updates', solver%n_m_updates)
    call js%add('projected_gradient', solver%gp_norm)
    call js%add('equality_residual', solver%cnorm)
    call js%add('norm_b', solver%norm_b)
    call js%add('rho', dual%rho())
    call js%add('norm_pfp', op%norm_pfp())
    call js%add('f_applications', op%f_applications())
    call js%add('coarse_solves', op%coarse_solves())
    call js%end_object()
    call js%begin_object('kkt')
    call js%add('equilibrium', sol%kkt%equilibrium)
    call js%add('equality', sol%kkt%equality)
    call js%add('feasibility', sol%kkt%feasibility)
    call js%add('dual_feasibility', sol%kkt%dual_feasibility)
    call js%add('complementarity', sol%kkt%complementarity)
    call js%add('passed', sol%kkt%worst() <= p%reconstruction%kkt_tol)
    call js%end_object()
    call js%begin_object('reconstruction')
    call js%add('method', trim(p%reconstruction%method))
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
    call js%add('assembly', sol%standard_cost%assembly)
    call js%add('factorization', sol%standard_cost%factorization)
    call js%add('solve', sol%standard_cost%solve)
    call js%add('active_contact_rows', sol%standard_cost%active_rows)
    call js%end_object()
    call js%end_object()
    call js%add_raw('timings', timings_json(stats))
    call js%begin_object('contact')
    call js%add('total_force', contact%total_force)
    call js%add('max_pressure', contact%max_pressure)
    call js%add('active_nodes', contact%active_nodes)
    call js%add('contact_radius', contact%contact_radius)
    call js%end_object()
    call js%add_raw('memory', memory)
    associate (b => blas_in_use())                 ! set up by the main program
      call js%add_raw('blas', blas_json(trim(b%library), trim(b%path), b%threads, trim(b%source), b%settable))
    end associate
    call js%begin_object('performance')
    call js%add('f_bytes_per_action_sum', f_bytes)
    call js%add('f_action_seconds_per_call', f_seconds)
    call js%add('f_bandwidth_bytes_per_second', real(f_bytes, dp)/max(f_seconds, tiny(1.0_dp)))
    call js%add('solve_seconds', seconds(1))
    call js%add('solve_f_action_seconds', seconds(2))
    call js%add('solve_coarse_seconds', seconds(3))
    call js%add('solve_coarse_share', seconds(3)/max(seconds(1), tiny(1.0_dp)))
    call js%end_object()
    call js%end_object()
    call js%write_file(trim(p%output%directory)//'/report.json', op%comm())

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

  !> Where the output is and how to look at it (a user's first question).
  subroutine log_where_to_look(p)
    type(params_t), intent(in) :: p
    character(len=:), allocatable :: dir
    dir = trim(p%output%directory)
    if (p%output%write_hdf5) then
      call log_message('output: '//dir//'/'//trim(p%output%run_name)//'.xdmf (fields for ParaView; '// &
                       'its grid "contact" holds the contact pressure and gap)')
      if (p%obstacle%shape == 'sphere') call log_message('contact pressure against Hertz: '// &
        '/usr/bin/python3 tools/plots.py hertz '//dir//' --figures '//dir)
    end if
    if (p%output%write_report) call log_message('report: '//dir//'/report.json (settings, iterations, '// &
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
