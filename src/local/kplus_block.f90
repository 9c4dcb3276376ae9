!> K^+ of all the subdomains of one rank at once: the block-diagonal matrix
!> diag(K_reg^1, ..., K_reg^n) factorized by ONE MUMPS instance (on
!> MPI_COMM_SELF). Each block is the subdomain's own K + rho_f R_F R_F^T (see
!> kplus); nothing is shared between subdomains. A solve with all the local
!> subdomains' right-hand sides is one MUMPS call, so MUMPS's fixed cost per
!> call (about 45 us, half of a solve on a 4^3 subdomain, docs/RESULTS.md) is
!> paid once per F action instead of once per subdomain, and a rank holds one
!> MUMPS instance (3 communicators) however many subdomains it owns.
module kplus_block
  use kinds, only: dp, ip, i8
  use errors, only: fatal_error
  use subdomain, only: subdomain_t
  use kplus, only: regularized_system
  use mumps_wrapper, only: mumps_t
  use local_inverse, only: local_inverse_t
  use mpi_f08, only: MPI_COMM_SELF
  implicit none
  private

  type, extends(local_inverse_t), public :: kplus_block_t
    integer(ip) :: nblocks = 0
    integer(ip) :: ndof = 0                    !< sum of the subdomains' dofs
    integer(ip), allocatable :: offset(:)      !< (nblocks+1): dofs of block s are offset(s)+1..offset(s+1)
    type(mumps_t) :: solver
    logical :: factorized = .false.
  contains
    procedure :: init
    procedure :: solve
    procedure :: factor_bytes
    procedure :: factor_flops
    procedure :: free
  end type kplus_block_t

contains

  !> Factorize the K_reg of every subdomain in `subs` (which hold K and R).
  subroutine init(this, subs, regularization, ordering)
    class(kplus_block_t), intent(inout) :: this
    type(subdomain_t), intent(in) :: subs(:)
    real(dp), intent(in) :: regularization
    character(len=*), intent(in) :: ordering
    integer(ip), allocatable :: irn(:), jcn(:), perm(:), bi(:), bj(:), bperm(:)
    real(dp), allocatable :: a(:), ba(:)
    integer(i8) :: nnz, cap
    integer(ip) :: s, n, o

    call this%free()
    if (ordering /= 'amd' .and. ordering /= 'metis') &
      call fatal_error("kplus_block: unknown ordering '"//trim(ordering)//"' (amd or metis)")
    this%nblocks = size(subs, kind=ip)
    allocate (this%offset(this%nblocks + 1))
    this%offset(1) = 0
    do s = 1, this%nblocks
      this%offset(s + 1) = this%offset(s) + subs(s)%ndof
    end do
    this%ndof = this%offset(this%nblocks + 1)
    if (this%ndof == 0) return
    ! entries: count first (K's upper triangle + fixing block per subdomain)
    nnz = 0
    allocate (bperm(this%ndof))
    do s = 1, this%nblocks
      call regularized_system(subs(s), regularization, ordering, irn, jcn, a, perm)
      nnz = nnz + size(a)
      if (s == 1) then
        cap = max(nnz*this%nblocks*11/10, nnz)
        allocate (bi(cap), bj(cap), ba(cap))
      else if (nnz > size(bi)) then
        call grow(max(nnz, 2*size(bi, kind=i8)))
      end if
      o = this%offset(s)
      n = size(a)
      bi(nnz - n + 1:nnz) = irn + o
      bj(nnz - n + 1:nnz) = jcn + o
      ba(nnz - n + 1:nnz) = a
      if (ordering == 'metis') bperm(o + 1:o + subs(s)%ndof) = perm + o
    end do
    call this%solver%init(MPI_COMM_SELF, spd=.true.)
    call this%solver%set_centralized(this%ndof, bi(1:nnz), bj(1:nnz), ba(1:nnz))
    deallocate (bi, bj, ba)
    if (ordering == 'metis') then
      call this%solver%set_ordering('metis', bperm)
    else
      call this%solver%set_ordering('amd')
    end if
    call this%solver%factorize()
    this%factorized = .true.
  contains
    subroutine grow(new_size)
      integer(i8), intent(in) :: new_size
      integer(ip), allocatable :: ti(:), tj(:)
      real(dp), allocatable :: ta(:)
      integer(i8) :: old
      old = nnz - size(a)
      allocate (ti(new_size), tj(new_size), ta(new_size))
      ti(1:old) = bi(1:old)
      tj(1:old) = bj(1:old)
      ta(1:old) = ba(1:old)
      call move_alloc(ti, bi)
      call move_alloc(tj, bj)
      call move_alloc(ta, ba)
    end subroutine grow
  end subroutine init

  !> x <- K^+ x for the concatenated vector of all blocks (length ndof).
  subroutine solve(this, x)
    class(kplus_block_t), intent(inout) :: this
    real(dp), intent(inout) :: x(:)
    if (this%ndof == 0) return
    if (size(x) /= this%ndof) call fatal_error('kplus_block%solve: x must have ndof entries')
    call this%solver%solve(x)
  end subroutine solve

  !> Bytes of the factors (see mumps_t%factor_bytes).
  integer(i8) function factor_bytes(this)
    class(kplus_block_t), intent(in) :: this
    factor_bytes = 0
    if (this%factorized) factor_bytes = this%solver%factor_bytes()
  end function factor_bytes

  !> Floating-point operations of the factorization (MUMPS's RINFOG(3)).
  real(dp) function factor_flops(this)
    class(kplus_block_t), intent(in) :: this
    factor_flops = 0
    if (this%factorized) factor_flops = this%solver%factor_flops()
  end function factor_flops

  subroutine free(this)
    class(kplus_block_t), intent(inout) :: this
    if (this%factorized) call this%solver%free()
    this%factorized = .false.
    if (allocated(this%offset)) deallocate (this%offset)
    this%nblocks = 0
    this%ndof = 0
  end subroutine free
end module kplus_block
