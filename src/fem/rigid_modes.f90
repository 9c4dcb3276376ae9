!> The kernel of a floating subdomain's stiffness: rigid body modes.
module rigid_modes
  use kinds, only: dp, ip
  use errors, only: fatal_error
  implicit none
  private

  public :: rigid_body_modes, orthonormalize

contains

  !> r(3n, 6): translations x, y, z and rotations about the x, y, z axes
  !> through `centre`, of the n nodes at coords(3, n), orthonormalized.
  subroutine rigid_body_modes(coords, centre, r)
    real(dp), intent(in) :: coords(:, :), centre(3)
    real(dp), intent(out) :: r(:, :)
    integer(ip) :: a, n
    real(dp) :: d(3)
    n = size(coords, 2)
    if (size(r, 1) /= 3*n .or. size(r, 2) /= 6) call fatal_error('rigid_body_modes: r must be (3n, 6)')
    r = 0
    do a = 1, n
      d = coords(:, a) - centre
      r(3*a - 2, 1) = 1
      r(3*a - 1, 2) = 1
      r(3*a, 3) = 1
      ! rotation about x: (0, -dz, dy); about y: (dz, 0, -dx); about z: (-dy, dx, 0)
      r(3*a - 1, 4) = -d(3)
      r(3*a, 4) = d(2)
      r(3*a - 2, 5) = d(3)
      r(3*a, 5) = -d(1)
      r(3*a - 2, 6) = -d(2)
      r(3*a - 1, 6) = d(1)
    end do
    call orthonormalize(r)
  end subroutine rigid_body_modes

  !> Orthonormalize the columns of q in place (modified Gram-Schmidt, applied
  !> twice for orthogonality to round-off). Stops on (numerically) dependent columns.
  subroutine orthonormalize(q)
    real(dp), intent(inout) :: q(:, :)
    integer :: j, k, pass
    real(dp) :: nrm, nrm0
    do j = 1, size(q, 2)
      nrm0 = norm2(q(:, j))
      do pass = 1, 2
        do k = 1, j - 1
          q(:, j) = q(:, j) - dot_product(q(:, k), q(:, j))*q(:, k)
        end do
      end do
      nrm = norm2(q(:, j))
      if (.not. nrm > 1.0e-10_dp*nrm0) call fatal_error('orthonormalize: dependent columns')
      q(:, j) = q(:, j)/nrm
    end do
  end subroutine orthonormalize
end module rigid_modes
