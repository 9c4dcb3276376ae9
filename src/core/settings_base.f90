!> What every component's settings type is (docs/INPUT.md holds their
!> variables): the namelist group it belongs to, the names of its variables,
!> its namelist (read from and written to the group's text), its check. The
!> input (src/input/params.f90) keeps a list of them and loops over it: a
!> new setting is an edit of its component's settings type only.
module settings_base
  use kinds, only: name_len
  implicit none
  private

  public :: refuse

  type, abstract, public :: settings_t
  contains
    !> the namelist group of its variables ('mesh', 'solver', ...)
    procedure(group_name), deferred :: group
    !> the names of its variables (lower case): those of its namelist
    procedure(variable_names), deferred :: variables
    !> read its variables from the group text '&group ... /' (given ones only)
    procedure(read_group), deferred :: read_namelist
    !> write its variables as the namelist '&group ... /' (strings quoted)
    procedure(write_group), deferred :: write_namelist
    !> the first value out of its range (none by default)
    procedure :: check => settings_check
  end type settings_t

  abstract interface
    function group_name(self) result(name)
      import :: settings_t
      class(settings_t), intent(in) :: self
      character(len=:), allocatable :: name
    end function group_name
    subroutine variable_names(self, names)
      import :: settings_t, name_len
      class(settings_t), intent(in) :: self
      character(len=name_len), allocatable, intent(out) :: names(:)
    end subroutine variable_names
    subroutine read_group(self, group, status, msg)
      import :: settings_t
      class(settings_t), intent(inout) :: self
      character(len=*), intent(in) :: group
      integer, intent(out) :: status
      character(len=*), intent(out) :: msg
    end subroutine read_group
    subroutine write_group(self, lines, status, msg)
      import :: settings_t
      class(settings_t), intent(in) :: self
      character(len=*), intent(out) :: lines(:)
      integer, intent(out) :: status
      character(len=*), intent(out) :: msg
    end subroutine write_group
  end interface

contains

  !> The first value out of its range: `variable` its name ('' if none),
  !> `rule` the allowed values, `got` the value(s). This default accepts all.
  subroutine settings_check(self, variable, rule, got)
    class(settings_t), intent(in) :: self
    character(len=:), allocatable, intent(out) :: variable, rule, got
    variable = ''
    rule = ''
    got = ''
  end subroutine settings_check

  !> The refusal of a value in a check: `name` the variable, `text` the rule
  !> it breaks (the allowed values), `value` the value as given; they become
  !> the check's `variable`, `rule` and `got` (the input's message then reads
  !> 'group &g, variable name: text (got value)').
  pure subroutine refuse(name, text, value, variable, rule, got)
    character(len=*), intent(in) :: name, text, value
    character(len=:), allocatable, intent(out) :: variable, rule, got
    variable = name
    rule = text
    got = trim(value)
  end subroutine refuse
end module settings_base
