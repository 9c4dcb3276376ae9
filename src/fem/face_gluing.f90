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
  use rigid_modes, only: rigid_body_modes, orthonormalize
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
    logical :: with_edges, pair_edges
    character(len=16) :: mode
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
    call get_environment_variable('FC_GLUE', mode)
    if (len_trim(mode) == 0) mode = 'mean'
    pair_edges = with_edges .and. (mode == 'mean' .or. mode == 'diag5')
    if (mode == 'full') then
      call build_full_gluing(sub)
      return
    end if
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
          if (.not. (sum(d) == 1 .or. (pair_edges .and. sum(d) == 2 .and. maxval(d) == 1))) cycle
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
    allocate (rows(54*np + 240*sub%nnodes), cols(54*np + 240*sub%nnodes), vals(54*np + 240*sub%nnodes))
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
        if (index(mode, 'a') > 0) then
          call face_affine(x, d, q)
        else
          allocate (q(3*n, 6))
          call rigid_body_modes(x, sum(x, dim=2)/n, q)
        end if
        do k = 1, n
          do c = 1, 3
            do r = 1, size(q, 2)
              call push(row0 + r, 3*(pa(order(first + k - 1)) - 1) + c, q(3*(k - 1) + c, r))
              call push(row0 + r, 3*(pb(order(first + k - 1)) - 1) + c, -q(3*(k - 1) + c, r))
            end do
          end do
        end do
        row0 = row0 + size(q, 2)
      else if (mode == 'diag5') then
        x = sub%coords(:, pa(order(first:last)))
        if (allocated(q)) deallocate (q)
        call edge_moments(x, q)
        do k = 1, n
          do c = 1, 3
            do r = 1, size(q, 2)
              call push(row0 + r, 3*(pa(order(first + k - 1)) - 1) + c, q(3*(k - 1) + c, r))
              call push(row0 + r, 3*(pb(order(first + k - 1)) - 1) + c, -q(3*(k - 1) + c, r))
            end do
          end do
        end do
        row0 = row0 + size(q, 2)
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
    if (with_edges .and. .not. pair_edges) call class_rows()
    call csr_from_coo(row0, sub%ndof, rows(1:nz), cols(1:nz), vals(1:nz), sub%C)
  contains
    !> star rows over the classes of nodes with >= 3 copies in the cluster
    !> (edges: 5 moments or 3 means; single nodes: 3 jumps when 'v' in mode)
    subroutine class_rows()
      integer(i8), allocatable :: ckey(:)
      integer(ip), allocatable :: gfirst(:), glast(:), corder(:)
      integer(ip) :: ng, g, lo, hi, m, j, kk, p0, s1, sj, pj, nn
      real(dp), allocatable :: xc(:, :), qc(:, :)
      allocate (ckey(sub%nnodes), gfirst(sub%nnodes), glast(sub%nnodes))
      ng = 0
      lo = 1
      do while (lo <= sub%nnodes)
        hi = lo
        do while (hi < sub%nnodes)
          if (sub%node_gid(hi + 1) /= sub%node_gid(lo)) exit
          hi = hi + 1
        end do
        if (hi - lo + 1 >= 3) then
          ng = ng + 1
          gfirst(ng) = lo
          glast(ng) = hi
          ckey(ng) = int(minval(sub%node_copy(lo:hi)), i8)*base + maxval(sub%node_copy(lo:hi))
        end if
        lo = hi + 1
      end do
      call sort_permutation(ckey(1:ng), corder)
      lo = 1
      do while (lo <= ng)
        hi = lo
        do while (hi < ng)
          if (ckey(corder(hi + 1)) /= ckey(corder(lo))) exit
          hi = hi + 1
        end do
        nn = hi - lo + 1
        g = corder(lo)
        m = glast(g) - gfirst(g) + 1
        if (allocated(qc)) deallocate (qc)
        if (mode == 'edgenodes') then
          allocate (qc(3*nn, 3*nn))
          qc = 0
          do kk = 1, 3*nn
            qc(kk, kk) = 1
          end do
        else if (nn >= 2) then
          allocate (xc(3, nn))
          do kk = 1, nn
            xc(:, kk) = sub%coords(:, gfirst(corder(lo + kk - 1)))
          end do
          if (index(mode, '5') > 0) then
            call edge_moments(xc, qc)
          else
            allocate (qc(3*nn, 3))
            qc = 0
            do kk = 1, nn
              do c = 1, 3
                qc(3*(kk - 1) + c, c) = 1/sqrt(real(nn, dp))
              end do
            end do
          end if
          deallocate (xc)
        else if (index(mode, 'v') > 0) then
          allocate (qc(3, 3))
          qc = 0
          do c = 1, 3
            qc(c, c) = 1
          end do
        else
          lo = hi + 1
          cycle
        end if
        ! star from the smallest copy: rows Q^T (u^s1 - u^sj), j = 2..m
        s1 = minval(sub%node_copy(gfirst(g):glast(g)))
        do j = 1, m
          sj = sub%node_copy(gfirst(g) + j - 1)
          if (sj == s1) cycle
          do kk = 1, nn
            p0 = gfirst(corder(lo + kk - 1))
            pj = p0 + findloc(sub%node_copy(p0:glast(corder(lo + kk - 1))), sj, 1) - 1
            p0 = p0 + findloc(sub%node_copy(p0:glast(corder(lo + kk - 1))), s1, 1) - 1
            do c = 1, 3
              do r = 1, size(qc, 2)
                call push(row0 + r, 3*(p0 - 1) + c, qc(3*(kk - 1) + c, r))
                call push(row0 + r, 3*(pj - 1) + c, -qc(3*(kk - 1) + c, r))
              end do
            end do
          end do
          row0 = row0 + size(qc, 2)
        end do
        lo = hi + 1
      end do
    end subroutine class_rows

    subroutine push(i, j, v)
      integer(ip), intent(in) :: i, j
      real(dp), intent(in) :: v
      nz = nz + 1
      rows(nz) = i
      cols(nz) = j
      vals(nz) = v
    end subroutine push
  end subroutine build_face_gluing

  !> The 5 rigid moments of an edge's nodes x (3, n >= 2), orthonormal: the
  !> 3 translations and the 2 rotations about axes perpendicular to the edge.
  subroutine edge_moments(x, q)
    real(dp), intent(in) :: x(:, :)
    real(dp), allocatable, intent(out) :: q(:, :)
    real(dp) :: c(3), a(3), p(3, 2), d(3), e(3)
    integer(ip) :: n, k, r
    n = size(x, 2, kind=ip)
    c = sum(x, dim=2)/n
    a = x(:, n) - x(:, 1)
    a = a/norm2(a)
    e = 0
    e(minloc(abs(a), 1)) = 1
    p(:, 1) = e - dot_product(e, a)*a
    p(:, 1) = p(:, 1)/norm2(p(:, 1))
    p(:, 2) = [a(2)*p(3, 1) - a(3)*p(2, 1), a(3)*p(1, 1) - a(1)*p(3, 1), a(1)*p(2, 1) - a(2)*p(1, 1)]
    allocate (q(3*n, 5))
    q = 0
    do k = 1, n
      q(3*k - 2, 1) = 1
      q(3*k - 1, 2) = 1
      q(3*k, 3) = 1
      d = x(:, k) - c
      do r = 1, 2
        q(3*k - 2:3*k, 3 + r) = [p(2, r)*d(3) - p(3, r)*d(2), p(3, r)*d(1) - p(1, r)*d(3), &
                                 p(1, r)*d(2) - p(2, r)*d(1)]
      end do
    end do
    call orthonormalize(q)
  end subroutine edge_moments

  !> The 9 affine moments of a face's nodes x (3, n): each component times
  !> 1 and the two in-plane coordinates (the face normal: the axis where d = 1).
  subroutine face_affine(x, d, q)
    real(dp), intent(in) :: x(:, :)
    integer(ip), intent(in) :: d(3)
    real(dp), allocatable, intent(out) :: q(:, :)
    real(dp) :: c(3)
    integer(ip) :: n, k, comp, ax(2), j
    n = size(x, 2, kind=ip)
    c = sum(x, dim=2)/n
    j = 0
    do k = 1, 3
      if (d(k) == 1) cycle
      j = j + 1
      ax(j) = k
    end do
    allocate (q(3*n, 9))
    q = 0
    do k = 1, n
      do comp = 1, 3
        q(3*(k - 1) + comp, 3*(comp - 1) + 1) = 1
        q(3*(k - 1) + comp, 3*(comp - 1) + 2) = x(ax(1), k) - c(ax(1))
        q(3*(k - 1) + comp, 3*(comp - 1) + 3) = x(ax(2), k) - c(ax(2))
      end do
    end do
    call orthonormalize(q)
  end subroutine face_affine

  !> Every shared node of the cluster glued: 3 rows per copy after the
  !> smallest, u^s1 - u^sj (the cluster assembled; the floor of any gluing).
  subroutine build_full_gluing(sub)
    type(subdomain_t), intent(inout) :: sub
    integer(ip), allocatable :: rows(:), cols(:)
    real(dp), allocatable :: vals(:)
    integer(ip) :: lo, hi, j, c, nz, row0, p1
    allocate (rows(6*sub%nnodes), cols(6*sub%nnodes), vals(6*sub%nnodes))
    nz = 0
    row0 = 0
    lo = 1
    do while (lo <= sub%nnodes)
      hi = lo
      do while (hi < sub%nnodes)
        if (sub%node_gid(hi + 1) /= sub%node_gid(lo)) exit
        hi = hi + 1
      end do
      p1 = lo + minloc(sub%node_copy(lo:hi), 1) - 1
      do j = lo, hi
        if (j == p1) cycle
        do c = 1, 3
          nz = nz + 1
          rows(nz) = row0 + c; cols(nz) = 3*(p1 - 1) + c; vals(nz) = 1/sqrt(2.0_dp)
          nz = nz + 1
          rows(nz) = row0 + c; cols(nz) = 3*(j - 1) + c; vals(nz) = -1/sqrt(2.0_dp)
        end do
        row0 = row0 + 3
      end do
      lo = hi + 1
    end do
    call csr_from_coo(row0, sub%ndof, rows(1:nz), cols(1:nz), vals(1:nz), sub%C)
  end subroutine build_full_gluing

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
