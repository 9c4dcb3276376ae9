!> Young's modulus and Poisson's ratio of each subdomain (&material).
!>
!> 'none': young everywhere. 'checkerboard': young or contrast*young by the
!> parity of I+J+K of a box subdomain (I,J,K) (even: young), or of id-1 for METIS
!> subdomains. 'random': log-uniform in [young, contrast*young), from a hash of
!> (id, seed) alone (independent of the rank count). Poisson's ratio is the same
!> everywhere.
module materials
  use kinds, only: dp, ip
  use errors, only: fatal_error
  use params, only: params_t
  use box_mesh, only: hash_unit
  use decomposition, only: decomposition_t
  implicit none
  private

  public :: subdomain_material

contains

  !> Material of subdomain `id`.
  subroutine subdomain_material(p, dec, id, young, poisson)
    type(params_t), intent(in) :: p
    type(decomposition_t), intent(in) :: dec
    integer(ip), intent(in) :: id
    real(dp), intent(out) :: young, poisson
    integer(ip) :: parity, r, ijk(3)

    poisson = p%material%poisson
    select case (trim(p%material%variation))
    case ('none')
      young = p%material%young
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
      young = p%material%young*p%material%contrast**parity
    case ('random')
      young = p%material%young*p%material%contrast**hash_unit(id, 0_ip, p%material%seed)
    case default
      call fatal_error('subdomain_material: unknown &material variation '//trim(p%material%variation))
    end select
  end subroutine subdomain_material
end module materials
