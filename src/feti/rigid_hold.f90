!> Whether the Dirichlet, symmetry and contact rows hold the body against
!> every rigid motion: the rank of the six rigid modes (three translations,
!> three rotations) restricted to those rows, from the mesh and the obstacle
!> alone (which bottom nodes can touch), before any set-up work. A body
!> whose rows leave a rigid motion free has a singular coarse problem
!> G G^T = R^T B^T B R; run_checks refuses it as an input error.
module rigid_hold
  use kinds, only: dp, ip
  use mesh_settings, only: mesh_settings_t
  use boundary_settings, only: boundary_settings_t
  use obstacle_settings, only: obstacle_settings_t
  use lapack_interfaces, only: dsyev
  implicit none
  private

  public :: held_modes

  !> A rigid mode counts as held when its eigenvalue of the Gram matrix of
  !> the restricted modes exceeds this fraction of the largest.
  real(dp), parameter :: rank_tol = 1.0e-10_dp

contains

  !> The number of rigid modes (0..6) the constraint rows of the box `mesh`
  !> hold, and `contact_nodes`, the bottom nodes over the obstacle (the
  !> contact rows: for a sphere, the nodes within `radius` of its axis).
  subroutine held_modes(mesh, boundary, obstacle, nheld, contact_nodes)
    type(mesh_settings_t), intent(in) :: mesh
    type(boundary_settings_t), intent(in) :: boundary
    type(obstacle_settings_t), intent(in) :: obstacle
    integer, intent(out) :: nheld
    integer(ip), intent(out) :: contact_nodes
    real(dp) :: gram(6, 6), h(3), c(2), x(3), scale, w(6), work(64)
    integer(ip) :: ng(3), i, j, k
    integer :: info

    ng = mesh%nsub*mesh%nel
    h = mesh%lengths/real(ng, dp)
    c = obstacle%centre_of(mesh%lengths)
    scale = maxval(mesh%lengths)
    gram = 0
    contact_nodes = 0
    do j = 0, ng(2)
      do i = 0, ng(1)
        x = [node_x(i, 1), node_x(j, 2), 0.0_dp]
        if (.not. over_obstacle(x)) cycle
        contact_nodes = contact_nodes + 1
        call add_row(3, x)
      end do
    end do
    if (boundary%top_dirichlet) then      ! every component of the top face: all modes held
      do j = 0, ng(2), max(ng(2), 1_ip)
        do i = 0, ng(1), max(ng(1), 1_ip)
          x = [node_x(i, 1), node_x(j, 2), mesh%lengths(3)]
          call add_row(1, x)
          call add_row(2, x)
          call add_row(3, x)
        end do
      end do
    end if
    do k = 0, ng(3)
      do j = 0, ng(2)
        if (boundary%symmetry_x0) call add_row(1, [0.0_dp, node_x(j, 2), node_x(k, 3)])
      end do
      do i = 0, ng(1)
        if (boundary%symmetry_y0) call add_row(2, [node_x(i, 1), 0.0_dp, node_x(k, 3)])
      end do
    end do
    call dsyev('N', 'U', 6, gram, 6, w, work, size(work), info)
    nheld = 0
    if (info == 0 .and. maxval(w) > 0) nheld = count(w > rank_tol*maxval(w))
  contains
    !> The coordinate of grid line `i` in direction `d` (as box_mesh places boundary nodes).
    real(dp) function node_x(i, d)
      integer(ip), intent(in) :: i
      integer, intent(in) :: d
      node_x = real(i, dp)*h(d)
      if (i == ng(d)) node_x = mesh%lengths(d)
    end function node_x
    !> A bottom node at `x` gets a contact row (constraints' node_conditions).
    logical function over_obstacle(x)
      real(dp), intent(in) :: x(3)
      select case (obstacle%shape)
      case ('plane')
        over_obstacle = .true.
      case ('sphere')
        over_obstacle = (x(1) - c(1))**2 + (x(2) - c(2))**2 <= obstacle%radius**2
      case default
        over_obstacle = .false.
      end select
    end function over_obstacle
    !> Add the row of component `comp` at the node `x` to the Gram matrix of
    !> the restricted rigid modes (u = t + theta x (x - origin), lengths scaled).
    subroutine add_row(comp, x)
      integer, intent(in) :: comp
      real(dp), intent(in) :: x(3)
      real(dp) :: r(6), y(3)
      y = (x - mesh%lengths/2)/scale
      select case (comp)
      case (1)
        r = [1.0_dp, 0.0_dp, 0.0_dp, 0.0_dp, y(3), -y(2)]
      case (2)
        r = [0.0_dp, 1.0_dp, 0.0_dp, -y(3), 0.0_dp, y(1)]
      case default
        r = [0.0_dp, 0.0_dp, 1.0_dp, y(2), -y(1), 0.0_dp]
      end select
      gram = gram + spread(r, 2, 6)*spread(r, 1, 6)
    end subroutine add_row
  end subroutine held_modes
end module rigid_hold
