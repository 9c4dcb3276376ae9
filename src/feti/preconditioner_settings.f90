!> The settings of the dual preconditioner (`&solver` variables
!> preconditioner, preconditioner_switch; docs/INPUT.md): the one home of
!> their defaults, ranges and namelist variables. Used by the dualization,
!> which hands the choice to the dual problem (dual_preconditioner).
module preconditioner_settings
  use kinds, only: dp, name_len
  use text, only: lower_case, reals_text
  use settings_base, only: settings_t, refuse
  implicit none
  private

  type, extends(settings_t), public :: preconditioner_settings_t
    !> MPRGP preconditioned in the face: 'none' | 'lumped' | 'dirichlet' | 'auto'
    !> ('lumped' until the face condition estimate exceeds preconditioner_switch,
    character(len=name_len) :: preconditioner = 'auto'  !< then 'dirichlet')
    real(dp) :: preconditioner_switch = 100  !< 'auto': the face condition estimate that switches
  contains
    procedure :: check => preconditioner_settings_check
    procedure :: group => preconditioner_settings_group
    procedure :: variables => preconditioner_settings_variables
    procedure :: read_namelist => preconditioner_settings_read
    procedure :: write_namelist => preconditioner_settings_write
  end type preconditioner_settings_t

contains

  !> The first value out of its range: `variable` its name ('' if none),
  !> `rule` the allowed values, `got` the value(s).
  subroutine preconditioner_settings_check(self, variable, rule, got)
    class(preconditioner_settings_t), intent(in) :: self
    character(len=:), allocatable, intent(out) :: variable, rule, got
    variable = ''
    rule = ''
    got = ''
    if (.not. any(self%preconditioner == [character(len=9) :: 'none', 'lumped', 'dirichlet', 'auto'])) then
      call refuse('preconditioner', "must be 'none', 'lumped', 'dirichlet' or 'auto'", self%preconditioner, &
                   variable, rule, got)
    else if (.not. (self%preconditioner_switch > 1 .and. self%preconditioner_switch <= huge(1.0_dp))) then
      call refuse('preconditioner_switch', 'must be > 1 (a condition number)', reals_text([self%preconditioner_switch]), &
                   variable, rule, got)
    end if
  end subroutine preconditioner_settings_check

  !> The namelist group of these variables.
  function preconditioner_settings_group(self) result(name)
    class(preconditioner_settings_t), intent(in) :: self
    character(len=:), allocatable :: name
    name = 'solver'
  end function preconditioner_settings_group

  !> The names of the namelist variables (those of read_namelist).
  subroutine preconditioner_settings_variables(self, names)
    class(preconditioner_settings_t), intent(in) :: self
    character(len=name_len), allocatable, intent(out) :: names(:)
    names = [character(len=name_len) :: 'preconditioner', 'preconditioner_switch']
  end subroutine preconditioner_settings_variables

  !> Read this component's variables from the group text `group`
  !> ('&solver ... /'); strings lower case.
  subroutine preconditioner_settings_read(self, group, status, msg)
    class(preconditioner_settings_t), intent(inout) :: self
    character(len=*), intent(in) :: group
    integer, intent(out) :: status
    character(len=*), intent(out) :: msg
    character(len=name_len) :: preconditioner
    real(dp) :: preconditioner_switch
    namelist /solver/ preconditioner, preconditioner_switch
    preconditioner = self%preconditioner; preconditioner_switch = self%preconditioner_switch
    read (group, nml=solver, iostat=status, iomsg=msg)
    if (status /= 0) return
    self%preconditioner = lower_case(preconditioner); self%preconditioner_switch = preconditioner_switch
  end subroutine preconditioner_settings_read

  !> Write this component's variables as the namelist '&solver ... /' (strings quoted).
  subroutine preconditioner_settings_write(self, lines, status, msg)
    class(preconditioner_settings_t), intent(in) :: self
    character(len=*), intent(out) :: lines(:)
    integer, intent(out) :: status
    character(len=*), intent(out) :: msg
    character(len=name_len) :: preconditioner
    real(dp) :: preconditioner_switch
    namelist /solver/ preconditioner, preconditioner_switch
    preconditioner = self%preconditioner; preconditioner_switch = self%preconditioner_switch
    lines = ''
    write (lines, nml=solver, delim='quote', iostat=status, iomsg=msg)
  end subroutine preconditioner_settings_write
end module preconditioner_settings
