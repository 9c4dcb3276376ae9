!> The gluing rows of a hybrid TFETI cluster glued by faces
!> (`&mesh cluster_gluing = 'faces'`, docs/THEORY.md "Hybrid TFETI"): the
!> shared nodes of a cluster fall into classes by the set of its subdomains
!> that hold them (a face: 2, an edge: 4, a vertex: 8), and each class glues
!> the copies of its nodes by the rigid-body moments of their jumps. The
!> cluster's K^+ (kplus) solves with K restricted to C u = 0.
module face_gluing
  use kinds, only: dp, ip, i8
  use errors, only: fatal_error
  use decomposition, only: decomposition_t
  use subdomain, only: subdomain_t
  use sorting, only: sort_permutation
  use csr_matrix, only: csr_from_coo
  use lapack_interfaces, only: dpotrf, dpotrs
  implicit none
  private

  public :: build_face_gluing, gluing_gram, remove_gluing_forces

  !> The block Cholesky factor of C C^T of a cluster (gluing_gram).
  type, public :: gluing_gram_t
    real(dp), allocatable :: u(:, :)           !< the factors of the diagonal blocks, in place
    integer(ip), allocatable :: first(:)       !< first row of each block, then nrows + 1
  end type gluing_gram_t

  !> The entries of C in coordinate form, filled jump by jump.
  type :: gluing_rows_t
    integer(ip) :: nrows = 0, nz = 0
    integer(ip), allocatable :: row(:), col(:)
    real(dp), allocatable :: val(:)
  contains
    procedure :: add_jump
  end type gluing_rows_t

contains

  !> sub%C of cluster `sub` (built by build_cluster without merging; `dec`
  !> the subdomains). Its shared nodes in classes by the set of its
  !> subdomains s_1 < ... < s_m holding them (a box of subdomains, named by
  !> s_1 and s_m): m = 2 a face's nodes off the cluster's inner edges, m = 4
  !> an inner edge's nodes off its inner vertices, m = 8 an inner vertex. Per
  !> class the rows Q^T (u^s_1 - u^s_k), k = 2..m, over its nodes, Q an
  !> orthonormal basis of the rigid-body moments there (class_moments: 6 on a
  !> face, 5 on a straight edge, 3 on one node). Classes hold disjoint nodes
  !> and each k another copy, so C has full row rank. Classes in the order of
  !> (s_1, s_m), nodes ascending: congruent clusters get the same rows.
  subroutine build_face_gluing(dec, sub)
    type(decomposition_t), intent(in) :: dec
    type(subdomain_t), intent(inout) :: sub
    integer(i8), allocatable :: key(:)
    integer(ip), allocatable :: gfirst(:), order(:), nodes(:), pa(:), pb(:)
    real(dp), allocatable :: q(:, :)
    integer(ip) :: ng, lo, hi, k, j, m
    integer(ip), allocatable :: copies(:)
    integer(i8) :: base
    type(gluing_rows_t) :: rows

    if (.not. allocated(sub%node_copy)) call fatal_error('face_gluing: not a cluster')
    if (any(sub%node_copy == 0)) call fatal_error('face_gluing: the cluster merges its corners')
    base = int(dec%nsubdomains, i8) + 1
    allocate (key(sub%nnodes), gfirst(sub%nnodes))
    ng = 0
    lo = 1
    do while (lo <= sub%nnodes)
      hi = same_node_last(sub, lo)
      if (hi > lo) then
        ng = ng + 1
        gfirst(ng) = lo
        key(ng) = int(minval(sub%node_copy(lo:hi)), i8)*base + maxval(sub%node_copy(lo:hi))
      end if
      lo = hi + 1
    end do
    call sort_permutation(key(1:ng), order)      ! stable: nodes ascending within a class
    allocate (rows%row(64*sub%nnodes), rows%col(64*sub%nnodes), rows%val(64*sub%nnodes))
    lo = 1
    do while (lo <= ng)
      hi = lo
      do while (hi < ng)
        if (key(order(hi + 1)) /= key(order(lo))) exit
        hi = hi + 1
      end do
      nodes = gfirst(order(lo:hi))
      m = same_node_last(sub, nodes(1)) - nodes(1) + 1
      copies = sub%node_copy(nodes(1):nodes(1) + m - 1)
      call sort_small(copies)
      call class_moments(sub%coords(:, nodes), q)
      allocate (pa(size(nodes)), pb(size(nodes)))
      do k = 1, size(nodes, kind=ip)
        pa(k) = nodes(k) - 1 + findloc(sub%node_copy(nodes(k):nodes(k) + m - 1), copies(1), 1)
      end do
      do j = 2, m
        do k = 1, size(nodes, kind=ip)
          pb(k) = nodes(k) - 1 + findloc(sub%node_copy(nodes(k):nodes(k) + m - 1), copies(j), 1)
        end do
        call rows%add_jump(q, pa, pb)
      end do
      deallocate (pa, pb)
      lo = hi + 1
    end do
    call csr_from_coo(rows%nrows, sub%ndof, rows%row(1:rows%nz), rows%col(1:rows%nz), rows%val(1:rows%nz), sub%C)
  end subroutine build_face_gluing

  !> The last position of the copies of the node at position `first` of the
  !> cluster (its copies are consecutive: node_gid ascending).
  pure integer(ip) function same_node_last(sub, first) result(last)
    type(subdomain_t), intent(in) :: sub
    integer(ip), intent(in) :: first
    last = first
    do while (last < sub%nnodes)
      if (sub%node_gid(last + 1) /= sub%node_gid(first)) exit
      last = last + 1
    end do
  end function same_node_last

  !> Ascending order of a few integers (insertion).
  pure subroutine sort_small(a)
    integer(ip), intent(inout) :: a(:)
    integer(ip) :: j, k
    do j = 2, size(a, kind=ip)
      do k = j, 2, -1
        if (a(k - 1) <= a(k)) exit
        a([k - 1, k]) = a([k, k - 1])
      end do
    end do
  end subroutine sort_small

  !> The rigid-body moments of a class's nodes x (3, n) about their centre
  !> (translations, rotations): q an orthonormal basis of their span on these
  !> nodes, columns that vanish or depend on the earlier ones dropped (6 on a
  !> face; 5 on collinear nodes, a straight edge: the rotation about the line
  !> moves none; 3 on one node: the jump itself).
  subroutine class_moments(x, q)
    real(dp), intent(in) :: x(:, :)
    real(dp), allocatable, intent(out) :: q(:, :)
    real(dp), allocatable :: a(:, :)
    real(dp) :: c(3), e(3)
    integer(ip) :: n, k
    n = size(x, 2, kind=ip)
    c = sum(x, dim=2)/n
    allocate (a(3*n, 6))
    a = 0
    do k = 1, n
      e = x(:, k) - c
      a(3*k - 2:3*k, 1:3) = reshape([1, 0, 0, 0, 1, 0, 0, 0, 1], [3, 3])
      a(3*k - 2:3*k, 4) = [0.0_dp, -e(3), e(2)]
      a(3*k - 2:3*k, 5) = [e(3), 0.0_dp, -e(1)]
      a(3*k - 2:3*k, 6) = [-e(2), e(1), 0.0_dp]
    end do
    call independent_columns(a, q)
  end subroutine class_moments

  !> q: an orthonormal basis of the span of a's columns (modified Gram-Schmidt,
  !> twice; a column is dropped when what remains of it is below 1e-8 of its
  !> norm, or its norm below 1e-12 of the largest column's).
  subroutine independent_columns(a, q)
    real(dp), intent(inout) :: a(:, :)
    real(dp), allocatable, intent(out) :: q(:, :)
    integer(ip) :: j, k, r, pass
    real(dp) :: nrm0, nrm, big
    big = maxval(norm2(a, dim=1))
    r = 0
    do j = 1, size(a, 2, kind=ip)
      nrm0 = norm2(a(:, j))
      if (.not. nrm0 > 1.0e-12_dp*big) cycle
      do pass = 1, 2
        do k = 1, r
          a(:, j) = a(:, j) - dot_product(a(:, k), a(:, j))*a(:, k)
        end do
      end do
      nrm = norm2(a(:, j))
      if (.not. nrm > 1.0e-8_dp*nrm0) cycle
      r = r + 1
      a(:, r) = a(:, j)/nrm
    end do
    q = a(:, 1:r)
  end subroutine independent_columns

  !> Rows q(:, r)^T (u^a - u^b), r = 1..size(q, 2), of the jump between the
  !> copies pa(k) and pb(k) of the nodes k (q's rows: node k, component c at 3(k-1)+c).
  subroutine add_jump(self, q, pa, pb)
    class(gluing_rows_t), intent(inout) :: self
    real(dp), intent(in) :: q(:, :)
    integer(ip), intent(in) :: pa(:), pb(:)
    integer(ip), allocatable :: itmp(:)
    real(dp), allocatable :: rtmp(:)
    integer(ip) :: k, c, r, need
    need = self%nz + 2*size(q, kind=ip)
    if (need > size(self%row, kind=ip)) then
      allocate (itmp(2*need))
      itmp(1:self%nz) = self%row(1:self%nz)
      call move_alloc(itmp, self%row)
      allocate (itmp(2*need))
      itmp(1:self%nz) = self%col(1:self%nz)
      call move_alloc(itmp, self%col)
      allocate (rtmp(2*need))
      rtmp(1:self%nz) = self%val(1:self%nz)
      call move_alloc(rtmp, self%val)
    end if
    do k = 1, size(pa, kind=ip)
      do c = 1, 3
        do r = 1, size(q, 2, kind=ip)
          self%row(self%nz + 1:self%nz + 2) = self%nrows + r
          self%col(self%nz + 1) = 3*(pa(k) - 1) + c
          self%col(self%nz + 2) = 3*(pb(k) - 1) + c
          self%val(self%nz + 1) = q(3*(k - 1) + c, r)
          self%val(self%nz + 2) = -q(3*(k - 1) + c, r)
          self%nz = self%nz + 2
        end do
      end do
    end do
    self%nrows = self%nrows + size(q, 2, kind=ip)
  end subroutine add_jump

  !> The Cholesky factor of C C^T for the gluing rows C of `sub`, block by
  !> block (C C^T is block diagonal: rows of different classes of shared
  !> nodes share no dof), what remove_gluing_forces takes; the same for every
  !> cluster with the same C.
  subroutine gluing_gram(sub, g)
    type(subdomain_t), intent(in) :: sub
    type(gluing_gram_t), intent(out) :: g
    real(dp), allocatable :: tval(:)
    integer(ip), allocatable :: tptr(:), trow(:), fill(:), starts(:)
    integer(ip) :: i, k, l, col, nc, first, reach, nb, nblocks
    integer :: info
    nc = sub%C%nrows
    allocate (g%u(nc, nc), starts(nc + 1))
    g%u = 0
    if (nc == 0) then
      g%first = [1_ip]
      return
    end if
    ! C^T by columns of C (the rows touching each dof), so that C C^T costs
    ! the sum over dofs of the squared number of rows touching it
    associate (c => sub%C)
      allocate (tptr(sub%ndof + 1), fill(sub%ndof), trow(c%rowptr(nc + 1) - 1), tval(c%rowptr(nc + 1) - 1))
      tptr = 0
      do k = 1, c%rowptr(nc + 1) - 1
        tptr(c%colind(k) + 1) = tptr(c%colind(k) + 1) + 1
      end do
      tptr(1) = 1
      do col = 1, sub%ndof
        tptr(col + 1) = tptr(col + 1) + tptr(col)
      end do
      fill = tptr(1:sub%ndof)
      do i = 1, nc
        do k = c%rowptr(i), c%rowptr(i + 1) - 1
          trow(fill(c%colind(k))) = i
          tval(fill(c%colind(k))) = c%values(k)
          fill(c%colind(k)) = fill(c%colind(k)) + 1
        end do
      end do
    end associate
    do col = 1, sub%ndof
      do k = tptr(col), tptr(col + 1) - 1
        do l = tptr(col), tptr(col + 1) - 1
          g%u(trow(k), trow(l)) = g%u(trow(k), trow(l)) + tval(k)*tval(l)
        end do
      end do
    end do
    ! factor block by block, a block ending where no row couples beyond it
    first = 1
    reach = 0
    nblocks = 0
    do i = 1, nc
      do k = 1, nc
        if (g%u(k, i) /= 0) reach = max(reach, k)
      end do
      if (reach > i) cycle
      nb = i - first + 1
      call dpotrf('U', nb, g%u(first, first), nc, info)
      if (info /= 0) call fatal_error('gluing_gram: C C^T is not positive definite')
      nblocks = nblocks + 1
      starts(nblocks) = first
      first = i + 1
    end do
    starts(nblocks + 1) = nc + 1
    g%first = starts(1:nblocks + 1)
  end subroutine gluing_gram

  !> r <- r - C^T (C C^T)^{-1} C r for the gluing rows C of `sub`, `g` the
  !> factor of gluing_gram: the part of a force vector that the face
  !> moments' multipliers cannot carry (the KKT check's equilibrium of a
  !> cluster glued by faces: K u - f + B^T lambda = -C^T mu). No change
  !> without rows.
  subroutine remove_gluing_forces(sub, g, r)
    type(subdomain_t), intent(in) :: sub
    type(gluing_gram_t), intent(in) :: g
    real(dp), intent(inout) :: r(:)
    real(dp), allocatable :: y(:, :)
    integer(ip) :: i, k, nc, b, first, nb
    integer :: info
    nc = sub%C%nrows
    if (nc == 0) return
    allocate (y(nc, 1))
    call sub%C%matvec(r, y(:, 1))
    do b = 1, size(g%first) - 1
      first = g%first(b)
      nb = g%first(b + 1) - first
      call dpotrs('U', nb, 1, g%u(first, first), nc, y(first, 1), nc, info)
    end do
    do i = 1, nc
      do k = sub%C%rowptr(i), sub%C%rowptr(i + 1) - 1
        r(sub%C%colind(k)) = r(sub%C%colind(k)) - sub%C%values(k)*y(i, 1)
      end do
    end do
  end subroutine remove_gluing_forces
end module face_gluing
