!> The settings of the row scaling of B (`&solver` variable scaling;
!> docs/INPUT.md): the gluing rows weighted by the Young's moduli of the
!> subdomains they join, or not. The one home of its default, range and
!> namelist variable; used by constraints and the dualization.
module scaling_settings
  use kinds, only: name_len
  use text, only: lower_case
  implicit none
  private

  type, public :: scaling_settings_t
    character(len=name_len) :: scaling = 'young'  !< rows of B weighted by Young's moduli: 'young' | 'none'
  contains
    procedure :: check => scaling_settings_check
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
      call bad('scaling', "must be 'none' or 'young'", self%scaling)
  contains
    subroutine bad(name, text, value)
      character(len=*), intent(in) :: name, text, value
      variable = name
      rule = text
      got = trim(value)
    end subroutine bad
  end subroutine scaling_settings_check

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
