!> What the contact face looks like at the solution: the pressure of each
!> owned contact row (force / tributary area of its node on the face z = 0),
!> the total force, the largest pressure, the active nodes (contact rows with
!> a force above &reconstruction active_tol times the largest, the same rows
!> as the standard reconstruction's active set) and the contact radius (the
!> farthest active node from the obstacle's axis, by default x = y = lengths/2).
module contact_summary
  use kinds, only: dp, ip, MPI_REAL_DP
  use box_mesh, only: box_mesh_t
  use feti_operators, only: feti_t
  use reconstruction, only: active_contact_mask
  use mpi_f08, only: MPI_Allreduce, MPI_SUM, MPI_MAX
  implicit none
  private

  public :: summarize_contact

  type, public :: contact_summary_t
    real(dp) :: total_force = 0, max_pressure = 0, contact_radius = 0
    integer(ip) :: active_nodes = 0
    real(dp), allocatable :: pressure(:)     !< (n_own) pressure of each owned row, 0 off contact
  end type contact_summary_t

contains

  !> The summary of the multipliers `lambda` of `op`; `axis`: the obstacle's
  !> axis (x, y) the contact radius is measured from (default the face
  !> centre). Collective.
  subroutine summarize_contact(op, lambda, active_tol, summary, axis)
    type(feti_t), intent(inout) :: op
    real(dp), intent(in) :: lambda(:)
    real(dp), intent(in) :: active_tol
    type(contact_summary_t), intent(out) :: summary
    real(dp), intent(in), optional :: axis(2)
    type(box_mesh_t) :: mesh
    logical, allocatable :: contact(:), active(:)
    real(dp), allocatable :: force(:), x(:, :)
    integer(ip), allocatable :: gid(:)
    real(dp) :: mine(3), total(3), area, c(2)
    integer(ip) :: i, ijk(3)
    integer :: ierr

    mesh = op%mesh()
    c = mesh%lengths(1:2)/2
    if (present(axis)) c = axis
    contact = op%is_contact()
    force = op%force_scale()*lambda
    gid = op%row_node_gid()
    x = op%row_coordinates()
    allocate (summary%pressure(size(lambda)), active(size(lambda)))
    call active_contact_mask(op, lambda, active_tol, active, summary%active_nodes)
    summary%pressure = 0
    mine = 0
    do i = 1, size(lambda, kind=ip)
      if (.not. contact(i)) cycle
      ijk = mesh%node_ijk(gid(i))
      area = mesh%h(1)*mesh%h(2)
      if (ijk(1) == 0 .or. ijk(1) == mesh%ng(1)) area = area/2
      if (ijk(2) == 0 .or. ijk(2) == mesh%ng(2)) area = area/2
      summary%pressure(i) = force(i)/area
      mine(1) = mine(1) + force(i)
      mine(2) = max(mine(2), summary%pressure(i))
      if (active(i)) mine(3) = max(mine(3), sqrt((x(1, i) - c(1))**2 + (x(2, i) - c(2))**2))
    end do
    call MPI_Allreduce(mine(1), total(1), 1, MPI_REAL_DP, MPI_SUM, op%comm(), ierr)
    call MPI_Allreduce(mine(2:3), total(2:3), 2, MPI_REAL_DP, MPI_MAX, op%comm(), ierr)
    summary%total_force = total(1)
    summary%max_pressure = total(2)
    summary%contact_radius = total(3)
  end subroutine summarize_contact
end module contact_summary
