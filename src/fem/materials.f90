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
  implicit none
  private

  public :: subdomain_material

  !> The settings of `&material` (docs/INPUT.md).
  type, public :: material_settings_t
    real(dp) :: young = 2.1e5_dp              !< Young's modulus [MPa]
    real(dp) :: poisson = 0.3_dp              !< Poisson's ratio
    character(len=name_len) :: variation = 'none'  !< 'none' | 'checkerboard' | 'random'
    real(dp) :: contrast = 1                  !< ratio of largest to smallest young
    integer(ip) :: seed = 1                   !< seed of 'random'
  end type material_settings_t

contains

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
      if (dec%method == 'box') then
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
