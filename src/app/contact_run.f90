!> One run of the pipeline (docs/ARCHITECTURE.md) on checked parameters:
!> set-up (the TFETI dualization builds the dual QP), solve (SMALBE with
!> MPRGP), post-solve (the inverse of the dualization: lambda, alpha_bar, u,
!> KKT check), report (contact summary, HDF5/XDMF fields, timing table,
!> report.json). Returns the exit status of the run.
module contact_run
  use kinds, only: dp
  use errors, only: exit_not_converged, exit_kkt_failed
  use logger, only: log_section, log_message, log_open_file
  use timers, only: timer_start, timer_stop, timers_reduce, timer_stat_t
  use memory_marks, only: memory_mark
  use params, only: params_t, feti_settings_of
  use input_report, only: run_case_of
  use smalbe, only: smalbe_t
  use tfeti_dualization, only: tfeti_dualization_t, dual_solution_t
  use feti_operators, only: feti_t
  use contact_summary, only: contact_summary_t, summarize_contact
  use model_validity, only: add_validity_warnings
  use run_report, only: run_case_t
  use run_checks, only: check_run
  use decomposition, only: decomposition_t
  use field_output, only: write_run_fields
  use run_report, only: write_run_report, log_where_to_look
  use report, only: print_timing_table
  use load_history, only: run_load_history
  use mpi_f08, only: MPI_Comm, MPI_Barrier
  implicit none
  private

  public :: run_contact_case

contains

  !> Run the case `p` on `comm`; `status` is 0 when SMALBE converged and the
  !> KKT residuals are within &reconstruction kkt_tol.
  subroutine run_contact_case(p, comm, status)
    type(params_t), intent(in) :: p
    type(MPI_Comm), intent(in) :: comm
    integer, intent(out) :: status
    type(tfeti_dualization_t), target :: dual
    !> the FETI operators inside `dual`, through a pointer: gfortran 12 copies the whole feti_t
    !> (every subdomain's matrices) for `associate (op => dual%operators())` and for the
    !> function result as an actual argument (a quarter of a 4096-subdomain run in page faults)
    type(feti_t), pointer :: op
    type(smalbe_t) :: solver
    type(dual_solution_t) :: sol
    type(contact_summary_t) :: contact
    type(run_case_t) :: run_case
    type(timer_stat_t), allocatable :: stats(:)
    real(dp), allocatable :: nu(:)
    real(dp) :: seconds(3)
    character(len=200) :: line
    type(decomposition_t) :: units
    integer :: ierr

    ! what --check checks: output folder, ranks, coarse groups; memory estimate; the decomposition
    call check_run(p, comm, units)
    ! the log so far and from now on also in <run_name>.log beside report.json
    if (p%output%write_report) call log_open_file(trim(p%output%directory)//'/'//trim(p%output%run_name)//'.log')
    if (p%history%is_history()) then
      ! &history: one set-up, a solve per step (load_history)
      call run_load_history(p, comm, status, units)
      return
    end if
    call MPI_Barrier(comm, ierr)
    call timer_start('total')
    ! 1. set-up: mesh, assembly, K^+, B and G, coarse problem, d, e, lambda~, ||P F P||, the dual QP
    call dual%setup(feti_settings_of(p), p%solver%dual, p%solver%preconditioner, p%reconstruction, comm, units)
    call memory_mark('dual QP setup')
    ! 2. solve: SMALBE (outer) + MPRGP (inner) on the dual QP
    call log_section('SMALBE / MPRGP')
    call solver%init(p%solver%smalbe, dual%hessian_norm())
    call dual%solve(solver, nu, seconds)
    call memory_mark('solve')
    ! 3. post-solve: lambda, alpha_bar (Eq. 24/25 and/or 10), u, KKT residuals
    call dual%post_solve(nu, solver%muhat, sol)
    call memory_mark('post-solve')
    ! 4. report: contact summary, fields, timings, report.json
    call timer_start('output')
    op => dual%operators()
    call summarize_contact(op, sol%lambda, p%reconstruction%active_tol, contact, &
                           p%obstacle%centre_of(p%mesh%lengths))
    run_case = run_case_of(p)
    call add_validity_warnings(op, sol%u, p%mesh%lengths, run_case%warnings)
    if (p%output%write_hdf5) call write_run_fields(op, sol%u, contact, p%output%directory, &
                                                   p%output%run_name)
    call timer_stop('output')
    call memory_mark('output')
    call timer_stop('total')
    write (line, '(a,es12.5,a,es12.5,a,i0,a,es12.5)') 'contact force ', contact%total_force, &
      ', max pressure ', contact%max_pressure, ', nodes in contact ', contact%active_nodes, &
      ', contact radius ', contact%contact_radius
    call log_message(line)
    call timers_reduce(comm, stats)
    call log_section('Timings [s] (min / max / mean over ranks)')
    call print_timing_table(stats)
    if (p%output%write_report) call write_run_report(run_case, p%output, p%reconstruction, &
                                                        dual, solver, sol, contact, stats, seconds)

    status = 0
    if (.not. solver%converged()) then
      call log_message('feticontact: the dual solver did not converge: '//trim(solver%message))
      status = exit_not_converged
    else if (sol%kkt%worst() > p%reconstruction%kkt_tol) then
      write (line, '(3a,es10.3,a,es10.3)') 'feticontact: KKT check failed: largest residual (', sol%kkt%worst_name(), &
        ') ', sol%kkt%worst(), ' > kkt_tol ', p%reconstruction%kkt_tol
      call log_message(line)
      status = exit_kkt_failed
    else
      call log_message('feticontact: converged, KKT check passed')
    end if
    call log_where_to_look(p%output, p%obstacle%shape == 'sphere')
    call dual%free()
  end subroutine run_contact_case
end module contact_run
