#include "assertions.h"
!> The displacement reconstruction of issue 6 on small `cube` and `block`
!> cases (box and METIS, plain and distorted), run by the pipeline pieces:
!> feti_t%setup, the dual QP + SMALBE, both formulas for alpha_bar,
!> feti_t%primal and check_kkt.
!>
!> Per case, with the MUMPS coarse problem (hat multiplier, Eq. 24) and a
!> sweep of solver tolerances tol:
!> - u of the new formula (Eq. 24) and of the standard one (Eq. 10) satisfy
!>   the primal KKT conditions: largest relative residual <= kkt_factor * tol;
!> - ||alpha_new - alpha_std|| / ||alpha_std|| <= alpha_factor * tol (the
!>   relation measured on these cases is printed, one line per tol);
!> - a wrong multiplier (muhat with its sign flipped: alpha_bar = alpha +
!>   muhat) fails the KKT check: largest residual > &reconstruction kkt_tol.
!> With the explicit G~ (coarse = 'cholesky', dual_problem_orth, Eq. 25):
!> - P^2 = P, G P = 0, the same P as the MUMPS variant, G~ G~^T = I;
!> - Eq. 25 (alpha~_bar = G~ g - mu, alpha_bar = L^{-T} alpha~_bar) and Eq. 24
!>   (alpha_bar = (G G^T)^{-1} G g - L^{-T} mu) agree to round-off for the
!>   same (lambda, mu): the identity behind Eq. 25;
!> - KKT <= kkt_factor * tol; the same u as the MUMPS variant to
!>   u_factor * tol (relative to max |u|); the wrong sign fails the KKT check.
!> `block` at tol = 1e-10: u = (nu p x/E, nu p y/E, -p z/E) to 1e-8 relative
!> for Eq. 24, Eq. 10 and Eq. 25. In `block` every contact row carries a
!> positive multiplier, so muhat = 0 (asserted to tol) and the wrong-sign
!> checks are made on `cube`, where |muhat| ~ 14 |alpha_bar|.
!> With any command-line argument the program instead measures the relation
!> between tol and the alpha differences (tol = 1e-3 ... 1e-10, against a
!> reference solved to 1e-12) and prints a table (docs/THEORY.md).
program test_reconstruction
  use kinds, only: dp, ip
  use assertions, only: assert_true, assert_below, test_finish
  use logger, only: logger_init
  use params, only: params_t
  use feti_operators, only: feti_t, local_field_t
  use qp_problem, only: qp_problem_t
  use dual_problem, only: dual_problem_t
  use dual_problem_orth, only: dual_problem_orth_t
  use smalbe, only: smalbe_t, smalbe_settings_t
  use tfeti_dualization, only: smalbe_settings
  use reconstruction, only: dual_gradient, alpha_new, alpha_orthonormal, alpha_standard, standard_cost_t, &
                            coarse_vector_norm
  use kkt, only: kkt_residuals_t, check_kkt
  use subdomain, only: subdomain_t
  use feti_test_support, only: small_case, coarse_condition
  use tolerances, only: solve_tol
  use mpi_f08, only: MPI_Init, MPI_COMM_WORLD, MPI_Comm_rank, MPI_Allreduce, MPI_MAX, MPI_DOUBLE_PRECISION
  implicit none

  !> Largest KKT residual accepted, in units of the solver tolerance
  !> (measured: 14-61 tol on the cube cases, 0.2-3 tol on block, tol = 1e-3 ... 1e-10).
  real(dp), parameter :: kkt_factor = 200
  !> ||alpha_new - alpha_std|| / ||alpha_std|| accepted, in units of tol
  !> (measured: 2-24 tol on the cube cases, 0 on block: run with an argument).
  real(dp), parameter :: alpha_factor = 100
  !> max |u_cholesky - u_mumps| / max |u| accepted, in units of tol.
  real(dp), parameter :: u_factor = 20
  integer :: ierr, rank

  call MPI_Init(ierr)
  call MPI_Comm_rank(MPI_COMM_WORLD, rank, ierr)
  call logger_init()
  if (command_argument_count() > 0) then
    call measure(small_case('cube', [2, 2, 2], [3, 3, 3], 'box', 0.0_dp), 'cube box')
    call measure(small_case('cube', [2, 2, 2], [2, 2, 2], 'metis', 0.3_dp), 'cube metis distorted')
    call measure(small_case('cube', [3, 3, 3], [3, 3, 3], 'box', 0.2_dp), 'cube 27 distorted')
    call measure(small_case('block', [2, 2, 2], [2, 2, 2], 'metis', 0.3_dp), 'block metis distorted')
  else
    call check_case(small_case('cube', [2, 2, 2], [3, 3, 3], 'box', 0.0_dp), 'cube box', &
                    [1.0e-4_dp, 1.0e-6_dp, 1.0e-8_dp], .false.)
    call check_case(small_case('cube', [2, 2, 2], [2, 2, 2], 'metis', 0.3_dp), 'cube metis distorted', &
                    [1.0e-4_dp, 1.0e-6_dp, 1.0e-8_dp], .false.)
    call check_case(small_case('block', [2, 2, 2], [2, 2, 2], 'box', 0.0_dp), 'block box', &
                    [1.0e-4_dp, 1.0e-6_dp, 1.0e-8_dp, 1.0e-10_dp], .true.)
    call check_case(small_case('block', [2, 2, 2], [2, 2, 2], 'metis', 0.3_dp), 'block metis distorted', &
                    [1.0e-6_dp, 1.0e-10_dp], .true.)
  end if
  call test_finish()

contains

  subroutine check_case(p, label, tols, exact)
    type(params_t), intent(in) :: p
    character(len=*), intent(in) :: label
    real(dp), intent(in) :: tols(:)
    logical, intent(in) :: exact
    type(feti_t), target :: op
    type(dual_problem_t) :: hat
    type(dual_problem_orth_t) :: orth
    type(standard_cost_t) :: cost
    type(kkt_residuals_t) :: res_new, res_std, res_wrong
    type(local_field_t), allocatable :: u_new(:), u_std(:), u_orth(:), u_wrong(:)
    real(dp), allocatable :: nu(:), lambda(:), g(:), muhat(:), mu(:), a_new(:), a_std(:), a_orth(:), &
                             a24(:), a_wrong(:), at(:), full(:)
    real(dp) :: tol, diff, kkt_tol, d24, mu_ratio
    integer(ip) :: it, n, nc
    character(len=200) :: line

    kkt_tol = p%reconstruction%kkt_tol
    call op%setup(p, MPI_COMM_WORLD)
    n = op%n_own()
    nc = op%n_coarse()
    allocate (nu(n), lambda(n), g(n), a_new(nc), a_std(nc), a_orth(nc), a24(nc), a_wrong(nc))
    allocate (u_new(op%nlocal()), u_std(op%nlocal()), u_orth(op%nlocal()), u_wrong(op%nlocal()))

    ! 1. MUMPS coarse problem, hat multiplier: Eq. 24 against Eq. 10 for a sweep of tol
    call hat%init(op, p%solver%rho_scale)
    do it = 1, size(tols)
      tol = tols(it)
      call solve_dual(p, op, hat, hat%rho, hat%scale, tol, nu, muhat, label)
      lambda = nu + op%lambda_tilde_vector()
      call dual_gradient(op, lambda, g)
      call alpha_new(op, g, muhat, a_new)
      call alpha_standard(op, lambda, g, p%reconstruction%active_tol, a_std, cost)
      diff = coarse_vector_norm(op, a_new - a_std)/coarse_vector_norm(op, a_std)
      call op%primal(lambda, a_new, u_new)
      call op%primal(lambda, a_std, u_std)
      res_new = check_kkt(op, u_new, lambda)
      res_std = check_kkt(op, u_std, lambda)
      write (line, '(a,a,es8.1,a,es9.2,a,f7.3,a,es9.2,a,es9.2)') label, ': tol ', tol, &
        ', |a_new - a_std|/|a_std| ', diff, ' = ', diff/tol, ' tol; KKT new ', res_new%worst(), &
        ', standard ', res_std%worst()
      if (rank == 0) write (*, '(a)') trim(line)
      call assert_below(diff, alpha_factor*tol, label//': alpha_new = alpha_standard to alpha_factor * tol', HERE)
      call assert_below(res_new%worst(), kkt_factor*tol, label//': KKT of Eq. 24 <= kkt_factor * tol', HERE)
      call assert_below(res_std%worst(), kkt_factor*tol, label//': KKT of Eq. 10 <= kkt_factor * tol', HERE)
    end do
    mu_ratio = coarse_vector_norm(op, muhat)/coarse_vector_norm(op, a_new)
    if (rank == 0) write (*, '(2a,es9.2)') label, ': |muhat| / |alpha_bar| ', mu_ratio
    if (exact) then
      ! block: every contact row has lambda > 0, so no bound of nu is active, the
      ! Lagrangian gradient s vanishes and muhat = 0 (up to tol): Eq. 24 = Eq. 14
      call assert_below(mu_ratio, alpha_factor*tol, label//': all rows in contact: muhat = 0 to tol', HERE)
    else
      ! a wrong multiplier (sign flipped: alpha_bar = alpha + muhat) must fail the KKT check
      call assert_true(mu_ratio > 1.0e-2_dp, label//': muhat matters (|muhat| > 0.01 |alpha_bar|)', HERE)
      call alpha_new(op, g, -muhat, a_wrong)
      call op%primal(lambda, a_wrong, u_wrong)
      res_wrong = check_kkt(op, u_wrong, lambda)
      if (rank == 0) write (*, '(2a,es9.2)') label, ': KKT with the sign of muhat flipped ', res_wrong%worst()
      call assert_true(res_wrong%worst() > kkt_tol, label//': wrong sign of muhat fails the KKT check', HERE)
    end if
    if (exact) then
      call assert_below(block_error(p, op, u_new), 1.0e-8_dp, label//': Eq. 24 u = exact block solution', HERE)
      call assert_below(block_error(p, op, u_std), 1.0e-8_dp, label//': Eq. 10 u = exact block solution', HERE)
    end if

    ! 2. explicit G~ (coarse = 'cholesky'): operators, then Eq. 25 at the last tol
    call orth%init(op, p%solver%rho_scale)
    call check_orthonormal_operators(op, orth, label)
    call solve_dual(p, op, orth, orth%rho, orth%scale, tol, nu, mu, label//' (cholesky)')
    lambda = nu + op%lambda_tilde_vector()
    call dual_gradient(op, lambda, g)
    allocate (at(orth%orth%dimension()), full(orth%orth%dimension()))
    call alpha_orthonormal(orth%orth, g, mu, a_orth, at)
    ! Eq. 24 with the same pair: muhat = L^{-T} mu
    full = mu
    call orth%orth%backward_solve(full)
    deallocate (muhat)
    allocate (muhat(nc))
    call orth%orth%to_local(full, muhat)
    call alpha_new(op, g, muhat, a24)
    d24 = coarse_vector_norm(op, a24 - a_orth)/coarse_vector_norm(op, a_orth)
    ! two coarse solves (Cholesky factor L vs MUMPS) of G G^T: c eps cond(G G^T)
    call assert_below(d24, solve_tol(coarse_condition(op)), label//': Eq. 25 = Eq. 24 for the same (lambda, mu)', &
                      HERE)
    call op%primal(lambda, a_orth, u_orth)
    res_new = check_kkt(op, u_orth, lambda)
    write (line, '(2a,es8.1,a,es9.2,a,es9.2,a,es9.2)') label, ' (cholesky): tol ', tol, ', KKT Eq. 25 ', &
      res_new%worst(), ', |Eq. 25 - Eq. 24| ', d24, ', max|u - u_mumps|/max|u| ', u_difference(u_orth, u_new)
    if (rank == 0) write (*, '(a)') trim(line)
    call assert_below(res_new%worst(), kkt_factor*tol, label//': KKT of Eq. 25 <= kkt_factor * tol', HERE)
    call assert_below(u_difference(u_orth, u_new), u_factor*tol, label//': cholesky u = mumps u', HERE)
    if (.not. exact) then
      call alpha_orthonormal(orth%orth, g, -mu, a_wrong)
      call op%primal(lambda, a_wrong, u_wrong)
      res_wrong = check_kkt(op, u_wrong, lambda)
      call assert_true(res_wrong%worst() > kkt_tol, label//': wrong sign of mu fails the KKT check of Eq. 25', HERE)
    end if
    if (exact) call assert_below(block_error(p, op, u_orth), 1.0e-8_dp, label//': Eq. 25 u = exact block solution', &
                                 HERE)

    call orth%free()
    call hat%free()
    call op%free()
  end subroutine check_case

  !> The relation between tol and the alpha difference, against a reference
  !> solved to tol = 1e-12 (run the program with any argument; not a test).
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
    call op%setup(p, MPI_COMM_WORLD)
    allocate (nu(op%n_own()), lambda(op%n_own()), g(op%n_own()), a_new(op%n_coarse()), &
              a_std(op%n_coarse()), a_ref(op%n_coarse()), u(op%nlocal()))
    call hat%init(op, p%solver%rho_scale)
    call solve_dual(p, op, hat, hat%rho, hat%scale, 1.0e-12_dp, nu, muhat, label)
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
      call solve_dual(p, op, hat, hat%rho, hat%scale, tol, nu, muhat, label)
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

  !> SMALBE from nu = 0 on `problem` (Eq. 8 divided by `scale`) to tolerance
  !> `tol`; mu is the multiplier of Eq. 8 (scale times SMALBE's).
  subroutine solve_dual(p, op, problem, rho, scale, tol, nu, mu, label)
    type(params_t), intent(in) :: p
    type(feti_t), intent(in) :: op
    class(qp_problem_t), intent(inout) :: problem
    real(dp), intent(in) :: rho, scale, tol
    real(dp), intent(out) :: nu(:)
    real(dp), allocatable, intent(inout) :: mu(:)
    character(len=*), intent(in) :: label
    type(smalbe_t) :: solver
    type(smalbe_settings_t) :: settings
    settings = smalbe_settings(p%solver)
    settings%tol = tol
    settings%monitor = .false.
    call solver%init_with(settings, max(op%norm_pfp(), rho)/scale)
    nu = 0
    call solver%solve(problem, nu)
    call assert_true(solver%converged(), label//': SMALBE converged: '//trim(solver%message), HERE)
    mu = scale*solver%muhat
    call solver%free()
  end subroutine solve_dual

  !> P^2 = P, G P = 0 and P = the MUMPS variant's P on keyed random vectors;
  !> G~ G~^T = I column by column.
  subroutine check_orthonormal_operators(op, orth, label)
    type(feti_t), intent(inout) :: op
    type(dual_problem_orth_t), intent(inout) :: orth
    character(len=*), intent(in) :: label
    real(dp), allocatable :: x(:), px(:), ppx(:), qx(:), z(:), e(:), y(:), col(:)
    real(dp) :: worst, tol_gg
    integer(ip) :: k, n
    ! G~ = L^{-1} G and P with L L^T = G G^T: exact to c eps cond(G G^T)
    tol_gg = solve_tol(coarse_condition(op))
    n = orth%orth%dimension()
    allocate (x(op%n_own()), px(op%n_own()), ppx(op%n_own()), qx(op%n_own()), z(op%n_coarse()), &
              e(n), y(op%n_own()), col(n))
    call op%keyed_random(11, x)
    call orth%orth%project(x, px)
    call orth%orth%project(px, ppx)
    call assert_below(op%norm(ppx - px), tol_gg*op%norm(x), label//': explicit G~: P P x = P x', HERE)
    call op%apply_g(px, z)
    call op%apply_g(x, e(1:op%n_coarse()))
    call assert_below(coarse_vector_norm(op, z), tol_gg*coarse_vector_norm(op, e(1:op%n_coarse())), &
                      label//': explicit G~: G P x = 0', HERE)
    call op%project(x, qx)
    call assert_below(op%norm(qx - px), tol_gg*op%norm(x), label//': explicit G~: the same P as MUMPS', HERE)
    worst = 0
    do k = 1, n
      e = 0
      e(k) = 1
      call orth%orth%apply_t(e, y)
      call orth%orth%apply(y, col)
      worst = max(worst, maxval(abs(col - e)))
    end do
    call assert_below(worst, tol_gg, label//': G~ G~^T = I', HERE)
  end subroutine check_orthonormal_operators

  !> max |u1 - u2| / max |u2| over all subdomains of all ranks.
  real(dp) function u_difference(u1, u2)
    type(local_field_t), intent(in) :: u1(:), u2(:)
    real(dp) :: mine(2), total(2)
    integer(ip) :: ls
    mine = 0
    do ls = 1, size(u1)
      mine(1) = max(mine(1), maxval(abs(u1(ls)%v - u2(ls)%v)))
      mine(2) = max(mine(2), maxval(abs(u2(ls)%v)))
    end do
    call MPI_Allreduce(mine, total, 2, MPI_DOUBLE_PRECISION, MPI_MAX, MPI_COMM_WORLD, ierr)
    u_difference = total(1)/total(2)
  end function u_difference

  !> max |u - u_exact| / max |u_exact| for `block` (docs/CASES.md):
  !> u_exact = (nu p x/E, nu p y/E, -p z/E) at every node copy.
  real(dp) function block_error(p, op, u)
    type(params_t), intent(in) :: p
    type(feti_t), intent(inout), target :: op
    type(local_field_t), intent(in) :: u(:)
    type(subdomain_t), pointer :: subs(:)
    real(dp) :: mine(2), total(2), ex(3), c
    integer(ip) :: ls, a
    c = p%load%top_pressure/p%material%young
    mine = 0
    subs => op%subdomains()
    do ls = 1, op%nlocal()
      associate (x => subs(ls)%coords)
        do a = 1, subs(ls)%nnodes
          ex = [p%material%poisson*c*x(1, a), p%material%poisson*c*x(2, a), -c*x(3, a)]
          mine(1) = max(mine(1), maxval(abs(u(ls)%v(3*a - 2:3*a) - ex)))
          mine(2) = max(mine(2), maxval(abs(ex)))
        end do
      end associate
    end do
    call MPI_Allreduce(mine, total, 2, MPI_DOUBLE_PRECISION, MPI_MAX, MPI_COMM_WORLD, ierr)
    block_error = total(1)/total(2)
    if (rank == 0) write (*, '(a,es9.2)') '  block: max |u - u_exact| / max |u_exact| = ', block_error
  end function block_error
end program test_reconstruction
