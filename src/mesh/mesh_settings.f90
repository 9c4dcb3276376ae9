!> The settings of the mesh and its decomposition (`&mesh`, docs/INPUT.md):
!> the box, its subdomains, their mapping to ranks and the clusters of hybrid
!> TFETI: the one home of their defaults, of the checks within the group
!> (`check`; those against other groups are params' check_params) and of
!> the namelist variables (`read_namelist`, `write_namelist`; params hands
!> the group over). Used by decomposition and clusters.
module mesh_settings
  use kinds, only: dp, ip, i8, name_len
  use text, only: lower_case
  use settings_base, only: settings_t, refuse
  implicit none
  private

  type, extends(settings_t), public :: mesh_settings_t
    integer(ip) :: nsub(3) = [2, 2, 2]        !< subdomains per direction
    integer(ip) :: nel(3) = [4, 4, 4]         !< elements per subdomain per direction
    real(dp) :: lengths(3) = [1, 1, 1]        !< box size Lx, Ly, Lz [mm]
    real(dp) :: distortion = 0                !< inner node offset, fraction of h
    integer(ip) :: distortion_seed = 1        !< seed of the node offsets
    character(len=name_len) :: decomposition = 'box'  !< 'box' | 'metis'
    character(len=name_len) :: mapping = 'block'      !< subdomains to ranks: 'block' | 'metis'
    !> hybrid TFETI: subdomains per cluster per direction (1,1,1: plain TFETI;
    !> 0,0,0: chosen by `auto_cluster` when `read_params` reads the input;
    !> settings made in code and never resolved keep 0,0,0 = plain TFETI)
    integer(ip) :: cluster(3) = [0, 0, 0]
    !> how the subdomains of a cluster are glued inside it: 'faces' (the 6
    !> rigid-body moments of every face two of them share, constraints of the
    !> cluster's local solve) | 'corners' (corner nodes merged by partial assembly)
    character(len=name_len) :: cluster_gluing = 'faces'
    !> decomposition = 'metis': elements per block edge of the block grid METIS
    !> partitions (0: automatic, see src/mesh/decomposition.f90)
    integer(ip) :: metis_block = 0
    !> not namelist variables: set by `resolve_cluster` (read_params) when
    !> `cluster` was 0,0,0: then `cluster` holds the choice, and the reason
    logical :: cluster_auto = .false.
    character(len=240) :: cluster_choice = ''
  contains
    procedure :: check => mesh_settings_check
    procedure :: group => mesh_settings_group
    procedure :: variables => mesh_settings_variables
    procedure :: read_namelist => mesh_settings_read
    procedure :: write_namelist => mesh_settings_write
  end type mesh_settings_t

contains

  !> The first value out of its range: `variable` its name ('' if none),
  !> `rule` the allowed values, `got` the value(s).
  subroutine mesh_settings_check(self, variable, rule, got)
    class(mesh_settings_t), intent(in) :: self
    character(len=:), allocatable, intent(out) :: variable, rule, got
    variable = ''
    rule = ''
    got = ''
    if (any(self%nsub < 1)) then
      call refuse('nsub', 'each entry must be >= 1', ints(self%nsub), variable, rule, got)
    else if (any(self%nel < 1)) then
      call refuse('nel', 'each entry must be >= 1', ints(self%nel), variable, rule, got)
    else if (any(self%lengths <= 0)) then
      call refuse('lengths', 'each entry must be > 0', reals(self%lengths), variable, rule, got)
    else if (self%distortion < 0 .or. self%distortion >= 0.5_dp) then
      call refuse('distortion', 'must be in [0, 0.5)', reals([self%distortion]), variable, rule, got)
    else if (.not. any(self%decomposition == [character(len=8) :: 'box', 'metis'])) then
      call refuse('decomposition', "must be 'box' or 'metis'", self%decomposition, variable, rule, got)
    else if (.not. any(self%mapping == [character(len=8) :: 'block', 'metis'])) then
      call refuse('mapping', "must be 'block' or 'metis'", self%mapping, variable, rule, got)
    else if (.not. (all(self%cluster == 0) .or. all(self%cluster >= 1))) then
      call refuse('cluster', 'each entry must be >= 1, or all three 0 (automatic choice)', ints(self%cluster), &
                   variable, rule, got)
    else if (.not. any(self%cluster_gluing == [character(len=8) :: 'faces', 'corners'])) then
      call refuse('cluster_gluing', "must be 'faces' or 'corners'", self%cluster_gluing, variable, rule, got)
    else if (self%metis_block < 0) then
      call refuse('metis_block', 'must be 0 (automatic) or a block edge b >= 1 in elements', ints([self%metis_block]), &
                   variable, rule, got)
    else if (divides_not()) then
      call refuse('cluster', 'must divide nsub in every direction (nsub = '//ints(self%nsub)//')', ints(self%cluster), &
                   variable, rule, got)
    else if (any(self%cluster > 1) .and. self%decomposition /= 'box') then
      call refuse('cluster', "> 1 (hybrid TFETI) needs decomposition = 'box'", ints(self%cluster), &
                   variable, rule, got)
    else if (product(int(self%nsub, i8))*product(int(self%nel, i8)) > 2_i8**27) then
      call refuse('nsub, nel', 'give at most 2**27 elements in all', ints(self%nsub)//' x '//ints(self%nel), &
                   variable, rule, got)
    end if
  contains
    logical function divides_not()
      divides_not = .false.
      if (all(self%cluster >= 1)) divides_not = any(mod(self%nsub, self%cluster) /= 0)
    end function divides_not
  end subroutine mesh_settings_check

  !> The namelist group of these variables.
  function mesh_settings_group(self) result(name)
    class(mesh_settings_t), intent(in) :: self
    character(len=:), allocatable :: name
    name = 'mesh'
  end function mesh_settings_group

  !> The names of the namelist variables (those of read_namelist).
  subroutine mesh_settings_variables(self, names)
    class(mesh_settings_t), intent(in) :: self
    character(len=name_len), allocatable, intent(out) :: names(:)
    names = [character(len=name_len) :: 'nsub', 'nel', 'lengths', 'distortion', 'distortion_seed', &
        'decomposition', 'mapping', 'cluster', 'cluster_gluing', 'metis_block']
  end subroutine mesh_settings_variables

  !> Read the group text `group` ('&mesh ... /'); strings lower case.
  subroutine mesh_settings_read(self, group, status, msg)
    class(mesh_settings_t), intent(inout) :: self
    character(len=*), intent(in) :: group
    integer, intent(out) :: status
    character(len=*), intent(out) :: msg
    integer(ip) :: nsub(3), nel(3), cluster(3), metis_block, distortion_seed
    real(dp) :: lengths(3), distortion
    character(len=name_len) :: decomposition, mapping, cluster_gluing
    namelist /mesh/ nsub, nel, lengths, distortion, distortion_seed, decomposition, mapping, cluster, &
      cluster_gluing, metis_block
    nsub = self%nsub; nel = self%nel; lengths = self%lengths
    distortion = self%distortion; distortion_seed = self%distortion_seed
    decomposition = self%decomposition; mapping = self%mapping; cluster = self%cluster
    metis_block = self%metis_block; cluster_gluing = self%cluster_gluing
    read (group, nml=mesh, iostat=status, iomsg=msg)
    if (status /= 0) return
    self%nsub = nsub; self%nel = nel; self%lengths = lengths
    self%distortion = distortion; self%distortion_seed = distortion_seed
    self%decomposition = lower_case(decomposition); self%mapping = lower_case(mapping)
    self%cluster = cluster; self%metis_block = metis_block
    self%cluster_gluing = lower_case(cluster_gluing)
  end subroutine mesh_settings_read

  !> Write the group as the namelist '&mesh ... /' (strings quoted).
  subroutine mesh_settings_write(self, lines, status, msg)
    class(mesh_settings_t), intent(in) :: self
    character(len=*), intent(out) :: lines(:)
    integer, intent(out) :: status
    character(len=*), intent(out) :: msg
    integer(ip) :: nsub(3), nel(3), cluster(3), metis_block, distortion_seed
    real(dp) :: lengths(3), distortion
    character(len=name_len) :: decomposition, mapping, cluster_gluing
    namelist /mesh/ nsub, nel, lengths, distortion, distortion_seed, decomposition, mapping, cluster, &
      cluster_gluing, metis_block
    nsub = self%nsub; nel = self%nel; lengths = self%lengths
    distortion = self%distortion; distortion_seed = self%distortion_seed
    decomposition = self%decomposition; mapping = self%mapping; cluster = self%cluster
    metis_block = self%metis_block; cluster_gluing = self%cluster_gluing
    lines = ''
    write (lines, nml=mesh, delim='quote', iostat=status, iomsg=msg)
  end subroutine mesh_settings_write

  !> The values of v separated by blanks (for messages).
  function ints(v) result(s)
    integer(ip), intent(in) :: v(:)
    character(len=:), allocatable :: s
    character(len=256) :: buf
    write (buf, '(*(i0,:," "))') v
    s = trim(buf)
  end function ints

  !> The values of v separated by blanks, 6 significant digits.
  function reals(v) result(s)
    real(dp), intent(in) :: v(:)
    character(len=:), allocatable :: s
    character(len=256) :: buf
    write (buf, '(*(g0.6,:," "))') v
    s = trim(buf)
  end function reals
end module mesh_settings
