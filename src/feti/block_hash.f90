!> A hash of dense 6x6 blocks keyed by (block row, block column), for
!> assembling coarse matrices (G G^T) before handing them to MUMPS as COO.
module block_hash
  use kinds, only: dp, ip, i8
  implicit none
  private

  type, public :: block_hash_t
    integer(ip) :: capacity = 0, used = 0
    integer(i8), allocatable :: keys(:)        !< 0 = empty
    integer(ip), allocatable :: bi(:), bj(:)
    real(dp), allocatable :: blocks(:, :, :)   !< (6, 6, capacity)
  contains
    procedure :: init
    procedure :: add
    procedure :: to_coo
  end type block_hash_t

contains

  !> An empty hash for about `expected` blocks.
  subroutine init(this, expected)
    class(block_hash_t), intent(inout) :: this
    integer(ip), intent(in) :: expected
    this%capacity = 1
    do while (this%capacity < 2*max(expected, 8))
      this%capacity = 2*this%capacity
    end do
    this%used = 0
    if (allocated(this%keys)) deallocate (this%keys, this%bi, this%bj, this%blocks)
    allocate (this%keys(this%capacity), this%bi(this%capacity), this%bj(this%capacity), &
              this%blocks(6, 6, this%capacity))
    this%keys = 0
  end subroutine init

  !> The slot of key = i 2^31 + j: linear probing from (73856093 i + 19349663 j)
  !> modulo the capacity (a power of two, so the modulo is a mask).
  integer(ip) function slot_of(this, i, j, key)
    class(block_hash_t), intent(in) :: this
    integer(ip), intent(in) :: i, j
    integer(i8), intent(in) :: key
    integer(i8) :: h
    h = int(i, i8)*73856093_i8 + int(j, i8)*19349663_i8
    slot_of = int(iand(h, int(this%capacity - 1, i8)), ip) + 1
    do while (this%keys(slot_of) /= 0 .and. this%keys(slot_of) /= key)
      slot_of = slot_of + 1
      if (slot_of > this%capacity) slot_of = 1
    end do
  end function slot_of

  !> block(i, j) += b
  subroutine add(this, i, j, b)
    class(block_hash_t), intent(inout) :: this
    integer(ip), intent(in) :: i, j
    real(dp), intent(in) :: b(6, 6)
    integer(i8) :: key
    integer(ip) :: s
    if (2*(this%used + 1) > this%capacity) call grow(this)
    key = int(i, i8)*2147483648_i8 + j
    s = slot_of(this, i, j, key)
    if (this%keys(s) == 0) then
      this%keys(s) = key
      this%bi(s) = i
      this%bj(s) = j
      this%blocks(:, :, s) = b
      this%used = this%used + 1
    else
      this%blocks(:, :, s) = this%blocks(:, :, s) + b
    end if
  end subroutine add

  subroutine grow(this)
    class(block_hash_t), intent(inout) :: this
    type(block_hash_t) :: bigger
    integer(ip) :: s
    call bigger%init(this%capacity)
    do s = 1, this%capacity
      if (this%keys(s) /= 0) call bigger%add(this%bi(s), this%bj(s), this%blocks(:, :, s))
    end do
    call move_alloc(bigger%keys, this%keys)
    call move_alloc(bigger%bi, this%bi)
    call move_alloc(bigger%bj, this%bj)
    call move_alloc(bigger%blocks, this%blocks)
    this%capacity = bigger%capacity
  end subroutine grow

  !> The entries as COO with scalar indices 6*(block-1)+a; diagonal blocks
  !> give their upper triangle only (for a symmetric MUMPS matrix).
  subroutine to_coo(this, irn, jcn, a)
    class(block_hash_t), intent(in) :: this
    integer(ip), allocatable, intent(out) :: irn(:), jcn(:)
    real(dp), allocatable, intent(out) :: a(:)
    integer(ip) :: s, n, a1, a2
    n = 0
    do s = 1, this%capacity
      if (this%keys(s) == 0) cycle
      n = n + merge(21, 36, this%bi(s) == this%bj(s))
    end do
    allocate (irn(n), jcn(n), a(n))
    n = 0
    do s = 1, this%capacity
      if (this%keys(s) == 0) cycle
      do a2 = 1, 6
        do a1 = 1, 6
          if (this%bi(s) == this%bj(s) .and. a1 > a2) cycle
          n = n + 1
          irn(n) = 6*(this%bi(s) - 1) + a1
          jcn(n) = 6*(this%bj(s) - 1) + a2
          a(n) = this%blocks(a1, a2, s)
        end do
      end do
    end do
  end subroutine to_coo
end module block_hash
