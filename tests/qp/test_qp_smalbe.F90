#include "assertions.h"
!> SMALBE-M on QPs with bounds and C x = 0 whose solution (x*, muhat*) is
!> known by construction (qp_test_problems, A = P A0 P + rho Q as for the
!> FETI dual). Each case is solved serially (MPI_COMM_SELF) and distributed
!> over MPI_COMM_WORLD: ||x - x*|| <= 1e-8 ||x*||, muhat close to muhat*, the
!> KKT residuals recomputed from the dense data below tol ||b||, and the same
!> iteration counts. Then the caps and the refusals.
program test_qp_smalbe
  use, intrinsic :: ieee_arithmetic, only: ieee_is_finite
  use, intrinsic :: ieee_exceptions, only: ieee_set_halting_mode, ieee_get_halting_mode, ieee_invalid
  use kinds, only: dp, ip
  use assertions, only: assert_true, assert_equal, assert_below, test_finish
  use logger, only: logger_init, log_message
  use qp_problem, only: qp_status_converged, qp_status_max_hessian, qp_status_max_outer, &
                        qp_status_incompatible, qp_status_not_finite
  use smalbe, only: smalbe_t, smalbe_settings_t
  use tolerances, only: drift_tol
  use qp_test_problems, only: qp_case_t, make_case, dense_qp_t, same_count
  use mpi_f08, only: MPI_Init, MPI_COMM_WORLD, MPI_COMM_SELF, MPI_Comm_size
  implicit none
  integer :: ierr, nranks

  call MPI_Init(ierr)
  call logger_init(MPI_COMM_WORLD)
  call MPI_Comm_size(MPI_COMM_WORLD, nranks, ierr)

  !                name                   n   m   cond      act deg unb orth     expansion  tol         seed
  call check_case('orthonormal rows',     50, 5, 10.0_dp,   15, 0, 10, .true.,  'fixed',   1.0e-10_dp, 11_ip, &
                  monitor=.true.)
  call check_case('general rows (hat)',   50, 5, 10.0_dp,   15, 0, 10, .false., 'fixed',   1.0e-10_dp, 12_ip)
  call check_case('cond 1e6',             50, 5, 1.0e6_dp,  15, 0, 10, .false., 'fixed',   1.0e-14_dp, 13_ip)
  call check_case('degenerate',           50, 5, 100.0_dp,  20, 8, 10, .false., 'fixed',   1.0e-12_dp, 14_ip)
  call check_case('all bounds active',    50, 5, 100.0_dp,  30, 0, 20, .false., 'fixed',   1.0e-12_dp, 15_ip)
  call check_case('no bound active',      50, 5, 100.0_dp,  0,  0, 25, .false., 'fixed',   1.0e-12_dp, 16_ip)
  call check_case('optimal expansion',    50, 5, 100.0_dp,  20, 4, 10, .false., 'optimal', 1.0e-12_dp, 17_ip)
  ! "all bounds active": every bounded component is at its bound; the unbounded ones
  ! play the part of the FETI gluing multipliers. (With only m free components the
  ! multiplier update contracts like K (K + rho I)^{-1}, K = C_F^{-T} A_FF C_F^{-1}, which
  ! is close to 1 for a random C: the augmented Lagrangian method is then very slow.)
  call check_per_component_stop()
  call check_rho_growth()
  call check_caps()
  call check_not_finite()
  call check_default_settings()
  call check_refusals()
  call test_finish()

contains

  subroutine check_case(name, n, m, cond, n_active, n_degenerate, n_unbounded, orthonormal, expansion, tol, &
                        seed, monitor)
    character(len=*), intent(in) :: name, expansion
    integer(ip), intent(in) :: n, m, n_active, n_degenerate, n_unbounded, seed
    real(dp), intent(in) :: cond, tol
    logical, intent(in) :: orthonormal
    logical, intent(in), optional :: monitor
    type(qp_case_t) :: cs
    type(dense_qp_t) :: serial, dist
    type(smalbe_t) :: s_solver, d_solver
    real(dp), allocatable :: xs(:), xd(:), x_full(:), g_full(:)
    character(len=300) :: buf
    logical :: identical

    call make_case(cs, n, m, cond, n_active, n_degenerate, n_unbounded, orthonormal, seed)
    call serial%create(MPI_COMM_SELF, cs, .true.)
    call dist%create(MPI_COMM_WORLD, cs, .true.)
    call s_solver%init(cs%a_norm, tol, 200_ip, 20000_ip, expansion=expansion)
    call d_solver%init(cs%a_norm, tol, 200_ip, 20000_ip, expansion=expansion, monitor=monitor)
    allocate (xs(serial%n), xd(dist%n), x_full(n), g_full(n))
    xs = 0
    xd = 0
    call s_solver%solve(serial, xs)
    call d_solver%solve(dist, xd)

    call assert_equal(qp_status_converged, s_solver%status, name//': serial converged', HERE)
    call assert_equal(qp_status_converged, d_solver%status, name//': distributed converged', HERE)
    call check_solution(name//' (serial)', cs, xs, s_solver%gradient, s_solver, tol)
    call dist%gather(xd, x_full)
    call dist%gather(d_solver%gradient, g_full)
    call check_solution(name//' (distributed)', cs, x_full, g_full, d_solver, tol)
    ! The distributed run differs from the serial one only by the rounding of
    ! the Hessian rows and reductions (the reductions are compensated, so the
    ! iterates are usually the same bits): each of k steps moves x by at most
    ! eps cond(A) |x|, so |x_dist - x_serial| <= drift_tol(k, cond |x*|).
    call assert_below(norm2(x_full - xs), drift_tol(int(s_solver%n_hessian), cond*norm2(cs%x_star)), &
                      name//': distributed x = serial x', HERE)
    identical = all(x_full == xs)
    call assert_below(norm2(d_solver%muhat - s_solver%muhat), &
                      drift_tol(int(s_solver%n_hessian), cond*norm2(cs%muhat_star)), &
                      name//': distributed muhat = serial muhat', HERE)
    call same_count(s_solver%n_outer, d_solver%n_outer, identical, name//': outer iterations serial/distributed', HERE)
    call same_count(s_solver%n_hessian, d_solver%n_hessian, identical, name//': Hessian count', HERE)
    call same_count(s_solver%n_cg, d_solver%n_cg, identical, name//': CG steps', HERE)
    call same_count(s_solver%n_expansion, d_solver%n_expansion, identical, name//': expansion steps', HERE)
    call same_count(s_solver%n_proportioning, d_solver%n_proportioning, identical, name//': proportioning steps', &
                    HERE)
    call assert_equal(dist%n_hessian_calls, d_solver%n_hessian, name//': Hessian calls counted', HERE)
    call assert_equal(d_solver%n_cg + d_solver%n_expansion + d_solver%n_proportioning, d_solver%n_inner, &
                      name//': inner = cg + expansion + proportioning', HERE)
    write (buf, '(a,i0,3a,i0,a,i0,a,i0,a,i0,a,i0,a,i0,a,i0,a,i0,2(a,es9.2))') 'np ', nranks, ' SMALBE ', name, &
      ': outer ', d_solver%n_outer, ', inner ', d_solver%n_inner, ' (cg ', d_solver%n_cg, ', exp ', &
      d_solver%n_expansion, ', prop ', d_solver%n_proportioning, '), Hessian ', d_solver%n_hessian, &
      ', ||Cx|| evals ', d_solver%n_eq_residual, ', M updates ', d_solver%n_m_updates, &
      ', ||x-x*||/||x*|| ', norm2(x_full - cs%x_star)/norm2(cs%x_star), &
      ', ||mu-mu*||/||mu*|| ', norm2(d_solver%muhat - cs%muhat_star)/norm2(cs%muhat_star)
    call log_message(buf)
  end subroutine check_case

  !> The KKT conditions of the returned pair, recomputed from the dense data.
  subroutine check_solution(name, cs, x, gradient, solver, tol)
    character(len=*), intent(in) :: name
    type(qp_case_t), intent(in) :: cs
    real(dp), intent(in) :: x(:), gradient(:), tol
    type(smalbe_t), intent(in) :: solver
    real(dp) :: g(cs%n), gp(cs%n), cx(cs%m), norm_b, lagr, floor
    integer :: i
    norm_b = norm2(cs%b)
    ! round-off of the gradient carried through k Hessian products and the
    ! multiplier updates: drift_tol(k, ||A|| ||x|| + ||b|| + ||C^T mu||)
    floor = drift_tol(int(solver%n_hessian), cs%a_norm*norm2(x) + norm_b + &
                      norm2(matmul(transpose(cs%c), solver%muhat)))
    call assert_below(norm2(x - cs%x_star), 1.0e-8_dp*norm2(cs%x_star), name//': ||x - x*|| <= 1e-8 ||x*||', HERE)
    call assert_below(norm2(solver%muhat - cs%muhat_star), 1.0e-6_dp*norm2(cs%muhat_star), &
                      name//': ||muhat - muhat*|| <= 1e-6 ||muhat*||', HERE)
    call assert_true(all(x >= cs%lower), name//': x >= l', HERE)
    ! gradient of the Lagrangian, its projection, and C x (in the norm of C~)
    g = matmul(cs%a, x) - cs%b + matmul(transpose(cs%c), solver%muhat)
    do i = 1, cs%n
      gp(i) = g(i)
      if (x(i) <= cs%lower(i)) gp(i) = min(g(i), 0.0_dp)
    end do
    cx = matmul(cs%c, x)
    call assert_below(norm2(gp), 10*tol*norm_b + floor, name//': KKT ||g^P(x, mu)|| from the dense data', HERE)
    call assert_below(norm2(cx), (10*tol*norm_b + floor)*max(1.0_dp, norm2(cs%c)), name//': KKT ||C x||', HERE)
    call assert_below(solver%cnorm, tol*norm_b, name//': reported ||C x|| <= tol ||b||', HERE)
    call assert_below(solver%gp_norm, tol*norm_b, name//': reported ||g^P|| <= tol ||b||', HERE)
    call assert_below(norm2(g - cs%s_star), 1.0e-6_dp*norm_b, name//': gradient = bound multipliers s*', HERE)
    ! the gradient carried through the multiplier updates and L(x, mu) as reported
    call assert_below(norm2(gradient - g), floor, name//': returned gradient = A x - b + C^T mu', HERE)
    lagr = 0.5_dp*dot_product(x, matmul(cs%a, x)) - dot_product(cs%b, x) + dot_product(solver%muhat, cx)
    ! L is a sum of products of x with vectors carried to within floor
    call assert_below(abs(solver%lagrangian - lagr), floor*norm2(x) + 10*epsilon(1.0_dp)*abs(lagr), &
                      name//': returned L(x, mu)', HERE)
  end subroutine check_solution

  !> A problem that asks for the per-component stopping test (stop_weight,
  !> stop_scale; qp_problem): the returned x meets max_i w_i |v^P_i| <= tol S,
  !> v = g - rho C^T C x the gradient without its penalty part,
  !> and ||C x|| <= tol S, recomputed from the dense data (up to the
  !> round-off of the carried gradient), and reaches x*.
  subroutine check_per_component_stop()
    type(qp_case_t) :: cs
    type(dense_qp_t) :: dist
    type(smalbe_t) :: solver
    real(dp), allocatable :: x(:), x_full(:), w(:), g(:), gp(:)
    real(dp) :: tol, scale, floor
    integer(ip) :: i
    tol = 1.0e-8_dp
    call make_case(cs, 50_ip, 5_ip, 100.0_dp, 15_ip, 0_ip, 10_ip, .true., 31_ip)
    call dist%create(MPI_COMM_WORLD, cs, .true.)
    allocate (w(cs%n), x(dist%n), x_full(cs%n), g(cs%n), gp(cs%n))
    do i = 1, cs%n
      w(i) = 1/(1 + real(mod(i, 3), dp))
    end do
    allocate (dist%stop_weight(dist%n))
    dist%stop_weight = w(dist%offset + 1:dist%offset + dist%n)
    scale = 0.5_dp*maxval(abs(w*cs%b))
    dist%stop_scale = scale
    call solver%init(cs%a_norm, tol, 200_ip, 20000_ip)
    x = 0
    call solver%solve(dist, x)
    call assert_equal(qp_status_converged, solver%status, 'per-component stop: converged', HERE)
    call assert_true(solver%per_component, 'per-component stop: used', HERE)
    call assert_below(abs(solver%tol_gp - tol*scale), 1.0e-15_dp*tol*scale, 'per-component stop: bound tol S', HERE)
    call dist%gather(x, x_full)
    ! the measured gradient is the one without its penalty part rho C^T C x
    g = matmul(cs%a, x_full) - cs%b + matmul(transpose(cs%c), solver%muhat) - &
        solver%rho*matmul(transpose(cs%c), matmul(cs%c, x_full))
    gp = merge(min(g, 0.0_dp), g, x_full <= cs%lower)
    floor = drift_tol(int(solver%n_hessian), cs%a_norm*norm2(x_full) + norm2(cs%b))
    call assert_below(maxval(abs(w*gp)), tol*scale + floor, 'per-component stop: max w |g^P| from the dense data', HERE)
    call assert_below(norm2(matmul(cs%c, x_full)), tol*scale + floor, 'per-component stop: ||C x|| <= tol S', HERE)
    call assert_below(norm2(x_full - cs%x_star), 1.0e-6_dp*norm2(cs%x_star), 'per-component stop: x = x*', HERE)
    call solver%free()
  end subroutine check_per_component_stop

  !> max_hessian = 3 and max_outer = 1: not converged with the right status.
  subroutine check_caps()
    type(qp_case_t) :: cs
    type(dense_qp_t) :: dist
    type(smalbe_t) :: solver
    real(dp), allocatable :: x(:)
    call make_case(cs, 50_ip, 5_ip, 100.0_dp, 15_ip, 0_ip, 10_ip, .false., 21_ip)
    call dist%create(MPI_COMM_WORLD, cs, .true.)
    allocate (x(dist%n))

    call solver%init(cs%a_norm, 1.0e-10_dp, 200_ip, 3_ip)
    x = 0
    call solver%solve(dist, x)
    call assert_equal(qp_status_max_hessian, solver%status, 'cap max_hessian: status', HERE)
    call assert_true(.not. solver%converged(), 'cap max_hessian: not converged', HERE)
    call assert_true(solver%n_hessian <= 3 .and. dist%n_hessian_calls <= 3, 'cap max_hessian: <= 3 products', HERE)
    call assert_true(index(solver%message, 'max_hessian = 3') > 0, 'cap max_hessian: message', HERE)
    call assert_true(index(solver%message, 'tol not met') > 0 .and. index(solver%message, 'must be <=') > 0, &
                     'cap max_hessian: message says how far from tol', HERE)

    call solver%init(cs%a_norm, 1.0e-10_dp, 1_ip, 20000_ip)
    x = 0
    call solver%solve(dist, x)
    call assert_equal(qp_status_max_outer, solver%status, 'cap max_outer: status', HERE)
    call assert_equal(1_ip, solver%n_outer, 'cap max_outer: one outer iteration', HERE)
    call assert_true(index(solver%message, 'max_outer = 1') > 0, 'cap max_outer: message', HERE)
    call assert_true(index(solver%message, 'tol not met') > 0, 'cap max_outer: message says how far from tol', HERE)
    call solver%free()
  end subroutine check_caps

  !> The Hessian returns NaN from its 10th call: status not_finite, x finite.
  subroutine check_not_finite()
    type(qp_case_t) :: cs
    type(dense_qp_t) :: dist
    type(smalbe_t) :: solver
    real(dp), allocatable :: x(:)
    logical :: halting
    call ieee_get_halting_mode(ieee_invalid, halting)
    call ieee_set_halting_mode(ieee_invalid, .false.)
    call make_case(cs, 50_ip, 5_ip, 100.0_dp, 15_ip, 0_ip, 10_ip, .false., 23_ip)
    call dist%create(MPI_COMM_WORLD, cs, .true.)
    dist%poison_after = 9
    call solver%init(cs%a_norm, 1.0e-10_dp, 200_ip, 20000_ip)
    allocate (x(dist%n))
    x = 0
    call solver%solve(dist, x)
    call ieee_set_halting_mode(ieee_invalid, halting)
    call assert_equal(qp_status_not_finite, solver%status, 'NaN Hessian: SMALBE status not_finite', HERE)
    call assert_true(all(ieee_is_finite(x)) .and. all(ieee_is_finite(solver%muhat)), &
                     'NaN Hessian: x and muhat stay finite', HERE)
    call assert_true(index(solver%message, 'non-finite') > 0, 'NaN Hessian: SMALBE message', HERE)
  end subroutine check_not_finite

  !> The adaptive penalty (rho_growth > 1) on a case whose outer loop
  !> contracts slowly (all bounds active, see above): rho is raised, the
  !> problem's Hessian follows (set_penalty), the solve still reaches x* and
  !> the KKT conditions of the final A = P A0 P + rho Q, the final rho is
  !> reported and stays below the cap; the serial and the distributed solve
  !> raise it equally often. Without growth, rho stays put.
  subroutine check_rho_growth()
    type(qp_case_t) :: cs, cs_final
    type(dense_qp_t) :: serial, dist
    type(smalbe_t) :: s_solver, d_solver
    type(smalbe_settings_t) :: settings
    real(dp), allocatable :: xs(:), x_full(:), xd(:), g_full(:)
    real(dp) :: rho0
    real(dp), parameter :: tol = 1.0e-12_dp
    call make_case(cs, 50_ip, 5_ip, 100.0_dp, 30_ip, 0_ip, 20_ip, .true., 15_ip)
    rho0 = cs%rho
    settings%tol = tol
    settings%rho_growth = 2
    settings%rho_contraction = 0.5_dp
    call serial%create(MPI_COMM_SELF, cs, .true.)
    call dist%create(MPI_COMM_WORLD, cs, .true.)
    call s_solver%init_with(settings, cs%a_norm)
    call d_solver%init_with(settings, cs%a_norm)
    allocate (xs(serial%n), xd(dist%n), x_full(cs%n), g_full(cs%n))
    xs = 0
    xd = 0
    call s_solver%solve(serial, xs)
    call d_solver%solve(dist, xd)
    call assert_equal(qp_status_converged, s_solver%status, 'rho growth: serial converged', HERE)
    call assert_equal(qp_status_converged, d_solver%status, 'rho growth: distributed converged', HERE)
    call assert_true(d_solver%n_rho_updates > 0, 'rho growth: rho raised at least once', HERE)
    call assert_true(d_solver%rho > rho0 .and. d_solver%rho <= 100*rho0*(1 + 1.0e-12_dp), &
                     'rho growth: final rho in (rho_0, 100 rho_0]', HERE)
    call assert_true(abs(d_solver%rho - rho0*2.0_dp**d_solver%n_rho_updates) <= 1.0e-12_dp*d_solver%rho, &
                     'rho growth: final rho = rho_0 2^(updates)', HERE)
    call assert_true(dist%penalty() == d_solver%rho .and. serial%penalty() == s_solver%rho, &
                     'rho growth: the problem carries the final rho', HERE)
    call assert_equal(s_solver%n_rho_updates, d_solver%n_rho_updates, 'rho growth: serial = distributed updates', &
                      HERE)
    ! the KKT conditions of the final Hessian (C has orthonormal rows: Q = C^T C)
    cs_final = cs
    cs_final%a = cs%a + (d_solver%rho - rho0)*matmul(transpose(cs%c), cs%c)
    cs_final%rho = d_solver%rho
    cs_final%a_norm = max(cs%a_norm, d_solver%rho)
    call check_solution('rho growth (serial)', cs_final, xs, s_solver%gradient, s_solver, tol)
    call dist%gather(xd, x_full)
    call dist%gather(d_solver%gradient, g_full)
    call check_solution('rho growth (distributed)', cs_final, x_full, g_full, d_solver, tol)
    call log_message('rho growth: rho raised ' // trim(itoa(d_solver%n_rho_updates)) // ' times')
    ! default: constant rho
    call dist%create(MPI_COMM_WORLD, cs, .true.)
    settings%rho_growth = 1
    call d_solver%init_with(settings, cs%a_norm)
    xd = 0
    call d_solver%solve(dist, xd)
    call assert_true(d_solver%n_rho_updates == 0 .and. d_solver%rho == rho0 .and. dist%penalty() == rho0, &
                     'rho growth 1: rho constant', HERE)
  end subroutine check_rho_growth

  function itoa(i) result(text)
    integer(ip), intent(in) :: i
    character(len=20) :: text
    write (text, '(i0)') i
  end function itoa

  !> init_with the default smalbe_settings_t: the literature defaults, and a solve.
  subroutine check_default_settings()
    type(qp_case_t) :: cs
    type(dense_qp_t) :: dist
    type(smalbe_t) :: solver
    type(smalbe_settings_t) :: settings
    real(dp), allocatable :: x(:)
    call make_case(cs, 50_ip, 5_ip, 10.0_dp, 15_ip, 0_ip, 10_ip, .false., 24_ip)
    call dist%create(MPI_COMM_WORLD, cs, .true.)
    call solver%init_with(settings, cs%a_norm)
    call assert_true(solver%m_scale == 100 .and. solver%beta == 0.5_dp .and. solver%eta_scale == 0.1_dp .and. &
                     solver%inner%gamma == 1 .and. solver%inner%alpha_scale == 1.9_dp .and. &
                     solver%inner%expansion == 'fixed', 'default settings: literature defaults', HERE)
    allocate (x(dist%n))
    x = 0
    call solver%solve(dist, x)
    call assert_equal(qp_status_converged, solver%status, 'default settings: converged', HERE)
    call assert_below(solver%gp_norm, settings%tol*norm2(cs%b), 'default settings: tol ||b|| met', HERE)
    call assert_true(abs(solver%m_initial - 100*cs%a_norm) <= 1.0e-12_dp*cs%a_norm .and. &
                     abs(solver%eta - 0.1_dp*norm2(cs%b)) <= 1.0e-12_dp*norm2(cs%b), &
                     'default settings: M0 = 100 ||A||, eta = 0.1 ||b||', HERE)
  end subroutine check_default_settings

  !> SMALBE refuses a problem without equality and one with penalty 0.
  subroutine check_refusals()
    type(qp_case_t) :: cs
    type(dense_qp_t) :: no_eq, no_rho
    type(smalbe_t) :: solver
    character(len=256) :: reason
    real(dp), allocatable :: x(:)
    call make_case(cs, 20_ip, 3_ip, 10.0_dp, 5_ip, 0_ip, 0_ip, .true., 22_ip)
    call no_eq%create(MPI_COMM_WORLD, cs, .false.)
    call no_rho%create(MPI_COMM_WORLD, cs, .true.)
    no_rho%rho = 0
    call solver%init(cs%a_norm, 1.0e-8_dp, 10_ip, 100_ip)
    call assert_true(.not. solver%is_compatible(no_eq, reason), 'SMALBE refuses a problem without equality', HERE)
    call assert_true(index(reason, 'equality') > 0, 'reason names the equality', HERE)
    call assert_true(.not. solver%is_compatible(no_rho, reason), 'SMALBE refuses penalty 0', HERE)
    call assert_true(index(reason, 'penalty') > 0, 'reason names the penalty', HERE)
    allocate (x(no_rho%n))
    x = 0
    call solver%solve(no_rho, x)
    call assert_equal(qp_status_incompatible, solver%status, 'refused problem: status', HERE)
    call assert_equal(0_ip, no_rho%n_hessian_calls, 'refused problem: no Hessian call', HERE)
  end subroutine check_refusals
end program test_qp_smalbe
