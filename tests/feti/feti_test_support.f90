!> Helpers shared by the FETI tests: parameter sets for small cases,
!> comparison of distributed dual vectors by their rank-independent keys, and
!> the condition numbers of K_reg, G G^T and P F P and the norm of K^+ from
!> which the tests derive their tolerances (tests/common/tolerances.f90). Each
!> is computed by LAPACK on the dense assembled matrix, never through the
!> solves under test (K^+ = K_reg^{-1}, (G G^T)^{-1}, a CG run): a wrong
!> solver cannot inflate its own bound.
module feti_test_support
  use kinds, only: dp, ip, i8, MPI_REAL_DP, MPI_INT_I8
  use params, only: params_t, default_params
  use sorting, only: sort_permutation
  use feti_operators, only: feti_t, local_field_t
  use subdomain, only: subdomain_t
  use kplus, only: regularized_system
  use assembly, only: assemble_stiffness
  use lapack_interfaces, only: dsyev
  use mpi_f08, only: MPI_Comm, MPI_Comm_rank, MPI_Comm_size, MPI_Gather, MPI_Gatherv, MPI_INTEGER, MPI_Allreduce, &
    MPI_SUM, MPI_MAX, MPI_Allgather, MPI_Allgatherv
  implicit none
  private

  public :: small_case, gather_keyed, coarse_norm, kplus_condition, kplus_norm, coarse_condition, &
            dense_k_condition, dense_pfp_condition

contains

  !> A small case: 'block' (symmetry, top pressure, plane contact) or 'cube'
  !> (top Dirichlet, sphere) or 'linear' (top Dirichlet + symmetry, no contact).
  function small_case(kind, nsub, nel, decomposition, distortion) result(p)
    character(len=*), intent(in) :: kind, decomposition
    integer(ip), intent(in) :: nsub(3), nel(3)
    real(dp), intent(in) :: distortion
    type(params_t) :: p
    p = default_params()
    p%mesh%nsub = nsub
    p%mesh%nel = nel
    p%mesh%decomposition = decomposition
    p%mesh%distortion = distortion
    select case (kind)
    case ('block')
      p%load%top_pressure = 100
      p%boundary%top_dirichlet = .false.
      p%boundary%symmetry_x0 = .true.
      p%boundary%symmetry_y0 = .true.
      p%obstacle%shape = 'plane'
    case ('cube')
      p%obstacle%shape = 'sphere'
    case ('linear')
      p%boundary%top_displacement = [0.001_dp, 0.0005_dp, -0.002_dp]
      p%boundary%symmetry_x0 = .true.
      p%boundary%symmetry_y0 = .true.
      p%obstacle%shape = 'none'
    end select
  end function small_case

  !> Gather (key, value) pairs of a distributed vector to rank 0 of `comm`,
  !> sorted by key (on other ranks the results are empty).
  subroutine gather_keyed(comm, keys, values, all_keys, all_values)
    type(MPI_Comm), intent(in) :: comm
    integer(i8), intent(in) :: keys(:)
    real(dp), intent(in) :: values(:)
    integer(i8), allocatable, intent(out) :: all_keys(:)
    real(dp), allocatable, intent(out) :: all_values(:)
    integer :: rank, nranks, ierr, n, r
    integer, allocatable :: counts(:), displs(:)
    integer(i8), allocatable :: k(:)
    real(dp), allocatable :: v(:)
    integer(ip), allocatable :: perm(:)

    call MPI_Comm_rank(comm, rank, ierr)
    call MPI_Comm_size(comm, nranks, ierr)
    n = size(keys)
    allocate (counts(nranks), displs(nranks))
    call MPI_Gather(n, 1, MPI_INTEGER, counts, 1, MPI_INTEGER, 0, comm, ierr)
    displs = 0
    do r = 2, nranks
      displs(r) = displs(r - 1) + counts(r - 1)
    end do
    if (rank == 0) then
      allocate (k(sum(counts)), v(sum(counts)))
    else
      allocate (k(1), v(1))
    end if
    call MPI_Gatherv(keys, n, MPI_INT_I8, k, counts, displs, MPI_INT_I8, 0, comm, ierr)
    call MPI_Gatherv(values, n, MPI_REAL_DP, v, counts, displs, MPI_REAL_DP, 0, comm, ierr)
    if (rank == 0) then
      call sort_permutation(k, perm)
      all_keys = k(perm)
      all_values = v(perm)
    else
      allocate (all_keys(0), all_values(0))
    end if
  end subroutine gather_keyed

  !> Global 2-norm of a vector of local coarse blocks.
  real(dp) function coarse_norm(comm, z)
    type(MPI_Comm), intent(in) :: comm
    real(dp), intent(in) :: z(:)
    real(dp) :: mine, total
    integer :: ierr
    mine = sum(z**2)
    call MPI_Allreduce(mine, total, 1, MPI_REAL_DP, MPI_SUM, comm, ierr)
    coarse_norm = sqrt(total)
  end function coarse_norm

  !> The largest cond(K_reg) = lambda_max / lambda_min over all subdomains (dense_kreg).
  !> `regularization`: `&solver regularization` of the case (default: the default's).
  !> Collective.
  real(dp) function kplus_condition(op, regularization) result(cond)
    type(feti_t), intent(inout), target :: op
    real(dp), intent(in), optional :: regularization
    real(dp) :: inv_norm
    call dense_kreg(op, regularization, cond, inv_norm)
  end function kplus_condition

  !> ||K^+|| = the largest 1/lambda_min(K_reg) over all subdomains (dense_kreg): the norm of
  !> K^+ on the concatenated local vectors. Collective.
  real(dp) function kplus_norm(op, regularization) result(inv_norm)
    type(feti_t), intent(inout), target :: op
    real(dp), intent(in), optional :: regularization
    real(dp) :: cond
    call dense_kreg(op, regularization, cond, inv_norm)
  end function kplus_norm

  !> cond(K_reg) and ||K_reg^{-1}||, largest over the subdomains, from LAPACK's dsyev on the
  !> dense K_reg = K + rho_f Q_F Q_F^T of every subdomain as kplus::regularized_system builds
  !> it (the matrix that every local solver factorizes, K^+ = K_reg^{-1}; with `local_solver`
  !> 'dense' the fixing nodes are chosen among the nodes whose three dofs B touches, as
  !> kplus_dense does, found here as the nonzeros of B^T r for a random r; per class of
  !> congruent subdomains ('shared') the fixing nodes, chosen by distances alone, and K_reg are
  !> those of every member). Independent of the factorizations and solves under test.
  !> For small subdomains only (ndof^2 doubles). Collective.
  subroutine dense_kreg(op, regularization, cond, inv_norm)
    type(feti_t), intent(inout), target :: op
    real(dp), intent(in), optional :: regularization
    real(dp), intent(out) :: cond, inv_norm
    type(subdomain_t), pointer :: subs(:)
    type(subdomain_t) :: own
    type(local_field_t), allocatable :: touched(:)
    real(dp), allocatable :: a(:, :), w(:), work(:), vals(:), r(:)
    integer(ip), allocatable :: irn(:), jcn(:), perm(:)
    logical, allocatable :: allowed(:)
    type(params_t) :: defaults
    real(dp) :: mine(2), largest(2), reg
    integer(ip) :: ls, k, i, j
    integer :: n, info, ierr
    logical :: dense_solver
    defaults = default_params()
    reg = defaults%solver%local%regularization
    if (present(regularization)) reg = regularization
    subs => op%subdomains()
    dense_solver = op%local_solver() == 'dense'
    allocate (touched(op%nlocal()))
    do ls = 1, op%nlocal()
      allocate (touched(ls)%v(subs(ls)%ndof))
    end do
    allocate (r(op%n_own()))
    call op%keyed_random(11, r)
    r = 1 + abs(r)
    call op%apply_bt(r, touched)
    mine = 0
    do ls = 1, op%nlocal()
      n = int(subs(ls)%ndof)
      ! a member of a class holds no K: its own assembled here
      own = subs(ls)
      if (own%k_of /= 0) call assemble_stiffness(own)
      if (dense_solver) then
        allowed = [(all_touched(touched(ls)%v(3*k - 2:3*k)), k=1, subs(ls)%nnodes)]
        call regularized_system(own, reg, 'amd', irn, jcn, vals, perm, allowed)
      else
        call regularized_system(own, reg, 'amd', irn, jcn, vals, perm)
      end if
      allocate (a(n, n), w(n), work(max(1, 3*n)))
      a = 0
      do k = 1, size(vals, kind=ip)
        i = min(irn(k), jcn(k))
        j = max(irn(k), jcn(k))
        a(i, j) = a(i, j) + vals(k)
      end do
      call dsyev('N', 'U', n, a, n, w, work, size(work), info)
      if (info /= 0) error stop 'dense_kreg: dsyev failed'
      if (.not. w(1) > 0) error stop 'dense_kreg: K_reg is not positive definite'
      mine(1) = max(mine(1), w(n)/w(1))
      mine(2) = max(mine(2), 1/w(1))
      deallocate (a, w, work)
    end do
    call MPI_Allreduce(mine, largest, 2, MPI_REAL_DP, MPI_MAX, op%comm(), ierr)
    cond = largest(1)
    inv_norm = largest(2)
  contains
    pure logical function all_touched(v)
      real(dp), intent(in) :: v(:)
      all_touched = all(v /= 0)
    end function all_touched
  end subroutine dense_kreg

  !> The largest condition number over all subdomains of K_s on its range, lambda_max / the
  !> smallest eigenvalue above 1e-10 lambda_max (the rigid modes: 0 to rounding), from LAPACK's
  !> dsyev on the dense K_s (K_s from the assembly alone, checked against the Q1 closed form and
  !> its kernel in tests/fem). Collective.
  real(dp) function dense_k_condition(op) result(cond)
    type(feti_t), intent(inout), target :: op
    type(subdomain_t), pointer :: subs(:)
    real(dp), allocatable :: a(:, :), w(:), work(:)
    real(dp) :: mine, lmax
    integer(ip) :: ls, i, k
    integer :: n, info, ierr
    subs => op%subdomains()
    mine = 1
    do ls = 1, op%nlocal()
      ! a member of a class holds no K: its class's (c_s K_r, the same condition number)
      associate (kk => subs(merge(subs(ls)%k_of, ls, subs(ls)%k_of /= 0))%K)
        n = int(kk%nrows)
        if (n == 0) cycle
        allocate (a(n, n), w(n), work(max(1, 3*n)))
        a = 0
        do i = 1, kk%nrows
          do k = kk%rowptr(i), kk%rowptr(i + 1) - 1
            a(i, kk%colind(k)) = kk%values(k)
          end do
        end do
      end associate
      call dsyev('N', 'U', n, a, n, w, work, size(work), info)
      if (info /= 0) error stop 'dense_k_condition: dsyev failed'
      lmax = w(n)
      mine = max(mine, lmax/minval(w, mask=w > 1.0e-10_dp*lmax))
      deallocate (a, w, work)
    end do
    call MPI_Allreduce(mine, cond, 1, MPI_REAL_DP, MPI_MAX, op%comm(), ierr)
  end function dense_k_condition

  !> The condition number of P F P on Im P: P F P assembled column by column (P F P e_j for every
  !> dual row j, the owned parts gathered in row_offset order) and its eigenvalues from LAPACK's
  !> dsyev, lambda_max / the smallest one above 1e-8 lambda_max (Ker P: 0 to rounding). For
  !> small cases only (n^2 doubles on every rank). Independent of any CG run: a bound scaled by it
  !> cannot grow with a solver under test. Collective.
  real(dp) function dense_pfp_condition(op) result(cond)
    type(feti_t), intent(inout) :: op
    real(dp), allocatable :: a(:, :), e(:), pe(:), fpe(:), y(:), w(:), work(:)
    integer, allocatable :: counts(:), displs(:)
    integer :: n, ntot, nranks, j, off, info, ierr
    n = int(op%n_own())
    off = int(op%row_offset())
    call MPI_Comm_size(op%comm(), nranks, ierr)
    allocate (counts(nranks), displs(nranks))
    call MPI_Allgather(n, 1, MPI_INTEGER, counts, 1, MPI_INTEGER, op%comm(), ierr)
    call MPI_Allgather(off, 1, MPI_INTEGER, displs, 1, MPI_INTEGER, op%comm(), ierr)
    ntot = sum(counts)
    allocate (a(ntot, ntot), e(n), pe(n), fpe(n), y(n))
    do j = 1, ntot
      e = 0
      if (j > off .and. j <= off + n) e(j - off) = 1
      call op%project(e, pe)
      call op%apply_f(pe, fpe)
      call op%project(fpe, y)
      call MPI_Allgatherv(y, n, MPI_REAL_DP, a(:, j), counts, displs, MPI_REAL_DP, op%comm(), ierr)
    end do
    a = (a + transpose(a))/2
    allocate (w(ntot), work(3*ntot))
    call dsyev('N', 'U', ntot, a, ntot, w, work, size(work), info)
    if (info /= 0) error stop 'dense_pfp_condition: dsyev failed'
    cond = w(ntot)/minval(w, mask=w > 1.0e-8_dp*w(ntot))
  end function dense_pfp_condition

  !> cond(G G^T) = lambda_max / lambda_min from LAPACK's dsyev on the dense G G^T, assembled
  !> column by column as G (G^T e_j) (the coarse blocks of all ranks in rank order), never
  !> through the coarse solve under test. `mask` (per owned dual row): G_M G_M^T of the rows in
  !> it instead (G (mask .* G^T e_j)); `lmax`: its largest eigenvalue. For small cases only
  !> (n_coarse^2 doubles on every rank). Collective.
  real(dp) function coarse_condition(op, mask, lmax) result(cond)
    type(feti_t), intent(inout) :: op
    logical, intent(in), optional :: mask(:)
    real(dp), intent(out), optional :: lmax
    real(dp), allocatable :: a(:, :), e(:), y(:), gy(:), w(:), work(:)
    integer, allocatable :: counts(:), displs(:)
    integer :: n, ntot, nranks, rank, j, info, ierr, r
    n = int(op%n_coarse())
    call MPI_Comm_size(op%comm(), nranks, ierr)
    call MPI_Comm_rank(op%comm(), rank, ierr)
    allocate (counts(nranks), displs(nranks))
    call MPI_Allgather(n, 1, MPI_INTEGER, counts, 1, MPI_INTEGER, op%comm(), ierr)
    displs(1) = 0
    do r = 2, nranks
      displs(r) = displs(r - 1) + counts(r - 1)
    end do
    ntot = sum(counts)
    allocate (a(ntot, ntot), e(n), y(op%n_own()), gy(n))
    do j = 1, ntot
      e = 0
      if (j > displs(rank + 1) .and. j <= displs(rank + 1) + n) e(j - displs(rank + 1)) = 1
      call op%apply_gt(e, y)
      if (present(mask)) y = merge(y, 0.0_dp, mask)
      call op%apply_g(y, gy)
      call MPI_Allgatherv(gy, n, MPI_REAL_DP, a(:, j), counts, displs, MPI_REAL_DP, op%comm(), ierr)
    end do
    a = (a + transpose(a))/2
    allocate (w(ntot), work(3*ntot))
    call dsyev('N', 'U', ntot, a, ntot, w, work, size(work), info)
    if (info /= 0) error stop 'coarse_condition: dsyev failed'
    if (.not. w(1) > 0) error stop 'coarse_condition: G G^T is not positive definite'
    cond = w(ntot)/w(1)
    if (present(lmax)) lmax = w(ntot)
  end function coarse_condition
end module feti_test_support
