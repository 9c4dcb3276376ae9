!> Young's modulus and Poisson's ratio of each subdomain (&material).
!>
!> 'none': young everywhere. 'checkerboard': young or contrast*young by the
!> parity of I+J+K of a box subdomain (I,J,K) (even: young), or of id-1 for METIS
!> subdomains. 'random': log-uniform in [young, contrast*young), from a hash of
!> (id, seed) alone (independent of the rank count). Poisson's ratio is the same
!> everywhere; so is the element formulation (`element`: 'q1' | 'q1_bbar').
module materials
  use kinds, only: dp, ip, name_len
  use errors, only: fatal_error
  use box_mesh, only: hash_unit
  use decomposition, only: decomposition_t
  use text, only: lower_case
  use settings_base, only: settings_t
  use q1_element, only: element_q1, element_q1_bbar
  implicit none
  private

  public :: subdomain_material

  !> Poisson's ratio from which the fully integrated Q1 draws a warning.
  real(dp), parameter :: nearly_incompressible = 0.45_dp

  !> The settings of `&material` (docs/INPUT.md): defaults, the checks within
  !> the group and the namelist variables (params hands the group over).
  type, extends(settings_t), public :: material_settings_t
    real(dp) :: young = 2.1e5_dp              !< Young's modulus [MPa]
    real(dp) :: poisson = 0.3_dp              !< Poisson's ratio
    character(len=name_len) :: variation = 'none'  !< 'none' | 'checkerboard' | 'random'
    real(dp) :: contrast = 1                  !< ratio of largest to smallest young
    integer(ip) :: seed = 1                   !< seed of 'random'
    character(len=name_len) :: element = 'q1' !< 'q1' (2x2x2) | 'q1_bbar' (mean dilatation)
  contains
    procedure :: check => material_settings_check
    procedure :: group => material_settings_group
    procedure :: variables => material_settings_variables
    procedure :: element_kind => material_element_kind
    procedure :: warning => material_settings_warning
    procedure :: read_namelist => material_settings_read
    procedure :: write_namelist => material_settings_write
  end type material_settings_t

contains

  !> The first value out of its range: `variable` its name ('' if none),
  !> `rule` the allowed values, `got` the value.
  subroutine material_settings_check(self, variable, rule, got)
    class(material_settings_t), intent(in) :: self
    character(len=:), allocatable, intent(out) :: variable, rule, got
    character(len=64) :: buf
    variable = ''
    rule = ''
    got = ''
    buf = ''
    if (self%young <= 0) then
      variable = 'young'
      rule = 'must be > 0'
      write (buf, '(g0.6)') self%young
    else if (self%poisson <= -1 .or. self%poisson >= 0.5_dp) then
      variable = 'poisson'
      rule = 'must be in (-1, 0.5)'
      write (buf, '(g0.6)') self%poisson
    else if (.not. any(self%variation == [character(len=12) :: 'none', 'checkerboard', 'random'])) then
      variable = 'variation'
      rule = "must be 'none', 'checkerboard' or 'random'"
      buf = self%variation
    else if (self%contrast < 1 .or. self%contrast > 1.0e12_dp) then
      variable = 'contrast'
      rule = 'must be in [1, 1e12]'
      write (buf, '(g0.6)') self%contrast
    else if (.not. any(self%element == [character(len=8) :: 'q1', 'q1_bbar'])) then
      variable = 'element'
      rule = "must be 'q1' or 'q1_bbar'"
      buf = self%element
    end if
    got = trim(buf)
  end subroutine material_settings_check

  !> The namelist group of these variables.
  function material_settings_group(self) result(name)
    class(material_settings_t), intent(in) :: self
    character(len=:), allocatable :: name
    name = 'material'
  end function material_settings_group

  !> The names of the namelist variables (those of read_namelist).
  subroutine material_settings_variables(self, names)
    class(material_settings_t), intent(in) :: self
    character(len=name_len), allocatable, intent(out) :: names(:)
    names = [character(len=name_len) :: 'young', 'poisson', 'variation', 'contrast', 'seed', 'element']
  end subroutine material_settings_variables

  !> The element formulation as q1_element's kind (element_q1, element_q1_bbar),
  !> for the element loops (resolved once per subdomain at set-up).
  integer function material_element_kind(self) result(kind)
    class(material_settings_t), intent(in) :: self
    select case (trim(self%element))
    case ('q1')
      kind = element_q1
    case ('q1_bbar')
      kind = element_q1_bbar
    case default
      call fatal_error('material_element_kind: unknown &material element '//trim(self%element))
    end select
  end function material_element_kind

  !> A valid setting that is probably a mistake, as a sentence ('' if none):
  !> the fully integrated Q1 locks (far too stiff) as nu -> 1/2.
  function material_settings_warning(self) result(line)
    class(material_settings_t), intent(in) :: self
    character(len=:), allocatable :: line
    character(len=16) :: buf
    line = ''
    if (self%element == 'q1' .and. self%poisson >= nearly_incompressible) then
      write (buf, '(f6.4)') self%poisson
      line = '&material poisson = '//trim(buf)//" with element = 'q1': the fully integrated "// &
             "hexahedron locks (too stiff) for a nearly incompressible material; "// &
             "element = 'q1_bbar' does not"
    end if
  end function material_settings_warning

  !> Read the group text `group` ('&material ... /'); strings lower case.
  subroutine material_settings_read(self, group, status, msg)
    class(material_settings_t), intent(inout) :: self
    character(len=*), intent(in) :: group
    integer, intent(out) :: status
    character(len=*), intent(out) :: msg
    real(dp) :: young, poisson, contrast
    character(len=name_len) :: variation
    integer(ip) :: seed
    character(len=name_len) :: element
    namelist /material/ young, poisson, variation, contrast, seed, element
    young = self%young; poisson = self%poisson; variation = self%variation
    contrast = self%contrast; seed = self%seed; element = self%element
    read (group, nml=material, iostat=status, iomsg=msg)
    if (status /= 0) return
    self%young = young; self%poisson = poisson; self%variation = lower_case(variation)
    self%contrast = contrast; self%seed = seed; self%element = lower_case(element)
  end subroutine material_settings_read

  !> Write the group as the namelist '&material ... /' (strings quoted).
  subroutine material_settings_write(self, lines, status, msg)
    class(material_settings_t), intent(in) :: self
    character(len=*), intent(out) :: lines(:)
    integer, intent(out) :: status
    character(len=*), intent(out) :: msg
    real(dp) :: young, poisson, contrast
    character(len=name_len) :: variation
    integer(ip) :: seed
    character(len=name_len) :: element
    namelist /material/ young, poisson, variation, contrast, seed, element
    young = self%young; poisson = self%poisson; variation = self%variation
    contrast = self%contrast; seed = self%seed; element = self%element
    lines = ''
    write (lines, nml=material, delim='quote', iostat=status, iomsg=msg)
  end subroutine material_settings_write

  !> Material of subdomain `id`.
  subroutine subdomain_material(material, dec, id, young, poisson)
    type(material_settings_t), intent(in) :: material
    type(decomposition_t), intent(in) :: dec
    integer(ip), intent(in) :: id
    real(dp), intent(out) :: young, poisson
    integer(ip) :: parity, r, ijk(3)

    poisson = material%poisson
    select case (trim(material%variation))
    case ('none')
      young = material%young
    case ('checkerboard')
      if (dec%is_box()) then
        r = id - 1
        ijk(1) = mod(r, dec%mesh%nsub(1))
        r = r/dec%mesh%nsub(1)
        ijk(2) = mod(r, dec%mesh%nsub(2))
        ijk(3) = r/dec%mesh%nsub(2)
        parity = mod(sum(ijk), 2)
      else
        parity = mod(id - 1, 2)
      end if
      young = material%young*material%contrast**parity
    case ('random')
      young = material%young*material%contrast**hash_unit(id, 0_ip, material%seed)
    case default
      call fatal_error('subdomain_material: unknown &material variation '//trim(material%variation))
    end select
  end subroutine subdomain_material
end module materials
