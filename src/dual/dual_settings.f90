!> The settings of the dual problem (`&solver` variables rho_scale,
!> stopping; docs/INPUT.md): SMALBE's penalty relative to ||P F P|| and the
!> stopping test the dual problem offers it. The one home of their
!> defaults, ranges and namelist variables; used by the dualization.
module dual_settings
  use kinds, only: dp, name_len
  use text, only: lower_case, reals_text
  use settings_base, only: settings_t, refuse
  implicit none
  private

  type, extends(settings_t), public :: dual_settings_t
    real(dp) :: rho_scale = 1  !< penalty rho = rho_scale ||P F P||
    !> SMALBE's stopping test: 'violation' (largest constraint violation in
    character(len=name_len) :: stopping = 'violation'  !< displacement units, relative) | 'norm' (the classical 2-norm test)
  contains
    procedure :: check => dual_settings_check
    procedure :: group => dual_settings_group
    procedure :: variables => dual_settings_variables
    procedure :: read_namelist => dual_settings_read
    procedure :: write_namelist => dual_settings_write
  end type dual_settings_t

contains

  !> The first value out of its range: `variable` its name ('' if none),
  !> `rule` the allowed values, `got` the value(s).
  subroutine dual_settings_check(self, variable, rule, got)
    class(dual_settings_t), intent(in) :: self
    character(len=:), allocatable, intent(out) :: variable, rule, got
    variable = ''
    rule = ''
    got = ''
    if (self%rho_scale <= 0) then
      call refuse('rho_scale', 'must be > 0', reals_text([self%rho_scale]), variable, rule, got)
    else if (.not. any(self%stopping == [character(len=9) :: 'violation', 'norm'])) then
      call refuse('stopping', "must be 'violation' or 'norm'", self%stopping, variable, rule, got)
    end if
  end subroutine dual_settings_check

  !> The namelist group of these variables.
  function dual_settings_group(self) result(name)
    class(dual_settings_t), intent(in) :: self
    character(len=:), allocatable :: name
    name = 'solver'
  end function dual_settings_group

  !> The names of the namelist variables (those of read_namelist).
  subroutine dual_settings_variables(self, names)
    class(dual_settings_t), intent(in) :: self
    character(len=name_len), allocatable, intent(out) :: names(:)
    names = [character(len=name_len) :: 'rho_scale', 'stopping']
  end subroutine dual_settings_variables

  !> Read this component's variables from the group text `group`
  !> ('&solver ... /'); strings lower case.
  subroutine dual_settings_read(self, group, status, msg)
    class(dual_settings_t), intent(inout) :: self
    character(len=*), intent(in) :: group
    integer, intent(out) :: status
    character(len=*), intent(out) :: msg
    real(dp) :: rho_scale
    character(len=name_len) :: stopping
    namelist /solver/ rho_scale, stopping
    rho_scale = self%rho_scale; stopping = self%stopping
    read (group, nml=solver, iostat=status, iomsg=msg)
    if (status /= 0) return
    self%rho_scale = rho_scale; self%stopping = lower_case(stopping)
  end subroutine dual_settings_read

  !> Write this component's variables as the namelist '&solver ... /' (strings quoted).
  subroutine dual_settings_write(self, lines, status, msg)
    class(dual_settings_t), intent(in) :: self
    character(len=*), intent(out) :: lines(:)
    integer, intent(out) :: status
    character(len=*), intent(out) :: msg
    real(dp) :: rho_scale
    character(len=name_len) :: stopping
    namelist /solver/ rho_scale, stopping
    rho_scale = self%rho_scale; stopping = self%stopping
    lines = ''
    write (lines, nml=solver, delim='quote', iostat=status, iomsg=msg)
  end subroutine dual_settings_write
end module dual_settings
