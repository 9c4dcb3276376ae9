#include "assertions.h"
!> K^+ of real subdomains is a generalized inverse of K:
!>   ||K K^+ K x - K x|| / ||K x|| small for "random" x, and
!>   u = K^+ f solves K u = f for f = K y in range(K) (several at once with
!>   solve_many, which must agree with solve column by column), where "small"
!>   is c eps cond(K_reg) with cond(K_reg) = lambda_max(K) lambda_max(K^+)
!>   estimated by power iterations (a bound that holds on any CPU and BLAS),
!> on plain, distorted (0.3), near-incompressible (poisson 0.499) and
!> high-contrast (young 1e6 in every other subdomain) meshes, for a single
!> element, 4x4x4, an elongated 2x3x8 and METIS-shaped subdomains, with both
!> orderings. Every rank checks the subdomains it owns (on MPI_COMM_SELF).
program test_local_kplus
  use kinds, only: dp, ip, i8
  use params, only: params_t, default_params
  use decomposition, only: decomposition_t, build_decomposition
  use subdomain, only: subdomain_t, build_subdomain
  use assembly, only: assemble_subdomain
  use kplus, only: kplus_t
  use mpi_f08, only: MPI_Init, MPI_COMM_WORLD
  use assertions, only: assert_true, assert_below, test_skip, test_finish
  use tolerances, only: solve_tol
  implicit none
  character(len=8), parameter :: orderings(2) = [character(len=8) :: 'amd', 'metis']
  character(len=16), parameter :: variants(4) = [character(len=16) :: 'plain', 'distorted', &
                                                 'incompressible', 'contrast']
  integer :: ierr, v, o

  call MPI_Init(ierr)
  do v = 1, size(variants)
    do o = 1, size(orderings)
      call check_case('box', [2, 1, 1], [1, 1, 1], variants(v), orderings(o), 'one element')
      call check_case('box', [2, 1, 1], [4, 4, 4], variants(v), orderings(o), '4x4x4')
      call check_case('box', [2, 1, 1], [2, 3, 8], variants(v), orderings(o), '2x3x8')
      call check_case('metis', [2, 2, 1], [3, 3, 3], variants(v), orderings(o), 'metis')
    end do
  end do
  call check_regularization_scales()
  call test_finish()

contains

  subroutine check_case(method, nsub, nel, variant, ordering, shape)
    character(len=*), intent(in) :: method, variant, ordering, shape
    integer(ip), intent(in) :: nsub(3), nel(3)
    type(params_t) :: p
    type(decomposition_t) :: dec
    type(subdomain_t) :: sub
    type(kplus_t) :: kp
    character(len=120) :: what
    integer(ip) :: s, id

    p = default_params()
    p%mesh%decomposition = method
    p%mesh%nsub = nsub
    p%mesh%nel = nel
    p%mesh%lengths = [1.0_dp, 1.5_dp, 2.0_dp]
    select case (variant)
    case ('distorted')
      p%mesh%distortion = 0.3_dp
    case ('incompressible')
      p%mesh%distortion = 0.1_dp
      p%material%poisson = 0.499_dp
    case ('contrast')
      p%material%variation = 'checkerboard'
      p%material%contrast = 1.0e6_dp/p%material%young
    end select
    call build_decomposition(p, MPI_COMM_WORLD, dec)
    do s = 1, size(dec%local_subdomains)
      id = dec%local_subdomains(s)
      call build_subdomain(dec, id, sub)
      call assemble_subdomain(p, dec, sub)
      write (what, '(5a,i0,3a)') trim(shape), ' ', trim(variant), ' subdomain ', '', id, ' (', trim(ordering), ')'
      call kp%init(sub, 1.0_dp, ordering)
      call check_generalized_inverse(sub, kp, trim(what))
      call kp%free()
    end do
  end subroutine check_case

  subroutine check_generalized_inverse(sub, kp, what)
    type(subdomain_t), intent(in) :: sub
    type(kplus_t), intent(inout) :: kp
    character(len=*), intent(in) :: what
    integer, parameter :: nrhs = 3
    real(dp), allocatable :: x(:), kx(:), w(:), kw(:), y(:, :), f(:, :), u(:, :), one(:)
    real(dp) :: cond, tol
    integer(ip) :: n, i, j

    n = sub%ndof
    allocate (x(n), kx(n), w(n), kw(n), y(n, nrhs), f(n, nrhs), u(n, nrhs), one(n))
    ! Every check below compares results of backward-stable solves with K_reg:
    ! their forward error is bounded by c eps cond(K_reg).
    cond = condition_estimate(sub, kp)
    tol = solve_tol(cond)
    call assert_true(cond > 1 .and. cond < 1/epsilon(1.0_dp), what//': cond(K_reg) estimate in (1, 1/eps)', HERE)
    call assert_true(size(kp%fixing_nodes) >= 3, what//': at least 3 fixing nodes', HERE)
    call assert_true(kp%gram_ratio >= 1.0e-2_dp, what//': R_F^T R_F well conditioned', HERE)
    call assert_true(kp%factor_bytes() > 0_i8, what//': factor_bytes > 0', HERE)

    ! K K^+ K x = K x
    do i = 1, n
      x(i) = sin(1.7_dp*i + 0.3_dp) + 0.5_dp*cos(0.11_dp*i*i)
    end do
    call sub%K%matvec(x, kx)
    w = kx
    call kp%solve(w)
    call sub%K%matvec(w, kw)
    call assert_below(norm2(kw - kx)/norm2(kx), tol, what//': K K+ K x = K x', HERE)

    ! K u = f for f = K y, several right-hand sides at once
    do j = 1, nrhs
      do i = 1, n
        y(i, j) = cos(0.37_dp*i*j) + real(j, dp)
      end do
      call sub%K%matvec(y(:, j), f(:, j))
    end do
    u = f
    call kp%solve_many(u)
    do j = 1, nrhs
      call sub%K%matvec(u(:, j), kw)
      call assert_below(norm2(kw - f(:, j))/norm2(f(:, j)), tol, what//': K (K+ f) = f', HERE)
      one = f(:, j)
      call kp%solve(one)
      ! the same factors, other kernels (dtrsm vs dtrsv): c eps cond(K_reg)
      call assert_below(norm2(one - u(:, j))/norm2(u(:, j)), tol, what//': solve_many = solve', HERE)
    end do
  end subroutine check_generalized_inverse

  !> cond(K_reg) ~ lambda_max(K_reg) lambda_max(K_reg^{-1}); K_reg = K + rho_f
  !> R_F R_F^T has lambda_max(K_reg) <= lambda_max(K) + rho_f, estimated here as
  !> 2 lambda_max(K) (rho_f is of the size of K's diagonal), each lambda_max by
  !> 30 power iterations (an underestimate by a factor of at most a few).
  real(dp) function condition_estimate(sub, kp) result(cond)
    type(subdomain_t), intent(in) :: sub
    type(kplus_t), intent(inout) :: kp
    real(dp), allocatable :: v(:), w(:)
    real(dp) :: lmax_k, lmax_kplus
    integer(ip) :: i
    integer :: it
    allocate (v(sub%ndof), w(sub%ndof))
    do i = 1, sub%ndof
      v(i) = 1 + 0.3_dp*sin(2.1_dp*i)
    end do
    lmax_k = 0
    do it = 1, 30
      v = v/norm2(v)
      call sub%K%matvec(v, w)
      lmax_k = norm2(w)
      v = w
    end do
    do i = 1, sub%ndof
      v(i) = 1 + 0.3_dp*cos(1.3_dp*i)
    end do
    lmax_kplus = 0
    do it = 1, 30
      v = v/norm2(v)
      w = v
      call kp%solve(w)
      lmax_kplus = norm2(w)
      v = w
    end do
    cond = 2*lmax_k*lmax_kplus
  end function condition_estimate

  !> The generalized inverse property does not depend on rho_f (in exact
  !> arithmetic); with rho_f from 1e-3 to 1e3 times the mean diagonal it holds
  !> to the same tolerance on a distorted 4x4x4 subdomain.
  subroutine check_regularization_scales()
    type(params_t) :: p
    type(decomposition_t) :: dec
    type(subdomain_t) :: sub
    type(kplus_t) :: kp
    real(dp) :: scale
    integer :: k
    character(len=60) :: what

    p = default_params()
    p%mesh%nsub = [2, 1, 1]
    p%mesh%nel = [4, 4, 4]
    p%mesh%distortion = 0.3_dp
    call build_decomposition(p, MPI_COMM_WORLD, dec)
    if (size(dec%local_subdomains) == 0) then
      call test_skip('regularization scales: this rank owns no subdomain', HERE)
      return
    end if
    call build_subdomain(dec, dec%local_subdomains(1), sub)
    call assemble_subdomain(p, dec, sub)
    do k = -3, 3, 2
      scale = 10.0_dp**k
      write (what, '(a,es8.1)') 'regularization ', scale
      call kp%init(sub, scale, 'metis')
      call check_generalized_inverse(sub, kp, trim(what))
    end do
    call kp%free()
  end subroutine check_regularization_scales
end program test_local_kplus
