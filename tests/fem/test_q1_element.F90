#include "assertions.h"
!> The Q1 element on a distorted hexahedron, against values derived here
!> independently: rigid modes in the kernel, exactly 6 zero eigenvalues,
!> patch test (K_e u for a linear field u = A x + b equals the nodal forces
!> of its constant stress, integral of sigma n N_a over the faces; the energy
!> u^T K_e u equals V eps:C:eps with V from the divergence theorem), face
!> integrals against the exact area, and stresses of known fields.
program test_q1_element
  use kinds, only: dp
  use q1_element, only: elasticity_matrix, q1_stiffness, q1_face_shape_integrals, q1_face_load, &
                        q1_centroid_stress, von_mises, q1_face_nodes
  use mpi_f08, only: MPI_Init
  use assertions, only: assert_true, assert_close, assert_below, test_finish
  implicit none
  ! faces with their corners ordered so that x_s x x_t points outward
  integer, parameter :: outward(4, 6) = reshape([1, 5, 8, 4, 2, 3, 7, 6, 1, 2, 6, 5, 4, 8, 7, 3, &
                                                 1, 4, 3, 2, 5, 6, 7, 8], [4, 6])
  real(dp), parameter :: young = 2.1e5_dp, poisson = 0.3_dp
  real(dp) :: x(3, 8), ke(24, 24), r(24, 6), kr(24, 6), amat(3, 3), bvec(3), u(24), f(24), eps(6), &
              sigma(6), stress(3, 3), flux(3, 8), vol, energy, d(6, 6), w(4), xf(3, 4), fe(3, 4), &
              area, eig(24), work(24*24), ks(24, 24), mu, lambda
  integer :: a, i, info, ierr

  call MPI_Init(ierr)
  ! a distorted, elongated hexahedron
  x = reshape([0.00_dp, 0.00_dp, 0.00_dp, 2.10_dp, 0.05_dp, -0.10_dp, 1.90_dp, 1.10_dp, 0.08_dp, &
               -0.15_dp, 0.95_dp, 0.02_dp, 0.07_dp, -0.04_dp, 0.70_dp, 2.00_dp, 0.10_dp, 0.85_dp, &
               2.20_dp, 0.90_dp, 0.75_dp, 0.10_dp, 1.05_dp, 0.80_dp], [3, 8])
  call q1_stiffness(x, young, poisson, ke)
  call assert_below(maxval(abs(ke - transpose(ke))), 1e-14_dp*maxval(abs(ke)), 'ke symmetric', HERE)

  ! rigid modes (about the origin, not orthonormalized) are in the kernel
  r = 0
  do a = 1, 8
    r(3*a - 2, 1) = 1
    r(3*a - 1, 2) = 1
    r(3*a, 3) = 1
    r(3*a - 2:3*a, 4) = [0.0_dp, -x(3, a), x(2, a)]
    r(3*a - 2:3*a, 5) = [x(3, a), 0.0_dp, -x(1, a)]
    r(3*a - 2:3*a, 6) = [-x(2, a), x(1, a), 0.0_dp]
  end do
  kr = matmul(ke, r)
  call assert_below(norm2(kr)/(norm2(ke)*norm2(r)), 1e-14_dp, 'K_e R = 0', HERE)

  ! exactly 6 zero eigenvalues
  ks = ke
  call dsyev('N', 'U', 24, ks, 24, eig, work, size(work), info)
  call assert_true(info == 0, 'dsyev', HERE)
  call assert_below(maxval(abs(eig(1:6))), 1e-12_dp*eig(24), '6 zero eigenvalues', HERE)
  call assert_true(eig(7) > 1e-3_dp*eig(24), 'eigenvalue 7 well above round-off', HERE)

  ! linear field u = A x + b
  amat = reshape([1.0_dp, 0.3_dp, -0.2_dp, 0.5_dp, -0.7_dp, 0.4_dp, 0.1_dp, 0.9_dp, 0.6_dp], [3, 3])*1e-3_dp
  bvec = [0.2_dp, -0.1_dp, 0.3_dp]
  do a = 1, 8
    u(3*a - 2:3*a) = matmul(amat, x(:, a)) + bvec
  end do
  ! its strain and stress, from Lame's law (independent of the Voigt matrix)
  lambda = young*poisson/((1 + poisson)*(1 - 2*poisson))
  mu = young/(2*(1 + poisson))
  stress = mu*(amat + transpose(amat))
  do i = 1, 3
    stress(i, i) = stress(i, i) + lambda*(amat(1, 1) + amat(2, 2) + amat(3, 3))
  end do
  eps = [amat(1, 1), amat(2, 2), amat(3, 3), amat(1, 2) + amat(2, 1), amat(2, 3) + amat(3, 2), &
         amat(1, 3) + amat(3, 1)]
  ! volume and flux(:, a) = integral over the boundary of N_a n dA (3x3 Gauss, exact here)
  call boundary_integrals(x, vol, flux)
  f = matmul(ke, u)
  do a = 1, 8
    call assert_below(maxval(abs(f(3*a - 2:3*a) - matmul(stress, flux(:, a)))), &
                      1e-10_dp*maxval(abs(stress))*vol, 'patch test: K_e u = nodal forces of sigma', HERE)
  end do
  energy = 0.5_dp*sum((stress)*(amat + transpose(amat)))*vol      ! sigma:eps V
  call assert_close(energy, dot_product(u, f), 1e-10_dp, 'energy u^T K_e u = V eps:C:eps', HERE)
  ! the Voigt matrix gives the same stress
  d = elasticity_matrix(young, poisson)
  sigma = matmul(d, eps)
  call assert_below(maxval(abs(sigma - [stress(1, 1), stress(2, 2), stress(3, 3), stress(1, 2), stress(2, 3), &
                                        stress(1, 3)])), 1e-9_dp*maxval(abs(stress)), 'elasticity matrix', HERE)
  ! centroid stress of the linear field
  call q1_centroid_stress(x, u, young, poisson, sigma)
  call assert_below(maxval(abs(sigma - [stress(1, 1), stress(2, 2), stress(3, 3), stress(1, 2), stress(2, 3), &
                                        stress(1, 3)])), 1e-9_dp*maxval(abs(stress)), 'centroid stress', HERE)

  ! uniaxial compression sigma_zz = -p: von Mises = p
  do a = 1, 8
    u(3*a - 2:3*a) = [poisson*x(1, a), poisson*x(2, a), -x(3, a)]*(50/young)
  end do
  call q1_centroid_stress(x, u, young, poisson, sigma)
  call assert_below(maxval(abs(sigma - [0, 0, -50, 0, 0, 0])), 1e-9_dp, 'uniaxial stress', HERE)
  call assert_close(50.0_dp, von_mises(sigma), 1e-10_dp, 'von Mises of uniaxial stress', HERE)
  call assert_close(sqrt(3.0_dp)*7, von_mises([0.0_dp, 0.0_dp, 0.0_dp, 0.0_dp, 7.0_dp, 0.0_dp]), 1e-14_dp, &
                    'von Mises of pure shear', HERE)

  ! face integrals: a planar skew quadrilateral (in a tilted plane)
  xf(:, 1) = [0.0_dp, 0.0_dp, 0.0_dp]
  xf(:, 2) = [1.0_dp, 0.1_dp, 0.0_dp]
  xf(:, 3) = [1.2_dp, 0.9_dp, 0.0_dp]
  xf(:, 4) = [0.1_dp, 1.0_dp, 0.0_dp]
  xf(3, :) = 0.3_dp*xf(1, :) - 0.2_dp*xf(2, :) + 1
  area = 0.5_dp*norm2(cross(xf(:, 3) - xf(:, 1), xf(:, 4) - xf(:, 2)))
  call q1_face_shape_integrals(xf, w)
  call assert_close(area, sum(w), 1e-14_dp, 'face: sum of shape integrals = area', HERE)
  call assert_true(all(w > 0), 'face: positive tributary areas', HERE)
  call q1_face_load(xf, [0.0_dp, 0.0_dp, -3.0_dp], fe)
  call assert_close(-3*area, sum(fe(3, :)), 1e-14_dp, 'face load total', HERE)
  ! a parallelogram: each node gets a quarter
  xf(:, 3) = xf(:, 2) + xf(:, 4) - xf(:, 1)
  area = norm2(cross(xf(:, 2) - xf(:, 1), xf(:, 4) - xf(:, 1)))
  call q1_face_shape_integrals(xf, w)
  call assert_below(maxval(abs(w - area/4)), 1e-15_dp, 'parallelogram: quarter each', HERE)
  ! the face node table lists the faces x0, x1, y0, y1, z0, z1
  call assert_true(all(q1_face_nodes(:, 5) == [1, 2, 3, 4]) .and. all(q1_face_nodes(:, 6) == [5, 6, 7, 8]), &
                   'z faces', HERE)
  do i = 1, 6
    call assert_true(all([(any(outward(:, i) == q1_face_nodes(a, i)), a=1, 4)]), 'face node sets', HERE)
  end do
  call test_finish()

contains

  pure function cross(p, q) result(c)
    real(dp), intent(in) :: p(3), q(3)
    real(dp) :: c(3)
    c = [p(2)*q(3) - p(3)*q(2), p(3)*q(1) - p(1)*q(3), p(1)*q(2) - p(2)*q(1)]
  end function cross

  !> V = 1/3 of the boundary integral of x.n, and flux(:,a) = boundary integral
  !> of N_a n, with 3x3 Gauss on every bilinear face (exact: polynomial integrands).
  subroutine boundary_integrals(x, vol, flux)
    real(dp), intent(in) :: x(3, 8)
    real(dp), intent(out) :: vol, flux(3, 8)
    real(dp), parameter :: g(3) = [-sqrt(0.6_dp), 0.0_dp, sqrt(0.6_dp)], gw(3) = [5, 8, 5]/9.0_dp
    real(dp), parameter :: s(4) = [-1, 1, 1, -1], t(4) = [-1, -1, 1, 1]
    real(dp) :: n(4), ns(4), nt(4), xf(3, 4), xp(3), xs(3), xt(3), nda(3)
    integer :: face, p, q, m
    vol = 0
    flux = 0
    do face = 1, 6
      xf = x(:, outward(:, face))
      do q = 1, 3
        do p = 1, 3
          n = (1 + s*g(p))*(1 + t*g(q))/4
          ns = s*(1 + t*g(q))/4
          nt = (1 + s*g(p))*t/4
          xp = matmul(xf, n)
          xs = matmul(xf, ns)
          xt = matmul(xf, nt)
          nda = cross(xs, xt)*gw(p)*gw(q)
          vol = vol + dot_product(xp, nda)/3
          do m = 1, 4
            flux(:, outward(m, face)) = flux(:, outward(m, face)) + n(m)*nda
          end do
        end do
      end do
    end do
  end subroutine boundary_integrals
end program test_q1_element
