!> The trilinear hexahedron (Q1, 8 nodes) of isotropic linear elasticity.
!>
!> Node order (reference coordinates): 1 (-,-,-) 2 (+,-,-) 3 (+,+,-) 4 (-,+,-),
!> 5..8 the same at +1, i.e. the mesh order (i,j,k) (i+1,j,k) (i+1,j+1,k) (i,j+1,k).
!> Element dof of node a, component c: 3*(a-1) + c. Voigt order of strains and
!> stresses: xx, yy, zz, xy, yz, zx, with engineering shear strains (2 eps_xy).
!> Two element formulations on the same nodes (chosen once at set-up by an
!> integer kind, `element_q1` or `element_q1_bbar`):
!> - Q1: full 2x2x2 Gauss quadrature of B^T D B (locks as nu -> 1/2);
!> - Q1 B-bar (mean dilatation, Q1/P0): the deviatoric part 2 mu dev(eps) at
!>   the 2x2x2 points, the volumetric part with the element's mean dilatation
!>   (1/V) integral of div u, i.e. one constant pressure per element condensed
!>   out (docs/THEORY.md "The element").
!> 2x2 Gauss on faces.
module q1_element
  use kinds, only: dp, ip
  use errors, only: fatal_error
  implicit none
  private

  public :: elasticity_matrix, q1_shape, q1_gradients, q1_stiffness, q1_face_shape_integrals, &
            q1_face_load, q1_centroid_stress, q1_centroid_strain, von_mises, q1_bbar_stiffness, &
            q1_bbar_centroid_stress, element_stiffness, element_centroid_stress

  !> Element formulations (kinds): fully integrated Q1, Q1 B-bar (mean dilatation).
  integer, parameter, public :: element_q1 = 1, element_q1_bbar = 2

  !> Local nodes of the 6 element faces, ordered around each face; faces in the
  !> order of box_mesh: x0, x1, y0, y1, z0, z1 (z0 = nodes 1..4, z1 = 5..8).
  integer(ip), parameter, public :: q1_face_nodes(4, 6) = reshape([1, 4, 8, 5, 2, 3, 7, 6, &
                                                                    1, 2, 6, 5, 4, 3, 7, 8, &
                                                                    1, 2, 3, 4, 5, 6, 7, 8], [4, 6])

  real(dp), parameter :: ref(3, 8) = reshape([-1, -1, -1, 1, -1, -1, 1, 1, -1, -1, 1, -1, &
                                              -1, -1, 1, 1, -1, 1, 1, 1, 1, -1, 1, 1], [3, 8])
  real(dp), parameter :: gauss = 0.577350269189625764509148780502_dp   ! 1/sqrt(3)

contains

  !> Lame's parameters lambda, mu of Young's modulus and Poisson's ratio.
  pure subroutine lame(young, poisson, lambda, mu)
    real(dp), intent(in) :: young, poisson
    real(dp), intent(out) :: lambda, mu
    lambda = young*poisson/((1 + poisson)*(1 - 2*poisson))
    mu = young/(2*(1 + poisson))
  end subroutine lame

  !> Isotropic elasticity matrix D (6x6, Voigt order above).
  pure function elasticity_matrix(young, poisson) result(d)
    real(dp), intent(in) :: young, poisson
    real(dp) :: d(6, 6), lambda, mu
    integer :: i
    call lame(young, poisson, lambda, mu)
    d = 0
    d(1:3, 1:3) = lambda
    do i = 1, 3
      d(i, i) = lambda + 2*mu
      d(i + 3, i + 3) = mu
    end do
  end function elasticity_matrix

  !> Shape functions n(8) and their reference derivatives dn(8,3) at xi(3).
  pure subroutine q1_shape(xi, n, dn)
    real(dp), intent(in) :: xi(3)
    real(dp), intent(out) :: n(8), dn(8, 3)
    real(dp) :: f(3)
    integer :: a
    do a = 1, 8
      f = 1 + ref(:, a)*xi
      n(a) = f(1)*f(2)*f(3)/8
      dn(a, 1) = ref(1, a)*f(2)*f(3)/8
      dn(a, 2) = f(1)*ref(2, a)*f(3)/8
      dn(a, 3) = f(1)*f(2)*ref(3, a)/8
    end do
  end subroutine q1_shape

  !> Physical gradients g(8,3) = dN_a/dx_i and det J at reference point xi,
  !> for node coordinates x(3,8). Stops on a non-positive Jacobian.
  subroutine q1_gradients(x, xi, g, detj)
    real(dp), intent(in) :: x(3, 8), xi(3)
    real(dp), intent(out) :: g(8, 3), detj
    real(dp) :: n(8), dn(8, 3), jac(3, 3), inv(3, 3)
    call q1_shape(xi, n, dn)
    jac = matmul(x, dn)                       ! jac(i,j) = dx_i/dxi_j
    inv(1, 1) = jac(2, 2)*jac(3, 3) - jac(2, 3)*jac(3, 2)
    inv(1, 2) = jac(1, 3)*jac(3, 2) - jac(1, 2)*jac(3, 3)
    inv(1, 3) = jac(1, 2)*jac(2, 3) - jac(1, 3)*jac(2, 2)
    inv(2, 1) = jac(2, 3)*jac(3, 1) - jac(2, 1)*jac(3, 3)
    inv(2, 2) = jac(1, 1)*jac(3, 3) - jac(1, 3)*jac(3, 1)
    inv(2, 3) = jac(1, 3)*jac(2, 1) - jac(1, 1)*jac(2, 3)
    inv(3, 1) = jac(2, 1)*jac(3, 2) - jac(2, 2)*jac(3, 1)
    inv(3, 2) = jac(1, 2)*jac(3, 1) - jac(1, 1)*jac(3, 2)
    inv(3, 3) = jac(1, 1)*jac(2, 2) - jac(1, 2)*jac(2, 1)
    detj = jac(1, 1)*inv(1, 1) + jac(1, 2)*inv(2, 1) + jac(1, 3)*inv(3, 1)
    if (.not. detj > 0) call fatal_error('q1_gradients: element with a non-positive Jacobian '// &
                                         '(mesh too distorted or inverted)')
    inv = inv/detj                            ! inv(j,i) = dxi_j/dx_i
    g = matmul(dn, inv)
  end subroutine q1_gradients

  !> Strain-displacement matrix b(6,24) from gradients g(8,3).
  pure subroutine strain_matrix(g, b)
    real(dp), intent(in) :: g(8, 3)
    real(dp), intent(out) :: b(6, 24)
    integer :: a, c
    b = 0
    do a = 1, 8
      c = 3*(a - 1)
      b(1, c + 1) = g(a, 1)
      b(2, c + 2) = g(a, 2)
      b(3, c + 3) = g(a, 3)
      b(4, c + 1) = g(a, 2)
      b(4, c + 2) = g(a, 1)
      b(5, c + 2) = g(a, 3)
      b(5, c + 3) = g(a, 2)
      b(6, c + 1) = g(a, 3)
      b(6, c + 3) = g(a, 1)
    end do
  end subroutine strain_matrix

  !> Element stiffness ke(24,24) of the element with node coordinates x(3,8).
  !>
  !> B^T D B of isotropic elasticity per node pair (a, b) and Gauss point, in
  !> closed form: with g_a = grad N_a,
  !>
  !>     (K_ab)_ij = lambda g_a,i g_b,j + mu g_a,j g_b,i + mu delta_ij g_a . g_b,
  !>
  !> which is the product of the strain matrices B_a^T D B_b written out (the
  !> zeros of B and the structure of D skipped: about 12x fewer flops than the
  !> dense 24x6x24 product per point). Only the blocks with a <= b are formed;
  !> the lower ones are their transposes, so K_e is exactly symmetric.
  subroutine q1_stiffness(x, young, poisson, ke)
    real(dp), intent(in) :: x(3, 8), young, poisson
    real(dp), intent(out) :: ke(24, 24)
    real(dp) :: lam, mu, gvol(8, 3), vol
    call lame(young, poisson, lam, mu)
    call gauss_stiffness(x, lam, mu, ke, gvol, vol)
  end subroutine q1_stiffness

  !> The B-bar (mean dilatation) stiffness ke(24,24): the deviatoric energy
  !> 2 mu dev(eps):dev(eps) at the 2x2x2 points, i.e. the closed form above
  !> with lambda replaced by -2 mu / 3, plus the volumetric energy of the
  !> element's mean dilatation theta = (1/V) integral div u = gbar . u_e,
  !>
  !>     K_e = K_dev + kappa V gbar gbar^T,   kappa = lambda + 2 mu / 3,
  !>
  !> gbar(a,i) = (1/V) integral dN_a/dx_i. This is Q1 with one constant
  !> pressure per element eliminated (Q1/P0): the incompressibility is one
  !> constraint per element instead of eight, so the element does not lock.
  !> The kernel is that of Q1 (the rigid modes; pfunit_fem_q1_element).
  subroutine q1_bbar_stiffness(x, young, poisson, ke)
    real(dp), intent(in) :: x(3, 8), young, poisson
    real(dp), intent(out) :: ke(24, 24)
    real(dp) :: lam, mu, kappa, gvol(8, 3), vol, sg(8, 3)
    integer :: a, b, i, j
    call lame(young, poisson, lam, mu)
    call gauss_stiffness(x, -2*mu/3, mu, ke, gvol, vol)
    kappa = lam + 2*mu/3
    ! kappa V gbar gbar^T = sg sg^T with sg = sqrt(kappa / V) gvol (exactly symmetric)
    sg = sqrt(kappa/vol)*gvol
    do b = 1, 8
      do j = 1, 3
        do a = 1, 8
          do i = 1, 3
            ke(3*(a - 1) + i, 3*(b - 1) + j) = ke(3*(a - 1) + i, 3*(b - 1) + j) + sg(a, i)*sg(b, j)
          end do
        end do
      end do
    end do
  end subroutine q1_bbar_stiffness

  !> The stiffness of element kind `kind` (element_q1, element_q1_bbar).
  subroutine element_stiffness(kind, x, young, poisson, ke)
    integer, intent(in) :: kind
    real(dp), intent(in) :: x(3, 8), young, poisson
    real(dp), intent(out) :: ke(24, 24)
    select case (kind)
    case (element_q1)
      call q1_stiffness(x, young, poisson, ke)
    case (element_q1_bbar)
      call q1_bbar_stiffness(x, young, poisson, ke)
    case default
      call fatal_error('element_stiffness: unknown element kind')
    end select
  end subroutine element_stiffness

  !> The closed form above summed over the 2x2x2 Gauss points with the
  !> coefficients lam (of g_a,i g_b,j) and mu; also gvol(a,i) = integral of
  !> dN_a/dx_i and the volume vol (the same quadrature, exact for them).
  subroutine gauss_stiffness(x, lam, mu, ke, gvol, vol)
    real(dp), intent(in) :: x(3, 8), lam, mu
    real(dp), intent(out) :: ke(24, 24), gvol(8, 3), vol
    real(dp) :: g(8, 3), detj, lg(8, 3), mg(8, 3), dot, blk(3, 3)
    integer :: p, q, r, a, b, i, j, ra, rb
    ke = 0
    gvol = 0
    vol = 0
    do r = -1, 1, 2
      do q = -1, 1, 2
        do p = -1, 1, 2
          call q1_gradients(x, gauss*[p, q, r], g, detj)
          gvol = gvol + detj*g
          vol = vol + detj
          lg = (lam*detj)*g
          mg = (mu*detj)*g
          do b = 1, 8
            rb = 3*(b - 1)
            do a = 1, b
              ra = 3*(a - 1)
              dot = mg(a, 1)*g(b, 1) + mg(a, 2)*g(b, 2) + mg(a, 3)*g(b, 3)
              do j = 1, 3
                do i = 1, 3
                  blk(i, j) = lg(a, i)*g(b, j) + mg(a, j)*g(b, i)
                end do
                blk(j, j) = blk(j, j) + dot
              end do
              ke(ra + 1:ra + 3, rb + 1:rb + 3) = ke(ra + 1:ra + 3, rb + 1:rb + 3) + blk
            end do
          end do
        end do
      end do
    end do
    ! the lower blocks (a > b) are the transposes of the upper ones
    do b = 1, 8
      rb = 3*(b - 1)
      do a = b + 1, 8
        ra = 3*(a - 1)
        ke(ra + 1:ra + 3, rb + 1:rb + 3) = transpose(ke(rb + 1:rb + 3, ra + 1:ra + 3))
      end do
    end do
  end subroutine gauss_stiffness

  !> Integrals w(4) of the 4 (bilinear) shape functions over a quadrilateral
  !> face with corners xf(3,4) in cyclic order: the tributary areas of its nodes.
  pure subroutine q1_face_shape_integrals(xf, w)
    real(dp), intent(in) :: xf(3, 4)
    real(dp), intent(out) :: w(4)
    real(dp), parameter :: s(4) = [-1, 1, 1, -1], t(4) = [-1, -1, 1, 1]
    real(dp) :: n(4), ns(4), nt(4), xs(3), xt(3), nrm(3), da
    integer :: p, q, a
    w = 0
    do q = -1, 1, 2
      do p = -1, 1, 2
        do a = 1, 4
          n(a) = (1 + s(a)*gauss*p)*(1 + t(a)*gauss*q)/4
          ns(a) = s(a)*(1 + t(a)*gauss*q)/4
          nt(a) = (1 + s(a)*gauss*p)*t(a)/4
        end do
        xs = matmul(xf, ns)
        xt = matmul(xf, nt)
        nrm = [xs(2)*xt(3) - xs(3)*xt(2), xs(3)*xt(1) - xs(1)*xt(3), xs(1)*xt(2) - xs(2)*xt(1)]
        da = norm2(nrm)
        w = w + n*da
      end do
    end do
  end subroutine q1_face_shape_integrals

  !> Consistent nodal forces fe(3,4) of a uniform traction t(3) (force per
  !> area) on the face with corners xf(3,4): fe(:,a) = t * integral of N_a.
  pure subroutine q1_face_load(xf, traction, fe)
    real(dp), intent(in) :: xf(3, 4), traction(3)
    real(dp), intent(out) :: fe(3, 4)
    real(dp) :: w(4)
    integer :: a
    call q1_face_shape_integrals(xf, w)
    do a = 1, 4
      fe(:, a) = traction*w(a)
    end do
  end subroutine q1_face_load

  !> Stress sigma(6) (Voigt order) at the element centroid (xi = 0) for the
  !> element displacements u(24).
  subroutine q1_centroid_stress(x, u, young, poisson, sigma)
    real(dp), intent(in) :: x(3, 8), u(24), young, poisson
    real(dp), intent(out) :: sigma(6)
    real(dp) :: g(8, 3), b(6, 24), detj
    call q1_gradients(x, [0.0_dp, 0.0_dp, 0.0_dp], g, detj)
    call strain_matrix(g, b)
    sigma = matmul(elasticity_matrix(young, poisson), matmul(b, u))
  end subroutine q1_centroid_stress

  !> Strain eps(6) (Voigt order, engineering shear strains) at the centroid of
  !> the element with node coordinates x(3,8) and displacements u(24).
  subroutine q1_centroid_strain(x, u, eps)
    real(dp), intent(in) :: x(3, 8), u(24)
    real(dp), intent(out) :: eps(6)
    real(dp) :: g(8, 3), b(6, 24), detj
    call q1_gradients(x, [0.0_dp, 0.0_dp, 0.0_dp], g, detj)
    call strain_matrix(g, b)
    eps = matmul(b, u)
  end subroutine q1_centroid_strain

  !> The B-bar element's stress sigma(6) at the centroid: the strain of the
  !> element's split, dev(eps(0)) + theta/3 I with theta the mean dilatation,
  !> times D: sigma = 2 mu dev(eps(0)) + kappa theta I. Its deviatoric part
  !> (hence von Mises) is Q1's at the centroid; its pressure is the element's
  !> condensed pressure -kappa theta.
  subroutine q1_bbar_centroid_stress(x, u, young, poisson, sigma)
    real(dp), intent(in) :: x(3, 8), u(24), young, poisson
    real(dp), intent(out) :: sigma(6)
    real(dp) :: g(8, 3), b(6, 24), detj, eps(6), gvol(8, 3), vol, theta
    integer :: p, q, r, a
    gvol = 0
    vol = 0
    do r = -1, 1, 2
      do q = -1, 1, 2
        do p = -1, 1, 2
          call q1_gradients(x, gauss*[p, q, r], g, detj)
          gvol = gvol + detj*g
          vol = vol + detj
        end do
      end do
    end do
    theta = 0
    do a = 1, 8
      theta = theta + dot_product(gvol(a, :), u(3*a - 2:3*a))
    end do
    theta = theta/vol
    call q1_gradients(x, [0.0_dp, 0.0_dp, 0.0_dp], g, detj)
    call strain_matrix(g, b)
    eps = matmul(b, u)
    eps(1:3) = eps(1:3) + (theta - sum(eps(1:3)))/3
    sigma = matmul(elasticity_matrix(young, poisson), eps)
  end subroutine q1_bbar_centroid_stress

  !> The centroid stress of element kind `kind`.
  subroutine element_centroid_stress(kind, x, u, young, poisson, sigma)
    integer, intent(in) :: kind
    real(dp), intent(in) :: x(3, 8), u(24), young, poisson
    real(dp), intent(out) :: sigma(6)
    select case (kind)
    case (element_q1)
      call q1_centroid_stress(x, u, young, poisson, sigma)
    case (element_q1_bbar)
      call q1_bbar_centroid_stress(x, u, young, poisson, sigma)
    case default
      call fatal_error('element_centroid_stress: unknown element kind')
    end select
  end subroutine element_centroid_stress

  !> Von Mises equivalent stress of sigma(6) (Voigt order).
  pure real(dp) function von_mises(sigma)
    real(dp), intent(in) :: sigma(6)
    von_mises = sqrt(((sigma(1) - sigma(2))**2 + (sigma(2) - sigma(3))**2 + (sigma(3) - sigma(1))**2)/2 + &
                     3*(sigma(4)**2 + sigma(5)**2 + sigma(6)**2))
  end function von_mises
end module q1_element
