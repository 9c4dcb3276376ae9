#include "assertions.h"
!> csr_from_coo (duplicates summed, columns ascending, empty rows) and the
!> products, against a dense matrix built from the same triplets.
program test_csr
  use kinds, only: dp, ip
  use csr_matrix, only: csr_t, csr_from_coo
  use mpi_f08, only: MPI_Init
  use assertions, only: assert_true, assert_equal, assert_close, assert_below, test_finish
  implicit none
  integer, parameter :: nr = 7, nc = 5, n = 40
  type(csr_t) :: a
  integer(ip) :: rows(n), cols(n), k, i, j
  real(dp) :: vals(n), dense(nr, nc), x(nc), y(nr), y2(nr), d(nc)
  real(dp), allocatable :: back(:, :)
  logical :: sorted
  integer :: ierr

  call MPI_Init(ierr)
  dense = 0
  do k = 1, n
    rows(k) = 1 + mod(7*k + 3, nr)
    if (rows(k) == 4) rows(k) = 5          ! row 4 stays empty
    cols(k) = 1 + mod(3*k*k + 1, nc)
    vals(k) = real(k, dp)/3 - 2
    dense(rows(k), cols(k)) = dense(rows(k), cols(k)) + vals(k)
  end do
  call csr_from_coo(int(nr, ip), int(nc, ip), rows, cols, vals, a)
  call assert_equal(int(nr, ip), a%nrows, 'nrows', HERE)
  call assert_equal(int(nc, ip), a%ncols, 'ncols', HERE)
  call assert_equal(int(count(dense /= 0 .or. stored_pattern()), ip), a%nnz(), 'nnz = distinct (i,j)', HERE)
  call assert_equal(a%rowptr(4), a%rowptr(5), 'empty row 4', HERE)
  sorted = .true.
  do i = 1, nr
    do k = a%rowptr(i) + 1, a%rowptr(i + 1) - 1
      sorted = sorted .and. a%colind(k - 1) < a%colind(k)
    end do
  end do
  call assert_true(sorted, 'columns ascending and unique', HERE)
  call a%to_dense(back)
  call assert_below(maxval(abs(back - dense)), 1e-14_dp, 'duplicates summed', HERE)
  do j = 1, nc
    x(j) = sin(real(j, dp))
  end do
  call a%matvec(x, y)
  call assert_below(maxval(abs(y - matmul(dense, x))), 1e-13_dp, 'matvec', HERE)
  y2 = 1
  call a%matvec_add(2.0_dp, x, y2)
  call assert_below(maxval(abs(y2 - 1 - 2*matmul(dense, x))), 1e-13_dp, 'matvec_add', HERE)
  call assert_close(dense(rows(5), cols(5)), a%get(rows(5), cols(5)), 1e-14_dp, 'get', HERE)
  call assert_equal(0_ip, a%position(4_ip, 1_ip), 'position of an absent entry', HERE)
  call a%diagonal(d)
  call assert_below(maxval(abs(d - [(dense(i, i), i=1, nc)])), 1e-14_dp, 'diagonal', HERE)
  call a%free()
  call assert_equal(0_ip, a%nnz(), 'free', HERE)
  call test_finish()

contains

  !> (i,j) that appear among the triplets (their sum may be 0).
  function stored_pattern() result(s)
    logical :: s(nr, nc)
    integer :: m
    s = .false.
    do m = 1, n
      s(rows(m), cols(m)) = .true.
    end do
  end function stored_pattern
end program test_csr
