#include "assertions.h"
!> The KKT check sees every jump, whatever the material (docs/CASES.md, "KKT
!> check"). On a checkerboard of Young's moduli with contrast 1e6 (and on
!> uniform material), solved to tol = 1e-10:
!> - the gluing measure of check_kkt agrees with the largest difference
!>   between the copies of a node computed here independently (all copies
!>   gathered by node id on rank 0): max-min <= max(gluing, 2 dirichlet) U
!>   (copies of a Dirichlet node are not glued) and gluing U <= 2 (max-min);
!> - the solution passes the check (every residual <= 1e-6);
!> - a perturbation of the multipliers that keeps every subdomain in
!>   equilibrium (delta lambda = P e_i, e_i one gluing row of a node between a
!>   soft and a stiff subdomain) makes the copies jump: the check reports the
!>   jump it makes (measured independently) and fails above its threshold,
!>   while the equilibrium residual stays small.
program test_kkt_check
  use kinds, only: dp, ip, i8
  use assertions, only: assert_true, assert_below, test_finish
  use logger, only: logger_init
  use params, only: params_t
  use feti_operators, only: feti_t, local_field_t
  use dual_problem, only: dual_problem_t
  use smalbe, only: smalbe_t, smalbe_settings_t
  use tfeti_dualization, only: smalbe_settings
  use subdomain, only: subdomain_t
  use reconstruction, only: dual_gradient, alpha_new
  use kkt, only: kkt_residuals_t, check_kkt
  use constraints, only: row_gluing
  use feti_test_support, only: small_case, gather_keyed
  use mpi_f08, only: MPI_Init, MPI_COMM_WORLD, MPI_Comm_rank, MPI_Allreduce, MPI_MAX, MPI_MIN, MPI_INTEGER, &
    MPI_DOUBLE_PRECISION, MPI_Bcast
  implicit none
  integer :: ierr, rank

  call MPI_Init(ierr)
  call MPI_Comm_rank(MPI_COMM_WORLD, rank, ierr)
  call logger_init()
  call check_case(1.0_dp, 'uniform')
  call check_case(1.0e6_dp, 'checkerboard 1e6')
  call test_finish()

contains

  subroutine check_case(contrast, label)
    real(dp), intent(in) :: contrast
    character(len=*), intent(in) :: label
    type(params_t) :: p
    type(feti_t), target :: op
    type(dual_problem_t) :: hat
    type(smalbe_t) :: solver
    type(smalbe_settings_t) :: sp
    type(kkt_residuals_t) :: res
    type(local_field_t), allocatable :: u(:)
    real(dp), allocatable :: nu(:), lambda(:), g(:), muhat(:), alpha(:), e(:), pe(:)
    real(dp) :: umax, jump, delta, lmax
    integer(ip) :: n, i, pick
    integer(ip), allocatable :: kind(:)
    integer :: owner, mine
    real(dp) :: lmine

    p = small_case('cube', [2_ip, 2_ip, 2_ip], [2_ip, 2_ip, 2_ip], 'box', 0.0_dp)
    p%boundary%top_displacement = [0.0_dp, 0.0_dp, -0.025_dp]
    if (contrast > 1) then
      p%material%variation = 'checkerboard'
      p%material%contrast = contrast
    end if
    call op%setup(p, MPI_COMM_WORLD)
    n = op%n_own()
    allocate (nu(n), lambda(n), g(n), alpha(op%n_coarse()), e(n), pe(n), u(op%nlocal()))
    call hat%init(op, p%solver%rho_scale)
    sp = smalbe_settings(p%solver)
    sp%tol = 1.0e-10_dp
    sp%max_hessian = 200000
    sp%max_outer = 2000
    sp%monitor = .false.
    call solver%init_with(sp, max(op%norm_pfp(), hat%rho)/hat%scale)
    nu = 0
    call solver%solve(hat, nu)
    call assert_true(solver%converged(), label//': SMALBE converged: '//trim(solver%message), HERE)
    muhat = hat%scale*solver%muhat
    lambda = nu + op%lambda_tilde_vector()
    call dual_gradient(op, lambda, g)
    call alpha_new(op, g, muhat, alpha)
    call op%primal(lambda, alpha, u)

    res = check_kkt(op, u, lambda)
    call copy_jump(op, u, jump, umax)
    ! copies of a Dirichlet node are not glued: two differ by <= 2 x its error
    call assert_true(jump <= max(res%gluing, 2*res%dirichlet)*umax*(1 + 1.0e-12_dp) + tiny(1.0_dp) .and. &
                     res%gluing*umax <= 2*jump*(1 + 1.0e-12_dp) + tiny(1.0_dp), &
                     label//': solved: gluing measure within [1, 2] x the largest copy difference', HERE)
    call assert_below(res%worst(), 1.0e-6_dp, label//': solved to 1e-10: every KKT residual <= 1e-6', HERE)

    ! the gluing row with the largest force on the lowest rank that has one
    pick = 0
    lmax = 0
    kind = op%row_kind()
    do i = 1, n
      if (kind(i) == row_gluing .and. abs(lambda(i)) >= lmax) then
        pick = i
        lmax = abs(lambda(i))
      end if
    end do
    mine = merge(rank, huge(1), pick > 0)
    call MPI_Allreduce(mine, owner, 1, MPI_INTEGER, MPI_MIN, MPI_COMM_WORLD, ierr)
    lmine = lmax
    call MPI_Allreduce(lmine, lmax, 1, MPI_DOUBLE_PRECISION, MPI_MAX, MPI_COMM_WORLD, ierr)
    e = 0
    if (rank == owner) e(pick) = 1
    call op%project(e, pe)
    ! a self-equilibrated change of the interface forces of 1e-3 of the largest one
    delta = 1.0e-3_dp*lmax
    lambda = lambda + delta*pe
    call op%primal(lambda, alpha, u)
    res = check_kkt(op, u, lambda)
    call copy_jump(op, u, jump, umax)
    call assert_true(jump/umax > 1.0e-5_dp, label//': the perturbation makes the copies jump (> 1e-5 U)', HERE)
    call assert_true(jump <= max(res%gluing, 2*res%dirichlet)*umax*(1 + 1.0e-12_dp) .and. &
                     res%gluing*umax <= 2*jump*(1 + 1.0e-12_dp), &
                     label//': perturbed: gluing measure within [1, 2] x the largest copy difference', HERE)
    call assert_true(res%worst() > 1.0e-5_dp, label//': perturbed: the check fails at a threshold of 1e-5', HERE)
    call assert_below(res%equilibrium, 1.0e-6_dp, label//': perturbed: equilibrium still holds (P e_i)', HERE)
    call solver%free()
    call hat%free()
    call op%free()
  end subroutine check_case

  !> The largest difference between the copies of any node component, and
  !> max |u|, computed from all copies gathered on rank 0 (sorted by key
  !> 3*node + component) and broadcast.
  subroutine copy_jump(op, u, jump, umax)
    type(feti_t), intent(inout), target :: op
    type(local_field_t), intent(in) :: u(:)
    real(dp), intent(out) :: jump, umax
    integer(i8), allocatable :: keys(:), all_keys(:)
    real(dp), allocatable :: vals(:), all_vals(:)
    real(dp) :: lo, hi
    integer(ip) :: ls, a, c, k, m, i, j
    type(subdomain_t), pointer :: subs(:)
    subs => op%subdomains()
    m = 0
    do ls = 1, op%nlocal()
      m = m + 3*subs(ls)%nnodes
    end do
    allocate (keys(m), vals(m))
    k = 0
    do ls = 1, op%nlocal()
      do a = 1, subs(ls)%nnodes
        do c = 1, 3
          k = k + 1
          keys(k) = 3*int(subs(ls)%node_gid(a), i8) + (c - 1)
          vals(k) = u(ls)%v(3*(a - 1) + c)
        end do
      end do
    end do
    call gather_keyed(MPI_COMM_WORLD, keys, vals, all_keys, all_vals)
    jump = 0
    umax = 0
    if (rank == 0) then
      umax = maxval(abs(all_vals))
      i = 1
      do while (i <= size(all_keys))
        j = i
        do while (j < size(all_keys))
          if (all_keys(j + 1) /= all_keys(i)) exit
          j = j + 1
        end do
        lo = minval(all_vals(i:j))
        hi = maxval(all_vals(i:j))
        jump = max(jump, hi - lo)
        i = j + 1
      end do
    end if
    call MPI_Bcast(jump, 1, MPI_DOUBLE_PRECISION, 0, MPI_COMM_WORLD, ierr)
    call MPI_Bcast(umax, 1, MPI_DOUBLE_PRECISION, 0, MPI_COMM_WORLD, ierr)
  end subroutine copy_jump
end program test_kkt_check
