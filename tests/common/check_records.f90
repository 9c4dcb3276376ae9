!> What an expensive test set-up found, kept for the pFUnit tests that assert
!> it. A test module whose set-up (a FETI problem, a QP solve) is shared by
!> several properties runs it once per rank count, before any assertion (no
!> collective may follow a failed assertion), and records each compared pair
!> in the list of its property: `value` <= `bound` (residuals, errors),
!> `ok` (a condition), `expected` = `actual` (counts, status codes), with a
!> text naming the case. Each @test / @mpitest then asserts its list item by
!> item, so pFUnit's message names the file, line, case and values.
!> With the environment variable FETICONTACT_TEST_VERBOSE set, every record
!> is printed when it is made ('check: ' and its values; for value <= bound
!> also their ratio, to see the margin of a tolerance): the number of these
!> lines is the number of assertions the tests then make on that rank.
module check_records
  use, intrinsic :: iso_fortran_env, only: output_unit
  use kinds, only: dp
  implicit none
  private

  !> One compared pair.
  type, public :: check_t
    character(len=240) :: what = ''
    real(dp) :: value = 0, bound = 0
    logical :: ok = .false.
    integer :: expected = 0, actual = 0
  end type check_t

  !> The checks of one property, in the order the set-up made them.
  type, public :: check_list_t
    integer :: n = 0
    type(check_t), allocatable :: c(:)
  contains
    procedure :: below => list_below
    procedure :: above => list_below
    procedure :: truth => list_truth
    procedure :: equal => list_equal
  end type check_list_t

contains

  subroutine append(self, item, kind)
    class(check_list_t), intent(inout) :: self
    type(check_t), intent(in) :: item
    character(len=*), intent(in) :: kind
    type(check_t), allocatable :: grown(:)
    integer :: status
    call get_environment_variable('FETICONTACT_TEST_VERBOSE', status=status)
    if (status == 0) then
      select case (kind)
      case ('compare')
        write (output_unit, '(a,es10.2,a,es10.2,a,es9.2,2a)') 'check: value ', item%value, ' bound ', item%bound, &
          ' ratio ', item%value/max(abs(item%bound), tiny(1.0_dp)), ' : ', trim(item%what)
      case ('truth')
        write (output_unit, '(a,l1,2a)') 'check: ', item%ok, ' : ', trim(item%what)
      case default
        write (output_unit, '(a,i0,a,i0,2a)') 'check: expected ', item%expected, ' actual ', item%actual, ' : ', &
          trim(item%what)
      end select
    end if
    if (.not. allocated(self%c)) allocate (self%c(8))
    if (self%n == size(self%c)) then
      allocate (grown(2*size(self%c)))
      grown(1:self%n) = self%c(1:self%n)
      call move_alloc(grown, self%c)
    end if
    self%n = self%n + 1
    self%c(self%n) = item
  end subroutine append

  !> Record that `value` must be <= `bound` (`below`, asserted with
  !> @assertLessThanOrEqual) or > `bound` (`above`, @assertGreaterThan).
  subroutine list_below(self, what, value, bound)
    class(check_list_t), intent(inout) :: self
    character(len=*), intent(in) :: what
    real(dp), intent(in) :: value, bound
    type(check_t) :: item
    item%what = what
    item%value = value
    item%bound = bound
    call append(self, item, 'compare')
  end subroutine list_below

  !> Record a condition that must hold (asserted with @assertTrue).
  subroutine list_truth(self, what, ok)
    class(check_list_t), intent(inout) :: self
    character(len=*), intent(in) :: what
    logical, intent(in) :: ok
    type(check_t) :: item
    item%what = what
    item%ok = ok
    call append(self, item, 'truth')
  end subroutine list_truth

  !> Record two integers that must be equal (asserted with @assertEqual).
  subroutine list_equal(self, what, expected, actual)
    class(check_list_t), intent(inout) :: self
    character(len=*), intent(in) :: what
    integer, intent(in) :: expected, actual
    type(check_t) :: item
    item%what = what
    item%expected = expected
    item%actual = actual
    call append(self, item, 'equal')
  end subroutine list_equal
end module check_records
