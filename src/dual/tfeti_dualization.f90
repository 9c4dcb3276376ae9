!> The TFETI dualization as one transform (PERMON's QPTDualize in this code's
!> words): `setup` builds the FETI operators of the subdomain problems and the
!> dual QP of Eq. (8) that the QP solvers see (class qp_problem_t), and
!> `post_solve` is its inverse: from the solver's nu and multiplier it forms
!> lambda = nu + lambda~, unscales the multiplier, computes alpha_bar by the
!> chosen formula (new: Eq. 24, or Eq. 25 with the explicit G~; standard:
!> Eq. 10; or both and their difference), u = K^+ (f - B^T lambda) + R alpha_bar
!> and checks the KKT conditions. The result is a dual_solution_t.
module tfeti_dualization
  use kinds, only: dp, name_len, MPI_REAL_DP
  use logger, only: log_section, log_message
  use timers, only: timer_start, timer_stop, timer_seconds
  use feti_settings, only: feti_settings_t
  use dual_settings, only: dual_settings_t
  use preconditioner_settings, only: preconditioner_settings_t
  use reconstruction_settings, only: reconstruction_settings_t
  use feti_operators, only: feti_t, local_field_t, feti_sizes_t
  use subdomain, only: subdomain_t
  use decomposition, only: decomposition_t
  use orthonormal_coarse, only: check_orthonormal_size
  use qp_problem, only: qp_problem_t, qp_solver_t
  use dual_problem, only: dual_problem_t
  use dual_problem_orth, only: dual_problem_orth_t
  use reconstruction, only: dual_gradient, alpha_standard, standard_cost_t, coarse_vector_norm
  use kkt, only: kkt_residuals_t, check_kkt
  use mpi_f08, only: MPI_Comm, MPI_Comm_size, MPI_Allreduce, MPI_IN_PLACE, MPI_MAX
  implicit none
  private


  !> What the inverse step returns: the primal and dual solution and what it
  !> cost to get u.
  type, public :: dual_solution_t
    real(dp), allocatable :: lambda(:)                 !< multipliers (owned rows)
    real(dp), allocatable :: alpha_bar(:)              !< rigid body amplitudes (local coarse blocks)
    type(local_field_t), allocatable :: u(:)           !< displacements per local subdomain
    real(dp) :: alpha_difference = -1                  !< ||alpha_new - alpha_std|| / ||alpha_std|| ('both'), else -1
    type(standard_cost_t) :: standard_cost             !< parts of the standard formula (if used)
    type(kkt_residuals_t) :: kkt                       !< the KKT residuals of (u, lambda)
  end type dual_solution_t

  type, public :: tfeti_dualization_t
    private
    type(feti_t) :: op
    type(dual_problem_t) :: hat                        !< hat form: (G G^T)^{-1} by MUMPS
    type(dual_problem_orth_t) :: orth                  !< explicit G~ (&solver coarse = 'orthonormal')
    class(dual_problem_t), pointer :: dual => null()   !< the one of the two in use
    character(len=name_len) :: method = 'both'         !< &reconstruction method
    real(dp) :: active_tol = 0
    real(dp) :: history_penalty = 0                    !< the scaled penalty every step of a history starts with
  contains
    procedure :: setup
    procedure :: problem
    procedure :: hessian_norm
    procedure :: solve
    procedure :: solve_from
    procedure :: set_load
    procedure :: prepare_history
    procedure :: preconditioner_switched
    procedure :: switch_preconditioner
    procedure :: post_solve
    procedure :: operators
    procedure :: sizes
    procedure :: rho
    procedure :: preconditioner_name
    procedure :: preconditioner_switch
    procedure :: free
  end type tfeti_dualization_t

contains

  !> Build the FETI operators (`feti`) and the dual QP (`dual`, its
  !> `preconditioner`) on `comm`; keep what the reconstruction needs
  !> (`reconstruction`). `this` must be a target (the dual problem points to
  !> its operators). `units`: the decomposition of the checks before the run
  !> (run_checks), built by the FETI set-up without it.
  subroutine setup(this, feti, dual, preconditioner, reconstruction, comm, units)
    class(tfeti_dualization_t), intent(inout), target :: this
    type(feti_settings_t), intent(in) :: feti
    type(dual_settings_t), intent(in) :: dual
    type(preconditioner_settings_t), intent(in) :: preconditioner
    type(reconstruction_settings_t), intent(in) :: reconstruction
    type(MPI_Comm), intent(in) :: comm
    type(decomposition_t), intent(in), optional :: units
    type(feti_sizes_t) :: n
    character(len=200) :: line
    character(len=name_len) :: kind
    integer :: nranks, ierr

    call this%free()
    this%method = reconstruction%method
    this%active_tol = reconstruction%active_tol
    if (feti%coarse%coarse == 'orthonormal') call check_orthonormal_size(product(feti%mesh%nsub), comm)
    call this%op%setup(feti, comm, units)
    call MPI_Comm_size(comm, nranks, ierr)
    n = this%op%sizes()
    call log_section('Problem')
    write (line, '(a,i0,a,i0,a,i0)') 'subdomains ', n%nsubdomains, ', ranks ', nranks, ', primal dofs ', n%primal_dofs
    call log_message(line)
    write (line, '(a,i0,a,i0,a,i0,a,i0,a,i0)') 'dual dofs ', n%dual_dofs, ' (gluing ', n%gluing_rows, &
      ', Dirichlet ', n%dirichlet_rows, ', contact ', n%contact_rows, '), coarse dimension ', n%coarse_dim
    call log_message(line)
    call timer_start('dual setup')
    if (feti%coarse%coarse == 'orthonormal') then
      this%dual => this%orth
    else
      this%dual => this%hat
    end if
    call this%dual%init(this%op, dual%rho_scale, dual%stopping)
    call timer_stop('dual setup')
    if (preconditioner%preconditioner /= 'none') then
      kind = preconditioner%preconditioner
      ! 'auto' with clusters glued at their corners: no Dirichlet
      ! preconditioner for them, so 'auto' is 'lumped' there
      if (kind == 'auto' .and. this%op%hybrid_units() .and. feti%mesh%cluster_gluing == 'corners') kind = 'lumped'
      call timer_start('preconditioner setup')
      call this%dual%set_preconditioner(kind, subdomain_weights(feti, this%op), preconditioner%preconditioner_switch)
      call timer_stop('preconditioner setup')
      if (kind == 'auto' .and. this%dual%switch_at == 0 .and. this%op%dirichlet_by_blocks()) then
        call log_message("preconditioner (MPRGP in the face): 'auto' -> dirichlet from the start (clusters "// &
                         'glued by faces, shared per class: one dense Schur block per subdomain of a class, '// &
                         'an application costs about what a lumped one does)')
      else if (kind == 'auto' .and. this%dual%switch_at == 0 .and. this%op%hybrid_units()) then
        call log_message("preconditioner (MPRGP in the face): 'auto' -> dirichlet from the start (clusters "// &
                         'glued by faces without classes: interior solves per cluster)')
      else if (kind == 'auto' .and. this%dual%switch_at == 0) then
        ! one statement of what is used: the dense local solver's factors give S_s at no set-up cost
        call log_message("preconditioner (MPRGP in the face): 'auto' -> dirichlet from the start (S_s from "// &
                         "the dense local solver's factors: no set-up, an application costs about what a "// &
                         'lumped one does)')
      else if (kind == 'auto') then
        write (line, '(a,es10.3)') "preconditioner (MPRGP in the face): 'auto' -> lumped, then dirichlet "// &
          'once the face condition estimate exceeds ', preconditioner%preconditioner_switch
        call log_message(trim(line))
      else if (kind /= preconditioner%preconditioner) then
        call log_message("preconditioner (MPRGP in the face): lumped ('auto' with clusters glued at "// &
                         'their corners, which have no Dirichlet preconditioner)')
      else
        call log_message('preconditioner (MPRGP in the face): '//trim(kind))
      end if
    end if
    write (line, '(a,es10.3,a,es10.3)') '||P F P|| ~ ', this%op%norm_pfp(), ', rho = ', this%dual%rho
    call log_message(line)
  end subroutine setup

  !> w_s = E_s/young of the local subdomains with &solver scaling = 'young'
  !> (the weights of the rows of B, constraints), else 1.
  function subdomain_weights(feti, op) result(w)
    type(feti_settings_t), intent(in) :: feti
    type(feti_t), intent(inout), target :: op
    real(dp), allocatable :: w(:)
    type(subdomain_t), pointer :: subs(:)
    integer :: ls
    subs => op%subdomains()
    allocate (w(size(subs)))
    w = 1
    if (feti%scaling%scaling == 'young') then
      do ls = 1, size(subs)
        w(ls) = subs(ls)%young/feti%material%young
      end do
    end if
  end function subdomain_weights

  !> The preconditioner of MPRGP in the face: 'none', 'lumped' or 'dirichlet'.
  function preconditioner_name(this) result(name)
    class(tfeti_dualization_t), intent(in) :: this
    character(len=:), allocatable :: name
    name = this%dual%preconditioner_name()
  end function preconditioner_name

  !> `&solver preconditioner = 'auto'`: whether it switched to 'dirichlet',
  !> at which count of Hessian products and on which face condition estimate
  !> (at = -1, estimate = 0 when it did not, or for the other variants).
  subroutine preconditioner_switch(this, at, estimate)
    class(tfeti_dualization_t), intent(in) :: this
    integer, intent(out) :: at
    real(dp), intent(out) :: estimate
    at = int(this%dual%switch_at)
    estimate = this%dual%switch_estimate
  end subroutine preconditioner_switch

  !> The dual QP for the solver.
  function problem(this) result(qp)
    class(tfeti_dualization_t), intent(in) :: this
    class(qp_problem_t), pointer :: qp
    qp => this%dual
  end function problem

  !> ||A|| of the dual QP (see dual_problem%hessian_norm).
  real(dp) function hessian_norm(this)
    class(tfeti_dualization_t), intent(in) :: this
    hessian_norm = this%dual%hessian_norm()
  end function hessian_norm

  !> Solve the dual QP by `solver` from nu = 0 (timer 'solve'). `seconds`:
  !> the time of the solve and, within it, of the F actions and of the coarse
  !> solves (max over ranks).
  subroutine solve(this, solver, nu, seconds)
    class(tfeti_dualization_t), intent(inout) :: this
    class(qp_solver_t), intent(inout) :: solver
    real(dp), allocatable, intent(out) :: nu(:)
    real(dp), intent(out) :: seconds(3)            !< solve, F action, coarse solve
    allocate (nu(this%op%n_own()))
    nu = 0
    call this%solve_from(solver, nu, seconds)
  end subroutine solve

  !> Solve the dual QP by `solver` from the given nu (a warm start; SMALBE
  !> projects it onto the bounds), timed as `solve`.
  subroutine solve_from(this, solver, nu, seconds)
    class(tfeti_dualization_t), intent(inout) :: this
    class(qp_solver_t), intent(inout) :: solver
    real(dp), intent(inout) :: nu(:)
    real(dp), intent(out) :: seconds(3)            !< solve, F action, coarse solve
    real(dp) :: before(3)
    integer :: ierr
    before = [timer_seconds('solve'), timer_seconds('F action'), timer_seconds('coarse solve')]
    call timer_start('solve')
    call solver%solve(this%dual, nu)
    call timer_stop('solve')
    seconds = [timer_seconds('solve') - before(1), timer_seconds('F action') - before(2), &
               timer_seconds('coarse solve') - before(3)]
    call MPI_Allreduce(MPI_IN_PLACE, seconds, 3, MPI_REAL_DP, MPI_MAX, this%op%comm(), ierr)
    ! 'auto' that did not switch says so (the switch itself is logged where it happens)
    if (this%dual%auto_mode .and. this%dual%switch_at < 0) &
      call log_message("preconditioner 'auto': no switch (lumped throughout)")
  end subroutine solve_from

  !> Before the first step of a load history: every state that a solve
  !> would otherwise settle on its way (a deferred explicit F, the Lanczos
  !> estimate of ||P F P||) settled now, so that each step sees the same
  !> operators whether it follows other steps or a restart. Collective.
  subroutine prepare_history(this)
    class(tfeti_dualization_t), intent(inout) :: this
    real(dp) :: a_norm
    call this%op%settle_f_action()
    a_norm = this%dual%refined_norm()
    this%history_penalty = this%dual%penalty()
  end subroutine prepare_history

  !> `&solver preconditioner = 'auto'` has switched to 'dirichlet'.
  logical function preconditioner_switched(this)
    class(tfeti_dualization_t), intent(in) :: this
    preconditioner_switched = this%dual%auto_mode .and. this%dual%switch_at >= 0
  end function preconditioner_switched

  !> 'auto': switch to 'dirichlet' now (a restart of a history whose earlier
  !> steps switched). Nothing when it has switched or is not 'auto'. Collective.
  subroutine switch_preconditioner(this)
    class(tfeti_dualization_t), intent(inout) :: this
    logical :: switched
    call this%dual%condition_estimate(huge(1.0_dp), switched)
  end subroutine switch_preconditioner

  !> The right-hand sides of a step of a load history (feti_t%set_load: the
  !> load factor, the obstacle moved by gap_shift) and the dual QP's linear
  !> term, bounds and stopping scale; the penalty back at its value of the
  !> history's start (SMALBE may have raised it). Collective.
  subroutine set_load(this, factor, gap_shift)
    class(tfeti_dualization_t), intent(inout) :: this
    real(dp), intent(in) :: factor, gap_shift
    call this%op%set_load(factor, gap_shift)
    if (this%history_penalty > 0) call this%dual%set_penalty(this%history_penalty)
    call this%dual%form_rhs()
  end subroutine set_load

  !> The penalty rho of Eq. (8), unscaled.
  real(dp) function rho(this)
    class(tfeti_dualization_t), intent(in) :: this
    rho = this%dual%rho
  end function rho

  !> The inverse of the dualization: from the solver's minimizer `nu` and its
  !> multiplier `mu_scaled` (of the scaled QP, hat form or explicit) to
  !> lambda, alpha_bar, u and the KKT residuals. Collective.
  subroutine post_solve(this, nu, mu_scaled, sol)
    class(tfeti_dualization_t), intent(inout) :: this
    real(dp), intent(in) :: nu(:), mu_scaled(:)
    type(dual_solution_t), intent(out) :: sol
    real(dp), allocatable :: g(:), a_new(:), a_std(:)
    character(len=200) :: line

    call log_section('Reconstruction')
    sol%lambda = nu + this%op%lambda_tilde_vector()
    allocate (g(size(nu)), a_new(this%op%n_coarse()), a_std(this%op%n_coarse()), sol%u(this%op%nlocal()))
    call timer_start('dual gradient')
    call dual_gradient(this%op, sol%lambda, g)
    call timer_stop('dual gradient')
    a_new = 0
    a_std = 0
    if (this%method /= 'standard') call this%dual%alpha_bar(g, mu_scaled, a_new)   ! Eq. 24 or 25
    if (this%method /= 'multiplier') then
      call alpha_standard(this%op, sol%lambda, g, this%active_tol, a_std, sol%standard_cost)
      write (line, '(a,3(es10.3,a))') 'standard formula: assembly ', sol%standard_cost%assembly, &
        ' s, factorization ', sol%standard_cost%factorization, ' s, solve ', sol%standard_cost%solve, ' s'
      call log_message(line)
    end if
    if (this%method == 'both') then
      sol%alpha_difference = coarse_vector_norm(this%op, a_new - a_std)/ &
                             max(coarse_vector_norm(this%op, a_std), tiny(1.0_dp))
      write (line, '(a,es10.3)') '||alpha_new - alpha_standard|| / ||alpha_standard|| = ', sol%alpha_difference
      call log_message(line)
    end if
    sol%alpha_bar = merge(a_std, a_new, this%method == 'standard')
    call timer_start('primal')
    call this%op%primal(sol%lambda, sol%alpha_bar, sol%u)
    call timer_stop('primal')

    call timer_start('kkt')
    sol%kkt = check_kkt(this%op, sol%u, sol%lambda)
    call timer_stop('kkt')
    call log_section('KKT residuals (relative: displacements to max |u|, forces per subdomain)')
    write (line, '(6(a,es10.3))') 'equilibrium (worst subdomain) ', sol%kkt%equilibrium, ', gluing jump ', &
      sol%kkt%gluing, ', Dirichlet ', sol%kkt%dirichlet, ', penetration ', sol%kkt%penetration, &
      ', dual feasibility ', sol%kkt%dual_feasibility, ', complementarity ', sol%kkt%complementarity
    call log_message(line)
  end subroutine post_solve

  !> The FETI operators (for the post-processing and the output); `this`
  !> must be a target.
  function operators(this) result(op)
    class(tfeti_dualization_t), intent(inout), target :: this
    type(feti_t), pointer :: op
    op => this%op
  end function operators

  type(feti_sizes_t) function sizes(this)
    class(tfeti_dualization_t), intent(in) :: this
    sizes = this%op%sizes()
  end function sizes

  subroutine free(this)
    class(tfeti_dualization_t), intent(inout) :: this
    call this%hat%free()
    call this%orth%free()
    call this%op%free()
    this%dual => null()
  end subroutine free
end module tfeti_dualization
