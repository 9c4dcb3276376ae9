!> The settings of the reconstruction and of the KKT check
!> (`&reconstruction`, docs/INPUT.md): which alpha_bar formulas, the active
!> threshold, the accepted KKT residual. The one home of their defaults,
!> ranges and namelist variables; used by the dualization and the run.
module reconstruction_settings
  use kinds, only: dp, name_len
  use text, only: lower_case, reals_text
  use settings_base, only: settings_t, refuse
  implicit none
  private

  type, extends(settings_t), public :: reconstruction_settings_t
    character(len=name_len) :: method = 'both'  !< 'multiplier' (Eq. 24/25) | 'standard' (Eq. 10) | 'both'
    real(dp) :: active_tol = 1.0e-8_dp  !< contact row active if lambda > active_tol max(lambda)
    real(dp) :: kkt_tol = 1.0e-3_dp  !< largest KKT residual accepted
  contains
    procedure :: check => reconstruction_settings_check
    procedure :: group => reconstruction_settings_group
    procedure :: variables => reconstruction_settings_variables
    procedure :: read_namelist => reconstruction_settings_read
    procedure :: write_namelist => reconstruction_settings_write
  end type reconstruction_settings_t

contains

  !> The first value out of its range: `variable` its name ('' if none),
  !> `rule` the allowed values, `got` the value(s).
  subroutine reconstruction_settings_check(self, variable, rule, got)
    class(reconstruction_settings_t), intent(in) :: self
    character(len=:), allocatable, intent(out) :: variable, rule, got
    variable = ''
    rule = ''
    got = ''
    if (self%method == 'new') then
      call refuse('method', "'new' is now spelled 'multiplier' (alpha_bar from SMALBE's multiplier, Eq. 24/25)", self%method, &
                   variable, rule, got)
    else if (.not. any(self%method == [character(len=10) :: 'multiplier', 'standard', 'both'])) then
      call refuse('method', "must be 'multiplier', 'standard' or 'both'", self%method, variable, rule, got)
    else if (self%active_tol < 0 .or. self%active_tol >= 1) then
      call refuse('active_tol', 'must be in [0, 1)', reals_text([self%active_tol]), variable, rule, got)
    else if (self%kkt_tol <= 0) then
      call refuse('kkt_tol', 'must be > 0', reals_text([self%kkt_tol]), variable, rule, got)
    end if
  end subroutine reconstruction_settings_check

  !> The namelist group of these variables.
  function reconstruction_settings_group(self) result(name)
    class(reconstruction_settings_t), intent(in) :: self
    character(len=:), allocatable :: name
    name = 'reconstruction'
  end function reconstruction_settings_group

  !> The names of the namelist variables (those of read_namelist).
  subroutine reconstruction_settings_variables(self, names)
    class(reconstruction_settings_t), intent(in) :: self
    character(len=name_len), allocatable, intent(out) :: names(:)
    names = [character(len=name_len) :: 'method', 'active_tol', 'kkt_tol']
  end subroutine reconstruction_settings_variables

  !> Read this component's variables from the group text `group`
  !> ('&reconstruction ... /'); strings lower case.
  subroutine reconstruction_settings_read(self, group, status, msg)
    class(reconstruction_settings_t), intent(inout) :: self
    character(len=*), intent(in) :: group
    integer, intent(out) :: status
    character(len=*), intent(out) :: msg
    character(len=name_len) :: method
    real(dp) :: active_tol, kkt_tol
    namelist /reconstruction/ method, active_tol, kkt_tol
    method = self%method; active_tol = self%active_tol; kkt_tol = self%kkt_tol
    read (group, nml=reconstruction, iostat=status, iomsg=msg)
    if (status /= 0) return
    self%method = lower_case(method); self%active_tol = active_tol; self%kkt_tol = kkt_tol
  end subroutine reconstruction_settings_read

  !> Write this component's variables as the namelist '&reconstruction ... /' (strings quoted).
  subroutine reconstruction_settings_write(self, lines, status, msg)
    class(reconstruction_settings_t), intent(in) :: self
    character(len=*), intent(out) :: lines(:)
    integer, intent(out) :: status
    character(len=*), intent(out) :: msg
    character(len=name_len) :: method
    real(dp) :: active_tol, kkt_tol
    namelist /reconstruction/ method, active_tol, kkt_tol
    method = self%method; active_tol = self%active_tol; kkt_tol = self%kkt_tol
    lines = ''
    write (lines, nml=reconstruction, delim='quote', iostat=status, iomsg=msg)
  end subroutine reconstruction_settings_write
end module reconstruction_settings
