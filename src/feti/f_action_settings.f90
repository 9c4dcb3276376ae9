!> The settings of the F action (`&solver` variables f_action, f_storage,
!> lanczos_steps, lanczos_setup_steps; docs/INPUT.md): how F = B K^+ B^T is
!> applied and stored, the cap of the Lanczos steps that estimate ||P F P||
!> and how many of them set-up makes. The one home of
!> their defaults, ranges and namelist variables; used by feti_builder.
module f_action_settings
  use kinds, only: ip, name_len
  use text, only: lower_case, ints_text
  use settings_base, only: settings_t, refuse
  implicit none
  private

  type, extends(settings_t), public :: f_action_settings_t
    !> how F is applied: 'implicit' (K^+ solves) | 'explicit' (dense local
    character(len=name_len) :: f_action = 'auto'  !< operators, BLAS) | 'auto' (the cheaper one by the measured cost model)
    character(len=name_len) :: f_storage = 'packed'  !< explicit F: 'packed' | 'symmetric' | 'general'
    integer(ip) :: lanczos_steps = 50  !< cap of the ||P F P|| Lanczos steps
    !> the Lanczos steps made in set-up, at most lanczos_steps (their estimate scales the dual
    !> problem); the rest when MPRGP first needs its step length (docs/THEORY.md "Deferred Lanczos")
    integer(ip) :: lanczos_setup_steps = 3
  contains
    procedure :: check => f_action_settings_check
    procedure :: group => f_action_settings_group
    procedure :: variables => f_action_settings_variables
    procedure :: read_namelist => f_action_settings_read
    procedure :: write_namelist => f_action_settings_write
  end type f_action_settings_t

contains

  !> The first value out of its range: `variable` its name ('' if none),
  !> `rule` the allowed values, `got` the value(s).
  subroutine f_action_settings_check(self, variable, rule, got)
    class(f_action_settings_t), intent(in) :: self
    character(len=:), allocatable, intent(out) :: variable, rule, got
    variable = ''
    rule = ''
    got = ''
    if (.not. any(self%f_action == [character(len=10) :: 'implicit', 'explicit', 'auto'])) then
      call refuse('f_action', "must be 'implicit', 'explicit' or 'auto'", self%f_action, variable, rule, got)
    else if (.not. any(self%f_storage == [character(len=10) :: 'symmetric', 'packed', 'general'])) then
      call refuse('f_storage', "must be 'symmetric', 'packed' or 'general'", self%f_storage, &
                   variable, rule, got)
    else if (self%lanczos_steps < 1) then
      call refuse('lanczos_steps', 'must be >= 1', ints_text([self%lanczos_steps]), variable, rule, got)
    else if (self%lanczos_setup_steps < 1) then
      call refuse('lanczos_setup_steps', 'must be >= 1 (at most lanczos_steps are made)', &
                  ints_text([self%lanczos_setup_steps]), variable, rule, got)
    end if
  end subroutine f_action_settings_check

  !> The namelist group of these variables.
  function f_action_settings_group(self) result(name)
    class(f_action_settings_t), intent(in) :: self
    character(len=:), allocatable :: name
    name = 'solver'
  end function f_action_settings_group

  !> The names of the namelist variables (those of read_namelist).
  subroutine f_action_settings_variables(self, names)
    class(f_action_settings_t), intent(in) :: self
    character(len=name_len), allocatable, intent(out) :: names(:)
    names = [character(len=name_len) :: 'f_action', 'f_storage', 'lanczos_steps', 'lanczos_setup_steps']
  end subroutine f_action_settings_variables

  !> Read this component's variables from the group text `group`
  !> ('&solver ... /'); strings lower case.
  subroutine f_action_settings_read(self, group, status, msg)
    class(f_action_settings_t), intent(inout) :: self
    character(len=*), intent(in) :: group
    integer, intent(out) :: status
    character(len=*), intent(out) :: msg
    character(len=name_len) :: f_action, f_storage
    integer(ip) :: lanczos_steps, lanczos_setup_steps
    namelist /solver/ f_action, f_storage, lanczos_steps, lanczos_setup_steps
    f_action = self%f_action; f_storage = self%f_storage; lanczos_steps = self%lanczos_steps
    lanczos_setup_steps = self%lanczos_setup_steps
    read (group, nml=solver, iostat=status, iomsg=msg)
    if (status /= 0) return
    self%f_action = lower_case(f_action); self%f_storage = lower_case(f_storage)
    self%lanczos_steps = lanczos_steps; self%lanczos_setup_steps = lanczos_setup_steps
  end subroutine f_action_settings_read

  !> Write this component's variables as the namelist '&solver ... /' (strings quoted).
  subroutine f_action_settings_write(self, lines, status, msg)
    class(f_action_settings_t), intent(in) :: self
    character(len=*), intent(out) :: lines(:)
    integer, intent(out) :: status
    character(len=*), intent(out) :: msg
    character(len=name_len) :: f_action, f_storage
    integer(ip) :: lanczos_steps, lanczos_setup_steps
    namelist /solver/ f_action, f_storage, lanczos_steps, lanczos_setup_steps
    f_action = self%f_action; f_storage = self%f_storage; lanczos_steps = self%lanczos_steps
    lanczos_setup_steps = self%lanczos_setup_steps
    lines = ''
    write (lines, nml=solver, delim='quote', iostat=status, iomsg=msg)
  end subroutine f_action_settings_write
end module f_action_settings
