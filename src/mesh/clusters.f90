!> Hybrid (two-level) TFETI: box subdomains grouped into clusters of
!> `&mesh cluster` = (cx, cy, cz) subdomains. The FETI unit (K^+, R, the 6
!> rows of G) is the cluster. `&mesh cluster_gluing` says how its subdomains
!> are glued inside it:
!> - 'faces' (the default): every node keeps one copy per subdomain, glued by
!>   B rows as between clusters, and every face two subdomains of the cluster
!>   share adds 6 rows C = Q_f^T (u^i - u^j) (Q_f the face's orthonormal
!>   rigid modes) that the cluster's K^+ imposes (`face_gluing`, kplus);
!> - 'corners': the corner nodes (subdomain vertices, all(mod(ijk, nel) ==
!>   0)) are merged by partial assembly, every other node as for 'faces'
!>   without C (docs/THEORY.md, "Hybrid TFETI").
!>
!> The clusters form a box decomposition themselves: nsub/cluster clusters
!> per direction of nel*cluster elements each (`unit_mesh`), so the
!> cluster-level decomposition_t gives the cluster->rank map, the cluster
!> graph and the clusters holding a node by index arithmetic. The
!> subdomain-level decomposition_t gives the subdomain copies of a node.
module clusters
  use kinds, only: dp, ip, i8
  use errors, only: fatal_error
  use mesh_settings, only: mesh_settings_t
  use decomposition, only: decomposition_t
  use subdomain, only: subdomain_t
  use sorting, only: sort_permutation
  implicit none
  private

  public :: is_hybrid, merges_corners, unit_mesh, cluster_of_subdomain, is_corner, node_copies, build_cluster

contains

  !> True when `&mesh cluster` groups more than one subdomain per cluster.
  pure logical function is_hybrid(m)
    type(mesh_settings_t), intent(in) :: m
    is_hybrid = any(m%cluster > 1)
  end function is_hybrid

  !> Hybrid TFETI whose clusters merge their corner nodes (cluster_gluing = 'corners').
  pure logical function merges_corners(m)
    type(mesh_settings_t), intent(in) :: m
    merges_corners = is_hybrid(m) .and. m%cluster_gluing == 'corners'
  end function merges_corners

  !> The mesh settings of the cluster-level box decomposition: nsub/cluster
  !> units per direction of nel*cluster elements (the same global mesh).
  function unit_mesh(m) result(q)
    type(mesh_settings_t), intent(in) :: m
    type(mesh_settings_t) :: q
    q = m
    q%nsub = m%nsub/m%cluster
    q%nel = m%nel*m%cluster
    q%cluster = 1
  end function unit_mesh

  !> The cluster (id in `udec`) of box subdomain `s` of `dec`.
  pure integer(ip) function cluster_of_subdomain(dec, udec, s) result(c)
    type(decomposition_t), intent(in) :: dec, udec
    integer(ip), intent(in) :: s
    integer(ip) :: r, b(3), cl(3)
    r = s - 1
    b(1) = mod(r, dec%mesh%nsub(1))
    r = r/dec%mesh%nsub(1)
    b(2) = mod(r, dec%mesh%nsub(2))
    b(3) = r/dec%mesh%nsub(2)
    cl = b/(dec%mesh%nsub/udec%mesh%nsub)
    c = 1 + cl(1) + udec%mesh%nsub(1)*(cl(2) + udec%mesh%nsub(2)*cl(3))
  end function cluster_of_subdomain

  !> Node `gid` is a vertex of every subdomain holding it.
  pure logical function is_corner(dec, gid)
    type(decomposition_t), intent(in) :: dec
    integer(ip), intent(in) :: gid
    is_corner = all(mod(dec%mesh%node_ijk(gid), dec%mesh%nel) == 0)
  end function is_corner

  !> The copies of node `gid` as B sees them: the subdomains s_1 < ... < s_n
  !> holding it, with the copies of a corner node inside one cluster merged
  !> into one. Copy k (1..m) has the representative subdomain reps(k) (the
  !> smallest of its merged subdomains; reps ascending), the cluster
  !> units(k) and merged(k) subdomains; member(i) = the copy of s_i.
  !> Without merging (m = n; `merge_corners` false, default true) this is
  !> the plain list.
  pure subroutine node_copies(dec, udec, gid, reps, units, merged, member, m, merge_corners)
    type(decomposition_t), intent(in) :: dec, udec
    integer(ip), intent(in) :: gid
    integer(ip), intent(out) :: reps(8), units(8), merged(8), member(8), m
    logical, intent(in), optional :: merge_corners
    integer(ip) :: ids(8), n, i, k, u
    logical :: corner
    call dec%node_subdomain_list(gid, ids, n)
    corner = is_corner(dec, gid)
    if (present(merge_corners)) corner = corner .and. merge_corners
    m = 0
    do i = 1, n
      u = cluster_of_subdomain(dec, udec, ids(i))
      k = 0
      if (corner) k = findloc(units(1:m), u, 1)
      if (k == 0) then
        m = m + 1
        reps(m) = ids(i)
        units(m) = u
        merged(m) = 0
        k = m
      end if
      merged(k) = merged(k) + 1
      member(i) = k
    end do
  end subroutine node_copies

  !> Geometry of cluster `id` of `udec` as one FETI unit: its elements, one
  !> local node per corner node (with `merge_corners`, default true) and one
  !> per (node, subdomain) pair for the other nodes (sub%node_copy),
  !> coordinates, centroid. node_gid ascending, copies of one node ordered by
  !> subdomain id (a merged corner first).
  subroutine build_cluster(dec, udec, id, sub, merge_corners)
    type(decomposition_t), intent(in) :: dec, udec
    integer(ip), intent(in) :: id
    type(subdomain_t), intent(out) :: sub
    logical, intent(in), optional :: merge_corners
    logical :: merge
    integer(i8), allocatable :: keys(:)
    integer(ip), allocatable :: loc(:)
    integer(ip) :: e, a, n, i, nodes(8), s
    integer(i8) :: base, last

    if (id < 1 .or. id > udec%nsubdomains) call fatal_error('build_cluster: no such cluster id')
    merge = .true.
    if (present(merge_corners)) merge = merge_corners
    base = int(dec%nsubdomains, i8) + 1
    sub%id = id
    sub%elem_gid = udec%subdomain_element_gids(id)
    sub%nelem = size(sub%elem_gid, kind=ip)
    allocate (keys(8*sub%nelem), sub%elem_nodes(8, sub%nelem), loc(8*sub%nelem))
    do e = 1, sub%nelem
      nodes = dec%mesh%element_nodes(sub%elem_gid(e))
      s = dec%subdomain_of_element(sub%elem_gid(e))
      do a = 1, 8
        if (merge .and. is_corner(dec, nodes(a))) then
          keys(8*(e - 1) + a) = int(nodes(a), i8)*base
        else
          keys(8*(e - 1) + a) = int(nodes(a), i8)*base + s
        end if
      end do
    end do
    ! local node of every (element, corner) position: one pass over the sorted keys
    n = 0
    last = -1
    block
      integer(ip), allocatable :: order(:)
      call sort_permutation(keys, order)
      do i = 1, size(keys, kind=ip)
        if (keys(order(i)) /= last) then
          n = n + 1
          last = keys(order(i))
        end if
        loc(order(i)) = n
      end do
      sub%nnodes = n
      sub%ndof = 3*n
      allocate (sub%node_gid(n), sub%node_copy(n), sub%coords(3, n))
      do i = 1, size(keys, kind=ip)
        a = loc(order(i))
        sub%node_gid(a) = int(keys(order(i))/base, ip)
        sub%node_copy(a) = int(mod(keys(order(i)), base), ip)
      end do
    end block
    do e = 1, sub%nelem
      sub%elem_nodes(:, e) = loc(8*(e - 1) + 1:8*e)
    end do
    do a = 1, n
      sub%coords(:, a) = dec%mesh%node_coords(sub%node_gid(a))
    end do
    sub%centroid = sum(sub%coords, dim=2)/real(n, dp)
  end subroutine build_cluster

end module clusters
