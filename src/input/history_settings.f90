!> The settings of a quasi-static load history (`&history`, docs/INPUT.md):
!> nsteps steps that scale the top displacement and the top pressure by a
!> load factor and may move the obstacle (its gap per step), solved one
!> after the other on the same operators. The one home of the defaults, of
!> the checks within the group (`check`; params checks it against the
!> others), of the namelist variables (`read_namelist`, `write_namelist`)
!> and of the step table (`factor`, `gap`). Without the group: one step at
!> factor 1 with the &obstacle gap, which is the plain run.
module history_settings
  use kinds, only: dp, ip, name_len
  use text, only: lower_case
  use settings_base, only: settings_t, refuse
  implicit none
  private

  !> the most steps of one history
  integer(ip), parameter, public :: max_steps = 1000
  !> a gap or factor that was not given
  real(dp), parameter :: unset = -huge(1.0_dp)

  type, extends(settings_t), public :: history_settings_t
    logical :: given = .false.                  !< the input has the group (not a namelist variable)
    integer(ip) :: nsteps = 1                   !< steps of the history
    !> load factors: 'ramp' (factor_peak i/nsteps), 'load_unload' (up to
    !> factor_peak in nsteps/2 steps, then down through the same factors to 0)
    !> or 'list' (load_factors)
    character(len=name_len) :: path = 'ramp'
    real(dp) :: factor_peak = 1                 !< the largest factor of 'ramp' and 'load_unload'
    real(dp) :: load_factors(max_steps) = unset !< 'list': the factor of each step
    real(dp) :: gaps(max_steps) = unset         !< the obstacle's gap per step (default: &obstacle gap)
    logical :: checkpoint = .true.              !< write a checkpoint after every step
    logical :: restart = .false.                !< continue from the checkpoint of the same input
    real(dp) :: time_limit = 0                  !< stop after the step that exceeds it [s] (0: none)
    logical :: warm_start = .true.              !< start each step from the previous one (else from 0)
    !> with warm_start: start the face solves from the face CG directions of the earlier steps
    logical :: recycle = .false.
  contains
    procedure :: check => history_check
    procedure :: group => history_group
    procedure :: variables => history_variables
    procedure :: read_namelist => history_read
    procedure :: write_namelist => history_write
    procedure :: factor => history_factor
    procedure :: gap => history_gap
    procedure :: is_history
  end type history_settings_t

contains

  !> The first value out of its range: `variable` its name ('' if none),
  !> `rule` the allowed values, `got` the value(s).
  subroutine history_check(self, variable, rule, got)
    class(history_settings_t), intent(in) :: self
    character(len=:), allocatable, intent(out) :: variable, rule, got
    integer(ip) :: n
    character(len=40) :: buf
    variable = ''
    rule = ''
    got = ''
    n = self%nsteps
    if (n < 1 .or. n > max_steps) then
      write (buf, '(i0)') max_steps
      call refuse('nsteps', 'must be in [1, '//trim(buf)//']', int_text(n), variable, rule, got)
    else if (.not. any(self%path == [character(len=11) :: 'ramp', 'load_unload', 'list'])) then
      call refuse('path', "must be 'ramp', 'load_unload' or 'list'", self%path, variable, rule, got)
    else if (.not. (self%factor_peak > 0 .and. self%factor_peak <= huge(1.0_dp))) then
      call refuse('factor_peak', 'must be > 0', real_text(self%factor_peak), variable, rule, got)
    else if (self%path == 'list' .and. any(self%load_factors(1:n) == unset)) then
      call refuse('load_factors', "needs nsteps values with path = 'list'", int_text(count(self%load_factors /= unset)) &
               //' values for nsteps = '//int_text(n), variable, rule, got)
    else if (self%path /= 'list' .and. any(self%load_factors /= unset)) then
      call refuse('load_factors', "is for path = 'list' only", trim(self%path), variable, rule, got)
    else if (self%path == 'list' .and. any(self%load_factors(n + 1:) /= unset)) then
      call refuse('load_factors', 'has more values than nsteps', int_text(count(self%load_factors /= unset)) &
               //' values for nsteps = '//int_text(n), variable, rule, got)
    else if (self%path == 'list' .and. .not. all(self%load_factors(1:n) >= 0)) then
      call refuse('load_factors', 'each factor must be >= 0 (0: the unloaded state)', &
                   real_text(minval(self%load_factors(1:n))), variable, rule, got)
    else if (any(self%gaps /= unset) .and. &
             (any(self%gaps(1:n) == unset) .or. any(self%gaps(n + 1:) /= unset))) then
      call refuse('gaps', 'needs exactly nsteps values when given', int_text(count(self%gaps /= unset)) &
               //' values for nsteps = '//int_text(n), variable, rule, got)
    else if (.not. (self%time_limit >= 0)) then
      call refuse('time_limit', 'must be >= 0 seconds (0: none)', real_text(self%time_limit), &
                   variable, rule, got)
    else if (self%recycle .and. .not. self%warm_start) then
      call refuse('recycle', 'needs warm_start = .true. (the directions are part of the warm start)', 'T', &
                   variable, rule, got)
    end if
  end subroutine history_check

  !> A history of more than one step, or a restart: the history driver runs.
  logical function is_history(self)
    class(history_settings_t), intent(in) :: self
    is_history = self%given
  end function is_history

  !> The load factor of step `i` (1..nsteps).
  real(dp) function history_factor(self, i)
    class(history_settings_t), intent(in) :: self
    integer(ip), intent(in) :: i
    integer(ip) :: up, k
    select case (self%path)
    case ('list')
      history_factor = self%load_factors(i)
    case ('load_unload')
      ! up steps to the peak and back down through the same factors to 0; an odd
      ! nsteps starts from the unloaded state (factor 0) as well
      up = self%nsteps/2
      k = i - mod(self%nsteps, 2_ip)
      if (up == 0) then
        history_factor = self%factor_peak
      else
        history_factor = self%factor_peak*real(min(k, 2*up - k), dp)/up
      end if
    case default
      history_factor = self%factor_peak*real(i, dp)/self%nsteps
    end select
  end function history_factor

  !> The obstacle's gap at step `i`: gaps(i), or `base` (&obstacle gap).
  real(dp) function history_gap(self, i, base)
    class(history_settings_t), intent(in) :: self
    integer(ip), intent(in) :: i
    real(dp), intent(in) :: base
    history_gap = base
    if (self%gaps(i) /= unset) history_gap = self%gaps(i)
  end function history_gap

  !> The namelist group of these variables.
  function history_group(self) result(name)
    class(history_settings_t), intent(in) :: self
    character(len=:), allocatable :: name
    name = 'history'
  end function history_group

  !> The names of the namelist variables (those of read_namelist).
  subroutine history_variables(self, names)
    class(history_settings_t), intent(in) :: self
    character(len=name_len), allocatable, intent(out) :: names(:)
    names = [character(len=name_len) :: 'nsteps', 'path', 'factor_peak', 'load_factors', 'gaps', &
        'checkpoint', 'restart', 'time_limit', 'warm_start', 'recycle']
  end subroutine history_variables

  !> Read the group text `group` ('&history ... /'); strings lower case.
  subroutine history_read(self, group, status, msg)
    class(history_settings_t), intent(inout) :: self
    character(len=*), intent(in) :: group
    integer, intent(out) :: status
    character(len=*), intent(out) :: msg
    integer(ip) :: nsteps
    character(len=name_len) :: path
    real(dp) :: factor_peak, time_limit
    real(dp), allocatable :: load_factors(:), gaps(:)
    logical :: checkpoint, restart, warm_start, recycle
    namelist /history/ nsteps, path, factor_peak, load_factors, gaps, checkpoint, restart, time_limit, warm_start, &
      recycle
    allocate (load_factors(max_steps), gaps(max_steps))
    nsteps = self%nsteps; path = self%path; factor_peak = self%factor_peak
    load_factors = self%load_factors; gaps = self%gaps
    checkpoint = self%checkpoint; restart = self%restart; time_limit = self%time_limit
    warm_start = self%warm_start; recycle = self%recycle
    read (group, nml=history, iostat=status, iomsg=msg)
    if (status /= 0) return
    self%given = .true.
    self%nsteps = nsteps; self%path = lower_case(path); self%factor_peak = factor_peak
    self%load_factors = load_factors; self%gaps = gaps
    self%checkpoint = checkpoint; self%restart = restart; self%time_limit = time_limit
    self%warm_start = warm_start; self%recycle = recycle
  end subroutine history_read

  !> Write the group as the namelist '&history ... /' (the lists with the
  !> given values only, a few per line).
  subroutine history_write(self, lines, status, msg)
    class(history_settings_t), intent(in) :: self
    character(len=*), intent(out) :: lines(:)
    integer, intent(out) :: status
    character(len=*), intent(out) :: msg
    integer(ip) :: nsteps
    character(len=name_len) :: path
    real(dp) :: factor_peak, time_limit
    logical :: checkpoint, restart, warm_start, recycle
    integer :: last, k
    namelist /history/ nsteps, path, factor_peak, checkpoint, restart, time_limit, warm_start, recycle
    nsteps = self%nsteps; path = self%path; factor_peak = self%factor_peak
    checkpoint = self%checkpoint; restart = self%restart; time_limit = self%time_limit
    warm_start = self%warm_start; recycle = self%recycle
    lines = ''
    write (lines, nml=history, delim='quote', iostat=status, iomsg=msg)
    if (status /= 0) return
    last = 0
    do k = 1, size(lines)
      if (len_trim(lines(k)) > 0 .and. adjustl(lines(k)) /= '/') last = k
    end do
    call add_list('LOAD_FACTORS', pack(self%load_factors, self%load_factors /= unset))
    call add_list('GAPS', pack(self%gaps, self%gaps /= unset))
    if (last < size(lines)) lines(last + 1) = '/'
  contains
    subroutine add_list(name, v)
      character(len=*), intent(in) :: name
      real(dp), intent(in) :: v(:)
      integer, parameter :: per_line = 8
      integer :: i
      if (size(v) == 0) return
      do i = 1, size(v), per_line
        if (last >= size(lines) - 1) then
          status = 1
          msg = 'history_write: too many values for the lines given'
          return
        end if
        last = last + 1
        lines(last) = ''
        if (i == 1) lines(last) = ' '//name//'='
        write (lines(last)(len_trim(lines(last)) + 2:), '(*(es24.16e3,:,", "))') v(i:min(i + per_line - 1, size(v)))
        if (i + per_line <= size(v)) lines(last) = trim(lines(last))//','
      end do
    end subroutine add_list
  end subroutine history_write

  function int_text(v) result(s)
    integer(ip), intent(in) :: v
    character(len=:), allocatable :: s
    character(len=24) :: buf
    write (buf, '(i0)') v
    s = trim(buf)
  end function int_text

  function real_text(v) result(s)
    real(dp), intent(in) :: v
    character(len=:), allocatable :: s
    character(len=32) :: buf
    write (buf, '(g0.6)') v
    s = trim(buf)
  end function real_text
end module history_settings
