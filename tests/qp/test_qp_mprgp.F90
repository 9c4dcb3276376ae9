#include "assertions.h"
!> MPRGP on bound constrained QPs whose solution is known by construction
!> (qp_test_problems): each case is solved serially (MPI_COMM_SELF, whole
!> rows on every rank) and distributed over MPI_COMM_WORLD; both must reach
!> ||x - x*|| <= 1e-8 ||x*||, satisfy the KKT conditions checked here from
!> the dense data, and take the same numbers of steps. Then the safeguards:
!> the Hessian cap, a problem with equality refused, NaN from the Hessian.
program test_qp_mprgp
  use, intrinsic :: ieee_arithmetic, only: ieee_is_finite
  use, intrinsic :: ieee_exceptions, only: ieee_set_halting_mode, ieee_get_halting_mode, ieee_invalid
  use kinds, only: dp, ip
  use assertions, only: assert_true, assert_equal, assert_below, test_finish
  use logger, only: logger_init, log_message
  use qp_problem, only: qp_status_converged, qp_status_max_hessian, qp_status_incompatible, &
                        qp_status_not_finite
  use mprgp, only: mprgp_t
  use tolerances, only: drift_tol
  use qp_test_problems, only: qp_case_t, make_case, dense_qp_t, same_count
  use mpi_f08, only: MPI_Init, MPI_COMM_WORLD, MPI_COMM_SELF, MPI_Comm_size
  implicit none
  integer :: ierr, nranks

  call MPI_Init(ierr)
  call logger_init(MPI_COMM_WORLD)
  call MPI_Comm_size(MPI_COMM_WORLD, nranks, ierr)

  !                name                 n   cond      act deg unb  expansion   tol
  call check_case('well conditioned',   50, 10.0_dp,  15, 0, 10, 'fixed',   1.0e-10_dp, 1_ip)
  call check_case('cond 1e6',           50, 1.0e6_dp, 15, 0, 10, 'fixed',   1.0e-15_dp, 2_ip)
  call check_case('degenerate',         50, 100.0_dp, 20, 8, 10, 'fixed',   1.0e-12_dp, 3_ip)
  call check_case('all active',         50, 100.0_dp, 50, 0, 0,  'fixed',   1.0e-12_dp, 4_ip)
  call check_case('none active',        50, 100.0_dp, 0,  0, 25, 'fixed',   1.0e-12_dp, 5_ip)
  call check_case('optimal expansion',  50, 100.0_dp, 20, 4, 10, 'optimal', 1.0e-12_dp, 6_ip)
  call check_case('optimal, cond 1e6',  50, 1.0e6_dp, 15, 0, 10, 'optimal', 1.0e-15_dp, 2_ip)
  call check_cap()
  call check_refuses_equality()
  call check_not_finite()
  call test_finish()

contains

  subroutine check_case(name, n, cond, n_active, n_degenerate, n_unbounded, expansion, tol, seed)
    character(len=*), intent(in) :: name, expansion
    integer(ip), intent(in) :: n, n_active, n_degenerate, n_unbounded, seed
    real(dp), intent(in) :: cond, tol
    type(qp_case_t) :: cs
    type(dense_qp_t) :: serial, dist
    type(mprgp_t) :: s_solver, d_solver
    real(dp), allocatable :: xs(:), xd(:), x_full(:), g_full(:)
    character(len=300) :: buf
    logical :: identical

    call make_case(cs, n, 0_ip, cond, n_active, n_degenerate, n_unbounded, .false., seed)
    call serial%create(MPI_COMM_SELF, cs, .false.)
    call dist%create(MPI_COMM_WORLD, cs, .false.)
    call s_solver%init(cs%a_norm, tol, 20000_ip, expansion=expansion)
    call d_solver%init(cs%a_norm, tol, 20000_ip, expansion=expansion)
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
    call same_count(s_solver%n_hessian, d_solver%n_hessian, identical, name//': Hessian count serial/distributed', HERE)
    call same_count(s_solver%n_cg, d_solver%n_cg, identical, name//': CG steps', HERE)
    call same_count(s_solver%n_expansion, d_solver%n_expansion, identical, name//': expansion steps', HERE)
    call same_count(s_solver%n_proportioning, d_solver%n_proportioning, identical, name//': proportioning steps', &
                    HERE)
    call assert_equal(dist%n_hessian_calls, d_solver%n_hessian, name//': Hessian calls counted', HERE)
    write (buf, '(a,i0,3a,i0,a,i0,a,i0,a,i0,a,i0,a,es9.2)') 'np ', nranks, ' MPRGP ', name, ': iterations ', &
      d_solver%n_iterations, ' (cg ', d_solver%n_cg, ', exp ', d_solver%n_expansion, ', prop ', &
      d_solver%n_proportioning, '), Hessian ', d_solver%n_hessian, ', ||x-x*||/||x*|| ', &
      norm2(x_full - cs%x_star)/norm2(cs%x_star)
    call log_message(buf)
  end subroutine check_case

  !> ||x - x*|| <= 1e-8 ||x*||, x >= l, and the KKT conditions recomputed
  !> from the dense data: ||g^P(x)|| <= tol ||b|| (the stopping test, up to
  !> the round-off that the recursively updated gradient gathers over the
  !> solver's k Hessian products, drift_tol(k, ||A|| ||x|| + ||b||)) and g
  !> close to s*.
  subroutine check_solution(name, cs, x, gradient, solver, tol)
    character(len=*), intent(in) :: name
    type(qp_case_t), intent(in) :: cs
    real(dp), intent(in) :: x(:), gradient(:), tol
    type(mprgp_t), intent(in) :: solver
    real(dp) :: g(cs%n), gp(cs%n), floor
    integer :: i
    floor = drift_tol(int(solver%n_hessian), cs%a_norm*norm2(x) + norm2(cs%b))
    call assert_below(norm2(x - cs%x_star), 1.0e-8_dp*norm2(cs%x_star), name//': ||x - x*|| <= 1e-8 ||x*||', HERE)
    call assert_true(all(x >= cs%lower), name//': x >= l', HERE)
    g = matmul(cs%a, x) - cs%b
    do i = 1, cs%n
      gp(i) = g(i)
      if (x(i) <= cs%lower(i)) gp(i) = min(g(i), 0.0_dp)
    end do
    call assert_below(norm2(gp), 10*tol*norm2(cs%b) + floor, name//': ||g^P|| from the dense data', HERE)
    call assert_below(abs(solver%gp_norm - norm2(gp)), floor + 0.5_dp*norm2(gp), &
                      name//': reported ||g^P|| matches', HERE)
    call assert_below(norm2(g - cs%s_star), 1.0e-6_dp*norm2(cs%b), name//': gradient = multipliers s*', HERE)
    call assert_below(norm2(gradient - g), floor, name//': returned gradient = A x - b', HERE)
  end subroutine check_solution

  !> max_hessian = 3 on a problem that needs many more: not converged, and
  !> never more than 3 multiplications.
  subroutine check_cap()
    type(qp_case_t) :: cs
    type(dense_qp_t) :: dist
    type(mprgp_t) :: solver
    real(dp), allocatable :: x(:)
    call make_case(cs, 50_ip, 0_ip, 1.0e3_dp, 15_ip, 0_ip, 10_ip, .false., 7_ip)
    call dist%create(MPI_COMM_WORLD, cs, .false.)
    call solver%init(cs%a_norm, 1.0e-10_dp, 3_ip)
    allocate (x(dist%n))
    x = 0
    call solver%solve(dist, x)
    call assert_equal(qp_status_max_hessian, solver%status, 'cap: status max_hessian', HERE)
    call assert_true(.not. solver%converged(), 'cap: not converged', HERE)
    call assert_true(solver%n_hessian <= 3, 'cap: at most 3 Hessian multiplications', HERE)
    call assert_true(index(solver%message, 'max_hessian = 3') > 0, 'cap: message names the cap', HERE)
    call assert_true(index(solver%message, 'smallest') > 0, 'cap: message gives the smallest ||g^P||', HERE)
    call assert_true(solver%best_gp_norm <= solver%gp_norm .and. solver%n_best <= solver%n_iterations, &
                     'cap: smallest ||g^P|| and its iteration are consistent', HERE)
    call assert_true(all(x >= dist%lower), 'cap: iterate feasible', HERE)
    call solver%free()
  end subroutine check_cap

  subroutine check_refuses_equality()
    type(qp_case_t) :: cs
    type(dense_qp_t) :: dist
    type(mprgp_t) :: solver
    real(dp), allocatable :: x(:)
    character(len=256) :: reason
    call make_case(cs, 20_ip, 3_ip, 10.0_dp, 5_ip, 0_ip, 0_ip, .true., 8_ip)
    call dist%create(MPI_COMM_WORLD, cs, .true.)
    call solver%init(cs%a_norm, 1.0e-8_dp, 100_ip)
    call assert_true(.not. solver%is_compatible(dist, reason), 'MPRGP refuses an equality problem', HERE)
    call assert_true(index(reason, 'equality') > 0, 'refusal reason names the equality', HERE)
    allocate (x(dist%n))
    x = 0
    call solver%solve(dist, x)
    call assert_equal(qp_status_incompatible, solver%status, 'solve of a refused problem: status', HERE)
    call assert_equal(0_ip, dist%n_hessian_calls, 'refused problem: no Hessian call', HERE)
  end subroutine check_refuses_equality

  !> The Hessian returns NaN from its 6th call: status not_finite, x finite.
  subroutine check_not_finite()
    type(qp_case_t) :: cs
    type(dense_qp_t) :: dist
    type(mprgp_t) :: solver
    real(dp), allocatable :: x(:)
    logical :: halting
    call ieee_get_halting_mode(ieee_invalid, halting)
    call ieee_set_halting_mode(ieee_invalid, .false.)
    call make_case(cs, 50_ip, 0_ip, 1.0e3_dp, 15_ip, 0_ip, 10_ip, .false., 9_ip)
    call dist%create(MPI_COMM_WORLD, cs, .false.)
    dist%poison_after = 5
    call solver%init(cs%a_norm, 1.0e-10_dp, 1000_ip)
    allocate (x(dist%n))
    x = 0
    call solver%solve(dist, x)
    call ieee_set_halting_mode(ieee_invalid, halting)
    call assert_equal(qp_status_not_finite, solver%status, 'NaN Hessian: status not_finite', HERE)
    call assert_true(all(ieee_is_finite(x)), 'NaN Hessian: x stays finite', HERE)
    call assert_true(index(solver%message, 'non-finite') > 0, 'NaN Hessian: message', HERE)
    call assert_true(solver%n_hessian <= 6, 'NaN Hessian: stopped at the first NaN product', HERE)
  end subroutine check_not_finite
end program test_qp_mprgp
