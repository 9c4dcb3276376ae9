!> K^+ of the subdomains of one rank with one factorization per class of
!> congruent subdomains (subdomain_classes): K^s = c_s K^r gives
!> K^+_s = K_reg^r^{-1} / c_s. A solve gathers the right-hand sides of a
!> class into the columns of one matrix, solves them with the
!> representative's factors in one MUMPS call (kplus_t%solve_many) and
!> scatters them back divided by c_s. `&solver share_subdomains`.
module kplus_shared
  use kinds, only: dp, ip, i8
  use subdomain, only: subdomain_t
  use kplus, only: kplus_t
  use local_inverse, only: local_inverse_t
  use subdomain_classes, only: subdomain_classes_t, find_classes
  implicit none
  private

  type, extends(local_inverse_t), public :: kplus_shared_t
    type(subdomain_classes_t) :: classes
    type(kplus_t), allocatable :: kplus(:)       !< one per class (its representative)
    integer(ip), allocatable :: offset(:)        !< (nsub+1): dofs of subdomain s are offset(s)+1..offset(s+1)
    real(dp), allocatable, private :: work(:, :)
  contains
    procedure :: init
    procedure :: init_classes
    procedure :: solve
    procedure :: factor_bytes
    procedure :: factor_flops
    procedure :: free
  end type kplus_shared_t

contains

  !> Find the classes of `subs` and factorize one representative per class.
  subroutine init(this, subs, regularization, ordering)
    class(kplus_shared_t), intent(inout) :: this
    type(subdomain_t), intent(in) :: subs(:)
    real(dp), intent(in) :: regularization
    character(len=*), intent(in) :: ordering
    type(subdomain_classes_t) :: classes
    call find_classes(subs, classes, .true.)
    call this%init_classes(subs, classes, regularization, ordering)
  end subroutine init

  !> Factorize one representative per class of `classes` (found on `subs`).
  subroutine init_classes(this, subs, classes, regularization, ordering)
    class(kplus_shared_t), intent(inout) :: this
    type(subdomain_t), intent(in) :: subs(:)
    type(subdomain_classes_t), intent(in) :: classes
    real(dp), intent(in) :: regularization
    character(len=*), intent(in) :: ordering
    integer(ip) :: s, c, n, mmax
    call this%free()
    this%classes = classes
    n = size(subs, kind=ip)
    allocate (this%offset(n + 1), this%kplus(classes%nclass))
    this%offset(1) = 0
    do s = 1, n
      this%offset(s + 1) = this%offset(s) + subs(s)%ndof
    end do
    mmax = 0
    do c = 1, classes%nclass
      call this%kplus(c)%init(subs(classes%rep(c)), regularization, ordering)
      mmax = max(mmax, (classes%moff(c + 1) - classes%moff(c))*subs(classes%rep(c))%ndof)
    end do
    allocate (this%work(max(1, mmax), 1))
  end subroutine init_classes

  !> x <- K^+ x for the concatenated vector of all the subdomains.
  subroutine solve(this, x)
    class(kplus_shared_t), intent(inout) :: this
    real(dp), intent(inout) :: x(:)
    integer(ip) :: c, j, m, nd, s, k
    do c = 1, this%classes%nclass
      m = this%classes%moff(c + 1) - this%classes%moff(c)
      s = this%classes%member(this%classes%moff(c) + 1)
      nd = this%offset(s + 1) - this%offset(s)
      if (m == 1) then
        call this%kplus(c)%solve(x(this%offset(s) + 1:this%offset(s + 1)))
        if (this%classes%scale(s) /= 1) x(this%offset(s) + 1:this%offset(s + 1)) = &
          x(this%offset(s) + 1:this%offset(s + 1))/this%classes%scale(s)
        cycle
      end if
      call solve_class(this%work(1:nd*m, 1), nd, m)
    end do
  contains
    subroutine solve_class(w, nd, m)
      integer(ip), intent(in) :: nd, m
      real(dp), intent(inout), target :: w(nd, m)
      do j = 1, m
        s = this%classes%member(this%classes%moff(c) + j)
        w(:, j) = x(this%offset(s) + 1:this%offset(s + 1))
      end do
      call this%kplus(c)%solve_many(w)
      do j = 1, m
        s = this%classes%member(this%classes%moff(c) + j)
        k = this%offset(s)
        x(k + 1:k + nd) = w(:, j)/this%classes%scale(s)
      end do
    end subroutine solve_class
  end subroutine solve

  integer(i8) function factor_bytes(this)
    class(kplus_shared_t), intent(in) :: this
    integer(ip) :: c
    factor_bytes = 0
    if (.not. allocated(this%kplus)) return
    do c = 1, size(this%kplus, kind=ip)
      factor_bytes = factor_bytes + this%kplus(c)%factor_bytes()
    end do
  end function factor_bytes

  real(dp) function factor_flops(this)
    class(kplus_shared_t), intent(in) :: this
    integer(ip) :: c
    factor_flops = 0
    if (.not. allocated(this%kplus)) return
    do c = 1, size(this%kplus, kind=ip)
      factor_flops = factor_flops + this%kplus(c)%factor_flops()
    end do
  end function factor_flops

  subroutine free(this)
    class(kplus_shared_t), intent(inout) :: this
    integer(ip) :: c
    if (allocated(this%kplus)) then
      do c = 1, size(this%kplus, kind=ip)
        call this%kplus(c)%free()
      end do
      deallocate (this%kplus)
    end if
    if (allocated(this%offset)) deallocate (this%offset)
    if (allocated(this%work)) deallocate (this%work)
  end subroutine free
end module kplus_shared
