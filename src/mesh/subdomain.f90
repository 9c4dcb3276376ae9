!> One subdomain: its geometry (filled here, from the decomposition) and its
!> linear system K, f, R (filled by fem/assembly).
!>
!> Local node a <-> global node node_gid(a), node_gid ascending; the local dof
!> of node a, component c (1..3) is 3*(a-1) + c.
module subdomain
  use kinds, only: dp, ip
  use errors, only: fatal_error
  use csr_matrix, only: csr_t
  use decomposition, only: decomposition_t
  use sorting, only: sort_unique, binary_search
  implicit none
  private

  public :: build_subdomain, local_node, node_dofs, stiffness_matvec, stiffness_max_abs

  !> A subdomain and its system.
  type, public :: subdomain_t
    integer(ip) :: id = 0
    integer(ip) :: nnodes = 0, nelem = 0, ndof = 0      !< ndof = 3*nnodes
    integer(ip), allocatable :: node_gid(:)             !< ascending; local node a <-> node_gid(a)
    !> hybrid TFETI only (a cluster of subdomains, src/mesh/clusters.f90): the
    !> subdomain whose copy local node a is, 0 for a corner merged over the
    !> cluster; node_gid is then ascending but not unique. Unallocated otherwise.
    integer(ip), allocatable :: node_copy(:)
    real(dp), allocatable :: coords(:, :)               !< (3, nnodes)
    integer(ip), allocatable :: elem_gid(:)             !< (nelem), ascending
    integer(ip), allocatable :: elem_nodes(:, :)        !< (8, nelem) local node numbers, Q1 order
    real(dp) :: centroid(3) = 0                         !< mean of the node coordinates
    real(dp) :: young = 0, poisson = 0
    integer :: element = 1                              !< element formulation (fem's q1_element kinds; 1: Q1)
    type(csr_t) :: K                                    !< stiffness (full symmetric storage)
    !> K shared per class of congruent subdomains (subdomain_classes): 0 when
    !> K is this subdomain's own; else the local index of the subdomain whose
    !> K, times k_scale, is this one's (K^s = k_scale K^k_of, K unallocated).
    !> Read K through stiffness_matvec / stiffness_max_abs.
    integer(ip) :: k_of = 0
    real(dp) :: k_scale = 1
    real(dp), allocatable :: f(:)                       !< (ndof) load
    real(dp), allocatable :: R(:, :)                    !< (ndof, 6) orthonormal kernel basis
    !> hybrid TFETI glued by faces only: the cluster's gluing rows C (6 per
    !> face two of its subdomains share: Q_f^T (u^i - u^j) on the face's
    !> nodes, Q_f the face's orthonormal rigid modes); 0 rows otherwise. The
    !> cluster's K^+ solves with K restricted to C u = 0 (kplus).
    type(csr_t) :: C
    !> hybrid TFETI glued by faces only: Young's modulus of every element
    !> (its subdomain's); unallocated: `young` for all elements
    real(dp), allocatable :: elem_young(:)
  end type subdomain_t

contains

  !> The subdomain dofs of the local nodes `nodes`, node by node (dof of
  !> local node a, component c: 3*(a-1) + c).
  pure function node_dofs(nodes) result(dofs)
    integer(ip), intent(in) :: nodes(:)
    integer(ip) :: dofs(3*size(nodes))
    integer(ip) :: i, c
    do i = 1, size(nodes, kind=ip)
      do c = 1, 3
        dofs(3*(i - 1) + c) = 3*(nodes(i) - 1) + c
      end do
    end do
  end function node_dofs

  !> Geometry of subdomain `id` of `dec`: nodes, coordinates, elements, centroid.
  !> Work proportional to the size of the subdomain.
  subroutine build_subdomain(dec, id, sub)
    type(decomposition_t), intent(in) :: dec
    integer(ip), intent(in) :: id
    type(subdomain_t), intent(out) :: sub
    integer(ip) :: e, a, n, nodes(8)
    integer(ip), allocatable :: gids(:)

    if (id < 1 .or. id > dec%nsubdomains) call fatal_error('build_subdomain: no such subdomain id')
    sub%id = id
    sub%elem_gid = dec%subdomain_element_gids(id)
    sub%nelem = size(sub%elem_gid, kind=ip)
    allocate (gids(8*sub%nelem), sub%elem_nodes(8, sub%nelem))
    do e = 1, sub%nelem
      gids(8*(e - 1) + 1:8*e) = dec%mesh%element_nodes(sub%elem_gid(e))
    end do
    call sort_unique(gids, n)
    sub%nnodes = n
    sub%ndof = 3*n
    sub%node_gid = gids(1:n)
    allocate (sub%coords(3, n))
    do a = 1, n
      sub%coords(:, a) = dec%mesh%node_coords(sub%node_gid(a))
    end do
    sub%centroid = sum(sub%coords, dim=2)/real(n, dp)
    do e = 1, sub%nelem
      nodes = dec%mesh%element_nodes(sub%elem_gid(e))
      do a = 1, 8
        sub%elem_nodes(a, e) = binary_search(sub%node_gid, nodes(a))
      end do
    end do
  end subroutine build_subdomain

  !> y = K^s x of local subdomain `s` of `subs`, its own K or its class's
  !> (k_scale K^k_of).
  subroutine stiffness_matvec(subs, s, x, y)
    type(subdomain_t), intent(in) :: subs(:)
    integer(ip), intent(in) :: s
    real(dp), intent(in) :: x(:)
    real(dp), intent(out) :: y(:)
    if (subs(s)%k_of == 0) then
      call subs(s)%K%matvec(x, y)
    else
      call subs(subs(s)%k_of)%K%matvec(x, y)
      y = subs(s)%k_scale*y
    end if
  end subroutine stiffness_matvec

  !> max |K^s| of local subdomain `s` of `subs` (its own K or its class's).
  real(dp) function stiffness_max_abs(subs, s) result(amax)
    type(subdomain_t), intent(in) :: subs(:)
    integer(ip), intent(in) :: s
    if (subs(s)%k_of == 0) then
      amax = maxval(abs(subs(s)%K%values))
    else
      amax = subs(s)%k_scale*maxval(abs(subs(subs(s)%k_of)%K%values))
    end if
  end function stiffness_max_abs

  !> Local number of global node `gid` in `sub` (binary search), 0 if absent.
  pure integer(ip) function local_node(sub, gid)
    type(subdomain_t), intent(in) :: sub
    integer(ip), intent(in) :: gid
    local_node = binary_search(sub%node_gid, gid)
  end function local_node
end module subdomain
