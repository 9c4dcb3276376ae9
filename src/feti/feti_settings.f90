!> The settings the FETI operators are built from, each owned by its
!> component (mesh, material, load, the constraints' boundary, obstacle and
!> row scaling, the local solver, the F action, the coarse problem): what
!> feti_t%setup receives instead of the whole input (params hands them over,
!> params::feti_settings_of).
module feti_settings
  use mesh_settings, only: mesh_settings_t
  use materials, only: material_settings_t
  use assembly, only: load_settings_t
  use boundary_settings, only: boundary_settings_t
  use obstacle_settings, only: obstacle_settings_t
  use scaling_settings, only: scaling_settings_t
  use local_settings, only: local_settings_t
  use f_action_settings, only: f_action_settings_t
  use coarse_settings, only: coarse_settings_t
  implicit none
  private

  type, public :: feti_settings_t
    type(mesh_settings_t) :: mesh              !< &mesh
    type(material_settings_t) :: material      !< &material
    type(load_settings_t) :: load              !< &load
    type(boundary_settings_t) :: boundary      !< &boundary: the Dirichlet rows of B
    type(obstacle_settings_t) :: obstacle      !< &obstacle: the contact rows of B
    type(scaling_settings_t) :: scaling        !< &solver scaling: the row weights of B
    type(local_settings_t) :: local            !< &solver: the local solver K^+
    type(f_action_settings_t) :: f_action      !< &solver: the F action, the ||P F P|| estimate
    type(coarse_settings_t) :: coarse          !< &solver: the coarse problem
  end type feti_settings_t
end module feti_settings
