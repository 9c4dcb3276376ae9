!> A quasi-static load history (`&history`, docs/INPUT.md): one set-up (mesh,
!> K^+, B and G, G G^T, the explicit operators, the preconditioner, the
!> Lanczos estimate), then per step: the right-hand sides for the step's load
!> factor and obstacle gap (tfeti_dualization%set_load), the solve warm
!> started from the previous steps (warm_guess: lambda and the SMALBE
!> multiplier extrapolated in the load factor), the inverse of the dualization (u by the new formula, and the
!> standard one with method = 'both'), the KKT check, the contact summary,
!> one log line, the step's fields (one HDF5 file per step and a temporal
!> XDMF collection) and a checkpoint. A step that fails stops the run with
!> its status and the step named; a time limit or a stop signal stops it
!> after the current step (its checkpoint written; `restart` continues).
module load_history
  use kinds, only: dp, ip, i8, path_len, MPI_REAL_DP, MPI_INT_I8
  use text, only: str
  use errors, only: exit_not_converged, exit_kkt_failed, exit_input_error, collective_error
  use logger, only: log_section, log_message
  use timers, only: timer_start, timer_stop, timers_reduce, timer_stat_t, timer_seconds
  use memory_marks, only: memory_mark
  use params, only: params_t, param_items, param_item_t, group_names, feti_settings_of
  use input_report, only: run_case_of
  use smalbe, only: smalbe_t
  use tfeti_dualization, only: tfeti_dualization_t, dual_solution_t
  use feti_operators, only: feti_t, feti_sizes_t
  use subdomain, only: subdomain_t
  use decomposition, only: decomposition_t
  use contact_summary, only: contact_summary_t, summarize_contact
  use hdf5_output, only: check_output_directory
  use field_output, only: write_run_fields
  use xdmf, only: write_xdmf_series
  use run_report, only: write_run_report, log_where_to_look, run_case_t
  use model_validity, only: add_validity_warnings
  use kkt, only: check_kkt
  use report, only: print_timing_table
  use json_writer, only: json_writer_t
  use history_checkpoint, only: step_record_t, checkpoint_t, warm_state_t, write_checkpoint, read_checkpoint, &
                                text_hash
  use stop_signal, only: install_stop_signal, stop_requested
  use face_recycle, only: face_recycle_t
  use mpi_f08, only: MPI_Comm, MPI_Barrier, MPI_Allreduce, MPI_Comm_rank, MPI_Comm_size, MPI_IN_PLACE, &
                     MPI_MAX, MPI_MIN, MPI_SUM, MPI_INTEGER, MPI_Wtime
  implicit none
  private

  public :: run_load_history

  !> The step report.json's top level describes: the peak (the largest load
  !> factor, the first of equal ones), its solution, contact and solver.
  type :: peak_step_t
    integer(ip) :: step = 0
    real(dp) :: factor = -huge(1.0_dp)
    real(dp) :: seconds(3) = 0
    type(dual_solution_t) :: sol
    type(contact_summary_t) :: contact
    type(smalbe_t) :: solver
  end type peak_step_t

  !> What a history run keeps from its set-up to its end.
  type :: history_run_t
    type(MPI_Comm) :: comm
    integer :: rank = 0, nranks = 1
    type(tfeti_dualization_t) :: dual
    type(feti_t), pointer :: op => null()
    type(smalbe_t) :: solver
    type(dual_solution_t) :: sol
    type(contact_summary_t) :: contact
    type(checkpoint_t) :: ck
    type(step_record_t), allocatable :: records(:)
    type(warm_state_t) :: warm                  !< the last solutions, for the next start
    real(dp), allocatable :: nu(:), work(:)
    type(peak_step_t) :: peak                   !< the step report.json's top level describes
    real(dp) :: t_start = 0
    integer(i8) :: fingerprint(2) = 0
  end type history_run_t

  !> How a step's solve started (step_record_t%warm)
  character(len=12), parameter :: start_names(0:3) = [character(len=12) :: 'cold', 'previous', 'scaled', &
                                                       'extrapolated']


contains

  !> Run the history of `p` on `comm`; `status` 0 when every step converged
  !> and passed the KKT check (also when a time limit or a signal stopped
  !> the run after a step), else that of the failed step. `units`: the
  !> decomposition of the checks (run_checks::check_run).
  subroutine run_load_history(p, comm, status, units)
    type(params_t), intent(in) :: p
    type(MPI_Comm), intent(in) :: comm
    integer, intent(out) :: status
    type(decomposition_t), intent(in), optional :: units
    type(history_run_t), target :: h
    type(step_record_t) :: rec
    integer(ip) :: step, first

    h%comm = comm
    call start_history(p, h, first, units)
    status = 0
    do step = first, p%history%nsteps
      call solve_step(p, h, step, rec)
      status = step_status(p, h, rec)
      if (status /= 0) exit
      if (stopped_after(p, h, step)) exit
    end do
    call memory_mark('history')
    call timer_stop('total')
    call finish_history(p, h, status)
  end subroutine run_load_history

  !> The set-up of a history: the output folder, the stop signal, one
  !> dual set-up for every step, and (restart) the checkpoint; `first`: the
  !> first step to solve; `units`: the checks' decomposition, if any.
  subroutine start_history(p, h, first, units)
    type(params_t), intent(in) :: p
    type(history_run_t), intent(inout), target :: h
    integer(ip), intent(out) :: first
    type(decomposition_t), intent(in), optional :: units
    integer :: ierr
    character(len=300) :: line
    call MPI_Comm_rank(h%comm, h%rank, ierr)
    call MPI_Comm_size(h%comm, h%nranks, ierr)
    if (p%output%write_hdf5 .or. p%output%write_report .or. p%history%checkpoint) &
      call check_output_directory(h%comm, p%output%directory)
    call install_stop_signal()
    call MPI_Barrier(h%comm, ierr)
    h%t_start = MPI_Wtime()
    call timer_start('total')
    call h%dual%setup(feti_settings_of(p), p%solver%dual, p%solver%preconditioner, p%reconstruction, h%comm, &
                      units)
    call h%dual%prepare_history()
    call memory_mark('dual QP setup')
    h%op => h%dual%operators()
    h%fingerprint = history_fingerprint(p, h%op, h%nranks)
    allocate (h%records(0))
    first = 1
    allocate (h%warm%lambda(h%op%n_own(), 2), h%warm%muhat(h%op%n_coarse(), 2))
    h%warm%lambda = 0
    h%warm%muhat = 0
    if (p%history%restart) then
      call restart_from(p, h%comm, h%rank, h%nranks, h%op, h%dual, h%fingerprint, h%ck, &
                        h%solver%kept_directions())
      h%records = h%ck%records
      h%warm = h%ck%warm
      first = h%ck%step + 1
      write (line, '(a,i0,a,i0)') 'history: restart after step ', h%ck%step, ' of ', p%history%nsteps
      call log_message(trim(line))
    end if
    allocate (h%nu(h%op%n_own()), h%work(h%op%n_own()))
    call log_section('Load history')
    write (line, '(a,i0,3a,es10.3,a,l1)') 'steps ', p%history%nsteps, ', path ', trim(p%history%path), &
      ', factor_peak ', p%history%factor_peak, ', warm start ', p%history%warm_start
    call log_message(trim(line))
  end subroutine start_history

  !> Step `step`: its right-hand sides, the warm-started solve, the inverse
  !> (lambda, alpha_bar, u, KKT), the contact summary, its fields and its
  !> record (appended to h%records, logged).
  subroutine solve_step(p, h, step, rec)
    type(params_t), intent(in) :: p
    type(history_run_t), intent(inout), target :: h
    integer(ip), intent(in) :: step
    type(step_record_t), intent(out) :: rec
    real(dp) :: t0, before(5), seconds(3)
    real(dp), allocatable :: muhat0(:)
    integer :: ierr
    t0 = MPI_Wtime()
    before = [timer_seconds('rec new'), timer_seconds('rec standard'), timer_seconds('primal'), &
              timer_seconds('kkt'), timer_seconds('step rhs')]
    rec%step = step
    rec%factor = p%history%factor(step)
    rec%gap = p%history%gap(step, p%obstacle%gap)
    call log_section('Step '//str(step))
    ! 1. the right-hand sides of the step
    call timer_start('step rhs')
    call h%dual%set_load(rec%factor, rec%gap - p%obstacle%gap)
    call timer_stop('step rhs')
    ! 2. the solve, warm started (warm_guess; nu = P lambda0, P lambda~ = 0, which SMALBE projects
    ! onto nu >= -lambda~)
    call h%solver%init(p%solver%smalbe, h%dual%hessian_norm())
    ! warm: the face CG directions of the earlier steps start this step's face solves (F is the
    ! same in every step; face_recycle)
    call h%solver%recycle_directions(p%history%warm_start .and. p%history%recycle)
    h%nu = 0
    ! the unloaded state starts cold, from its exact nu = 0 (finish_step)
    if (h%warm%n > 0 .and. p%history%warm_start .and. .not. (rec%factor == 0 .and. rec%gap >= 0)) then
      call warm_guess(h%warm, rec%factor, rec%gap, h%work, muhat0, rec%warm)
      call h%op%project(h%work, h%nu)
      ! contact rows without force in the guess exactly at their bound (lambda = 0), not a
      ! rounding error above it: their face is that of the guess
      where (h%op%is_contact() .and. h%work <= 0) h%nu = h%op%lower_bounds()
      call h%solver%warm_start(muhat0)
    end if
    call h%dual%solve_from(h%solver, h%nu, seconds)
    ! 3. the inverse: lambda, alpha_bar, u, KKT
    call h%dual%post_solve(h%nu, h%solver%muhat, h%sol)
    call finish_step(p, h%op, h%solver, seconds, h%sol, h%contact, rec, h%peak)
    ! 4. output of the step
    call timer_start('output')
    if (p%output%write_hdf5) call write_step_fields(p, h%op, h%sol, h%contact, step, h%comm, h%rank)
    call timer_stop('output')
    rec%seconds = [timer_seconds('step rhs') - before(5), seconds(1), timer_seconds('rec new') - before(1), &
                   timer_seconds('rec standard') - before(2), timer_seconds('primal') - before(3), &
                   timer_seconds('kkt') - before(4), MPI_Wtime() - t0]
    call MPI_Allreduce(MPI_IN_PLACE, rec%seconds, size(rec%seconds), MPI_REAL_DP, MPI_MAX, h%comm, ierr)
    h%records = [h%records, rec]
    call log_step(rec, p%history%nsteps)
    call remember(h%warm, rec%factor, rec%gap, h%sol%lambda, h%solver%muhat)
  end subroutine solve_step

  !> 5. A failed step stops the history: its status (0: the step converged
  !> and passed the KKT check), the reason logged.
  integer function step_status(p, h, rec) result(status)
    type(params_t), intent(in) :: p
    type(history_run_t), intent(in) :: h
    type(step_record_t), intent(in) :: rec
    character(len=300) :: line
    status = 0
    if (rec%converged == 0) then
      write (line, '(a,i0,a,es10.3,2a)') 'feticontact: step ', rec%step, ' (load factor ', rec%factor, &
        '): the dual solver did not converge: ', trim(h%solver%message)
      call log_message(trim(line))
      status = exit_not_converged
    else if (rec%kkt_passed == 0) then
      write (line, '(a,i0,a,es10.3,3a,es10.3,a,es10.3)') 'feticontact: step ', rec%step, ' (load factor ', &
        rec%factor, '): KKT check failed: largest residual (', h%sol%kkt%worst_name(), ') ', &
        h%sol%kkt%worst(), ' > kkt_tol ', p%reconstruction%kkt_tol
      call log_message(trim(line))
      status = exit_kkt_failed
    end if
  end function step_status

  !> 6. The checkpoint of step `step`, then whether a time limit or a stop
  !> signal ends the run here (before the last step). Collective.
  logical function stopped_after(p, h, step) result(stopped)
    type(params_t), intent(in) :: p
    type(history_run_t), intent(inout), target :: h
    integer(ip), intent(in) :: step
    integer :: stop_flag, ierr
    character(len=300) :: line
    if (p%history%checkpoint) then
      h%ck%fingerprint = h%fingerprint
      h%ck%step = step
      h%ck%switched = merge(1, 0, h%dual%preconditioner_switched())
      h%ck%warm = h%warm
      h%ck%records = h%records
      call save_checkpoint(p, h%comm, h%rank, h%nranks, h%ck, h%solver%kept_directions())
    end if
    stop_flag = 0
    if (stop_requested()) stop_flag = 1
    if (p%history%time_limit > 0 .and. MPI_Wtime() - h%t_start > p%history%time_limit) stop_flag = 2
    call MPI_Allreduce(MPI_IN_PLACE, stop_flag, 1, MPI_INTEGER, MPI_MAX, h%comm, ierr)
    stopped = stop_flag > 0 .and. step < p%history%nsteps
    if (stopped) then
      write (line, '(a,i0,a,i0,3a)') 'history: stopped after step ', step, ' of ', p%history%nsteps, ' (', &
        trim(merge('stop signal         ', '&history time_limit ', stop_flag == 1)), &
        '); continue with &history restart = .true.'
      call log_message(trim(line))
    end if
  end function stopped_after

  !> The end of a history: the timing table, the summary, report.json (the
  !> peak step's solve and solution with every step's record).
  subroutine finish_history(p, h, status)
    type(params_t), intent(in) :: p
    type(history_run_t), intent(inout), target :: h
    integer, intent(in) :: status
    type(timer_stat_t), allocatable :: stats(:)
    call timers_reduce(h%comm, stats)
    call log_section('Timings [s] (min / max / mean over ranks)')
    call print_timing_table(stats)
    call log_history_summary(h%records)
    if (p%output%write_report .and. h%peak%step > 0) call write_peak_report(p, h%dual, h%peak, stats, h%records)
    if (status == 0) call log_message('feticontact: history done, every step converged, KKT check passed')
    call log_where_to_look(p%output, p%obstacle%shape == 'sphere')
    call h%dual%free()
  end subroutine finish_history

  !> The unloaded state (load factor 0, the obstacle not inside the body):
  !> no load, every Dirichlet value 0 and every gap >= 0, so u = 0 and
  !> lambda = 0 solve the contact problem exactly. The solve's round-off
  !> would be all there is of u, and the KKT check measures displacements
  !> relative to max |u|: the exact solution replaces it, checked by the KKT
  !> check like any other.
  subroutine unloaded_state(op, sol)
    type(feti_t), intent(inout), target :: op
    type(dual_solution_t), intent(inout) :: sol
    integer :: ls
    character(len=300) :: line
    sol%lambda = 0
    sol%alpha_bar = 0
    do ls = 1, size(sol%u)
      sol%u(ls)%v = 0
    end do
    sol%kkt = check_kkt(op, sol%u, sol%lambda)
    write (line, '(a,es10.3)') 'unloaded state (load factor 0): the exact solution u = 0, lambda = 0; '// &
      'KKT largest residual ', sol%kkt%worst()
    call log_message(trim(line))
  end subroutine unloaded_state

  !> After a step's post-solve: the unloaded state's exact solution
  !> (unloaded_state), the contact summary, the step's record, and the step
  !> kept in `peak` when its load factor is the largest so far (a warm step
  !> at factor 0 starts cold, from its exact nu = 0: the run's loop).
  subroutine finish_step(p, op, solver, seconds, sol, contact, rec, peak)
    type(params_t), intent(in) :: p
    type(feti_t), intent(inout), target :: op
    type(smalbe_t), intent(inout) :: solver
    real(dp), intent(in) :: seconds(3)
    type(dual_solution_t), intent(inout) :: sol
    type(contact_summary_t), intent(out) :: contact
    type(step_record_t), intent(inout) :: rec
    type(peak_step_t), intent(inout) :: peak
    if (rec%factor == 0 .and. rec%gap >= 0) call unloaded_state(op, sol)
    call summarize_contact(op, sol%lambda, p%reconstruction%active_tol, contact, p%obstacle%centre_of(p%mesh%lengths))
    call fill_record(rec, contact, solver, sol, p%reconstruction%kkt_tol)
    if (rec%factor <= peak%factor) return
    peak%step = rec%step
    peak%factor = rec%factor
    peak%seconds = seconds
    peak%sol = sol
    peak%contact = contact
    call solver%report_copy(peak%solver)
  end subroutine finish_step

  !> report.json of a history: the top level describes the peak step (named
  !> in `step`, with the warnings of its solution), `history` every step.
  subroutine write_peak_report(p, dual, peak, stats, records)
    type(params_t), intent(in) :: p
    type(tfeti_dualization_t), intent(inout), target :: dual
    type(peak_step_t), intent(in) :: peak
    type(timer_stat_t), intent(in) :: stats(:)
    type(step_record_t), intent(in) :: records(:)
    type(run_case_t) :: run_case
    type(feti_t), pointer :: op
    op => dual%operators()
    run_case = run_case_of(p)
    call add_validity_warnings(op, peak%sol%u, p%mesh%lengths, run_case%warnings)
    call write_run_report(run_case, p%output, p%reconstruction, dual, peak%solver, peak%sol, peak%contact, stats, &
                          peak%seconds, history_json(records), peak%step)
  end subroutine write_peak_report

  !> The step's contact summary, solver counts and KKT outcome into its record.
  subroutine fill_record(rec, contact, solver, sol, kkt_tol)
    type(step_record_t), intent(inout) :: rec
    type(contact_summary_t), intent(in) :: contact
    type(smalbe_t), intent(in) :: solver
    type(dual_solution_t), intent(in) :: sol
    real(dp), intent(in) :: kkt_tol
    rec%total_force = contact%total_force
    rec%max_pressure = contact%max_pressure
    rec%contact_radius = contact%contact_radius
    rec%active_nodes = contact%active_nodes
    rec%outer = solver%n_outer
    rec%hessian = solver%n_hessian
    call solver%reuse_counts(rec%faces_reused, rec%recycled)
    rec%kkt_worst = sol%kkt%worst()
    rec%alpha_difference = sol%alpha_difference
    rec%converged = merge(1, 0, solver%converged())
    rec%kkt_passed = merge(1, 0, sol%kkt%worst() <= kkt_tol)
  end subroutine fill_record

  !> The start of the next solve from the last steps held in `ws`:
  !> lambda and the SMALBE multiplier are affine in the load factor while
  !> the active set and the obstacle stay (d, e, lambda~ are, and the gaps
  !> do not change), so with two earlier steps at the same gap and
  !> different factors the start is their linear extrapolation to `factor`
  !> (how = 3), exact for an unchanged active set; with one at the same gap,
  !> its solution scaled by factor / its factor (how = 2: exact when the
  !> constant part vanishes, as for an obstacle touching at one point);
  !> else the last solution itself (how = 1).
  subroutine warm_guess(ws, factor, gap, lambda0, muhat0, how)
    type(warm_state_t), intent(in) :: ws
    real(dp), intent(in) :: factor, gap
    real(dp), intent(out) :: lambda0(:)
    real(dp), allocatable, intent(out) :: muhat0(:)
    integer(ip), intent(out) :: how
    real(dp) :: t
    if (ws%n >= 2 .and. ws%gap(1) == gap .and. ws%gap(2) == gap .and. ws%factor(1) /= ws%factor(2)) then
      t = (factor - ws%factor(1))/(ws%factor(1) - ws%factor(2))
      lambda0 = ws%lambda(:, 1) + t*(ws%lambda(:, 1) - ws%lambda(:, 2))
      muhat0 = ws%muhat(:, 1) + t*(ws%muhat(:, 1) - ws%muhat(:, 2))
      how = 3
    else if (ws%gap(1) == gap .and. ws%factor(1) > 0) then
      t = factor/ws%factor(1)
      lambda0 = t*ws%lambda(:, 1)
      muhat0 = t*ws%muhat(:, 1)
      how = 2
    else
      lambda0 = ws%lambda(:, 1)
      muhat0 = ws%muhat(:, 1)
      how = 1
    end if
  end subroutine warm_guess

  !> Keep the solution of the step just done as the last one of `ws`.
  subroutine remember(ws, factor, gap, lambda, muhat)
    type(warm_state_t), intent(inout) :: ws
    real(dp), intent(in) :: factor, gap, lambda(:), muhat(:)
    ws%lambda(:, 2) = ws%lambda(:, 1)
    ws%muhat(:, 2) = ws%muhat(:, 1)
    ws%factor(2) = ws%factor(1)
    ws%gap(2) = ws%gap(1)
    ws%lambda(:, 1) = lambda
    ws%muhat(:, 1) = muhat
    ws%factor(1) = factor
    ws%gap(1) = gap
    ws%n = min(ws%n + 1, 2_ip)
  end subroutine remember

  !> The fingerprint of the input (every group as echoed, without the
  !> &history variables that only steer a run: restart, time_limit,
  !> checkpoint, and without the file name) and of the problem's sizes.
  function history_fingerprint(p, op, nranks) result(h)
    type(params_t), intent(in) :: p
    type(feti_t), intent(inout) :: op
    integer, intent(in) :: nranks
    integer(i8) :: h(2)
    type(params_t) :: q
    type(param_item_t), allocatable :: items(:)
    type(feti_sizes_t) :: n
    character(len=:), allocatable :: text
    character(len=120) :: buf
    integer :: g, k, v
    q = p
    q%file = ''
    q%history%restart = .false.
    q%history%time_limit = 0
    q%history%checkpoint = .true.
    text = ''
    do g = 1, size(group_names)
      call param_items(q, trim(group_names(g)), items)
      text = text//'&'//trim(group_names(g))
      do k = 1, size(items)
        text = text//' '//trim(items(k)%name)//'='
        do v = 1, items(k)%n
          text = text//trim(items(k)%values(v))//','
        end do
      end do
    end do
    n = op%sizes()
    write (buf, '(*(i0,1x))') n%nsubdomains, n%coarse_dim, n%primal_dofs, n%dual_dofs, n%contact_rows, nranks, &
      op%n_own(), op%n_coarse()
    h = text_hash(text//trim(buf))
  end function history_fingerprint

  !> Read this rank's checkpoint, agree over the ranks that every one is
  !> valid and of the same step (else every rank stops with exit status 2
  !> and the first reason), switch 'auto' as the earlier steps did.
  subroutine restart_from(p, comm, rank, nranks, op, dual, fingerprint, ck, recycle)
    type(params_t), intent(in) :: p
    type(MPI_Comm), intent(in) :: comm
    integer, intent(in) :: rank, nranks
    type(feti_t), intent(inout) :: op
    type(tfeti_dualization_t), intent(inout) :: dual
    integer(i8), intent(in) :: fingerprint(2)
    type(checkpoint_t), intent(out) :: ck
    type(face_recycle_t), intent(inout) :: recycle   !< the face CG directions the next steps start from
    integer :: status, bad, ierr, steps(2)
    character(len=600) :: msg
    call read_checkpoint(checkpoint_base(p), rank, nranks, fingerprint, op%n_own(), op%n_coarse(), ck, recycle, status, msg)
    if (status == 0 .and. ck%warm%n < 1) then
      status = 1
      msg = 'checkpoint '//trim(checkpoint_base(p))//' holds no solution'
    end if
    steps = -1
    if (status == 0) steps = [int(ck%step), -int(ck%step)]
    call MPI_Allreduce(MPI_IN_PLACE, steps, 2, MPI_INTEGER, MPI_MAX, comm, ierr)
    if (status == 0 .and. steps(1) /= -steps(2)) then
      status = 1
      msg = 'the checkpoint files '//trim(checkpoint_base(p))//'.* hold different steps (a run stopped while '// &
            'writing them): run the history again without restart'
    end if
    if (status == 0 .and. ck%step >= p%history%nsteps) then
      status = 1
      msg = 'checkpoint '//trim(checkpoint_base(p))//' holds the whole history already (nothing to continue)'
    end if
    ! the first rank (lowest) with a reason gives the message
    bad = merge(1, 0, status /= 0)
    call MPI_Allreduce(MPI_IN_PLACE, bad, 1, MPI_INTEGER, MPI_MAX, comm, ierr)
    if (bad /= 0) then
      call share_message(comm, rank, status /= 0, msg)
      call collective_error('&history restart: '//trim(msg), comm, exit_input_error)
    end if
    if (ck%switched == 1) call dual%switch_preconditioner()
  end subroutine restart_from

  !> Rank 0 gets the message of the lowest rank that has one (`mine`).
  subroutine share_message(comm, rank, mine, msg)
    type(MPI_Comm), intent(in) :: comm
    integer, intent(in) :: rank
    logical, intent(in) :: mine
    character(len=*), intent(inout) :: msg
    integer :: first, ierr, k
    integer, allocatable :: codes(:)
    integer :: nranks
    call MPI_Comm_size(comm, nranks, ierr)
    first = huge(1)
    if (mine) first = rank
    call MPI_Allreduce(MPI_IN_PLACE, first, 1, MPI_INTEGER, MPI_MIN, comm, ierr)
    ! the message as character codes, summed (only `first` contributes)
    allocate (codes(len(msg)))
    codes = 0
    if (rank == first) then
      do k = 1, len(msg)
        codes(k) = iachar(msg(k:k))
      end do
    end if
    call MPI_Allreduce(MPI_IN_PLACE, codes, size(codes), MPI_INTEGER, MPI_SUM, comm, ierr)
    do k = 1, len(msg)
      msg(k:k) = achar(codes(k))
    end do
  end subroutine share_message

  !> Write every rank's checkpoint; an I/O error on any rank stops every rank.
  subroutine save_checkpoint(p, comm, rank, nranks, ck, recycle)
    type(params_t), intent(in) :: p
    type(MPI_Comm), intent(in) :: comm
    integer, intent(in) :: rank, nranks
    type(checkpoint_t), intent(in) :: ck
    type(face_recycle_t), intent(in) :: recycle
    integer :: status, worst, ierr
    character(len=600) :: msg
    call timer_start('checkpoint')
    call write_checkpoint(checkpoint_base(p), rank, nranks, ck, recycle, status, msg)
    call timer_stop('checkpoint')
    worst = merge(1, 0, status /= 0)
    call MPI_Allreduce(MPI_IN_PLACE, worst, 1, MPI_INTEGER, MPI_MAX, comm, ierr)
    if (worst /= 0) then
      call share_message(comm, rank, status /= 0, msg)
      call collective_error('history checkpoint: '//trim(msg), comm, exit_input_error)
    end if
  end subroutine save_checkpoint

  !> <directory>/<run_name>.checkpoint (each rank adds .<rank>).
  function checkpoint_base(p) result(base)
    type(params_t), intent(in) :: p
    character(len=:), allocatable :: base
    base = trim(p%output%directory)//'/'//trim(p%output%run_name)//'.checkpoint'
  end function checkpoint_base

  !> The fields of step `step` to <run_name>_step<NNNN>.h5 (+ its own .xdmf),
  !> and <run_name>.xdmf, the temporal collection of steps 1..step. Collective.
  subroutine write_step_fields(p, op, sol, contact, step, comm, rank)
    type(params_t), intent(in) :: p
    type(feti_t), intent(inout), target :: op
    type(dual_solution_t), intent(in) :: sol
    type(contact_summary_t), intent(in) :: contact
    integer(ip), intent(in) :: step
    type(MPI_Comm), intent(in) :: comm
    integer, intent(in) :: rank
    type(subdomain_t), pointer :: subs(:)
    integer(i8) :: counts(3)
    character(len=path_len), allocatable :: names(:)
    real(dp), allocatable :: times(:)
    integer(ip) :: k
    integer :: status, ierr
    character(len=300) :: msg
    call write_run_fields(op, sol%u, contact, p%output%directory, step_name(p, step))
    subs => op%subdomains()
    counts = [sum(int(subs(:)%nnodes, i8)), sum(int(subs(:)%nelem, i8)), count(op%is_contact(), kind=i8)]
    call MPI_Allreduce(MPI_IN_PLACE, counts, 3, MPI_INT_I8, MPI_SUM, comm, ierr)
    status = 0
    if (rank == 0) then
      allocate (names(step), times(step))
      do k = 1, step
        names(k) = step_name(p, k)//'.h5'
        times(k) = real(k, dp)
      end do
      call write_xdmf_series(trim(p%output%directory)//'/'//trim(p%output%run_name)//'.xdmf', names, times, &
                             counts(1), counts(2), counts(3), status, msg)
    end if
    call MPI_Allreduce(MPI_IN_PLACE, status, 1, MPI_INTEGER, MPI_MAX, comm, ierr)
    if (status /= 0) call collective_error('cannot write the temporal XDMF file: '//trim(msg), comm, exit_input_error)
  end subroutine write_step_fields

  function step_name(p, step) result(name)
    type(params_t), intent(in) :: p
    integer(ip), intent(in) :: step
    character(len=:), allocatable :: name
    character(len=8) :: buf
    write (buf, '(i4.4)') step
    name = trim(p%output%run_name)//'_step'//trim(buf)
  end function step_name

  !> One line per step.
  subroutine log_step(rec, nsteps)
    type(step_record_t), intent(in) :: rec
    integer(ip), intent(in) :: nsteps
    character(len=400) :: line
    write (line, '(a,i0,a,i0,a,f8.4,a,es10.3,a,es11.4,a,i0,a,es10.3,a,es10.3,a,i0,a,i0,3a,es9.2,a,es9.2,a,es9.2,a,a)') &
      'step ', rec%step, '/', nsteps, ': factor ', rec%factor, ', gap ', rec%gap, ', force ', rec%total_force, &
      ', contact nodes ', rec%active_nodes, ', radius ', rec%contact_radius, ', max pressure ', rec%max_pressure, &
      ', outer ', rec%outer, ', Hessian ', rec%hessian, ' (', trim(start_names(rec%warm)), &
      ', faces reused '//str(rec%faces_reused)//', recycled '//str(rec%recycled)//'), rec new ', &
      rec%seconds(3), ' s, rec standard ', rec%seconds(4), ' s, KKT ', rec%kkt_worst, &
      merge(' ok    ', ' FAILED', rec%kkt_passed == 1)
    call log_message(trim(line))
  end subroutine log_step

  !> The history's totals: Hessian products of the first step and of the
  !> others, reconstruction seconds (new against standard) over all steps.
  subroutine log_history_summary(records)
    type(step_record_t), intent(in) :: records(:)
    character(len=300) :: line
    integer :: n
    n = size(records)
    if (n == 0) return
    call log_section('History summary')
    write (line, '(a,i0,a,i0,a,f10.1)') 'steps ', n, ', Hessian products: first step ', records(1)%hessian, &
      ', mean of the others ', sum(real(records(2:)%hessian, dp))/max(n - 1, 1)
    call log_message(trim(line))
    write (line, '(a,es10.3,a,es10.3,a,es10.3,a)') 'reconstruction over all steps: new ', &
      sum(records%seconds(3)), ' s, standard ', sum(records%seconds(4)), ' s; first step ', &
      records(1)%seconds(7), ' s'
    call log_message(trim(line))
  end subroutine log_history_summary

  !> report.json's `history`: one record per step.
  function history_json(records) result(json)
    type(step_record_t), intent(in) :: records(:)
    character(len=:), allocatable :: json
    type(json_writer_t) :: js
    integer :: k
    call js%begin_array()
    do k = 1, size(records)
      associate (r => records(k))
        call js%begin_object()
        call js%add('step', int(r%step, i8))
        call js%add_each([character(len=16) :: 'load_factor', 'gap', 'total_force', 'max_pressure', &
                          'contact_radius'], [r%factor, r%gap, r%total_force, r%max_pressure, r%contact_radius])
        call js%add('active_nodes', int(r%active_nodes, i8))
        call js%add_each([character(len=24) :: 'outer_iterations', 'hessian_multiplications'], &
                         int([r%outer, r%hessian], i8))
        call js%add('warm_start', trim(start_names(r%warm)))
        call js%add_each([character(len=24) :: 'faces_reused', 'recycled_directions'], &
                         int([r%faces_reused, r%recycled], i8))
        call js%begin_object('seconds')
        call js%add_each([character(len=16) :: 'rhs', 'solve', 'rec_new', 'rec_standard', 'primal', 'kkt', &
                          'step'], r%seconds)
        call js%end_object()
        if (r%alpha_difference >= 0) then
          call js%add('alpha_difference', r%alpha_difference)
        else
          call js%add_null('alpha_difference')
        end if
        call js%add('kkt_worst', r%kkt_worst)
        call js%add('kkt_passed', r%kkt_passed == 1)
        call js%add('converged', r%converged == 1)
        call js%end_object()
      end associate
    end do
    call js%end_array()
    json = js%text()
  end function history_json
end module load_history
