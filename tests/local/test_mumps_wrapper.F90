#include "assertions.h"
!> mumps_t alone, on a 7-point 3D Laplacian (SPD) and a shifted, indefinite
!> one (general symmetric), with a known solution and three right-hand sides:
!> - centralized input on MPI_COMM_SELF (every rank its own instance) and on
!>   MPI_COMM_WORLD (the host gives everything);
!> - distributed input on MPI_COMM_WORLD, every rank a slice of the entries,
!>   with the diagonal and some off-diagonal entries split in two halves given
!>   by two different ranks (MUMPS must sum them);
!> - the orderings amd, metis (user pivot order), pord, auto, and AMD on the
!>   graph compressed by blocks of 3; a refactorization with new values.
program test_mumps_wrapper
  use kinds, only: dp, ip, i8
  use assertions, only: assert_true, assert_below, test_finish
  use tolerances, only: solve_tol
  use mumps_wrapper, only: mumps_t
  use metis_wrapper, only: metis_node_nd
  use mpi_f08, only: MPI_Init, MPI_COMM_WORLD, MPI_COMM_SELF, MPI_Comm, MPI_Comm_rank, MPI_Comm_size, &
                     MPI_Bcast, MPI_DOUBLE_PRECISION
  implicit none
  integer, parameter :: m = 6, n = m**3, nrhs = 3
  integer :: ierr, rank, nranks
  real(dp) :: tol

  call MPI_Init(ierr)
  call MPI_Comm_rank(MPI_COMM_WORLD, rank, ierr)
  call MPI_Comm_size(MPI_COMM_WORLD, nranks, ierr)
  ! A backward-stable solve is exact to c eps cond; cond of the shifted
  ! Laplacians is known in closed form (the larger of the two matrices')
  tol = solve_tol(max(laplacian_condition(0.0_dp), laplacian_condition(3.0_dp)))

  ! centralized, one instance per rank
  call check_centralized(MPI_COMM_SELF, .true., 0.0_dp, 'amd', 'self spd amd')
  call check_centralized(MPI_COMM_SELF, .true., 0.0_dp, 'metis', 'self spd metis')
  call check_centralized(MPI_COMM_SELF, .true., 0.0_dp, 'pord', 'self spd pord')
  call check_centralized(MPI_COMM_SELF, .true., 0.0_dp, 'auto', 'self spd auto')
  call check_centralized(MPI_COMM_SELF, .true., 0.0_dp, 'amd-blocks', 'self spd amd blocks of 3')
  call check_centralized(MPI_COMM_SELF, .false., 3.0_dp, 'amd', 'self indefinite amd')
  ! centralized on all ranks
  call check_centralized(MPI_COMM_WORLD, .true., 0.0_dp, 'amd', 'world spd amd')
  call check_centralized(MPI_COMM_WORLD, .true., 0.0_dp, 'metis', 'world spd metis')
  call check_centralized(MPI_COMM_WORLD, .false., 3.0_dp, 'auto', 'world indefinite auto')
  ! distributed on all ranks
  call check_distributed(.true., 0.0_dp, 'amd', 'distributed spd amd')
  call check_distributed(.true., 0.0_dp, 'metis', 'distributed spd metis')
  call check_distributed(.false., 3.0_dp, 'amd', 'distributed indefinite amd')
  call check_distributed(.true., 0.0_dp, 'pord', 'distributed spd pord')
  call check_refactorization()
  call check_free_twice()
  call test_finish()

contains

  !> Grid point (i,j,k), 0-based, to its variable number.
  integer function var(i, j, k)
    integer, intent(in) :: i, j, k
    var = 1 + i + m*(j + m*k)
  end function var

  !> cond of the m^3 Dirichlet Laplacian minus shift*I: its eigenvalues are
  !> sum over the 3 directions of 2 - 2 cos(k pi/(m+1)), k = 1..m, minus shift.
  real(dp) function laplacian_condition(shift) result(cond)
    real(dp), intent(in) :: shift
    real(dp) :: lam, big, small, h
    integer :: i, j, k
    h = acos(-1.0_dp)/(m + 1)
    big = 0
    small = huge(1.0_dp)
    do k = 1, m
      do j = 1, m
        do i = 1, m
          lam = 6 - 2*(cos(i*h) + cos(j*h) + cos(k*h)) - shift
          big = max(big, abs(lam))
          small = min(small, abs(lam))
        end do
      end do
    end do
    cond = big/small
  end function laplacian_condition

  !> Upper triangle of the Dirichlet Laplacian minus shift*I, one entry per
  !> position (row <= column).
  subroutine laplacian(shift, irn, jcn, a)
    real(dp), intent(in) :: shift
    integer(ip), allocatable, intent(out) :: irn(:), jcn(:)
    real(dp), allocatable, intent(out) :: a(:)
    integer :: i, j, k, nz
    allocate (irn(4*n), jcn(4*n), a(4*n))
    nz = 0
    do k = 0, m - 1
      do j = 0, m - 1
        do i = 0, m - 1
          call push_entry(irn, jcn, a, nz, var(i, j, k), var(i, j, k), 6 - shift)
          if (i < m - 1) call push_entry(irn, jcn, a, nz, var(i, j, k), var(i + 1, j, k), -1.0_dp)
          if (j < m - 1) call push_entry(irn, jcn, a, nz, var(i, j, k), var(i, j + 1, k), -1.0_dp)
          if (k < m - 1) call push_entry(irn, jcn, a, nz, var(i, j, k), var(i, j, k + 1), -1.0_dp)
        end do
      end do
    end do
    irn = irn(1:nz)
    jcn = jcn(1:nz)
    a = a(1:nz)
  end subroutine laplacian

  subroutine push_entry(irn, jcn, a, nz, r, c, v)
    integer(ip), intent(inout) :: irn(:), jcn(:)
    real(dp), intent(inout) :: a(:)
    integer, intent(inout) :: nz
    integer, intent(in) :: r, c
    real(dp), intent(in) :: v
    nz = nz + 1
    irn(nz) = r
    jcn(nz) = c
    a(nz) = v
  end subroutine push_entry

  !> y = A x for A symmetric given by its upper triangle.
  subroutine sym_matmul(irn, jcn, a, x, y)
    integer(ip), intent(in) :: irn(:), jcn(:)
    real(dp), intent(in) :: a(:), x(:, :)
    real(dp), intent(out) :: y(:, :)
    integer :: k
    y = 0
    do k = 1, size(a)
      y(irn(k), :) = y(irn(k), :) + a(k)*x(jcn(k), :)
      if (irn(k) /= jcn(k)) y(jcn(k), :) = y(jcn(k), :) + a(k)*x(irn(k), :)
    end do
  end subroutine sym_matmul

  !> Known solutions and their right-hand sides.
  subroutine problem(irn, jcn, a, x, b)
    integer(ip), intent(in) :: irn(:), jcn(:)
    real(dp), intent(in) :: a(:)
    real(dp), intent(out) :: x(n, nrhs), b(n, nrhs)
    integer :: i, c
    do c = 1, nrhs
      do i = 1, n
        x(i, c) = sin(0.37_dp*i*c) + c
      end do
    end do
    call sym_matmul(irn, jcn, a, x, b)
  end subroutine problem

  !> Nested dissection of the grid graph: perm(i) = pivot position of i.
  subroutine grid_order(perm)
    integer(ip), intent(out) :: perm(n)
    integer(ip), allocatable :: xadj(:), adjncy(:)
    integer(ip) :: order(n)
    integer :: i, j, k, p
    allocate (xadj(n + 1), adjncy(6*n))
    p = 0
    xadj(1) = 1
    do k = 0, m - 1
      do j = 0, m - 1
        do i = 0, m - 1
          if (i > 0) call push_vertex(adjncy, p, var(i - 1, j, k))
          if (i < m - 1) call push_vertex(adjncy, p, var(i + 1, j, k))
          if (j > 0) call push_vertex(adjncy, p, var(i, j - 1, k))
          if (j < m - 1) call push_vertex(adjncy, p, var(i, j + 1, k))
          if (k > 0) call push_vertex(adjncy, p, var(i, j, k - 1))
          if (k < m - 1) call push_vertex(adjncy, p, var(i, j, k + 1))
          xadj(var(i, j, k) + 1) = p + 1
        end do
      end do
    end do
    call metis_node_nd(int(n, ip), xadj, adjncy(1:p), order, perm)
  end subroutine grid_order

  subroutine push_vertex(adjncy, p, v)
    integer(ip), intent(inout) :: adjncy(:)
    integer, intent(inout) :: p
    integer, intent(in) :: v
    p = p + 1
    adjncy(p) = v
  end subroutine push_vertex

  subroutine choose_ordering(solver, ordering)
    type(mumps_t), intent(inout) :: solver
    character(len=*), intent(in) :: ordering
    integer(ip) :: perm(n)
    select case (ordering)
    case ('metis')
      call grid_order(perm)
      call solver%set_ordering('metis', perm)
    case ('amd-blocks')
      ! n = 216 is a multiple of 3 (the blocks are not nodes here, but any
      ! grouping of consecutive variables is valid)
      call solver%set_block_size(3)
      call solver%set_ordering('amd')
    case default
      call solver%set_ordering(ordering)
    end select
  end subroutine choose_ordering

  real(dp) function relative_error(x, x_true)
    real(dp), intent(in) :: x(:, :), x_true(:, :)
    relative_error = norm2(x - x_true)/norm2(x_true)
  end function relative_error

  subroutine check_centralized(comm, spd, shift, ordering, what)
    type(MPI_Comm), intent(in) :: comm
    logical, intent(in) :: spd
    real(dp), intent(in) :: shift
    character(len=*), intent(in) :: ordering, what
    type(mumps_t) :: solver
    integer(ip), allocatable :: irn(:), jcn(:)
    real(dp), allocatable :: a(:)
    real(dp) :: x_true(n, nrhs), b(n, nrhs), x1(n)
    integer :: crank

    call MPI_Comm_rank(comm, crank, ierr)
    call laplacian(shift, irn, jcn, a)
    call problem(irn, jcn, a, x_true, b)
    call solver%init(comm, spd)
    if (crank == 0) then
      call solver%set_centralized(int(n, ip), irn, jcn, a)
    else
      call solver%set_centralized(int(n, ip), irn(1:0), jcn(1:0), a(1:0))
    end if
    call choose_ordering(solver, ordering)
    call solver%factorize()
    call assert_true(solver%factor_bytes() > 0_i8, what//': factor_bytes > 0', HERE)
    call assert_true(solver%factor_entries() >= int(n, i8), what//': factor_entries >= n', HERE)
    call solver%solve(b)
    if (crank == 0) call assert_below(relative_error(b, x_true), tol, what//': 3 right-hand sides', HERE)
    ! one vector, twice (the solve buffer is reused)
    call problem(irn, jcn, a, x_true, b)
    x1 = b(:, 2)
    call solver%solve(x1)
    if (crank == 0) call assert_below(norm2(x1 - x_true(:, 2))/norm2(x_true(:, 2)), tol, what//': one vector', HERE)
    x1 = b(:, 3)
    call solver%solve(x1)
    if (crank == 0) call assert_below(norm2(x1 - x_true(:, 3))/norm2(x_true(:, 3)), tol, what//': again', HERE)
    call solver%free()
  end subroutine check_centralized

  !> Every rank gives the entries k with mod(k, nranks) == rank; the diagonal
  !> entries and every third off-diagonal entry are split into halves given by
  !> this rank and the next one.
  subroutine check_distributed(spd, shift, ordering, what)
    logical, intent(in) :: spd
    real(dp), intent(in) :: shift
    character(len=*), intent(in) :: ordering, what
    type(mumps_t) :: solver
    integer(ip), allocatable :: irn(:), jcn(:), irn_loc(:), jcn_loc(:)
    real(dp), allocatable :: a(:), a_loc(:)
    real(dp) :: x_true(n, nrhs), b(n, nrhs)
    integer :: k, owner, nz

    call laplacian(shift, irn, jcn, a)
    call problem(irn, jcn, a, x_true, b)
    allocate (irn_loc(2*size(a)), jcn_loc(2*size(a)), a_loc(2*size(a)))
    nz = 0
    do k = 1, size(a)
      owner = mod(k, nranks)
      if (irn(k) == jcn(k) .or. mod(k, 3) == 0) then
        if (owner == rank) call push_entry(irn_loc, jcn_loc, a_loc, nz, irn(k), jcn(k), 0.5_dp*a(k))
        if (mod(owner + 1, nranks) == rank) call push_entry(irn_loc, jcn_loc, a_loc, nz, irn(k), jcn(k), 0.5_dp*a(k))
      else if (owner == rank) then
        ! give some entries as their transpose: either triangle is accepted
        if (mod(k, 5) == 0) then
          call push_entry(irn_loc, jcn_loc, a_loc, nz, jcn(k), irn(k), a(k))
        else
          call push_entry(irn_loc, jcn_loc, a_loc, nz, irn(k), jcn(k), a(k))
        end if
      end if
    end do
    call solver%init(MPI_COMM_WORLD, spd)
    call solver%set_distributed(int(n, ip), irn_loc(1:nz), jcn_loc(1:nz), a_loc(1:nz))
    call choose_ordering(solver, ordering)
    call solver%factorize()
    call solver%solve(b)
    if (rank == 0) call assert_below(relative_error(b, x_true), tol, what//': 3 right-hand sides', HERE)
    ! the caller broadcasts the solution
    call MPI_Bcast(b, n*nrhs, MPI_DOUBLE_PRECISION, 0, MPI_COMM_WORLD, ierr)
    call assert_below(relative_error(b, x_true), tol, what//': broadcast solution', HERE)
    call solver%free()
  end subroutine check_distributed

  !> New values, same instance: set, factorize, solve again.
  subroutine check_refactorization()
    type(mumps_t) :: solver
    integer(ip), allocatable :: irn(:), jcn(:)
    real(dp), allocatable :: a(:)
    real(dp) :: x_true(n, nrhs), b(n, nrhs)
    integer :: round

    call solver%init(MPI_COMM_SELF, .true.)
    do round = 1, 3
      call laplacian(-real(round, dp), irn, jcn, a)   ! 6 + round on the diagonal
      call problem(irn, jcn, a, x_true, b)
      call solver%set_centralized(int(n, ip), irn, jcn, a)
      call solver%factorize()
      call solver%solve(b)
      call assert_below(relative_error(b, x_true), tol, 'refactorization', HERE)
    end do
    ! init on a live instance frees it first
    call solver%init(MPI_COMM_SELF, .true.)
    call solver%set_centralized(int(n, ip), irn, jcn, a)
    call solver%factorize()
    call problem(irn, jcn, a, x_true, b)
    call solver%solve(b)
    call assert_below(relative_error(b, x_true), tol, 're-init of a live instance', HERE)
    call solver%free()
  end subroutine check_refactorization

  subroutine check_free_twice()
    type(mumps_t) :: solver
    call solver%free()
    call solver%init(MPI_COMM_SELF, .false.)
    call solver%free()
    call solver%free()
    call assert_true(.not. solver%is_factorized(), 'free twice', HERE)
  end subroutine check_free_twice
end program test_mumps_wrapper
