#include "assertions.h"
!> Invariants of the TFETI dual operators on small box and METIS cases:
!> G lambda~ = e, P^2 = P, G P = 0, F symmetric positive semidefinite,
!> orthonormal equality rows (B_E B_E^T = I), full row rank of B, and the
!> same d, lambda~, F x and P x (compared by multiplier keys) on this number
!> of ranks as on one rank.
program test_feti_operators
  use kinds, only: dp, ip, i8
  use assertions, only: assert_true, assert_below, assert_equal, test_skip, test_finish
  use params, only: params_t
  use feti_operators, only: feti_t, local_field_t, feti_sizes_t
  use feti_test_support, only: small_case, gather_keyed, coarse_norm, kplus_condition, coarse_condition
  use tolerances, only: solve_tol, reorder_tol
  use mpi_f08, only: MPI_Init, MPI_COMM_WORLD, MPI_COMM_SELF, MPI_Comm_rank, MPI_Comm_size, MPI_Gatherv, &
    MPI_Allgather, MPI_INTEGER, MPI_DOUBLE_PRECISION
  implicit none
  integer :: ierr, rank, nranks

  call MPI_Init(ierr)
  call MPI_Comm_rank(MPI_COMM_WORLD, rank, ierr)
  call MPI_Comm_size(MPI_COMM_WORLD, nranks, ierr)

  call check_case(small_case('block', [2, 2, 2], [2, 2, 2], 'box', 0.0_dp), 'block box', .true.)
  call check_case(small_case('cube', [2, 2, 2], [2, 2, 2], 'metis', 0.3_dp), 'cube metis distorted', .true.)
  call check_case(small_case('block', [3, 2, 2], [2, 1, 3], 'box', 0.2_dp), 'block elongated distorted', .false.)
  call test_finish()

contains

  subroutine check_case(p, label, check_rank)
    type(params_t), intent(in) :: p
    character(len=*), intent(in) :: label
    logical, intent(in) :: check_rank
    type(feti_t) :: op
    real(dp), allocatable :: x(:), y(:), px(:), ppx(:), fx(:), fy(:), z(:), z2(:)
    type(local_field_t), allocatable :: u(:)
    integer(ip) :: n
    type(feti_sizes_t) :: sizes
    real(dp) :: tol_k, tol_gg
    character(len=120) :: buf

    call op%setup(p, MPI_COMM_WORLD)
    n = op%n_own()
    allocate (x(n), y(n), px(n), ppx(n), fx(n), fy(n), z(op%n_coarse()), z2(op%n_coarse()))
    ! What goes through K^+ is exact to c eps cond(K_reg), what goes through
    ! the coarse solve to c eps cond(G G^T) (tests/common/tolerances.f90).
    tol_k = solve_tol(kplus_condition(op))
    tol_gg = solve_tol(coarse_condition(op))
    write (buf, '(2a,2es10.2)') label, ': tolerances from cond(K_reg), cond(G G^T):', tol_k, tol_gg
    if (rank == 0) write (*, '(a)') trim(buf)

    ! G lambda~ = e: the residual of one coarse solve
    call op%apply_g(op%lambda_tilde_vector(), z)
    call assert_below(coarse_norm(op%comm(), z - op%rigid_rhs()), tol_gg*coarse_norm(op%comm(), op%rigid_rhs()) + tiny(1.0_dp), &
                      label//': G lambda~ = e', HERE)
    call assert_true(coarse_norm(op%comm(), op%rigid_rhs()) > 0 .or. p%load%top_pressure == 0, label//': e /= 0', HERE)

    ! P^2 = P and G P = 0
    call op%keyed_random(1, x)
    call op%project(x, px)
    call op%project(px, ppx)
    ! P P x - P x and G P x are (images of) the residual of a coarse solve
    call assert_below(op%norm(ppx - px), tol_gg*op%norm(x), label//': P P x = P x', HERE)
    call op%apply_g(px, z)
    call op%apply_g(x, z2)
    call assert_below(coarse_norm(op%comm(), z), tol_gg*coarse_norm(op%comm(), z2), label//': G P x = 0', HERE)

    ! F symmetric and positive semidefinite
    call op%keyed_random(2, y)
    call op%apply_f(x, fx)
    call op%apply_f(y, fy)
    ! F is symmetric PSD in exact arithmetic; K^+ solves perturb it by c eps cond(K_reg)
    call assert_below(abs(op%dot(x, fy) - op%dot(y, fx)), tol_k*op%norm(x)*op%norm(fy), &
                      label//': x.F y = y.F x', HERE)
    call assert_true(op%dot(x, fx) >= -tol_k*op%norm(x)*op%norm(fx), label//': x.F x >= 0', HERE)
    ! a second application of F to the same x, after F y, gives the same bits
    ! (no state kept between applications: work arrays, ghost buffers)
    call op%apply_f(x, px)
    call assert_true(all(px == fx), label//': F x again after F y gives the same F x', HERE)

    ! B_E B_E^T = I on the equality rows
    x = merge(0.0_dp, x, op%is_contact())
    allocate (u(op%nlocal()))
    call op%apply_bt(x, u)
    call op%apply_b(u, y)
    y = merge(0.0_dp, y, op%is_contact())
    ! each entry of B_E B_E^T x sums at most 8 copies x 8 rows of products of
    ! rounded Helmert entries: a sum of at most 64 terms of size |x|
    call assert_below(op%norm(y - x), reorder_tol(64)*op%norm(x), label//': B_E B_E^T = I', HERE)

    sizes = op%sizes()
    call assert_true(sizes%contact_rows > 0, label//': has contact rows', HERE)
    call check_full_rank(op, label)
    if (check_rank .and. nranks > 1) call compare_with_one_rank(op, p, label)
    call op%free()
  end subroutine check_case

  !> Smallest eigenvalue of B B^T (assembled column by column) is not small.
  subroutine check_full_rank(op, label)
    type(feti_t), intent(inout) :: op
    character(len=*), intent(in) :: label
    real(dp), allocatable :: x(:), y(:), bbt(:, :), column(:), w(:), work(:)
    type(local_field_t), allocatable :: u(:)
    integer, allocatable :: counts(:), displs(:)
    integer :: j, r, info, ng
    type(feti_sizes_t) :: sizes
    sizes = op%sizes()
    ng = sizes%dual_dofs
    if (ng > 1500) then
      if (rank == 0) call test_skip(label//': full row rank of B (dense B B^T of more than 1500 rows)', HERE)
      return
    end if
    allocate (x(op%n_own()), y(op%n_own()), u(op%nlocal()), counts(nranks), displs(nranks), column(ng))
    call MPI_Allgather(int(op%n_own()), 1, MPI_INTEGER, counts, 1, MPI_INTEGER, op%comm(), ierr)
    displs(1) = 0
    do r = 2, nranks
      displs(r) = displs(r - 1) + counts(r - 1)
    end do
    if (rank == 0) allocate (bbt(ng, ng))
    do j = 1, ng
      x = 0
      if (j > op%row_offset() .and. j <= op%row_offset() + op%n_own()) x(j - op%row_offset()) = 1
      call op%apply_bt(x, u)
      call op%apply_b(u, y)
      call MPI_Gatherv(y, op%n_own(), MPI_DOUBLE_PRECISION, column, counts, displs, MPI_DOUBLE_PRECISION, &
                       0, op%comm(), ierr)
      if (rank == 0) bbt(:, j) = column
    end do
    if (rank == 0) then
      allocate (w(ng), work(3*ng))
      call dsyev('N', 'U', ng, bbt, ng, w, work, 3*ng, info)
      call assert_equal(0, info, label//': dsyev', HERE)
      call assert_true(w(1) > 1.0e-2_dp, label//': B has full row rank (min eig B B^T > 0.01)', HERE)
      call assert_below(w(ng), 8.0_dp, label//': max eig B B^T bounded', HERE)
    end if
  end subroutine check_full_rank

  !> d, lambda~, F x and P x agree (by keys) with a one-rank run.
  subroutine compare_with_one_rank(op, p, label)
    type(feti_t), intent(inout) :: op
    type(params_t), intent(in) :: p
    character(len=*), intent(in) :: label
    type(feti_t) :: serial
    real(dp), allocatable :: x(:), fx(:), px(:), sx(:), sfx(:), spx(:)
    integer(i8), allocatable :: k1(:), k2(:)
    real(dp), allocatable :: v1(:), v2(:)
    integer :: what
    real(dp) :: tol(4)

    ! d and F x go through K^+ (another factorization on one rank: block
    ! diagonal of other subdomains), lambda~ and P x through the coarse solve
    tol(1) = solve_tol(kplus_condition(op))
    tol(2) = solve_tol(coarse_condition(op))
    tol(3) = tol(1)
    tol(4) = tol(2)
    allocate (x(op%n_own()), fx(op%n_own()), px(op%n_own()))
    call op%keyed_random(3, x)
    call op%apply_f(x, fx)
    call op%project(x, px)
    if (rank == 0) then
      call serial%setup(p, MPI_COMM_SELF)
      allocate (sx(serial%n_own()), sfx(serial%n_own()), spx(serial%n_own()))
      call serial%keyed_random(3, sx)
      call serial%apply_f(sx, sfx)
      call serial%project(sx, spx)
    end if
    do what = 1, 4
      select case (what)
      case (1)
        call gather_keyed(op%comm(), op%row_keys(), op%dual_rhs(), k1, v1)
        if (rank == 0) call gather_keyed(MPI_COMM_SELF, serial%row_keys(), serial%dual_rhs(), k2, v2)
      case (2)
        call gather_keyed(op%comm(), op%row_keys(), op%lambda_tilde_vector(), k1, v1)
        if (rank == 0) call gather_keyed(MPI_COMM_SELF, serial%row_keys(), serial%lambda_tilde_vector(), k2, v2)
      case (3)
        call gather_keyed(op%comm(), op%row_keys(), fx, k1, v1)
        if (rank == 0) call gather_keyed(MPI_COMM_SELF, serial%row_keys(), sfx, k2, v2)
      case (4)
        call gather_keyed(op%comm(), op%row_keys(), px, k1, v1)
        if (rank == 0) call gather_keyed(MPI_COMM_SELF, serial%row_keys(), spx, k2, v2)
      end select
      if (rank == 0) then
        call assert_true(size(k1) == size(k2), label//': same number of multipliers', HERE)
        if (size(k1) == size(k2)) then
          call assert_true(all(k1 == k2), label//': same multiplier keys', HERE)
          call assert_below(maxval(abs(v1 - v2)), tol(what)*maxval(abs(v2)) + tiny(1.0_dp), &
                            label//': same values on 1 and N ranks', HERE)
        end if
      end if
    end do
    if (rank == 0) call serial%free()
  end subroutine compare_with_one_rank
end program test_feti_operators
