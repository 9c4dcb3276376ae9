!> The settings of the rigid obstacle (`&obstacle`, docs/INPUT.md): its
!> shape, radius and initial gap, the one home of their defaults, ranges and
!> namelist variables (the gap against the body's height is params'
!> check_params). Used by constraints (the contact rows of B and the gaps).
module obstacle_settings
  use kinds, only: dp, name_len
  use text, only: lower_case, reals_text
  use settings_base, only: settings_t, refuse
  implicit none
  private

  type, extends(settings_t), public :: obstacle_settings_t
    character(len=name_len) :: shape = 'sphere'  !< 'sphere' | 'plane' | 'none'
    real(dp) :: radius = 1  !< sphere radius [mm]
    real(dp) :: gap = 0  !< initial gap below z = 0 [mm]
  contains
    procedure :: check => obstacle_settings_check
    procedure :: group => obstacle_settings_group
    procedure :: variables => obstacle_settings_variables
    procedure :: read_namelist => obstacle_settings_read
    procedure :: write_namelist => obstacle_settings_write
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
    names = [character(len=name_len) :: 'shape', 'radius', 'gap']
  end subroutine obstacle_settings_variables

  !> Read this component's variables from the group text `group`
  !> ('&obstacle ... /'); strings lower case.
  subroutine obstacle_settings_read(self, group, status, msg)
    class(obstacle_settings_t), intent(inout) :: self
    character(len=*), intent(in) :: group
    integer, intent(out) :: status
    character(len=*), intent(out) :: msg
    character(len=name_len) :: shape
    real(dp) :: radius, gap
    namelist /obstacle/ shape, radius, gap
    shape = self%shape; radius = self%radius; gap = self%gap
    read (group, nml=obstacle, iostat=status, iomsg=msg)
    if (status /= 0) return
    self%shape = lower_case(shape); self%radius = radius; self%gap = gap
  end subroutine obstacle_settings_read

  !> Write this component's variables as the namelist '&obstacle ... /' (strings quoted).
  subroutine obstacle_settings_write(self, lines, status, msg)
    class(obstacle_settings_t), intent(in) :: self
    character(len=*), intent(out) :: lines(:)
    integer, intent(out) :: status
    character(len=*), intent(out) :: msg
    character(len=name_len) :: shape
    real(dp) :: radius, gap
    namelist /obstacle/ shape, radius, gap
    shape = self%shape; radius = self%radius; gap = self%gap
    lines = ''
    write (lines, nml=obstacle, delim='quote', iostat=status, iomsg=msg)
  end subroutine obstacle_settings_write
end module obstacle_settings
