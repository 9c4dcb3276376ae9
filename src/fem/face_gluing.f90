!> The gluing rows of a hybrid TFETI cluster glued by faces
!> (`&mesh cluster_gluing = 'faces'`, docs/THEORY.md "Hybrid TFETI"): 6 rows
!> per face two of its subdomains share, the jump of u weighted by the
!> face's rigid modes. The cluster's K^+ (kplus) solves with K restricted
!> to C u = 0.
module face_gluing
  use kinds, only: dp, ip, i8
  use errors, only: fatal_error
  use decomposition, only: decomposition_t
  use subdomain, only: subdomain_t
  use sorting, only: sort_permutation
  use csr_matrix, only: csr_from_coo
  use rigid_modes, only: rigid_body_modes
  use lapack_interfaces, only: dpotrf, dpotrs
  implicit none
  private

  public :: build_face_gluing, remove_gluing_forces

contains

  !> sub%C of cluster `sub` (built by build_cluster without merging; `dec`
  !> the subdomains): for every pair of its subdomains i < j sharing a face
  !> (box neighbours across one face: all the face's nodes, its edges and
  !> corners too), 6 rows Q_f^T (u^i|_f - u^j|_f) with Q_f the orthonormal
  !> rigid modes of the face's nodes about their centre (rank 6: a face of a
  !> box subdomain holds at least 2 x 2 nodes, not collinear). Faces in the
  !> order of (i, j), nodes in ascending global number, so congruent clusters
  !> get the same rows.
  subroutine build_face_gluing(dec, sub, edges)
    type(decomposition_t), intent(in) :: dec
    type(subdomain_t), intent(inout) :: sub
    !> also 3 rows per pair sharing only an edge: the mean jump over its nodes
    logical, intent(in), optional :: edges
    logical :: with_edges
    integer(ip) :: d(3), row0
    integer(i8), allocatable :: pkey(:)
    integer(ip), allocatable :: pa(:), pb(:), order(:), rows(:), cols(:)
    real(dp), allocatable :: vals(:), q(:, :), x(:, :)
    integer(ip) :: a, b, first, last, np, i, k, f, nf, nz, r, c, n
    integer(i8) :: base

    if (.not. allocated(sub%node_copy)) call fatal_error('face_gluing: not a cluster')
    if (any(sub%node_copy == 0)) call fatal_error('face_gluing: the cluster merges its corners')
    with_edges = .false.
    if (present(edges)) with_edges = edges
    base = int(dec%nsubdomains, i8) + 1
    ! (pair of subdomains, node copy in i, node copy in j) for every shared node of a face pair
    allocate (pkey(8*sub%nnodes), pa(8*sub%nnodes), pb(8*sub%nnodes))
    np = 0
    first = 1
    do while (first <= sub%nnodes)
      last = first
      do while (last < sub%nnodes)
        if (sub%node_gid(last + 1) /= sub%node_gid(first)) exit
        last = last + 1
      end do
      do a = first, last
        do b = a + 1, last
          d = abs(box_index(dec, sub%node_copy(a)) - box_index(dec, sub%node_copy(b)))
          if (.not. (sum(d) == 1 .or. (with_edges .and. sum(d) == 2 .and. maxval(d) == 1))) cycle
          np = np + 1
          pkey(np) = int(sub%node_copy(a), i8)*base + sub%node_copy(b)
          pa(np) = a
          pb(np) = b
        end do
      end do
      first = last + 1
    end do
    call sort_permutation(pkey(1:np), order)      ! stable: nodes ascending within a face
    nf = 0
    do i = 1, np
      if (i == 1) then
        nf = 1
      else if (pkey(order(i)) /= pkey(order(i - 1))) then
        nf = nf + 1
      end if
    end do
    allocate (rows(36*np), cols(36*np), vals(36*np))
    nz = 0
    f = 0
    row0 = 0
    first = 1
    do while (first <= np)
      last = first
      do while (last < np)
        if (pkey(order(last + 1)) /= pkey(order(first))) exit
        last = last + 1
      end do
      f = f + 1
      n = last - first + 1
      d = abs(box_index(dec, sub%node_copy(pa(order(first)))) - box_index(dec, sub%node_copy(pb(order(first)))))
      if (sum(d) == 1) then
        ! a face: its 6 rigid-body moments
        x = sub%coords(:, pa(order(first:last)))
        if (allocated(q)) deallocate (q)
        allocate (q(3*n, 6))
        call rigid_body_modes(x, sum(x, dim=2)/n, q)
        do k = 1, n
          do c = 1, 3
            do r = 1, 6
              call push(row0 + r, 3*(pa(order(first + k - 1)) - 1) + c, q(3*(k - 1) + c, r))
              call push(row0 + r, 3*(pb(order(first + k - 1)) - 1) + c, -q(3*(k - 1) + c, r))
            end do
          end do
        end do
        row0 = row0 + 6
      else
        ! an edge: the mean jump of each component
        do k = 1, n
          do c = 1, 3
            call push(row0 + c, 3*(pa(order(first + k - 1)) - 1) + c, 1/sqrt(real(n, dp)))
            call push(row0 + c, 3*(pb(order(first + k - 1)) - 1) + c, -1/sqrt(real(n, dp)))
          end do
        end do
        row0 = row0 + 3
      end if
      first = last + 1
    end do
    call csr_from_coo(row0, sub%ndof, rows(1:nz), cols(1:nz), vals(1:nz), sub%C)
  contains
    subroutine push(i, j, v)
      integer(ip), intent(in) :: i, j
      real(dp), intent(in) :: v
      nz = nz + 1
      rows(nz) = i
      cols(nz) = j
      vals(nz) = v
    end subroutine push
  end subroutine build_face_gluing

  !> The box position (0-based, per direction) of subdomain `s` of `dec`.
  pure function box_index(dec, s) result(b)
    type(decomposition_t), intent(in) :: dec
    integer(ip), intent(in) :: s
    integer(ip) :: b(3), r
    r = s - 1
    b(1) = mod(r, dec%mesh%nsub(1))
    r = r/dec%mesh%nsub(1)
    b(2) = mod(r, dec%mesh%nsub(2))
    b(3) = r/dec%mesh%nsub(2)
  end function box_index
  !> r <- r - C^T (C C^T)^{-1} C r for the gluing rows C of `sub`: the part of
  !> a force vector that the face moments' multipliers cannot carry (the KKT
  !> check's equilibrium of a cluster glued by faces: K u - f + B^T lambda =
  !> -C^T mu). No change without rows.
  subroutine remove_gluing_forces(sub, r)
    type(subdomain_t), intent(in) :: sub
    real(dp), intent(inout) :: r(:)
    real(dp), allocatable :: cct(:, :), y(:, :), row(:)
    integer(ip) :: i, j, k, nc
    integer :: info
    nc = sub%C%nrows
    if (nc == 0) return
    allocate (cct(nc, nc), y(nc, 1), row(sub%ndof))
    row = 0
    do i = 1, nc
      associate (c => sub%C)
        row(c%colind(c%rowptr(i):c%rowptr(i + 1) - 1)) = c%values(c%rowptr(i):c%rowptr(i + 1) - 1)
        do j = 1, nc
          cct(i, j) = 0
          do k = c%rowptr(j), c%rowptr(j + 1) - 1
            cct(i, j) = cct(i, j) + c%values(k)*row(c%colind(k))
          end do
        end do
        row(c%colind(c%rowptr(i):c%rowptr(i + 1) - 1)) = 0
      end associate
    end do
    call sub%C%matvec(r, y(:, 1))
    call dpotrf('U', nc, cct, nc, info)
    if (info /= 0) call fatal_error('remove_gluing_forces: C C^T is not positive definite')
    call dpotrs('U', nc, 1, cct, nc, y, nc, info)
    do i = 1, nc
      do k = sub%C%rowptr(i), sub%C%rowptr(i + 1) - 1
        r(sub%C%colind(k)) = r(sub%C%colind(k)) - sub%C%values(k)*y(i, 1)
      end do
    end do
  end subroutine remove_gluing_forces
end module face_gluing
