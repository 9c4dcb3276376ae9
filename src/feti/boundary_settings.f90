!> The settings of the Dirichlet conditions (`&boundary`, docs/INPUT.md):
!> the prescribed top face and the symmetry planes, the one home of their
!> defaults and namelist variables (the check that the body is held against
!> every rigid motion involves &obstacle: params' check_params). Used by
!> constraints (the Dirichlet rows of B).
module boundary_settings
  use kinds, only: dp, name_len
  use settings_base, only: settings_t
  implicit none
  private

  type, extends(settings_t), public :: boundary_settings_t
    logical :: top_dirichlet = .true.  !< prescribe u on z = Lz
    real(dp) :: top_displacement(3) = [0.0_dp, 0.0_dp, -0.005_dp]  !< its value [mm]
    logical :: symmetry_x0 = .false.  !< u_x = 0 on x = 0
    logical :: symmetry_y0 = .false.  !< u_y = 0 on y = 0
  contains
    procedure :: check => boundary_settings_check
    procedure :: group => boundary_settings_group
    procedure :: variables => boundary_settings_variables
    procedure :: read_namelist => boundary_settings_read
    procedure :: write_namelist => boundary_settings_write
  end type boundary_settings_t

contains

  !> The first value out of its range: `variable` its name ('' if none),
  !> `rule` the allowed values, `got` the value(s).
  subroutine boundary_settings_check(self, variable, rule, got)
    class(boundary_settings_t), intent(in) :: self
    character(len=:), allocatable, intent(out) :: variable, rule, got
    variable = ''
    rule = ''
    got = ''
    ! every value is allowed (the checks across groups are params' check_params)
  end subroutine boundary_settings_check

  !> The namelist group of these variables.
  function boundary_settings_group(self) result(name)
    class(boundary_settings_t), intent(in) :: self
    character(len=:), allocatable :: name
    name = 'boundary'
  end function boundary_settings_group

  !> The names of the namelist variables (those of read_namelist).
  subroutine boundary_settings_variables(self, names)
    class(boundary_settings_t), intent(in) :: self
    character(len=name_len), allocatable, intent(out) :: names(:)
    names = [character(len=name_len) :: 'top_dirichlet', 'top_displacement', 'symmetry_x0', 'symmetry_y0']
  end subroutine boundary_settings_variables

  !> Read this component's variables from the group text `group`
  !> ('&boundary ... /').
  subroutine boundary_settings_read(self, group, status, msg)
    class(boundary_settings_t), intent(inout) :: self
    character(len=*), intent(in) :: group
    integer, intent(out) :: status
    character(len=*), intent(out) :: msg
    logical :: top_dirichlet, symmetry_x0, symmetry_y0
    real(dp) :: top_displacement(3)
    namelist /boundary/ top_dirichlet, top_displacement, symmetry_x0, symmetry_y0
    top_dirichlet = self%top_dirichlet; top_displacement = self%top_displacement
    symmetry_x0 = self%symmetry_x0; symmetry_y0 = self%symmetry_y0
    read (group, nml=boundary, iostat=status, iomsg=msg)
    if (status /= 0) return
    self%top_dirichlet = top_dirichlet; self%top_displacement = top_displacement
    self%symmetry_x0 = symmetry_x0; self%symmetry_y0 = symmetry_y0
  end subroutine boundary_settings_read

  !> Write this component's variables as the namelist '&boundary ... /' (strings quoted).
  subroutine boundary_settings_write(self, lines, status, msg)
    class(boundary_settings_t), intent(in) :: self
    character(len=*), intent(out) :: lines(:)
    integer, intent(out) :: status
    character(len=*), intent(out) :: msg
    logical :: top_dirichlet, symmetry_x0, symmetry_y0
    real(dp) :: top_displacement(3)
    namelist /boundary/ top_dirichlet, top_displacement, symmetry_x0, symmetry_y0
    top_dirichlet = self%top_dirichlet; top_displacement = self%top_displacement
    symmetry_x0 = self%symmetry_x0; symmetry_y0 = self%symmetry_y0
    lines = ''
    write (lines, nml=boundary, delim='quote', iostat=status, iomsg=msg)
  end subroutine boundary_settings_write
end module boundary_settings
