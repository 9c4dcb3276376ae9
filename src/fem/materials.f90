!> Young's modulus and Poisson's ratio of each subdomain (&material).
!>
!> 'none': young everywhere. 'checkerboard': young or contrast*young by the
!> parity of I+J+K of a box subdomain (I,J,K) (even: young), or of id-1 for METIS
!> subdomains. 'random': log-uniform in [young, contrast*young), from a hash of
!> (id, seed) alone (independent of the rank count). Poisson's ratio is the same
!> everywhere.
module materials
  use kinds, only: dp, ip, name_len
  use errors, only: fatal_error
  use box_mesh, only: hash_unit
  use decomposition, only: decomposition_t
  use text, only: lower_case
  use settings_base, only: settings_t
  implicit none
  private

  public :: subdomain_material

  !> The settings of `&material` (docs/INPUT.md): defaults, the checks within
  !> the group and the namelist variables (params hands the group over).
  type, extends(settings_t), public :: material_settings_t
    real(dp) :: young = 2.1e5_dp              !< Young's modulus [MPa]
    real(dp) :: poisson = 0.3_dp              !< Poisson's ratio
    character(len=name_len) :: variation = 'none'  !< 'none' | 'checkerboard' | 'random'
    real(dp) :: contrast = 1                  !< ratio of largest to smallest young
    integer(ip) :: seed = 1                   !< seed of 'random'
  contains
    procedure :: check => material_settings_check
    procedure :: group => material_settings_group
    procedure :: variables => material_settings_variables
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
    names = [character(len=name_len) :: 'young', 'poisson', 'variation', 'contrast', 'seed']
  end subroutine material_settings_variables

  !> Read the group text `group` ('&material ... /'); strings lower case.
  subroutine material_settings_read(self, group, status, msg)
    class(material_settings_t), intent(inout) :: self
    character(len=*), intent(in) :: group
    integer, intent(out) :: status
    character(len=*), intent(out) :: msg
    real(dp) :: young, poisson, contrast
    character(len=name_len) :: variation
    integer(ip) :: seed
    namelist /material/ young, poisson, variation, contrast, seed
    young = self%young; poisson = self%poisson; variation = self%variation
    contrast = self%contrast; seed = self%seed
    read (group, nml=material, iostat=status, iomsg=msg)
    if (status /= 0) return
    self%young = young; self%poisson = poisson; self%variation = lower_case(variation)
    self%contrast = contrast; self%seed = seed
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
    namelist /material/ young, poisson, variation, contrast, seed
    young = self%young; poisson = self%poisson; variation = self%variation
    contrast = self%contrast; seed = self%seed
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
