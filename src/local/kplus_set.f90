!> K^+ of the subdomains of one rank as one kplus_t (one MUMPS factorization)
!> per subdomain: `&solver local_solver = 'subdomain'`.
module kplus_set
  use kinds, only: dp, ip, i8
  use subdomain, only: subdomain_t
  use kplus, only: kplus_t
  use local_inverse, only: local_inverse_t
  implicit none
  private

  type, extends(local_inverse_t), public :: kplus_set_t
    type(kplus_t), allocatable :: kplus(:)       !< one per subdomain
    integer(ip), allocatable :: offset(:)        !< (n+1): dofs of subdomain s are offset(s)+1..offset(s+1)
  contains
    procedure :: init
    procedure :: solve
    procedure :: factor_bytes
    procedure :: factor_flops
    procedure :: free
  end type kplus_set_t

contains

  subroutine init(this, subs, regularization, ordering)
    class(kplus_set_t), intent(inout) :: this
    type(subdomain_t), intent(in) :: subs(:)
    real(dp), intent(in) :: regularization
    character(len=*), intent(in) :: ordering
    integer(ip) :: s, n
    call this%free()
    n = size(subs, kind=ip)
    allocate (this%kplus(n), this%offset(n + 1))
    this%offset(1) = 0
    do s = 1, n
      this%offset(s + 1) = this%offset(s) + subs(s)%ndof
      call this%kplus(s)%init(subs(s), regularization, ordering)
    end do
  end subroutine init

  subroutine solve(this, x)
    class(kplus_set_t), intent(inout) :: this
    real(dp), intent(inout) :: x(:)
    integer(ip) :: s
    do s = 1, size(this%kplus, kind=ip)
      call this%kplus(s)%solve(x(this%offset(s) + 1:this%offset(s + 1)))
    end do
  end subroutine solve

  integer(i8) function factor_bytes(this)
    class(kplus_set_t), intent(in) :: this
    integer(ip) :: s
    factor_bytes = 0
    if (.not. allocated(this%kplus)) return
    do s = 1, size(this%kplus, kind=ip)
      factor_bytes = factor_bytes + this%kplus(s)%factor_bytes()
    end do
  end function factor_bytes

  real(dp) function factor_flops(this)
    class(kplus_set_t), intent(in) :: this
    integer(ip) :: s
    factor_flops = 0
    if (.not. allocated(this%kplus)) return
    do s = 1, size(this%kplus, kind=ip)
      factor_flops = factor_flops + this%kplus(s)%factor_flops()
    end do
  end function factor_flops

  subroutine free(this)
    class(kplus_set_t), intent(inout) :: this
    integer(ip) :: s
    if (allocated(this%kplus)) then
      do s = 1, size(this%kplus, kind=ip)
        call this%kplus(s)%free()
      end do
      deallocate (this%kplus)
    end if
    if (allocated(this%offset)) deallocate (this%offset)
  end subroutine free
end module kplus_set
