!> The settings of the mesh and its decomposition (`&mesh`, docs/INPUT.md):
!> the box, its subdomains, their mapping to ranks and the clusters of hybrid
!> TFETI. Read and checked by the input layer (params), used by
!> decomposition and clusters.
module mesh_settings
  use kinds, only: dp, ip, name_len
  implicit none
  private

  type, public :: mesh_settings_t
    integer(ip) :: nsub(3) = [2, 2, 2]        !< subdomains per direction
    integer(ip) :: nel(3) = [4, 4, 4]         !< elements per subdomain per direction
    real(dp) :: lengths(3) = [1, 1, 1]        !< box size Lx, Ly, Lz [mm]
    real(dp) :: distortion = 0                !< inner node offset, fraction of h
    integer(ip) :: distortion_seed = 1        !< seed of the node offsets
    character(len=name_len) :: decomposition = 'box'  !< 'box' | 'metis'
    character(len=name_len) :: mapping = 'block'      !< subdomains to ranks: 'block' | 'metis'
    !> hybrid TFETI: subdomains per cluster per direction (1,1,1: plain TFETI;
    !> 0,0,0: chosen by `auto_cluster` when `read_params` reads the input; a
    !> params_t made in code and never resolved keeps 0,0,0 = plain TFETI)
    integer(ip) :: cluster(3) = [0, 0, 0]
    !> decomposition = 'metis': elements per block edge of the block grid METIS
    !> partitions (0: automatic, see src/mesh/decomposition.f90)
    integer(ip) :: metis_block = 0
    !> not namelist variables: set by `resolve_cluster` (read_params) when
    !> `cluster` was 0,0,0: then `cluster` holds the choice, and the reason
    logical :: cluster_auto = .false.
    character(len=160) :: cluster_choice = ''
  end type mesh_settings_t
end module mesh_settings
