!> (Tests only.) Projected conjugate gradients for the dual of a problem without contact
!> rows (the classical FETI solver): min 1/2 l^T F l - l^T d  s.t.  G l = e,
!> started from lambda~ and kept in lambda~ + Im P. Then the rigid body
!> amplitudes alpha = (G G^T)^{-1} G (F lambda - d).
!>
!> With a preconditioner M^{-1} (dual_preconditioner: lumped or Dirichlet)
!> the search directions use z = P M^{-1} P r (r = P (d - F lambda) is in
!> Im P already, so one projection after M^{-1}); without, z = r. Optionally
!> the Ritz values of the run (ritz_values: the extreme eigenvalues of the
!> Lanczos matrix from the CG coefficients) estimate the condition number of
!> P M^{-1} P F on Im P (of P F P without preconditioner).
module pcpg
  use kinds, only: dp, ip
  use logger, only: log_message
  use feti_operators, only: feti_t
  use dual_preconditioner, only: dual_preconditioner_t
  use ritz_values, only: cg_ritz_t
  implicit none
  private

  public :: pcpg_solve

contains

  !> Solve to ||P (d - F lambda)|| <= tol ||P d||. Returns lambda (owned
  !> rows), alpha (local coarse blocks), the iteration count and whether it
  !> converged within max_iterations. `prec`: the preconditioner (none when
  !> absent); `ritz`: the Ritz values of the run (reset first).
  subroutine pcpg_solve(op, tol, max_iterations, lambda, alpha, iterations, converged, prec, ritz)
    type(feti_t), intent(inout) :: op
    real(dp), intent(in) :: tol
    integer(ip), intent(in) :: max_iterations
    real(dp), allocatable, intent(out) :: lambda(:), alpha(:)
    integer(ip), intent(out) :: iterations
    logical, intent(out) :: converged
    type(dual_preconditioner_t), intent(inout), optional :: prec
    type(cg_ritz_t), intent(inout), optional :: ritz
    real(dp), allocatable :: r(:), pdir(:), fp(:), w(:), pr(:), z(:)
    real(dp) :: rz, rz_new, rr, a, b, stop_norm
    integer(ip) :: n
    character(len=120) :: line

    n = op%n_own()
    allocate (lambda(n), r(n), pdir(n), fp(n), w(n), pr(n), z(n), alpha(op%n_coarse()))
    if (present(ritz)) then
      call ritz%reset()
      call ritz%begin_run()
    end if
    lambda = op%lambda_tilde_vector()
    call op%project(op%dual_rhs(), w)
    stop_norm = tol*op%norm(w)
    call op%apply_f(lambda, fp)
    w = op%dual_rhs() - fp
    call op%project(w, r)
    call precondition(r, z)
    pdir = z
    rz = op%dot(r, z)
    rr = op%dot(r, r)
    converged = sqrt(rr) <= stop_norm
    iterations = 0
    do while (.not. converged .and. iterations < max_iterations)
      iterations = iterations + 1
      call op%apply_f(pdir, fp)
      a = rz/op%dot(pdir, fp)
      if (present(ritz)) call ritz%add_alpha(a)
      lambda = lambda + a*pdir
      call op%project(fp, pr)
      r = r - a*pr
      rr = op%dot(r, r)
      converged = sqrt(rr) <= stop_norm
      if (converged) exit
      call precondition(r, z)
      rz_new = op%dot(r, z)
      b = rz_new/rz
      if (present(ritz)) call ritz%add_beta(b)
      pdir = z + b*pdir
      rz = rz_new
    end do
    if (present(ritz)) call ritz%end_run()
    write (line, '(a,i0,a,es10.3,a,l1)') 'PCPG: iterations ', iterations, ', ||P r|| ', sqrt(rr), &
      ', converged ', converged
    call log_message(line)
    if (present(prec)) call log_message('PCPG: preconditioner '//prec%kind())
    ! alpha = (G G^T)^{-1} G (F lambda - d)
    call op%apply_f(lambda, fp)
    w = fp - op%dual_rhs()
    deallocate (pr)
    allocate (pr(op%n_coarse()))
    call op%apply_g(w, pr)
    call op%coarse_solve(pr, alpha)

  contains

    !> zz = P M^{-1} rr (rr in Im P), or zz = rr without preconditioner.
    subroutine precondition(rr_in, zz)
      real(dp), intent(in) :: rr_in(:)
      real(dp), intent(inout) :: zz(:)
      if (present(prec)) then
        call prec%apply(rr_in, w)
        call op%project(w, zz)
      else
        zz = rr_in
      end if
    end subroutine precondition
  end subroutine pcpg_solve
end module pcpg
