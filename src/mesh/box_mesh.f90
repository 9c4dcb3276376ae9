!> The global structured mesh of the box (0,Lx) x (0,Ly) x (0,Lz): index
!> arithmetic only, no arrays of the size of the mesh.
!>
!> ng = nsub*nel elements per direction, ng+1 nodes per direction. Node (i,j,k),
!> 0 <= i <= ng(1), has gid 1 + i + (ng(1)+1)*(j + (ng(2)+1)*k); element
!> (i,j,k) (its lower corner), 0 <= i < ng(1), has gid 1 + i + ng(1)*(j + ng(2)*k).
!> The 8 nodes of an element are in the standard Q1 order: (i,j,k) (i+1,j,k)
!> (i+1,j+1,k) (i,j+1,k), then the same at k+1.
!>
!> Distortion (docs/CASES.md): every node not on the outer boundary moves by an
!> offset in [-distortion*h(c), distortion*h(c)) in each component c, a hash of
!> (gid, c, seed) alone, so every copy of a node sits at the same place.
module box_mesh
  use kinds, only: dp, ip, i8
  use errors, only: fatal_error
  implicit none
  private

  public :: box_mesh_init, hash_unit

  !> Faces of the box (and of a Q1 element, same numbering, see q1_element).
  integer(ip), parameter, public :: face_x0 = 1, face_x1 = 2, face_y0 = 3, face_y1 = 4, &
                                    face_z0 = 5, face_z1 = 6

  integer(i8), parameter :: mask32 = 4294967295_i8       ! 2**32 - 1
  integer(i8), parameter :: golden = 2654435769_i8       ! 0x9e3779b9

  !> The global mesh.
  type, public :: box_mesh_t
    integer(ip) :: nsub(3) = 1, nel(3) = 1, ng(3) = 1   !< ng = nsub*nel
    real(dp) :: lengths(3) = 1, h(3) = 1, distortion = 0
    integer(ip) :: seed = 1
  contains
    procedure :: num_nodes
    procedure :: num_elements
    procedure :: node_ijk
    procedure :: node_gid
    procedure :: element_ijk
    procedure :: element_gid
    procedure :: elements_near
    procedure :: node_coords
    procedure :: element_nodes
    procedure :: node_on_face
    procedure :: node_on_boundary
    procedure :: element_on_face
    procedure :: box_subdomain
  end type box_mesh_t

contains

  !> Set up the mesh of nsub*nel elements per direction over `lengths`.
  subroutine box_mesh_init(mesh, nsub, nel, lengths, distortion, seed)
    type(box_mesh_t), intent(out) :: mesh
    integer(ip), intent(in) :: nsub(3), nel(3)
    real(dp), intent(in) :: lengths(3), distortion
    integer(ip), intent(in) :: seed

    if (any(nsub < 1) .or. any(nel < 1)) call fatal_error('box_mesh_init: nsub and nel must be >= 1')
    if (product(int(nsub, i8)*int(nel, i8) + 1) > int(huge(1_ip), i8)) &
      call fatal_error('box_mesh_init: too many nodes for 32-bit global ids')
    mesh%nsub = nsub
    mesh%nel = nel
    mesh%ng = nsub*nel
    mesh%lengths = lengths
    mesh%h = lengths/real(mesh%ng, dp)
    mesh%distortion = distortion
    mesh%seed = seed
  end subroutine box_mesh_init

  !> Number of global nodes, product(ng+1).
  integer(ip) function num_nodes(this)
    class(box_mesh_t), intent(in) :: this
    num_nodes = product(this%ng + 1)
  end function num_nodes

  !> Number of global elements, product(ng).
  integer(ip) function num_elements(this)
    class(box_mesh_t), intent(in) :: this
    num_elements = product(this%ng)
  end function num_elements

  !> Node gid -> (i,j,k), 0-based.
  pure function node_ijk(this, gid) result(ijk)
    class(box_mesh_t), intent(in) :: this
    integer(ip), intent(in) :: gid
    integer(ip) :: ijk(3), r
    r = gid - 1
    ijk(1) = mod(r, this%ng(1) + 1)
    r = r/(this%ng(1) + 1)
    ijk(2) = mod(r, this%ng(2) + 1)
    ijk(3) = r/(this%ng(2) + 1)
  end function node_ijk

  !> (i,j,k), 0-based -> node gid.
  pure integer(ip) function node_gid(this, ijk)
    class(box_mesh_t), intent(in) :: this
    integer(ip), intent(in) :: ijk(3)
    node_gid = 1 + ijk(1) + (this%ng(1) + 1)*(ijk(2) + (this%ng(2) + 1)*ijk(3))
  end function node_gid

  !> Element gid -> (i,j,k) of its lower corner, 0-based.
  pure function element_ijk(this, gid) result(ijk)
    class(box_mesh_t), intent(in) :: this
    integer(ip), intent(in) :: gid
    integer(ip) :: ijk(3), r
    r = gid - 1
    ijk(1) = mod(r, this%ng(1))
    r = r/this%ng(1)
    ijk(2) = mod(r, this%ng(2))
    ijk(3) = r/this%ng(2)
  end function element_ijk

  !> (i,j,k) of the lower corner, 0-based -> element gid.
  pure integer(ip) function element_gid(this, ijk)
    class(box_mesh_t), intent(in) :: this
    integer(ip), intent(in) :: ijk(3)
    element_gid = 1 + ijk(1) + this%ng(1)*(ijk(2) + this%ng(2)*ijk(3))
  end function element_gid

  !> The gids of the elements (i,j,k) + (di,dj,dk) with lo <= di,dj,dk <= hi
  !> that lie in the mesh, dk slowest then dj then di: gids(1:n). The
  !> elements around a node (i,j,k): lo = -1, hi = 0; the neighbours of an
  !> element and itself: lo = -1, hi = 1.
  pure subroutine elements_near(this, ijk, lo, hi, gids, n)
    class(box_mesh_t), intent(in) :: this
    integer(ip), intent(in) :: ijk(3), lo, hi
    integer(ip), intent(out) :: gids(27), n
    integer(ip) :: di, dj, dk, e(3)
    n = 0
    do dk = lo, hi
      do dj = lo, hi
        do di = lo, hi
          e = ijk + [di, dj, dk]
          if (any(e < 0) .or. any(e >= this%ng)) cycle
          n = n + 1
          gids(n) = this%element_gid(e)
        end do
      end do
    end do
  end subroutine elements_near

  !> The 8 node gids of element `gid` in Q1 order.
  pure function element_nodes(this, gid) result(nodes)
    class(box_mesh_t), intent(in) :: this
    integer(ip), intent(in) :: gid
    integer(ip) :: nodes(8), ijk(3), n1, sj, sk
    ijk = this%element_ijk(gid)
    n1 = this%node_gid(ijk)
    sj = this%ng(1) + 1
    sk = sj*(this%ng(2) + 1)
    nodes(1:4) = [n1, n1 + 1, n1 + 1 + sj, n1 + sj]
    nodes(5:8) = nodes(1:4) + sk
  end function element_nodes

  !> True when node `gid` lies on box face `face` (face_x0 ... face_z1).
  pure logical function node_on_face(this, gid, face)
    class(box_mesh_t), intent(in) :: this
    integer(ip), intent(in) :: gid, face
    integer(ip) :: ijk(3), d
    ijk = this%node_ijk(gid)
    d = (face + 1)/2
    if (mod(face, 2) == 1) then
      node_on_face = ijk(d) == 0
    else
      node_on_face = ijk(d) == this%ng(d)
    end if
  end function node_on_face

  !> True when node `gid` lies on the outer boundary of the box.
  pure logical function node_on_boundary(this, gid)
    class(box_mesh_t), intent(in) :: this
    integer(ip), intent(in) :: gid
    integer(ip) :: ijk(3)
    ijk = this%node_ijk(gid)
    node_on_boundary = any(ijk == 0) .or. any(ijk == this%ng)
  end function node_on_boundary

  !> True when element `gid` has a face on box face `face`.
  pure logical function element_on_face(this, gid, face)
    class(box_mesh_t), intent(in) :: this
    integer(ip), intent(in) :: gid, face
    integer(ip) :: ijk(3), d
    ijk = this%element_ijk(gid)
    d = (face + 1)/2
    if (mod(face, 2) == 1) then
      element_on_face = ijk(d) == 0
    else
      element_on_face = ijk(d) == this%ng(d) - 1
    end if
  end function element_on_face

  !> Id of the box subdomain (I,J,K) holding element `gid`: 1 + I + Nx*(J + Ny*K).
  pure integer(ip) function box_subdomain(this, gid)
    class(box_mesh_t), intent(in) :: this
    integer(ip), intent(in) :: gid
    integer(ip) :: s(3)
    s = this%element_ijk(gid)/this%nel
    box_subdomain = 1 + s(1) + this%nsub(1)*(s(2) + this%nsub(2)*s(3))
  end function box_subdomain

  !> Coordinates of node `gid`, with the distortion of inner nodes.
  pure function node_coords(this, gid) result(x)
    class(box_mesh_t), intent(in) :: this
    integer(ip), intent(in) :: gid
    real(dp) :: x(3)
    integer(ip) :: ijk(3), c
    ijk = this%node_ijk(gid)
    x = real(ijk, dp)*this%h
    ! nodes on the far faces sit exactly at L (no round-off from ng*h)
    where (ijk == this%ng) x = this%lengths
    if (this%distortion > 0 .and. all(ijk > 0) .and. all(ijk < this%ng)) then
      do c = 1, 3
        x(c) = x(c) + this%distortion*this%h(c)*(2*hash_unit(gid, c, this%seed) - 1)
      end do
    end if
  end function node_coords

  !> A pseudo-random number in [0, 1) from three integers alone (a 32-bit
  !> integer hash applied in turn to seed, a and b; 32-bit products are formed
  !> from 16-bit halves, so no intermediate overflows a 64-bit integer).
  pure real(dp) function hash_unit(a, b, seed)
    integer(ip), intent(in) :: a, b, seed
    integer(i8) :: h
    h = mix32(iand(int(seed, i8), mask32))
    h = mix32(iand(ieor(h, iand(int(a, i8), mask32)) + golden, mask32))
    h = mix32(iand(ieor(h, iand(int(b, i8), mask32)) + golden, mask32))
    hash_unit = real(h, dp)/4294967296.0_dp
  end function hash_unit

  !> The "lowbias32" integer finalizer on x in [0, 2**32).
  pure integer(i8) function mix32(x)
    integer(i8), intent(in) :: x
    mix32 = x
    mix32 = ieor(mix32, shiftr(mix32, 16))
    mix32 = mul32(mix32, 2146121005_i8)   ! 0x7feb352d
    mix32 = ieor(mix32, shiftr(mix32, 15))
    mix32 = mul32(mix32, 2221713035_i8)   ! 0x846ca68b
    mix32 = ieor(mix32, shiftr(mix32, 16))
  end function mix32

  !> x*m mod 2**32 for x, m in [0, 2**32).
  pure integer(i8) function mul32(x, m)
    integer(i8), intent(in) :: x, m
    integer(i8) :: lo, hi
    lo = iand(x, 65535_i8)
    hi = shiftr(x, 16)
    mul32 = iand(lo*m + shiftl(iand(hi*m, 65535_i8), 16), mask32)
  end function mul32
end module box_mesh
