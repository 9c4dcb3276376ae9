!> One run of the pipeline (docs/ARCHITECTURE.md, "The pipeline") on checked parameters:
!> set-up of the TFETI operators, the SMALBE/MPRGP dual solve, the two
!> reconstructions, the KKT check, HDF5/XDMF output, report.json and the
!> timing table. Returns the exit status of the run.
module contact_run
  use kinds, only: dp, ip, i8, MPI_REAL_DP, MPI_INT_IP, MPI_INT_I8
  use errors, only: exit_not_converged, exit_kkt_failed
  use logger, only: log_section, log_message
  use timers, only: timer_start, timer_stop, timers_reduce, timer_stat_t, timer_seconds
  use params, only: params_t, params_json
  use assembly, only: subdomain_von_mises
  use feti_operators, only: feti_t, local_field_t
  use qp_problem, only: qp_status_name, qp_problem_t
  use dual_problem, only: dual_problem_t
  use dual_problem_orth, only: dual_problem_orth_t
  use orthonormal_coarse, only: check_orthonormal_size
  use smalbe, only: smalbe_t
  use reconstruction, only: dual_gradient, alpha_new, alpha_orthonormal, alpha_standard, standard_cost_t, &
                            coarse_vector_norm, active_contact_mask
  use kkt, only: kkt_residuals_t, check_kkt
  use hdf5_output, only: output_fields_t, write_fields, check_output_directory
  use json_writer, only: json_writer_t
  use report, only: print_timing_table, timings_json, memory_json, blas_json
  use blas_threads, only: blas_in_use
  use mpi_f08, only: MPI_Comm, MPI_Comm_size, MPI_Allreduce, MPI_SUM, MPI_MAX, MPI_Barrier, MPI_IN_PLACE
  implicit none
  private

  public :: run_contact_case

  !> What the contact face looks like at the solution.
  type :: contact_summary_t
    real(dp) :: total_force = 0, max_pressure = 0, contact_radius = 0
    integer(ip) :: active_nodes = 0
  end type contact_summary_t

contains

  !> Run the case `p` on `comm`; `status` is 0 when SMALBE converged and the
  !> KKT residuals are within &reconstruction kkt_tol.
  subroutine run_contact_case(p, comm, status)
    type(params_t), intent(in) :: p
    type(MPI_Comm), intent(in) :: comm
    integer, intent(out) :: status
    type(feti_t), target :: op
    type(dual_problem_t), target :: problem_hat
    type(dual_problem_orth_t), target :: problem_orth
    class(qp_problem_t), pointer :: problem             ! one of the two, by &solver coarse
    real(dp) :: rho, scale
    type(smalbe_t) :: solver
    real(dp), allocatable :: nu(:), lambda(:), g(:), a_new(:), a_std(:), alpha_bar(:)
    type(local_field_t), allocatable :: u(:)
    type(standard_cost_t) :: std_cost
    type(kkt_residuals_t) :: res
    type(contact_summary_t) :: contact
    type(timer_stat_t), allocatable :: stats(:)
    real(dp) :: alpha_difference, a_norm, f_seconds, in_solve(3)
    integer(i8) :: mine_bytes, f_bytes
    integer :: k
    integer(ip) :: nactive
    integer :: nranks, ierr
    character(len=200) :: line
    logical :: converged, kkt_ok, orthonormal
    logical, allocatable :: active(:)

    status = 0
    call MPI_Comm_size(comm, nranks, ierr)
    if (p%output%write_hdf5 .or. p%output%write_report) call check_output_directory(comm, p%output%directory)
    orthonormal = p%solver%coarse == 'cholesky'     ! explicit G~ = L^{-1} G, paper Eq. 25
    if (orthonormal) call check_orthonormal_size(product(p%mesh%nsub), comm)
    call MPI_Barrier(comm, ierr)
    call timer_start('total')

    ! 1. set-up: mesh, assembly, K^+, B and G, coarse problem, d, e, lambda~, ||P F P||
    call op%setup(p, comm)
    call log_section('Problem')
    write (line, '(a,i0,a,i0,a,i0)') 'subdomains ', op%dec%nsubdomains, ', ranks ', nranks, &
      ', primal dofs ', op%primal_dofs
    call log_message(line)
    write (line, '(a,i0,a,i0,a,i0,a,i0,a,i0)') 'dual dofs ', op%con%n_global, ' (gluing ', &
      op%con%n_gluing_global, ', Dirichlet ', op%con%n_dirichlet_global, ', contact ', &
      op%con%n_contact_global, '), coarse dimension ', 6*op%dec%nsubdomains
    call log_message(line)
    call timer_start('dual setup')
    if (orthonormal) then
      call problem_orth%init(op, p%solver%rho_scale)
      problem => problem_orth
      rho = problem_orth%rho
      scale = problem_orth%scale
    else
      call problem_hat%init(op, p%solver%rho_scale)
      problem => problem_hat
      rho = problem_hat%rho
      scale = problem_hat%scale
    end if
    call timer_stop('dual setup')
    write (line, '(a,es10.3,a,es10.3)') '||P F P|| ~ ', op%norm_pfp, ', rho = ', rho
    call log_message(line)

    ! 2. SMALBE (outer) + MPRGP (inner); ||A|| = max(||P F P||, rho): P F P and rho Q act on
    !    complementary subspaces; the QP is scaled by 1/||P F P|| (see dual_problem)
    call log_section('SMALBE / MPRGP')
    a_norm = max(op%norm_pfp, rho)/scale
    call solver%init_from_params(p%solver, a_norm)
    allocate (nu(op%con%n_own), lambda(op%con%n_own), g(op%con%n_own))
    nu = 0
    in_solve = [timer_seconds('F action'), timer_seconds('coarse solve'), 0.0_dp]
    call timer_start('solve')
    call solver%solve(problem, nu)
    call timer_stop('solve')
    in_solve = [timer_seconds('F action'), timer_seconds('coarse solve'), timer_seconds('solve')] - &
               [in_solve(1), in_solve(2), 0.0_dp]
    call MPI_Allreduce(MPI_IN_PLACE, in_solve, 3, MPI_REAL_DP, MPI_MAX, comm, ierr)
    converged = solver%converged()
    lambda = nu + op%lambda_tilde

    ! 3. reconstruction: alpha_bar new (Eq. 24, or Eq. 25 with the explicit G~) and standard (Eq. 10), then u
    call log_section('Reconstruction')
    allocate (a_new(6*op%nlocal), a_std(6*op%nlocal), u(op%nlocal))
    call timer_start('dual gradient')
    call dual_gradient(op, lambda, g)
    call timer_stop('dual gradient')
    a_new = 0
    a_std = 0
    alpha_difference = -1
    if (p%reconstruction%method /= 'standard') then
      if (orthonormal) then
        call alpha_orthonormal(problem_orth%orth, g, problem_orth%unscaled_multiplier(solver%muhat), a_new)
      else
        call alpha_new(op, g, problem_hat%unscaled_multiplier(solver%muhat), a_new)
      end if
    end if
    if (p%reconstruction%method /= 'new') then
      call alpha_standard(op, lambda, g, p%reconstruction%active_tol, a_std, std_cost)
      write (line, '(a,3(es10.3,a))') 'standard formula: assembly ', std_cost%assembly, ' s, factorization ', &
        std_cost%factorization, ' s, solve ', std_cost%solve, ' s'
      call log_message(line)
    end if
    if (p%reconstruction%method == 'both') then
      alpha_difference = coarse_vector_norm(op, a_new - a_std)/max(coarse_vector_norm(op, a_std), tiny(1.0_dp))
      write (line, '(a,es10.3)') '||alpha_new - alpha_standard|| / ||alpha_standard|| = ', alpha_difference
      call log_message(line)
    end if
    alpha_bar = merge(a_std, a_new, p%reconstruction%method == 'standard')
    call timer_start('primal')
    call op%primal(lambda, alpha_bar, u)
    call timer_stop('primal')

    ! 4. KKT conditions of the primal problem
    call timer_start('kkt')
    res = check_kkt(op, u, lambda)
    call timer_stop('kkt')
    kkt_ok = res%worst() <= p%reconstruction%kkt_tol
    call log_section('KKT residuals (relative: displacements to max |u|, forces per subdomain)')
    write (line, '(6(a,es10.3))') 'equilibrium (worst subdomain) ', res%equilibrium, ', gluing jump ', &
      res%gluing, ', Dirichlet ', res%dirichlet, ', penetration ', res%penetration, ', dual feasibility ', &
      res%dual_feasibility, ', complementarity ', res%complementarity
    call log_message(line)

    ! 5. contact summary and output
    allocate (active(op%con%n_own))
    call active_contact_mask(op, lambda, p%reconstruction%active_tol, active, nactive)
    call timer_start('output')
    call contact_output(p, op, u, lambda, contact)
    call timer_stop('output')
    call timer_stop('total')
    write (line, '(a,es12.5,a,es12.5,a,i0,a,es12.5)') 'contact force ', contact%total_force, &
      ', max pressure ', contact%max_pressure, ', active nodes ', contact%active_nodes, &
      ', contact radius ', contact%contact_radius
    call log_message(line)

    call timers_reduce(comm, stats)
    ! bytes one F action reads on all ranks, and the time of one F action
    mine_bytes = op%bytes_per_f_action()
    call MPI_Allreduce(mine_bytes, f_bytes, 1, MPI_INT_I8, MPI_SUM, comm, ierr)
    f_seconds = 0
    do k = 1, size(stats)
      if (stats(k)%name == 'F action') f_seconds = stats(k)%max/max(op%f_applications, 1_i8)
    end do
    call log_section('Timings [s] (min / max / mean over ranks)')
    call print_timing_table(stats)
    call log_message("('F action' and 'coarse solve' are parts of the phases that use them: dual setup, solve, "// &
                     "reconstruction)")
    if (p%output%write_report) call write_report()

    if (.not. converged) then
      call log_message('feticontact: the dual solver did not converge: '//trim(solver%message))
      status = exit_not_converged
    else if (.not. kkt_ok) then
      write (line, '(a,es10.3,a,es10.3)') 'feticontact: KKT check failed: largest residual ', res%worst(), &
        ' > kkt_tol ', p%reconstruction%kkt_tol
      call log_message(line)
      status = exit_kkt_failed
    else
      call log_message('feticontact: converged, KKT check passed')
    end if
    call log_where_to_look(p)
    call problem_hat%free()
    call problem_orth%free()
    call op%free()

  contains

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

    subroutine write_report()
      type(json_writer_t) :: js
      character(len=:), allocatable :: memory, timings
      memory = memory_json(comm)
      timings = timings_json(stats)
      call js%begin_object()
      call js%add_raw('case', params_json(p))
      call js%begin_object('sizes')
      call js%add('subdomains', op%dec%nsubdomains)
      call js%add('ranks', int(nranks, ip))
      call js%add('primal_dofs', op%primal_dofs)
      call js%add('dual_dofs', op%con%n_global)
      call js%add('coarse_dim', 6*op%dec%nsubdomains)
      call js%add('contact_rows', op%con%n_contact_global)
      call js%add('active_contact', nactive)
      call js%add('gluing_rows', op%con%n_gluing_global)
      call js%add('dirichlet_rows', op%con%n_dirichlet_global)
      call js%end_object()
      call js%begin_object('solver')
      call js%add('converged', converged)
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
      call js%add('rho', rho)
      call js%add('norm_pfp', op%norm_pfp)
      call js%add('f_applications', op%f_applications)
      call js%add('coarse_solves', op%coarse_solves)
      call js%end_object()
      call js%begin_object('kkt')
      call js%add('equilibrium', res%equilibrium)
      call js%add('gluing', res%gluing)
      call js%add('dirichlet', res%dirichlet)
      call js%add('penetration', res%penetration)
      call js%add('equality', res%equality)
      call js%add('feasibility', res%feasibility)
      call js%add('dual_feasibility', res%dual_feasibility)
      call js%add('complementarity', res%complementarity)
      call js%add('passed', kkt_ok)
      call js%end_object()
      call js%begin_object('reconstruction')
      call js%add('method', trim(p%reconstruction%method))
      if (alpha_difference >= 0) then
        call js%add('alpha_difference', alpha_difference)
      else
        call js%add_null('alpha_difference')
      end if
      call js%begin_object('new')
      call js%add_raw('seconds', stat_json('rec new'))
      call js%end_object()
      call js%begin_object('standard')
      call js%add_raw('seconds', stat_json('rec standard'))
      call js%add('assembly', std_cost%assembly)
      call js%add('factorization', std_cost%factorization)
      call js%add('solve', std_cost%solve)
      call js%add('active_contact_rows', std_cost%active_rows)
      call js%end_object()
      call js%end_object()
      call js%add_raw('timings', timings)
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
      call js%add('solve_seconds', in_solve(3))
      call js%add('solve_f_action_seconds', in_solve(1))
      call js%add('solve_coarse_seconds', in_solve(2))
      call js%add('solve_coarse_share', in_solve(2)/max(in_solve(3), tiny(1.0_dp)))
      call js%end_object()
      call js%end_object()
      call js%write_file(trim(p%output%directory)//'/report.json', comm)
    end subroutine write_report

    !> The max over ranks of a timer (the time the run waited for it), as
    !> JSON (null if it never ran).
    function stat_json(name) result(json)
      character(len=*), intent(in) :: name
      character(len=:), allocatable :: json
      character(len=32) :: buf
      integer :: k
      json = 'null'
      do k = 1, size(stats)
        if (stats(k)%name == name) then
          write (buf, '(es24.16e3)') stats(k)%max
          json = trim(adjustl(buf))
        end if
      end do
    end function stat_json
  end subroutine run_contact_case

  !> Contact pressure (multiplier / tributary area of the node on the face
  !> z = 0), deformed gap c - B u, the summary, and the HDF5/XDMF fields.
  subroutine contact_output(p, op, u, lambda, contact)
    type(params_t), intent(in) :: p
    type(feti_t), intent(inout) :: op
    type(local_field_t), intent(inout) :: u(:)
    real(dp), intent(in) :: lambda(:)
    type(contact_summary_t), intent(out) :: contact
    type(output_fields_t) :: fields
    real(dp), allocatable :: bu(:), pressure(:)
    real(dp) :: mine(3), total(3), biggest, area, r, threshold
    integer(ip) :: i, ls, nn, ne, nc, k, ijk(3), a, e, local_count, all_count
    integer :: ierr

    associate (n => op%con%n_own, mesh => op%dec%mesh)
      allocate (bu(n), pressure(n))
      call op%apply_b(u, bu)
      pressure = 0
      do i = 1, n
        if (.not. op%is_contact(i)) cycle
        ijk = mesh%node_ijk(op%con%node(i))
        area = mesh%h(1)*mesh%h(2)
        if (ijk(1) == 0 .or. ijk(1) == mesh%ng(1)) area = area/2
        if (ijk(2) == 0 .or. ijk(2) == mesh%ng(2)) area = area/2
        pressure(i) = op%con%scale(i)*lambda(i)/area
      end do
      mine(1) = sum(op%con%scale*lambda, mask=op%is_contact)
      call MPI_Allreduce(mine(1), total(1), 1, MPI_REAL_DP, MPI_SUM, op%comm, ierr)
      mine(1) = 0
      if (any(op%is_contact)) mine(1) = maxval(op%con%scale*lambda, mask=op%is_contact)
      call MPI_Allreduce(mine(1), biggest, 1, MPI_REAL_DP, MPI_MAX, op%comm, ierr)
      threshold = p%reconstruction%active_tol*max(biggest, 0.0_dp)
      mine = 0
      local_count = 0
      do i = 1, n
        if (.not. op%is_contact(i)) cycle
        mine(1) = max(mine(1), pressure(i))
        if (op%con%scale(i)*lambda(i) > threshold .and. lambda(i) > 0) then
          local_count = local_count + 1
          associate (x => op%subs(op%con%row_sub(i))%coords(:, op%con%row_node(i)))
            r = sqrt((x(1) - mesh%lengths(1)/2)**2 + (x(2) - mesh%lengths(2)/2)**2)
          end associate
          mine(2) = max(mine(2), r)
        end if
      end do
      contact%total_force = total(1)
      call MPI_Allreduce(mine(1:2), total(1:2), 2, MPI_REAL_DP, MPI_MAX, op%comm, ierr)
      contact%max_pressure = total(1)
      contact%contact_radius = total(2)
      call MPI_Allreduce(local_count, all_count, 1, MPI_INT_IP, MPI_SUM, op%comm, ierr)
      contact%active_nodes = all_count

      if (.not. p%output%write_hdf5) return
      nn = 0
      ne = 0
      do ls = 1, op%nlocal
        nn = nn + op%subs(ls)%nnodes
        ne = ne + op%subs(ls)%nelem
      end do
      nc = count(op%is_contact, kind=ip)
      call fields%init(nn, ne, nc)
      nn = 0
      ne = 0
      do ls = 1, op%nlocal
        associate (sub => op%subs(ls))
          fields%coordinates(:, nn + 1:nn + sub%nnodes) = sub%coords
          fields%displacement(:, nn + 1:nn + sub%nnodes) = reshape(u(ls)%v, [3, sub%nnodes])
          do e = 1, sub%nelem
            fields%connectivity(:, ne + e) = sub%elem_nodes(:, e) + nn
          end do
          fields%subdomain(ne + 1:ne + sub%nelem) = sub%id
          call subdomain_von_mises(sub, u(ls)%v, fields%von_mises(ne + 1:ne + sub%nelem))
          nn = nn + sub%nnodes
          ne = ne + sub%nelem
        end associate
      end do
      k = 0
      do i = 1, n
        if (.not. op%is_contact(i)) cycle
        k = k + 1
        a = op%con%row_node(i)
        fields%contact_coordinates(:, k) = op%subs(op%con%row_sub(i))%coords(:, a)
        fields%contact_pressure(k) = pressure(i)
        fields%contact_gap(k) = op%con%c(i) - bu(i)
      end do
      call write_fields(op%comm, p%output%directory, p%output%run_name, fields)
      call fields%free()
    end associate
  end subroutine contact_output
end module contact_run
