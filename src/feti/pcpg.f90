!> Projected conjugate gradients for the dual of a problem without contact
!> rows (the classical FETI solver): min 1/2 l^T F l - l^T d  s.t.  G l = e,
!> started from lambda~ and kept in lambda~ + Im P. Then the rigid body
!> amplitudes alpha = (G G^T)^{-1} G (F lambda - d).
module pcpg
  use kinds, only: dp, ip
  use logger, only: log_message
  use feti_operators, only: feti_t
  implicit none
  private

  public :: pcpg_solve

contains

  !> Solve to ||P (d - F lambda)|| <= tol ||P d||. Returns lambda (owned
  !> rows), alpha (local coarse blocks), the iteration count and whether it
  !> converged within max_iterations.
  subroutine pcpg_solve(op, tol, max_iterations, lambda, alpha, iterations, converged)
    type(feti_t), intent(inout) :: op
    real(dp), intent(in) :: tol
    integer(ip), intent(in) :: max_iterations
    real(dp), allocatable, intent(out) :: lambda(:), alpha(:)
    integer(ip), intent(out) :: iterations
    logical, intent(out) :: converged
    real(dp), allocatable :: r(:), pdir(:), fp(:), w(:), pr(:)
    real(dp) :: rr, rr_new, a, stop_norm
    integer(ip) :: n
    character(len=120) :: line

    n = op%n_own()
    allocate (lambda(n), r(n), pdir(n), fp(n), w(n), pr(n), alpha(op%n_coarse()))
    lambda = op%lambda_tilde_vector()
    call op%project(op%dual_rhs(), w)
    stop_norm = tol*op%norm(w)
    call op%apply_f(lambda, fp)
    w = op%dual_rhs() - fp
    call op%project(w, r)
    pdir = r
    rr = op%dot(r, r)
    converged = sqrt(rr) <= stop_norm
    iterations = 0
    do while (.not. converged .and. iterations < max_iterations)
      iterations = iterations + 1
      call op%apply_f(pdir, fp)
      a = rr/op%dot(pdir, fp)
      lambda = lambda + a*pdir
      call op%project(fp, pr)
      r = r - a*pr
      rr_new = op%dot(r, r)
      converged = sqrt(rr_new) <= stop_norm
      pdir = r + (rr_new/rr)*pdir
      rr = rr_new
    end do
    write (line, '(a,i0,a,es10.3,a,l1)') 'PCPG: iterations ', iterations, ', ||P r|| ', sqrt(rr), &
      ', converged ', converged
    call log_message(line)
    ! alpha = (G G^T)^{-1} G (F lambda - d)
    call op%apply_f(lambda, fp)
    w = fp - op%dual_rhs()
    deallocate (pr)
    allocate (pr(op%n_coarse()))
    call op%apply_g(w, pr)
    call op%coarse_solve(pr, alpha)
  end subroutine pcpg_solve
end module pcpg
