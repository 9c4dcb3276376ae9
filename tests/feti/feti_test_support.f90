!> Helpers shared by the FETI tests: parameter sets for small cases,
!> comparison of distributed dual vectors by their rank-independent keys, and
!> condition estimates of K_reg and G G^T from which the tests derive their
!> tolerances (tests/common/tolerances.f90).
module feti_test_support
  use kinds, only: dp, ip, i8, MPI_REAL_DP, MPI_INT_I8
  use params, only: params_t, default_params
  use sorting, only: sort_permutation
  use feti_operators, only: feti_t
  use subdomain, only: subdomain_t
  use lapack_interfaces, only: dsyev
  use mpi_f08, only: MPI_Comm, MPI_Comm_rank, MPI_Comm_size, MPI_Gather, MPI_Gatherv, MPI_INTEGER, MPI_Allreduce, &
    MPI_SUM, MPI_MAX, MPI_Allgather, MPI_Allgatherv
  implicit none
  private

  public :: small_case, gather_keyed, coarse_norm, kplus_condition, coarse_condition, dense_k_condition, &
            dense_pfp_condition

  !> kplus_condition's estimate (through op%local_solve, the code under test) is bounded before
  !> use by this factor times the dense LAPACK condition number of K on its range
  !> (dense_k_condition, independent of K^+). K_reg = K + a rank-6 fixing term, so
  !> lambda_min(K_reg) <= lambda_7(K), but the fixing nodes leave lambda_min(K_reg) far below
  !> lambda_7(K): 370 x on test_shared_f's checkerboard (2.6e4 against 70), 4.8e4 x on
  !> test_dual_preconditioner's case (3.0e6 against 61). The cap 1e6 therefore only stops a K^+
  !> that inflates its own tolerance grossly (by more than 1e6 / 5e4 = 20 x beyond that).
  real(dp), parameter :: kplus_condition_cap = 1.0e6_dp

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

  !> Largest cond(K_reg) over all subdomains, estimated as 2 lambda_max(K)
  !> lambda_max(K^+) by 30 power iterations each on the concatenated local
  !> vectors (an underestimate of the largest one by a factor of a few at most).
  real(dp) function kplus_condition(op) result(cond)
    type(feti_t), intent(inout), target :: op
    type(subdomain_t), pointer :: subs(:)
    real(dp), allocatable :: v(:), w(:)
    integer(ip), allocatable :: offset(:)
    real(dp) :: lmax(2), mine, dense
    integer(ip) :: i, ls, n
    integer :: it, ierr
    subs => op%subdomains()
    allocate (offset(size(subs) + 1))
    offset(1) = 0
    do ls = 1, size(subs, kind=ip)
      offset(ls + 1) = offset(ls) + subs(ls)%ndof
    end do
    n = offset(size(subs) + 1)
    allocate (v(n), w(n))
    do i = 1, n
      v(i) = 1 + 0.3_dp*sin(2.1_dp*i)
    end do
    lmax = 0
    do it = 1, 30
      call normalize(v)
      do ls = 1, op%nlocal()
        call subs(ls)%K%matvec(v(offset(ls) + 1:offset(ls + 1)), w(offset(ls) + 1:offset(ls + 1)))
      end do
      mine = sum(w**2)
      call MPI_Allreduce(mine, lmax(1), 1, MPI_REAL_DP, MPI_SUM, op%comm(), ierr)
      lmax(1) = sqrt(lmax(1))
      v = w
    end do
    do i = 1, n
      v(i) = 1 + 0.3_dp*cos(1.3_dp*i)
    end do
    do it = 1, 30
      call normalize(v)
      w = v
      call op%local_solve(w)
      mine = sum(w**2)
      call MPI_Allreduce(mine, lmax(2), 1, MPI_REAL_DP, MPI_SUM, op%comm(), ierr)
      lmax(2) = sqrt(lmax(2))
      v = w
    end do
    cond = 2*lmax(1)*lmax(2)
    dense = dense_k_condition(op)
    if (.not. cond <= kplus_condition_cap*dense) then
      write (*, '(a,es10.3,a,es10.3,a,es10.3,a)') 'kplus_condition: the estimate through K^+ ', cond, ' exceeds ', &
        kplus_condition_cap, ' x the dense condition number of K on its range ', dense, &
        ': the local solver under test inflates its own tolerance'
      error stop 1
    end if
  contains
    subroutine normalize(x)
      real(dp), intent(inout) :: x(:)
      real(dp) :: local, total
      local = sum(x**2)
      call MPI_Allreduce(local, total, 1, MPI_REAL_DP, MPI_SUM, op%comm(), ierr)
      x = x/sqrt(total)
    end subroutine normalize
  end function kplus_condition

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
      n = int(subs(ls)%K%nrows)
      if (n == 0) cycle
      allocate (a(n, n), w(n), work(max(1, 3*n)))
      a = 0
      do i = 1, subs(ls)%K%nrows
        do k = subs(ls)%K%rowptr(i), subs(ls)%K%rowptr(i + 1) - 1
          a(i, subs(ls)%K%colind(k)) = subs(ls)%K%values(k)
        end do
      end do
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

  !> cond(G G^T) = lambda_max(G G^T) lambda_max((G G^T)^{-1}), each by 30
  !> power iterations (G G^T applied as G (G^T z), the inverse by the coarse
  !> solve), times 2 for the underestimate of power iterations.
  real(dp) function coarse_condition(op) result(cond)
    type(feti_t), intent(inout) :: op
    real(dp), allocatable :: z(:), w(:), y(:)
    real(dp) :: lmax(2)
    integer(ip) :: i
    integer :: it
    allocate (z(op%n_coarse()), w(op%n_coarse()), y(op%n_own()))
    do i = 1, size(z)
      z(i) = 1 + 0.3_dp*sin(1.7_dp*i)
    end do
    lmax = 0
    do it = 1, 30
      z = z/coarse_norm(op%comm(), z)
      call op%apply_gt(z, y)
      call op%apply_g(y, w)
      lmax(1) = coarse_norm(op%comm(), w)
      z = w
    end do
    do i = 1, size(z)
      z(i) = 1 + 0.3_dp*cos(0.9_dp*i)
    end do
    do it = 1, 30
      z = z/coarse_norm(op%comm(), z)
      call op%coarse_solve(z, w)
      lmax(2) = coarse_norm(op%comm(), w)
      z = w
    end do
    cond = 2*lmax(1)*lmax(2)
  end function coarse_condition
end module feti_test_support
