!> The settings of the row scaling of B (`&solver` variable scaling;
!> docs/INPUT.md): the gluing rows weighted by the Young's moduli of the
!> subdomains they join, or not. The one home of its default, range and
!> namelist variable; used by constraints and the dualization.
module scaling_settings
  use kinds, only: name_len
  use text, only: lower_case
  use settings_base, only: settings_t, refuse
  implicit none
  private

  type, extends(settings_t), public :: scaling_settings_t
    character(len=name_len) :: scaling = 'young'  !< rows of B weighted by Young's moduli: 'young' | 'none'
  contains
    procedure :: check => scaling_settings_check
    procedure :: group => scaling_settings_group
    procedure :: variables => scaling_settings_variables
    procedure :: read_namelist => scaling_settings_read
    procedure :: write_namelist => scaling_settings_write
  end type scaling_settings_t

contains

  !> The first value out of its range: `variable` its name ('' if none),
  !> `rule` the allowed values, `got` the value(s).
  subroutine scaling_settings_check(self, variable, rule, got)
    class(scaling_settings_t), intent(in) :: self
    character(len=:), allocatable, intent(out) :: variable, rule, got
    variable = ''
    rule = ''
    got = ''
    if (.not. any(self%scaling == [character(len=8) :: 'none', 'young'])) &
      call refuse('scaling', "must be 'none' or 'young'", self%scaling, variable, rule, got)
  end subroutine scaling_settings_check

  !> The namelist group of these variables.
  function scaling_settings_group(self) result(name)
    class(scaling_settings_t), intent(in) :: self
    character(len=:), allocatable :: name
    name = 'solver'
  end function scaling_settings_group

  !> The names of the namelist variables (those of read_namelist).
  subroutine scaling_settings_variables(self, names)
    class(scaling_settings_t), intent(in) :: self
    character(len=name_len), allocatable, intent(out) :: names(:)
    names = [character(len=name_len) :: 'scaling']
  end subroutine scaling_settings_variables

  !> Read this component's variables from the group text `group`
  !> ('&solver ... /'); strings lower case.
  subroutine scaling_settings_read(self, group, status, msg)
    class(scaling_settings_t), intent(inout) :: self
    character(len=*), intent(in) :: group
    integer, intent(out) :: status
    character(len=*), intent(out) :: msg
    character(len=name_len) :: scaling
    namelist /solver/ scaling
    scaling = self%scaling
    read (group, nml=solver, iostat=status, iomsg=msg)
    if (status /= 0) return
    self%scaling = lower_case(scaling)
  end subroutine scaling_settings_read

  !> Write this component's variables as the namelist '&solver ... /' (strings quoted).
  subroutine scaling_settings_write(self, lines, status, msg)
    class(scaling_settings_t), intent(in) :: self
    character(len=*), intent(out) :: lines(:)
    integer, intent(out) :: status
    character(len=*), intent(out) :: msg
    character(len=name_len) :: scaling
    namelist /solver/ scaling
    scaling = self%scaling
    lines = ''
    write (lines, nml=solver, delim='quote', iostat=status, iomsg=msg)
  end subroutine scaling_settings_write
end module scaling_settings
