!> The settings of the local solver K^+ (`&solver` variables local_ordering,
!> local_solver, share_subdomains, regularization; docs/INPUT.md): the one
!> home of their defaults, ranges and namelist variables, and of the
!> automatic choices (local_ordering_for, local_solver_for).
module local_settings
  use kinds, only: dp, i8, name_len
  use text, only: lower_case, reals_text
  use settings_base, only: settings_t, refuse
  implicit none
  private

  public :: local_ordering_for, local_solver_for

  !> local_ordering = 'auto': MUMPS's AMD up to this many dofs in the largest subdomain, METIS above
  integer(i8), parameter, public :: amd_max_dofs = 1500
  !> local_solver = 'auto': the dense split K^+ up to this many dofs in the largest subdomain
  integer(i8), parameter, public :: dense_max_dofs = 500

  type, extends(settings_t), public :: local_settings_t
    character(len=name_len) :: local_ordering = 'auto'  !< 'auto' | 'metis' | 'amd' (local_ordering_for)
    character(len=name_len) :: local_solver = 'auto'  !< 'auto' | 'dense' | 'block' | 'subdomain' (local_solver_for)
    !> 'auto': one K^+ (and one explicit S^) per class of congruent subdomains
    character(len=name_len) :: share_subdomains = 'auto'  !< of a rank, when there are such classes | 'none': per subdomain
    real(dp) :: regularization = 1  !< rho_f relative to the mean diagonal of K
  contains
    procedure :: check => local_settings_check
    procedure :: group => local_settings_group
    procedure :: variables => local_settings_variables
    procedure :: read_namelist => local_settings_read
    procedure :: write_namelist => local_settings_write
  end type local_settings_t

contains

  !> The first value out of its range: `variable` its name ('' if none),
  !> `rule` the allowed values, `got` the value(s).
  subroutine local_settings_check(self, variable, rule, got)
    class(local_settings_t), intent(in) :: self
    character(len=:), allocatable, intent(out) :: variable, rule, got
    variable = ''
    rule = ''
    got = ''
    if (.not. any(self%local_ordering == [character(len=8) :: 'auto', 'amd', 'metis'])) then
      call refuse('local_ordering', "must be 'auto', 'amd' or 'metis'", self%local_ordering, &
                   variable, rule, got)
    else if (.not. any(self%local_solver == [character(len=10) :: 'auto', 'dense', 'block', 'subdomain'])) then
      call refuse('local_solver', "must be 'auto', 'dense', 'block' or 'subdomain'", self%local_solver, &
                   variable, rule, got)
    else if (.not. any(self%share_subdomains == [character(len=10) :: 'auto', 'none'])) then
      call refuse('share_subdomains', "must be 'auto' or 'none'", self%share_subdomains, variable, rule, got)
    else if (self%regularization <= 0) then
      call refuse('regularization', 'must be > 0', reals_text([self%regularization]), variable, rule, got)
    end if
  end subroutine local_settings_check

  !> The namelist group of these variables.
  function local_settings_group(self) result(name)
    class(local_settings_t), intent(in) :: self
    character(len=:), allocatable :: name
    name = 'solver'
  end function local_settings_group

  !> The names of the namelist variables (those of read_namelist).
  subroutine local_settings_variables(self, names)
    class(local_settings_t), intent(in) :: self
    character(len=name_len), allocatable, intent(out) :: names(:)
    names = [character(len=name_len) :: 'local_ordering', 'local_solver', 'share_subdomains', &
        'regularization']
  end subroutine local_settings_variables

  !> Read this component's variables from the group text `group`
  !> ('&solver ... /'); strings lower case.
  subroutine local_settings_read(self, group, status, msg)
    class(local_settings_t), intent(inout) :: self
    character(len=*), intent(in) :: group
    integer, intent(out) :: status
    character(len=*), intent(out) :: msg
    character(len=name_len) :: local_ordering, local_solver, share_subdomains
    real(dp) :: regularization
    namelist /solver/ local_ordering, local_solver, share_subdomains, regularization
    local_ordering = self%local_ordering; local_solver = self%local_solver
    share_subdomains = self%share_subdomains; regularization = self%regularization
    read (group, nml=solver, iostat=status, iomsg=msg)
    if (status /= 0) return
    self%local_ordering = lower_case(local_ordering); self%local_solver = lower_case(local_solver)
    self%share_subdomains = lower_case(share_subdomains); self%regularization = regularization
  end subroutine local_settings_read

  !> Write this component's variables as the namelist '&solver ... /' (strings quoted).
  subroutine local_settings_write(self, lines, status, msg)
    class(local_settings_t), intent(in) :: self
    character(len=*), intent(out) :: lines(:)
    integer, intent(out) :: status
    character(len=*), intent(out) :: msg
    character(len=name_len) :: local_ordering, local_solver, share_subdomains
    real(dp) :: regularization
    namelist /solver/ local_ordering, local_solver, share_subdomains, regularization
    local_ordering = self%local_ordering; local_solver = self%local_solver
    share_subdomains = self%share_subdomains; regularization = self%regularization
    lines = ''
    write (lines, nml=solver, delim='quote', iostat=status, iomsg=msg)
  end subroutine local_settings_write

  !> The ordering of the subdomain factorizations that `&solver local_ordering`
  !> asks for, when the largest subdomain (or cluster) of the run has
  !> `max_ndof` dofs: 'amd' and 'metis' as given; 'auto' (the default) is
  !> MUMPS's AMD up to amd_max_dofs dofs (no METIS call per subdomain) and
  !> METIS nested dissection above (its factors make the solves faster).
  pure function local_ordering_for(requested, max_ndof) result(used)
    character(len=*), intent(in) :: requested
    integer(i8), intent(in) :: max_ndof
    character(len=8) :: used
    used = requested
    if (requested /= 'auto') return
    used = merge('amd     ', 'metis   ', max_ndof <= amd_max_dofs)
  end function local_ordering_for

  !> The local solver that `&solver local_solver` asks for, when the largest
  !> subdomain (or cluster) of the run has `max_ndof` dofs; `hybrid`: clusters
  !> (hybrid TFETI). 'dense', 'block' and 'subdomain' as given; 'auto' (the
  !> default) is the dense split K^+ (kplus_dense) up to dense_max_dofs dofs
  !> in plain TFETI, one MUMPS factorization per rank ('block') otherwise.
  !> Where the subdomains form classes of congruent ones (share_subdomains),
  !> K^+ is shared per class whatever this says.
  pure function local_solver_for(requested, max_ndof, hybrid) result(used)
    character(len=*), intent(in) :: requested
    integer(i8), intent(in) :: max_ndof
    logical, intent(in) :: hybrid
    character(len=10) :: used
    used = requested
    if (requested /= 'auto') return
    used = merge('dense     ', 'block     ', max_ndof <= dense_max_dofs .and. .not. hybrid)
  end function local_solver_for
end module local_settings
