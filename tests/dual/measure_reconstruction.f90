!> Not a test: measures the relation between the solver tolerance tol and the
!> difference of the two formulas for alpha_bar (Eq. 24 new, Eq. 10
!> standard), tol = 1e-3 ... 1e-10, against a reference solved to 1e-12, on
!> the cases of test_reconstruction.pf, and prints a table (docs/THEORY.md):
!>   mpirun -n 2 build-debug/tests/bin/measure_reconstruction
!> The factors that test_reconstruction.pf accepts (kkt_factor, alpha_factor)
!> come from these tables.
program measure_reconstruction
  use kinds, only: dp, ip
  use logger, only: logger_init
  use params, only: params_t, feti_settings_of
  use feti_operators, only: feti_t, local_field_t
  use dual_problem, only: dual_problem_t
  use smalbe, only: smalbe_t, smalbe_settings_t
  use reconstruction, only: dual_gradient, alpha_new, alpha_standard, standard_cost_t, coarse_vector_norm
  use kkt, only: kkt_residuals_t, check_kkt
  use feti_test_support, only: small_case
  use mpi_f08, only: MPI_Init, MPI_Finalize, MPI_COMM_WORLD, MPI_Comm_rank
  implicit none
  integer :: ierr, rank

  call MPI_Init(ierr)
  call MPI_Comm_rank(MPI_COMM_WORLD, rank, ierr)
  call logger_init()
  call measure(small_case('cube', [2, 2, 2], [3, 3, 3], 'box', 0.0_dp), 'cube box')
  call measure(small_case('cube', [2, 2, 2], [2, 2, 2], 'metis', 0.3_dp), 'cube metis distorted')
  call measure(small_case('cube', [3, 3, 3], [3, 3, 3], 'box', 0.2_dp), 'cube 27 distorted')
  call measure(small_case('block', [2, 2, 2], [2, 2, 2], 'metis', 0.3_dp), 'block metis distorted')
  call MPI_Finalize(ierr)

contains

  subroutine measure(p, label)
    type(params_t), intent(in) :: p
    character(len=*), intent(in) :: label
    type(feti_t), target :: op
    type(dual_problem_t) :: hat
    type(standard_cost_t) :: cost
    type(local_field_t), allocatable :: u(:)
    real(dp), allocatable :: nu(:), lambda(:), g(:), muhat(:), a_new(:), a_std(:), a_ref(:)
    type(kkt_residuals_t) :: rn, rs
    real(dp) :: tol, r(3)
    integer(ip) :: k, nref
    call op%setup(feti_settings_of(p), MPI_COMM_WORLD)
    allocate (nu(op%n_own()), lambda(op%n_own()), g(op%n_own()), a_new(op%n_coarse()), &
              a_std(op%n_coarse()), a_ref(op%n_coarse()), u(op%nlocal()))
    call hat%init(op, p%solver%dual%rho_scale)
    call solve_dual(p, op, hat, 1.0e-12_dp, nu, muhat, label)
    lambda = nu + op%lambda_tilde_vector()
    call dual_gradient(op, lambda, g)
    call alpha_new(op, g, muhat, a_ref)
    call alpha_standard(op, lambda, g, p%reconstruction%active_tol, a_std, cost)
    nref = cost%active_rows
    r(1) = rel(op, a_std, a_ref)
    if (rank == 0) write (*, '(2a,es9.2,a,i0)') label, ': reference |a_new - a_std|/|a| at 1e-12 ', &
      r(1), ', active contact rows ', nref
    if (rank == 0) write (*, '(a)') '     tol   |new-std|/|std|  /tol  |new-ref|/|ref|  /tol  |std-ref|/|ref|  /tol'// &
      '  KKT new   KKT std  active'
    do k = 3, 10
      tol = 10.0_dp**(-k)
      call solve_dual(p, op, hat, tol, nu, muhat, label)
      lambda = nu + op%lambda_tilde_vector()
      call dual_gradient(op, lambda, g)
      call alpha_new(op, g, muhat, a_new)
      call alpha_standard(op, lambda, g, p%reconstruction%active_tol, a_std, cost)
      call op%primal(lambda, a_new, u)
      rn = check_kkt(op, u, lambda)
      call op%primal(lambda, a_std, u)
      rs = check_kkt(op, u, lambda)
      r = [rel(op, a_new, a_std), rel(op, a_new, a_ref), rel(op, a_std, a_ref)]
      if (rank == 0) write (*, '(es8.1,3(es12.2,f8.2),2es10.2,i6)') tol, r(1), r(1)/tol, r(2), r(2)/tol, &
        r(3), r(3)/tol, rn%worst(), rs%worst(), cost%active_rows
    end do
    call hat%free()
    call op%free()
  end subroutine measure

  !> ||a - b|| / ||b|| for local coarse blocks.
  real(dp) function rel(op, a, b)
    type(feti_t), intent(in) :: op
    real(dp), intent(in) :: a(:), b(:)
    rel = coarse_vector_norm(op, a - b)/coarse_vector_norm(op, b)
  end function rel

  !> SMALBE from nu = 0 on the hat problem to tolerance `tol`; muhat is the
  !> multiplier of Eq. 8 (scale times SMALBE's). A solve that does not
  !> converge is reported (its row of the table is then not a measurement).
  subroutine solve_dual(p, op, problem, tol, nu, mu, label)
    type(params_t), intent(in) :: p
    type(feti_t), intent(in) :: op
    type(dual_problem_t), intent(inout) :: problem
    real(dp), intent(in) :: tol
    real(dp), intent(out) :: nu(:)
    real(dp), allocatable, intent(inout) :: mu(:)
    character(len=*), intent(in) :: label
    type(smalbe_t) :: solver
    type(smalbe_settings_t) :: settings
    settings = p%solver%smalbe
    settings%tol = tol
    settings%monitor = .false.
    call solver%init_with(settings, max(op%norm_pfp(), problem%rho)/problem%scale)
    nu = 0
    call solver%solve(problem, nu)
    if (.not. solver%converged() .and. rank == 0) &
      write (*, '(3a)') label, ': SMALBE did not converge: ', trim(solver%message)
    mu = problem%scale*solver%muhat
    call solver%free()
  end subroutine solve_dual
end program measure_reconstruction
