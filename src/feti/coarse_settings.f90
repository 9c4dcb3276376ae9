!> The settings of the coarse problem (`&solver` variables coarse,
!> coarse_placement, coarse_ranks, coarse_blr, coarse_ooc, coarse_factor;
!> docs/INPUT.md): the one home of their defaults, ranges and namelist
!> variables. Used by the projector (coarse_problem's options) and the
!> dualization (the explicit orthonormal G~).
module coarse_settings
  use kinds, only: dp, ip, name_len
  use text, only: lower_case, ints_text, reals_text
  use settings_base, only: settings_t, refuse
  implicit none
  private

  type, extends(settings_t), public :: coarse_settings_t
    !> how SMALBE holds G: 'mumps' ((G G^T)^{-1} by its factors) |
    character(len=name_len) :: coarse = 'mumps'  !< 'orthonormal' (the explicit orthonormal G~)
    !> 'auto' (coarse_ranks decides) | 'redundant' (= coarse_ranks 1) |
    character(len=name_len) :: coarse_placement = 'auto'  !< 'distributed' (= all ranks)
    integer(ip) :: coarse_ranks = 0  !< ranks per coarse group (0: chosen from the coarse dimension)
    real(dp) :: coarse_blr = 0  !< MUMPS BLR dropping tolerance for G G^T (0: full rank)
    logical :: coarse_ooc = .false.  !< MUMPS out-of-core factors of G G^T
    !> how G G^T is factorized: 'mumps' | 'dense' (LAPACK Cholesky, one-rank
    character(len=name_len) :: coarse_factor = 'auto'  !< coarse groups) | 'auto' ('dense' up to coarse_dense_max, else 'mumps')
  contains
    procedure :: check => coarse_settings_check
    procedure :: group => coarse_settings_group
    procedure :: variables => coarse_settings_variables
    procedure :: read_namelist => coarse_settings_read
    procedure :: write_namelist => coarse_settings_write
  end type coarse_settings_t

contains

  !> The first value out of its range: `variable` its name ('' if none),
  !> `rule` the allowed values, `got` the value(s).
  subroutine coarse_settings_check(self, variable, rule, got)
    class(coarse_settings_t), intent(in) :: self
    character(len=:), allocatable, intent(out) :: variable, rule, got
    variable = ''
    rule = ''
    got = ''
    if (self%coarse == 'cholesky') then
      call refuse('coarse', "'cholesky' is now spelled 'orthonormal' (the explicit orthonormal G~)", self%coarse, &
                   variable, rule, got)
    else if (.not. any(self%coarse == [character(len=11) :: 'mumps', 'orthonormal'])) then
      call refuse('coarse', "must be 'mumps' or 'orthonormal'", self%coarse, variable, rule, got)
    else if (.not. any(self%coarse_placement == [character(len=12) :: 'auto', 'redundant', 'distributed'])) then
      call refuse('coarse_placement', "must be 'auto', 'redundant' or 'distributed'", self%coarse_placement, &
                   variable, rule, got)
    else if (self%coarse_ranks < 0) then
      call refuse('coarse_ranks', 'must be >= 0 (0: chosen from the coarse dimension and the ranks)', &
               ints_text([self%coarse_ranks]), variable, rule, got)
    else if (self%coarse_ranks > 0 .and. self%coarse_placement /= 'auto') then
      call refuse('coarse_ranks', "give coarse_ranks or coarse_placement ('redundant' = 1, "// &
               "'distributed' = all ranks), not both", ints_text([self%coarse_ranks])//', '//trim(self%coarse_placement), &
                            variable, rule, got)
    else if (.not. (self%coarse_blr >= 0 .and. self%coarse_blr < 1)) then
      call refuse('coarse_blr', 'must be in [0, 1) (0: full-rank factors)', reals_text([self%coarse_blr]), &
                   variable, rule, got)
    else if (.not. any(self%coarse_factor == [character(len=6) :: 'auto', 'mumps', 'dense'])) then
      call refuse('coarse_factor', "must be 'auto', 'mumps' or 'dense'", self%coarse_factor, &
                   variable, rule, got)
    else if (self%coarse_factor == 'dense' .and. (self%coarse_ranks > 1 .or. self%coarse_placement == 'distributed')) then
      call refuse('coarse_factor', "'dense' factorizes G G^T on every rank: it needs coarse groups of one "// &
               "rank (coarse_ranks = 0 or 1, coarse_placement 'auto' or 'redundant')", self%coarse_factor, &
                            variable, rule, got)
    end if
  end subroutine coarse_settings_check

  !> The namelist group of these variables.
  function coarse_settings_group(self) result(name)
    class(coarse_settings_t), intent(in) :: self
    character(len=:), allocatable :: name
    name = 'solver'
  end function coarse_settings_group

  !> The names of the namelist variables (those of read_namelist).
  subroutine coarse_settings_variables(self, names)
    class(coarse_settings_t), intent(in) :: self
    character(len=name_len), allocatable, intent(out) :: names(:)
    names = [character(len=name_len) :: 'coarse', 'coarse_placement', 'coarse_ranks', 'coarse_blr', &
        'coarse_ooc', 'coarse_factor']
  end subroutine coarse_settings_variables

  !> Read this component's variables from the group text `group`
  !> ('&solver ... /'); strings lower case.
  subroutine coarse_settings_read(self, group, status, msg)
    class(coarse_settings_t), intent(inout) :: self
    character(len=*), intent(in) :: group
    integer, intent(out) :: status
    character(len=*), intent(out) :: msg
    character(len=name_len) :: coarse, coarse_placement, coarse_factor
    integer(ip) :: coarse_ranks
    real(dp) :: coarse_blr
    logical :: coarse_ooc
    namelist /solver/ coarse, coarse_placement, coarse_ranks, coarse_blr, coarse_ooc, coarse_factor
    coarse = self%coarse; coarse_placement = self%coarse_placement; coarse_ranks = self%coarse_ranks
    coarse_blr = self%coarse_blr; coarse_ooc = self%coarse_ooc; coarse_factor = self%coarse_factor
    read (group, nml=solver, iostat=status, iomsg=msg)
    if (status /= 0) return
    self%coarse = lower_case(coarse); self%coarse_placement = lower_case(coarse_placement)
    self%coarse_ranks = coarse_ranks; self%coarse_blr = coarse_blr; self%coarse_ooc = coarse_ooc
    self%coarse_factor = lower_case(coarse_factor)
  end subroutine coarse_settings_read

  !> Write this component's variables as the namelist '&solver ... /' (strings quoted).
  subroutine coarse_settings_write(self, lines, status, msg)
    class(coarse_settings_t), intent(in) :: self
    character(len=*), intent(out) :: lines(:)
    integer, intent(out) :: status
    character(len=*), intent(out) :: msg
    character(len=name_len) :: coarse, coarse_placement, coarse_factor
    integer(ip) :: coarse_ranks
    real(dp) :: coarse_blr
    logical :: coarse_ooc
    namelist /solver/ coarse, coarse_placement, coarse_ranks, coarse_blr, coarse_ooc, coarse_factor
    coarse = self%coarse; coarse_placement = self%coarse_placement; coarse_ranks = self%coarse_ranks
    coarse_blr = self%coarse_blr; coarse_ooc = self%coarse_ooc; coarse_factor = self%coarse_factor
    lines = ''
    write (lines, nml=solver, delim='quote', iostat=status, iomsg=msg)
  end subroutine coarse_settings_write
end module coarse_settings
