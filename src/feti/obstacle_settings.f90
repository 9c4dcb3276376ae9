!> The settings of the rigid obstacle (`&obstacle`, docs/INPUT.md): its
!> shape, radius, initial gap and the position of its axis, the one home of
!> their defaults, ranges and namelist variables (the gap against the body's
!> height and the axis against the symmetry planes are params' checks).
!> Used by constraints (the contact rows of B and the gaps).
module obstacle_settings
  use kinds, only: dp, name_len
  use text, only: lower_case, reals_text
  use settings_base, only: settings_t, refuse
  implicit none
  private

  !> &obstacle axis not given: the face centre, resolved at start (centre_of)
  real(dp), parameter, public :: unset_axis = -huge(1.0_dp)

  type, extends(settings_t), public :: obstacle_settings_t
    character(len=name_len) :: shape = 'sphere'  !< 'sphere' | 'plane' | 'none'
    real(dp) :: radius = 1  !< sphere radius [mm]
    real(dp) :: gap = 0  !< initial gap below z = 0 [mm]
    !> the sphere's axis (x, y) in the bottom plane [mm]; unset_axis: the face centre (Lx/2, Ly/2)
    real(dp) :: axis(2) = unset_axis
    logical :: mirror_images = .false.  !< symmetry planes off the axis model mirror images of the obstacle
  contains
    procedure :: check => obstacle_settings_check
    procedure :: group => obstacle_settings_group
    procedure :: variables => obstacle_settings_variables
    procedure :: read_namelist => obstacle_settings_read
    procedure :: write_namelist => obstacle_settings_write
    procedure :: centre_of => obstacle_centre_of
  end type obstacle_settings_t

contains

  !> The first value out of its range: `variable` its name ('' if none),
  !> `rule` the allowed values, `got` the value(s).
  subroutine obstacle_settings_check(self, variable, rule, got)
    class(obstacle_settings_t), intent(in) :: self
    character(len=:), allocatable, intent(out) :: variable, rule, got
    variable = ''
    rule = ''
    got = ''
    if (.not. any(self%shape == [character(len=8) :: 'sphere', 'plane', 'none'])) then
      call refuse('shape', "must be 'sphere', 'plane' or 'none'", self%shape, variable, rule, got)
    else if (self%radius <= 0) then
      call refuse('radius', 'must be > 0', reals_text([self%radius]), variable, rule, got)
    end if
  end subroutine obstacle_settings_check

  !> The namelist group of these variables.
  function obstacle_settings_group(self) result(name)
    class(obstacle_settings_t), intent(in) :: self
    character(len=:), allocatable :: name
    name = 'obstacle'
  end function obstacle_settings_group

  !> The names of the namelist variables (those of read_namelist).
  subroutine obstacle_settings_variables(self, names)
    class(obstacle_settings_t), intent(in) :: self
    character(len=name_len), allocatable, intent(out) :: names(:)
    names = [character(len=name_len) :: 'shape', 'radius', 'gap', 'axis', 'mirror_images']
  end subroutine obstacle_settings_variables

  !> Read this component's variables from the group text `group`
  !> ('&obstacle ... /'); strings lower case.
  subroutine obstacle_settings_read(self, group, status, msg)
    class(obstacle_settings_t), intent(inout) :: self
    character(len=*), intent(in) :: group
    integer, intent(out) :: status
    character(len=*), intent(out) :: msg
    character(len=name_len) :: shape
    real(dp) :: radius, gap, axis(2)
    logical :: mirror_images
    namelist /obstacle/ shape, radius, gap, axis, mirror_images
    shape = self%shape; radius = self%radius; gap = self%gap
    axis = self%axis; mirror_images = self%mirror_images
    read (group, nml=obstacle, iostat=status, iomsg=msg)
    if (status /= 0) return
    self%shape = lower_case(shape); self%radius = radius; self%gap = gap
    self%axis = axis; self%mirror_images = mirror_images
  end subroutine obstacle_settings_read

  !> Write this component's variables as the namelist '&obstacle ... /' (strings quoted).
  subroutine obstacle_settings_write(self, lines, status, msg)
    class(obstacle_settings_t), intent(in) :: self
    character(len=*), intent(out) :: lines(:)
    integer, intent(out) :: status
    character(len=*), intent(out) :: msg
    character(len=name_len) :: shape
    real(dp) :: radius, gap, axis(2)
    logical :: mirror_images
    namelist /obstacle/ shape, radius, gap, axis, mirror_images
    shape = self%shape; radius = self%radius; gap = self%gap
    axis = self%axis; mirror_images = self%mirror_images
    lines = ''
    write (lines, nml=obstacle, delim='quote', iostat=status, iomsg=msg)
  end subroutine obstacle_settings_write

  !> The sphere's axis (x, y) in the bottom plane of a body of `lengths`:
  !> `axis`, or the face centre when it is not given.
  pure function obstacle_centre_of(self, lengths) result(c)
    class(obstacle_settings_t), intent(in) :: self
    real(dp), intent(in) :: lengths(3)
    real(dp) :: c(2)
    if (any(self%axis == unset_axis)) then
      c = lengths(1:2)/2
    else
      c = self%axis
    end if
  end function obstacle_centre_of
end module obstacle_settings
