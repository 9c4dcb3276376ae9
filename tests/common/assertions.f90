!> A small assertion module for the test programs (pFUnit is not packaged for
!> Debian). Each failed assertion prints the file, line, what was checked, the
!> expected and the actual value; `test_skip` records a check that could not
!> run here, with its reason. `test_finish` prints 'N passed, N failed,
!> N skipped' summed over all ranks and exits with status 1 when anything
!> failed or when no assertion ran at all (a test that checks nothing is a
!> defect), and with status 77 (CTest's SKIP_RETURN_CODE, see
!> cmake/FeticontactTesting.cmake) when every check was skipped.
!> Tests are .F90 files and pass `__FILE__, __LINE__` (see assertions.h: HERE).
module assertions
  use, intrinsic :: iso_fortran_env, only: error_unit, output_unit
  use kinds, only: dp, ip, i8
  use mpi_f08, only: MPI_COMM_WORLD, MPI_Allreduce, MPI_SUM, MPI_INTEGER, MPI_Comm_rank, MPI_Finalize
  implicit none
  private

  public :: assert_true, assert_equal, assert_close, assert_below, test_skip, test_finish, test_failures

  !> Exit status of a test program none of whose checks could run here.
  integer, parameter, public :: exit_skipped = 77

  integer :: passed = 0, failed = 0, skipped = 0

  interface assert_equal
    module procedure assert_equal_int, assert_equal_i8
  end interface assert_equal

contains

  subroutine report(ok, what, file, line, detail)
    logical, intent(in) :: ok
    character(len=*), intent(in) :: what, file, detail
    integer, intent(in) :: line
    integer :: rank, ierr
    if (ok) then
      passed = passed + 1
      return
    end if
    failed = failed + 1
    call MPI_Comm_rank(MPI_COMM_WORLD, rank, ierr)
    write (error_unit, '(a,i0,a,a,a,i0,4a)') 'FAIL [rank ', rank, '] ', trim(file), ':', line, ': ', &
      trim(what), ': ', trim(detail)
    flush (error_unit)
  end subroutine report

  !> Assert that `condition` holds.
  subroutine assert_true(condition, what, file, line)
    logical, intent(in) :: condition
    character(len=*), intent(in) :: what, file
    integer, intent(in) :: line
    call report(condition, what, file, line, 'expected true, got false')
  end subroutine assert_true

  subroutine assert_equal_int(expected, actual, what, file, line)
    integer(ip), intent(in) :: expected, actual
    character(len=*), intent(in) :: what, file
    integer, intent(in) :: line
    character(len=80) :: buf
    write (buf, '(a,i0,a,i0)') 'expected ', expected, ', got ', actual
    call report(expected == actual, what, file, line, buf)
  end subroutine assert_equal_int

  subroutine assert_equal_i8(expected, actual, what, file, line)
    integer(i8), intent(in) :: expected, actual
    character(len=*), intent(in) :: what, file
    integer, intent(in) :: line
    character(len=80) :: buf
    write (buf, '(a,i0,a,i0)') 'expected ', expected, ', got ', actual
    call report(expected == actual, what, file, line, buf)
  end subroutine assert_equal_i8

  !> Assert |actual - expected| <= rtol * |expected| + atol (atol default 0).
  subroutine assert_close(expected, actual, rtol, what, file, line, atol)
    real(dp), intent(in) :: expected, actual, rtol
    character(len=*), intent(in) :: what, file
    integer, intent(in) :: line
    real(dp), intent(in), optional :: atol
    real(dp) :: a
    character(len=160) :: buf
    a = 0
    if (present(atol)) a = atol
    write (buf, '(a,es23.15,a,es23.15,a,es9.2,a,es9.2)') 'expected ', expected, ', got ', actual, &
      ', rtol ', rtol, ', atol ', a
    call report(abs(actual - expected) <= rtol*abs(expected) + a .and. actual == actual, &
                what, file, line, buf)
  end subroutine assert_close

  !> Assert value <= bound (residuals, errors); NaN fails. With the
  !> environment variable FETICONTACT_TEST_VERBOSE set, every call prints its
  !> value, bound and their ratio (to see the margin of a tolerance).
  subroutine assert_below(value, bound, what, file, line)
    real(dp), intent(in) :: value, bound
    character(len=*), intent(in) :: what, file
    integer, intent(in) :: line
    character(len=120) :: buf
    integer :: status
    call get_environment_variable('FETICONTACT_TEST_VERBOSE', status=status)
    if (status == 0) write (output_unit, '(a,es10.2,a,es10.2,a,es9.2,4a)') 'margin: value ', value, ' bound ', bound, &
      ' ratio ', value/max(bound, tiny(1.0_dp)), ' : ', trim(what)
    write (buf, '(a,es12.4,a,es12.4)') 'value ', value, ' not <= ', bound
    call report(value <= bound, what, file, line, buf)
  end subroutine assert_below

  !> Record that a check (or a group of checks) did not run here, and why.
  !> Printed on every rank that skips, counted by test_finish.
  subroutine test_skip(what, file, line)
    character(len=*), intent(in) :: what, file
    integer, intent(in) :: line
    integer :: rank, ierr
    skipped = skipped + 1
    call MPI_Comm_rank(MPI_COMM_WORLD, rank, ierr)
    write (output_unit, '(a,i0,a,a,a,i0,2a)') 'SKIPPED [rank ', rank, '] ', trim(file), ':', line, ': ', trim(what)
    flush (output_unit)
  end subroutine test_skip

  !> Failures so far on this rank.
  integer function test_failures()
    test_failures = failed
  end function test_failures

  !> Sum over ranks, print 'N passed, N failed, N skipped' on rank 0, finalize
  !> MPI and exit with status 1 if any assertion failed on any rank or if no
  !> assertion ran at all, with exit_skipped if only skipped checks were met.
  subroutine test_finish()
    integer :: counts(3), total(3), rank, ierr
    counts = [passed, failed, skipped]
    call MPI_Allreduce(counts, total, 3, MPI_INTEGER, MPI_SUM, MPI_COMM_WORLD, ierr)
    call MPI_Comm_rank(MPI_COMM_WORLD, rank, ierr)
    if (rank == 0) then
      write (output_unit, '(i0,a,i0,a,i0,a)') total(1), ' passed, ', total(2), ' failed, ', total(3), ' skipped'
      if (total(1) + total(2) == 0 .and. total(3) == 0) &
        write (error_unit, '(a)') 'FAIL: no assertion ran (a test that checks nothing cannot pass)'
      flush (output_unit)
      flush (error_unit)
    end if
    call MPI_Finalize(ierr)
    if (total(2) > 0) error stop 1
    if (total(1) + total(2) == 0) then
      if (total(3) > 0) error stop exit_skipped
      error stop 1
    end if
  end subroutine test_finish
end module assertions
