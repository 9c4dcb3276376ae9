!> Tolerances that follow from what a test compares, not from the rounding of
!> one CPU: two numerical paths to the same quantity (another summation order,
!> FMA or not, another BLAS kernel, another number of ranks, another
!> factorization) differ by a bound of the form (small constant) x eps x (a
!> condition number or a number of terms). Each test states which bound it uses.
module tolerances
  use kinds, only: dp
  implicit none
  private

  public :: eps, reorder_tol, solve_tol, drift_tol

  !> Unit round-off of real(dp) (2.2e-16).
  real(dp), parameter :: eps = epsilon(1.0_dp)

contains

  !> Two evaluations of a sum of n terms in different orders differ by at most
  !> 2 gamma_n ~ 2 n eps relative to the sum of the magnitudes of the terms
  !> (Higham, Accuracy and Stability of Numerical Algorithms, 2nd ed., Sec. 4.2).
  pure real(dp) function reorder_tol(n)
    integer, intent(in) :: n
    reorder_tol = 2*max(n, 1)*eps
  end function reorder_tol

  !> Two backward-stable solves of a system whose condition number is `cond`
  !> each have a relative forward error of about c eps cond; c = 100 covers the
  !> growth of sparse LDL^T / LU and of the condition estimate's error.
  pure real(dp) function solve_tol(cond)
    real(dp), intent(in) :: cond
    solve_tol = 100*eps*max(cond, 1.0_dp)
  end function solve_tol

  !> Round-off that a recursively updated quantity (a gradient g = A x - b
  !> carried through k steps) accumulates: each step adds about eps of its
  !> scale, so k steps add at most 10 k eps scale.
  pure real(dp) function drift_tol(k, scale)
    integer, intent(in) :: k
    real(dp), intent(in) :: scale
    drift_tol = 10*max(k, 1)*eps*scale
  end function drift_tol
end module tolerances
