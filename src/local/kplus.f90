!> Generalized inverse K^+ of a floating subdomain stiffness matrix by
!> regularization with fixing nodes (docs/THEORY.md, "Generalized inverse K^+").
!>
!> K_reg = K + rho_f Q_F Q_F^T, where F is a small set of well separated
!> "fixing" nodes of the subdomain and the columns of Q_F are an orthonormal
!> basis of the rigid body motions restricted to the dofs of F
!> (Q_F = R_F (R_F^T R_F)^{-1/2}, R_F = the rows of R at the dofs of F, the
!> other rows zero). rho_f = regularization * mean(diag(K)).
!>
!> Why it is a generalized inverse: for b = K y, among the solutions u of
!> K u = b (u0 + R g for any g) there is one with R_F^T u = 0 (solve the 6x6
!> system R_F^T R_F g = -R_F^T u0, R_F of rank 6); it also solves K_reg u = b,
!> and K_reg is positive definite (x^T K_reg x = 0 forces x = R g and
!> R_F^T R g = R_F^T R_F g = 0, so g = 0). Hence K K_reg^{-1} K y = K y, and
!> K^+ b is that solution whatever rho_f > 0 and whatever basis of span(R_F):
!> they only change the conditioning of K_reg. The orthonormal basis makes
!> the added block rho_f times an orthogonal projector, so rho_f really is the
!> stiffness of the fixing springs (with R_F itself the block would shrink
!> like |F|/nnodes, because R is orthonormal over the whole subdomain).
!> Measured: ||K K^+ K x - K x|| / ||K x|| ~ 1e-15 for nel^3 = 1 ... 16^3,
!> nu = 0.3 and 0.499, rho_f / mean(diag K) = 1e-3 ... 1e3.
!>
!> The added block couples only the dofs of F (3|F| <= 36 of them), so K_reg
!> keeps the sparsity of K plus one small dense block. Its upper triangle goes
!> to MUMPS (SYM = 1, MPI_COMM_SELF, one instance per subdomain kept for the
!> repeated solves).
!>
!> A cluster glued by faces (sub%C with rows, src/fem/face_gluing.f90): K^+
!> applies u = the first block of the solution of
!>   [K_reg  C^T] [u ]   [b]
!>   [C      0  ] [mu] = [0],
!> factorized once by MUMPS as a symmetric indefinite matrix (SYM = 2, AMD
!> ordering): a generalized inverse of K restricted to null(C), whose kernel
!> there is the cluster's 6 rigid modes (docs/THEORY.md "Hybrid TFETI").
!> Ordering: 'metis' = METIS nested dissection of the node
!> graph of K_reg (3x smaller than the dof graph) expanded to the dofs of each
!> node, given to MUMPS as its pivot order; 'amd' = MUMPS's AMD.
module kplus
  use kinds, only: dp, ip, i8
  use lapack_interfaces, only: dsyev
  use errors, only: fatal_error
  use subdomain, only: subdomain_t, node_dofs
  use sorting, only: sort_ints, append_int
  use mumps_wrapper, only: mumps_t
  use metis_wrapper, only: metis_node_nd
  use mpi_f08, only: MPI_COMM_SELF
  implicit none
  private

  !> Fixing nodes are added until the smallest eigenvalue of R_F^T R_F is at
  !> least this fraction of the largest one ...
  real(dp), parameter :: gram_ratio_wanted = 1.0e-2_dp
  !> ... up to this many nodes; below `gram_ratio_min` R_F has no rank 6.
  integer(ip), parameter :: max_fixing_nodes = 12
  real(dp), parameter :: gram_ratio_min = 1.0e-12_dp


  !> K^+ of one subdomain. Components are for reading (diagnostics, tests).
  !> Do not copy a kplus_t by assignment (it holds a MUMPS instance).
  public :: regularized_system

  type, public :: kplus_t
    integer(ip) :: ndof = 0                       !< order of K
    integer(ip) :: nc = 0                         !< constraint rows C (a cluster glued by faces), else 0
    real(dp) :: rho = 0                           !< rho_f, stiffness of the fixing springs
    real(dp) :: gram_ratio = 0                    !< min/max eigenvalue of R_F^T R_F
    integer(ip), allocatable :: fixing_nodes(:)   !< local node numbers of F
    type(mumps_t), private :: solver
    real(dp), allocatable, private :: w(:), wm(:, :)   !< [u; mu] of the constrained solves
  contains
    procedure :: init
    procedure :: solve
    procedure :: solve_many
    procedure :: factor_bytes
    procedure :: factor_flops
    procedure :: free
  end type kplus_t

contains

  !> Factorize K_reg of `sub` (which must hold K and R). `regularization`:
  !> rho_f relative to the mean diagonal of K (> 0; 1 is a good value).
  !> `ordering`: 'amd' or 'metis'.
  subroutine init(this, sub, regularization, ordering)
    class(kplus_t), intent(inout) :: this
    type(subdomain_t), intent(in) :: sub
    real(dp), intent(in) :: regularization
    character(len=*), intent(in) :: ordering
    real(dp), allocatable :: block(:, :)
    integer(ip), allocatable :: fixing_dofs(:), irn(:), jcn(:), perm(:)
    real(dp), allocatable :: a(:)

    call this%free()
    call check_subdomain(sub)
    if (.not. (regularization > 0)) call fatal_error('kplus: the regularization must be > 0')
    if (ordering /= 'amd' .and. ordering /= 'metis') &
      call fatal_error("kplus: unknown ordering '"//trim(ordering)//"' (amd or metis)")
    this%ndof = sub%ndof
    this%rho = regularization*mean_diagonal(sub)
    if (.not. (this%rho > 0)) call fatal_error('kplus: K has no positive diagonal')

    call choose_fixing_nodes(sub, this%fixing_nodes, this%gram_ratio)
    call fixing_block(sub, this%fixing_nodes, this%rho, fixing_dofs, block)
    call upper_coo(sub, fixing_dofs, block, irn, jcn, a)
    this%nc = sub%C%nrows
    if (this%nc > 0) then
      call add_constraints(sub, irn, jcn, a)
      allocate (this%w(sub%ndof + this%nc))
      call this%solver%init(MPI_COMM_SELF, spd=.false.)
      call this%solver%set_centralized(sub%ndof + this%nc, irn, jcn, a)
      call this%solver%set_ordering('amd')
      call this%solver%factorize()
      return
    end if

    call this%solver%init(MPI_COMM_SELF, spd=.true.)
    call this%solver%set_centralized(sub%ndof, irn, jcn, a)
    deallocate (irn, jcn, a)
    if (ordering == 'metis') then
      call node_nested_dissection(sub, this%fixing_nodes, perm)
      call this%solver%set_ordering('metis', perm)
    else
      call this%solver%set_ordering('amd')
    end if
    call this%solver%factorize()
  end subroutine init

  !> x <- K^+ x (in place).
  subroutine solve(this, x)
    class(kplus_t), intent(inout) :: this
    real(dp), intent(inout) :: x(:)
    if (size(x) /= this%ndof) call fatal_error('kplus%solve: x must have ndof entries')
    if (this%nc > 0) then
      this%w(1:this%ndof) = x
      this%w(this%ndof + 1:) = 0
      call this%solver%solve(this%w)
      x = this%w(1:this%ndof)
      return
    end if
    call this%solver%solve(x)
  end subroutine solve

  !> x(:, j) <- K^+ x(:, j) for every column j, in one MUMPS call.
  subroutine solve_many(this, x)
    class(kplus_t), intent(inout) :: this
    real(dp), intent(inout) :: x(:, :)
    if (size(x, 1) /= this%ndof) call fatal_error('kplus%solve_many: x must have ndof rows')
    if (size(x, 2) == 0) return
    if (this%nc > 0) then
      if (allocated(this%wm)) then
        if (size(this%wm, 2) /= size(x, 2)) deallocate (this%wm)
      end if
      if (.not. allocated(this%wm)) allocate (this%wm(this%ndof + this%nc, size(x, 2)))
      this%wm(1:this%ndof, :) = x
      this%wm(this%ndof + 1:, :) = 0
      call this%solver%solve(this%wm)
      x = this%wm(1:this%ndof, :)
      return
    end if
    call this%solver%solve(x)
  end subroutine solve_many

  !> Bytes of the factors of K_reg (see mumps_t%factor_bytes).
  integer(i8) function factor_bytes(this)
    class(kplus_t), intent(in) :: this
    factor_bytes = this%solver%factor_bytes()
  end function factor_bytes

  !> Floating-point operations of the factorization (MUMPS's count).
  real(dp) function factor_flops(this)
    class(kplus_t), intent(in) :: this
    factor_flops = this%solver%factor_flops()
  end function factor_flops

  !> Release the factorization. Safe on a never initialized object.
  subroutine free(this)
    class(kplus_t), intent(inout) :: this
    call this%solver%free()
    if (allocated(this%fixing_nodes)) deallocate (this%fixing_nodes)
    if (allocated(this%w)) deallocate (this%w)
    if (allocated(this%wm)) deallocate (this%wm)
    this%ndof = 0
    this%nc = 0
    this%rho = 0
    this%gram_ratio = 0
  end subroutine free

  !> The upper triangle of K_reg = K + rho_f R_F R_F^T of `sub` in
  !> coordinate form, with rho_f = regularization * mean diag(K) and the
  !> fixing nodes chosen as in `init`, and (ordering 'metis') the METIS pivot
  !> order perm(dof) = position; perm is not allocated for 'amd'. Used by
  !> kplus_block to factorize many subdomains as one block-diagonal matrix.
  !> `allowed` (optional, per node): choose the fixing nodes among these
  !> when they fix the rigid body motions (else among all nodes);
  !> `fixing_dofs_out`, `fixing_block_out` (optional): the dofs of the fixing
  !> nodes (ascending) and the block rho_f Q_F Q_F^T added on them.
  subroutine regularized_system(sub, regularization, ordering, irn, jcn, a, perm, allowed, fixing_dofs_out, &
                                fixing_block_out)
    type(subdomain_t), intent(in) :: sub
    real(dp), intent(in) :: regularization
    character(len=*), intent(in) :: ordering
    integer(ip), allocatable, intent(out) :: irn(:), jcn(:), perm(:)
    real(dp), allocatable, intent(out) :: a(:)
    logical, intent(in), optional :: allowed(:)
    integer(ip), allocatable, intent(out), optional :: fixing_dofs_out(:)
    real(dp), allocatable, intent(out), optional :: fixing_block_out(:, :)
    integer(ip), allocatable :: nodes(:), fixing_dofs(:)
    real(dp), allocatable :: block(:, :)
    real(dp) :: ratio, rho
    call check_subdomain(sub)
    if (sub%C%nrows > 0) call fatal_error('kplus: a cluster glued by faces has no K_reg of its own '// &
                                          '(its K^+ is the constrained solve of kplus_t)')
    if (.not. (regularization > 0)) call fatal_error('kplus: the regularization must be > 0')
    rho = regularization*mean_diagonal(sub)
    if (.not. (rho > 0)) call fatal_error('kplus: K has no positive diagonal')
    call choose_fixing_nodes(sub, nodes, ratio, allowed)
    call fixing_block(sub, nodes, rho, fixing_dofs, block)
    call upper_coo(sub, fixing_dofs, block, irn, jcn, a)
    if (ordering == 'metis') call node_nested_dissection(sub, nodes, perm)
    if (present(fixing_dofs_out)) fixing_dofs_out = fixing_dofs
    if (present(fixing_block_out)) fixing_block_out = block
  end subroutine regularized_system

  ! ---------------------------------------------------------------- private

  subroutine check_subdomain(sub)
    type(subdomain_t), intent(in) :: sub
    if (sub%ndof < 1 .or. sub%ndof /= 3*sub%nnodes) call fatal_error('kplus: subdomain without dofs')
    if (.not. allocated(sub%K%rowptr) .or. sub%K%nrows /= sub%ndof .or. sub%K%ncols /= sub%ndof) &
      call fatal_error('kplus: the subdomain has no stiffness matrix K (assemble it first)')
    if (.not. allocated(sub%R)) call fatal_error('kplus: the subdomain has no kernel basis R')
    if (size(sub%R, 1) /= sub%ndof .or. size(sub%R, 2) /= 6) &
      call fatal_error('kplus: the kernel basis R must be ndof x 6')
    if (.not. allocated(sub%coords)) call fatal_error('kplus: the subdomain has no coordinates')
  end subroutine check_subdomain

  real(dp) function mean_diagonal(sub)
    type(subdomain_t), intent(in) :: sub
    integer(ip) :: i, k
    real(dp) :: s
    s = 0
    do i = 1, sub%ndof
      do k = sub%K%rowptr(i), sub%K%rowptr(i + 1) - 1
        if (sub%K%colind(k) == i) s = s + sub%K%values(k)
      end do
    end do
    mean_diagonal = s/sub%ndof
  end function mean_diagonal

  !> Fixing nodes: the node farthest from the centroid, the node farthest from
  !> it, the node that maximizes the triangle area with these two, the node
  !> farthest from their plane; then, while R_F^T R_F is poorly conditioned,
  !> the node farthest from all chosen ones. Works for any shape (METIS-cut
  !> subdomains too): only distances between nodes are used.
  subroutine choose_fixing_nodes(sub, nodes, ratio, allowed)
    type(subdomain_t), intent(in) :: sub
    integer(ip), allocatable, intent(out) :: nodes(:)
    real(dp), intent(out) :: ratio
    logical, intent(in), optional :: allowed(:)
    logical, allocatable :: ok(:)
    allocate (ok(sub%nnodes))
    ok = .true.
    if (present(allowed)) then
      if (size(allowed) /= sub%nnodes) call fatal_error('kplus: the allowed fixing nodes need one flag per node')
      if (any(allowed)) then
        ok = allowed
        call choose_among(sub, ok, nodes, ratio)
        if (ratio >= gram_ratio_min) return
      end if
      ok = .true.
    end if
    call choose_among(sub, ok, nodes, ratio)
    if (ratio < gram_ratio_min) then
      block
        character(len=160) :: msg
        write (msg, '(a,i0,a,es9.2)') 'kplus: no set of fixing nodes of subdomain ', sub%id, &
          ' fixes its rigid body motions; eigenvalue ratio of R_F^T R_F ', ratio
        call fatal_error(trim(msg))
      end block
    end if
  end subroutine choose_fixing_nodes

  !> choose_fixing_nodes's rule among the nodes with ok(node) (at least one).
  subroutine choose_among(sub, ok, nodes, ratio)
    type(subdomain_t), intent(in) :: sub
    logical, intent(in) :: ok(:)
    integer(ip), allocatable, intent(out) :: nodes(:)
    real(dp), intent(out) :: ratio
    real(dp), allocatable :: mindist(:)
    integer(ip) :: chosen(max_fixing_nodes), nf, a, best, limit
    real(dp) :: c(3), normal(3), score, best_score, diameter

    allocate (mindist(sub%nnodes))
    associate (xyz => sub%coords, nn => sub%nnodes)
      limit = min(max_fixing_nodes, count(ok, kind=ip))
      if (all(ok)) then
        c = sum(xyz, dim=2)/nn
      else
        c = 0
        do a = 1, nn
          if (ok(a)) c = c + xyz(:, a)
        end do
        c = c/count(ok)
      end if
      chosen(1) = farthest_from(c)
      chosen(2) = farthest_from(xyz(:, chosen(1)))
      nf = 2
      diameter = norm2(xyz(:, chosen(2)) - xyz(:, chosen(1)))
      ! largest triangle with the first two
      best = 0
      best_score = 0
      do a = 1, nn
        if (.not. ok(a)) cycle
        score = norm2(cross(xyz(:, a) - xyz(:, chosen(1)), xyz(:, chosen(2)) - xyz(:, chosen(1))))
        if (score > best_score) then
          best_score = score
          best = a
        end if
      end do
      if (best > 0 .and. best_score > 1.0e-8_dp*diameter**2) then
        nf = nf + 1
        chosen(nf) = best
        ! farthest from the plane of the three
        normal = cross(xyz(:, chosen(2)) - xyz(:, chosen(1)), xyz(:, chosen(3)) - xyz(:, chosen(1)))
        normal = normal/norm2(normal)
        best = 0
        best_score = 0
        do a = 1, nn
          if (.not. ok(a)) cycle
          score = abs(dot_product(xyz(:, a) - xyz(:, chosen(1)), normal))
          if (score > best_score) then
            best_score = score
            best = a
          end if
        end do
        if (best > 0 .and. best_score > 1.0e-8_dp*diameter .and. nf < limit) then
          nf = nf + 1
          chosen(nf) = best
        end if
      end if

      ! more nodes while R_F^T R_F is poorly conditioned: farthest-point sampling
      do a = 1, nn
        mindist(a) = merge(huge(1.0_dp), -1.0_dp, ok(a))
      end do
      do a = 1, nf
        call update_mindist(chosen(a))
      end do
      ratio = gram_ratio_of(sub, chosen(1:nf))
      do while (ratio < gram_ratio_wanted .and. nf < limit)
        best = maxloc(mindist, dim=1)
        if (mindist(best) <= 0) exit
        nf = nf + 1
        chosen(nf) = best
        call update_mindist(best)
        ratio = gram_ratio_of(sub, chosen(1:nf))
      end do
      nodes = chosen(1:nf)
    end associate

  contains

    integer(ip) function farthest_from(p)
      real(dp), intent(in) :: p(3)
      integer(ip) :: b
      real(dp) :: d, dmax
      farthest_from = 1
      dmax = -1
      do b = 1, sub%nnodes
        if (.not. ok(b)) cycle
        d = sum((sub%coords(:, b) - p)**2)
        if (d > dmax) then
          dmax = d
          farthest_from = b
        end if
      end do
    end function farthest_from

    subroutine update_mindist(node)
      integer(ip), intent(in) :: node
      integer(ip) :: b
      real(dp) :: x(3)
      x = sub%coords(:, node)
      do b = 1, sub%nnodes
        if (mindist(b) < 0) cycle
        mindist(b) = min(mindist(b), norm2(sub%coords(:, b) - x))
      end do
    end subroutine update_mindist
  end subroutine choose_among

  pure function cross(u, v) result(w)
    real(dp), intent(in) :: u(3), v(3)
    real(dp) :: w(3)
    w = [u(2)*v(3) - u(3)*v(2), u(3)*v(1) - u(1)*v(3), u(1)*v(2) - u(2)*v(1)]
  end function cross

  !> The rows of R at the dofs of `nodes`: (3*size(nodes), 6).
  function restricted_r(sub, nodes) result(rf)
    type(subdomain_t), intent(in) :: sub
    integer(ip), intent(in) :: nodes(:)
    real(dp) :: rf(3*size(nodes), 6)
    integer(ip) :: i, c
    do i = 1, size(nodes)
      do c = 1, 3
        rf(3*(i - 1) + c, :) = sub%R(3*(nodes(i) - 1) + c, :)
      end do
    end do
  end function restricted_r

  !> Eigenvalues (ascending) and eigenvectors of the 6x6 Gram matrix R_F^T R_F.
  subroutine gram_eigen(rf, lambda, v)
    real(dp), intent(in) :: rf(:, :)
    real(dp), intent(out) :: lambda(6), v(6, 6)
    real(dp) :: work(64)
    integer :: info
    v = matmul(transpose(rf), rf)
    call dsyev('V', 'U', 6, v, 6, lambda, work, size(work), info)
    if (info /= 0) call fatal_error('kplus: LAPACK dsyev failed on the 6x6 Gram matrix of R_F')
  end subroutine gram_eigen

  real(dp) function gram_ratio_of(sub, nodes)
    type(subdomain_t), intent(in) :: sub
    integer(ip), intent(in) :: nodes(:)
    real(dp) :: lambda(6), v(6, 6)
    call gram_eigen(restricted_r(sub, nodes), lambda, v)
    gram_ratio_of = 0
    if (lambda(6) > 0) gram_ratio_of = max(lambda(1), 0.0_dp)/lambda(6)
  end function gram_ratio_of

  !> The dense block rho Q_F Q_F^T on the dofs of the fixing nodes, the dofs
  !> in ascending order.
  subroutine fixing_block(sub, nodes, rho, dofs, block)
    type(subdomain_t), intent(in) :: sub
    integer(ip), intent(in) :: nodes(:)
    real(dp), intent(in) :: rho
    integer(ip), allocatable, intent(out) :: dofs(:)
    real(dp), allocatable, intent(out) :: block(:, :)
    integer(ip), allocatable :: sorted(:)
    real(dp), allocatable :: rf(:, :), q(:, :)
    real(dp) :: lambda(6), v(6, 6)
    integer(ip) :: j

    sorted = nodes
    call sort_ints(sorted)
    dofs = node_dofs(sorted)
    rf = restricted_r(sub, sorted)
    call gram_eigen(rf, lambda, v)
    ! Q_F = R_F V diag(lambda)^(-1/2): orthonormal columns spanning R_F
    do j = 1, 6
      v(:, j) = v(:, j)/sqrt(lambda(j))
    end do
    q = matmul(rf, v)
    block = rho*matmul(q, transpose(q))
  end subroutine fixing_block

  !> Upper triangle of K_reg in coordinate form: the entries of K with
  !> column >= row, then the upper triangle of the fixing block (MUMPS sums
  !> the duplicates).
  subroutine upper_coo(sub, fixing_dofs, block, irn, jcn, a)
    type(subdomain_t), intent(in) :: sub
    integer(ip), intent(in) :: fixing_dofs(:)
    real(dp), intent(in) :: block(:, :)
    integer(ip), allocatable, intent(out) :: irn(:), jcn(:)
    real(dp), allocatable, intent(out) :: a(:)
    integer(ip) :: i, j, nz, nb

    nb = size(fixing_dofs)
    call sub%K%upper_coo(irn, jcn, a, nb*(nb + 1)/2)
    nz = size(a) - nb*(nb + 1)/2
    do j = 1, nb
      do i = 1, j
        nz = nz + 1
        irn(nz) = fixing_dofs(i)
        jcn(nz) = fixing_dofs(j)
        a(nz) = block(i, j)
      end do
    end do
  end subroutine upper_coo

  !> Append the entries of C^T (rows 1..ndof, columns ndof+1..ndof+nc: the
  !> upper triangle of the constrained system) to the coordinate form.
  subroutine add_constraints(sub, irn, jcn, a)
    type(subdomain_t), intent(in) :: sub
    integer(ip), allocatable, intent(inout) :: irn(:), jcn(:)
    real(dp), allocatable, intent(inout) :: a(:)
    integer(ip) :: i, k, n0
    n0 = size(a, kind=ip)
    irn = [irn, (0_ip, k = 1, sub%C%nnz())]
    jcn = [jcn, (0_ip, k = 1, sub%C%nnz())]
    a = [a, sub%C%values(1:sub%C%nnz())]
    do i = 1, sub%C%nrows
      do k = sub%C%rowptr(i), sub%C%rowptr(i + 1) - 1
        irn(n0 + k) = sub%C%colind(k)
        jcn(n0 + k) = sub%ndof + i
      end do
    end do
  end subroutine add_constraints

  !> Pivot order of the dofs (perm(dof) = its position) from METIS nested
  !> dissection of the node graph of K_reg: nodes coupled by K, plus the clique
  !> of the fixing nodes. The three dofs of a node stay consecutive.
  subroutine node_nested_dissection(sub, fixing, perm)
    type(subdomain_t), intent(in) :: sub
    integer(ip), intent(in) :: fixing(:)
    integer(ip), allocatable, intent(out) :: perm(:)
    integer(ip), allocatable :: xadj(:), adjncy(:), mark(:), order(:), position(:)
    integer(ip) :: nn, a, b, c, k, p, row, f, g
    logical :: is_fixing

    nn = sub%nnodes
    allocate (xadj(nn + 1), mark(nn), order(nn), position(nn))
    ! K's pattern has at most (27 neighbours * 3) entries per row for Q1; size
    ! the adjacency from the rows, plus the clique of the fixing nodes
    allocate (adjncy(sub%K%nnz()/3 + nn + size(fixing)**2))
    mark = 0
    p = 0
    xadj(1) = 1
    do a = 1, nn
      mark(a) = a                       ! no self loop
      do c = 1, 3
        row = 3*(a - 1) + c
        do k = sub%K%rowptr(row), sub%K%rowptr(row + 1) - 1
          b = (sub%K%colind(k) - 1)/3 + 1
          if (mark(b) /= a) then
            mark(b) = a
            call push(b)
          end if
        end do
      end do
      is_fixing = any(fixing == a)
      if (is_fixing) then
        do f = 1, size(fixing)
          g = fixing(f)
          if (mark(g) /= a) then
            mark(g) = a
            call push(g)
          end if
        end do
      end if
      xadj(a + 1) = p + 1
    end do
    call metis_node_nd(nn, xadj, adjncy(1:p), order, position)
    perm = node_dofs(position)
  contains
    subroutine push(node)
      integer(ip), intent(in) :: node
      call append_int(adjncy, p, node)
    end subroutine push
  end subroutine node_nested_dissection
end module kplus
