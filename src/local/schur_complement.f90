!> The Schur complements S_s = K_bb - K_bi K_ii^{-1} K_ib of the subdomains of
!> one rank on their interfaces (the dofs marked by the caller: for the
!> Dirichlet preconditioner of FETI, the dofs that B touches), applied
!> implicitly: for x on the interface,
!>
!>     v = [x_b; 0],  t = K v,  w_i = K_ii^{-1} t_i,  v_i = -w_i,  S x = (K v)_b,
!>
!> two sparse products with K and one solve with K_ii per application. The
!> K_ii of all the rank's subdomains form one block-diagonal matrix, factorized
!> once by ONE MUMPS instance on MPI_COMM_SELF (as kplus_block does for K^+),
!> so that an application is one MUMPS solve however many subdomains the rank
!> owns. K_ii is positive definite when the interface fixes the rigid body
!> motions (every subdomain that shares a face with another one, or has
!> Dirichlet rows on a face); a subdomain without interior dofs gives S = K_bb.
!>
!> `dense_schur`: the same Schur complement formed explicitly, dense, of a
!> symmetric matrix given by its upper triangle (one MUMPS factorization with
!> the Schur variables kept, MPI_COMM_SELF); the one routine that forms dense
!> Schur complements, for the explicit F (of K_reg, f_operator) and for the
!> Dirichlet preconditioner shared per class (of K, dual_preconditioner,
!> through `stiffness_schur`).
module schur_complement
  use kinds, only: dp, ip, i8
  use errors, only: fatal_error
  use subdomain, only: subdomain_t, stiffness_matvec
  use mumps_wrapper, only: mumps_t
  use mpi_f08, only: MPI_COMM_SELF
  implicit none
  private

  public :: dense_schur, stiffness_schur

  type, public :: schur_complement_t
    integer(ip) :: nblocks = 0
    integer(ip) :: ndof = 0                     !< length of the concatenated vector
    integer(ip) :: ninterior = 0                !< interior dofs of all blocks
    integer(ip), allocatable :: offset(:)       !< (nblocks+1) dof offsets
    integer(ip), allocatable :: interior(:)     !< (ndof) position among the interior dofs, 0 on the interface
    real(dp), allocatable, private :: v(:), t(:), wi(:)
    type(mumps_t), private :: solver
    logical, private :: factorized = .false.
  contains
    procedure :: init
    procedure :: apply
    procedure :: factor_bytes
    procedure :: free
  end type schur_complement_t

contains

  !> Factorize the K_ii of every subdomain in `subs` (K assembled);
  !> `on_interface(1:ndof)` marks the interface dofs of the concatenated
  !> vector (subdomain s at sum of the ndof before it).
  subroutine init(this, subs, on_interface)
    class(schur_complement_t), intent(inout) :: this
    type(subdomain_t), intent(in) :: subs(:)
    logical, intent(in) :: on_interface(:)
    integer(ip), allocatable :: irn(:), jcn(:)
    real(dp), allocatable :: a(:)
    integer(ip) :: s, i, k, j, o, nz, ks
    integer(i8) :: nupper

    call this%free()
    this%nblocks = size(subs, kind=ip)
    allocate (this%offset(this%nblocks + 1))
    this%offset(1) = 0
    do s = 1, this%nblocks
      this%offset(s + 1) = this%offset(s) + subs(s)%ndof
    end do
    this%ndof = this%offset(this%nblocks + 1)
    if (size(on_interface) /= this%ndof) call fatal_error('schur_complement: interface mask of the wrong length')
    allocate (this%interior(this%ndof), this%v(this%ndof), this%t(this%ndof))
    this%ninterior = 0
    do i = 1, this%ndof
      this%interior(i) = 0
      if (.not. on_interface(i)) then
        this%ninterior = this%ninterior + 1
        this%interior(i) = this%ninterior
      end if
    end do
    allocate (this%wi(max(this%ninterior, 1)))
    if (this%ninterior == 0) return
    ! the upper triangle of the block-diagonal K_ii in the interior numbering
    nupper = 0
    do s = 1, this%nblocks
      o = this%offset(s)
      ks = k_owner(subs, s)
      do i = 1, subs(s)%ndof
        if (this%interior(o + i) == 0) cycle
        do k = subs(ks)%K%rowptr(i), subs(ks)%K%rowptr(i + 1) - 1
          j = subs(ks)%K%colind(k)
          if (this%interior(o + j) >= this%interior(o + i)) nupper = nupper + 1
        end do
      end do
    end do
    allocate (irn(nupper), jcn(nupper), a(nupper))
    nz = 0
    do s = 1, this%nblocks
      o = this%offset(s)
      ks = k_owner(subs, s)
      do i = 1, subs(s)%ndof
        if (this%interior(o + i) == 0) cycle
        do k = subs(ks)%K%rowptr(i), subs(ks)%K%rowptr(i + 1) - 1
          j = subs(ks)%K%colind(k)
          if (this%interior(o + j) >= this%interior(o + i)) then
            nz = nz + 1
            irn(nz) = this%interior(o + i)
            jcn(nz) = this%interior(o + j)
            a(nz) = subs(s)%k_scale*subs(ks)%K%values(k)
          end if
        end do
      end do
    end do
    call this%solver%init(MPI_COMM_SELF, spd=.true.)
    call this%solver%set_centralized(this%ninterior, irn, jcn, a)
    deallocate (irn, jcn, a)
    call this%solver%set_ordering('amd')
    call this%solver%factorize()
    this%factorized = .true.
  end subroutine init

  !> x <- S x on the concatenated vector: x is read on the interface dofs
  !> (its interior entries are ignored); on return it holds S x there and 0
  !> on the interior dofs.
  subroutine apply(this, subs, x)
    class(schur_complement_t), intent(inout) :: this
    type(subdomain_t), intent(in) :: subs(:)
    real(dp), intent(inout) :: x(:)
    integer(ip) :: s, i, r1, r2
    if (size(x) /= this%ndof) call fatal_error('schur_complement%apply: x must have ndof entries')
    do i = 1, this%ndof
      this%v(i) = x(i)
      if (this%interior(i) > 0) this%v(i) = 0
    end do
    if (this%ninterior > 0) then
      do s = 1, this%nblocks
        r1 = this%offset(s) + 1
        r2 = this%offset(s + 1)
        call stiffness_matvec(subs, s, this%v(r1:r2), this%t(r1:r2))
      end do
      do i = 1, this%ndof
        if (this%interior(i) > 0) this%wi(this%interior(i)) = this%t(i)
      end do
      call this%solver%solve(this%wi(1:this%ninterior))
      do i = 1, this%ndof
        if (this%interior(i) > 0) this%v(i) = -this%wi(this%interior(i))
      end do
    end if
    do s = 1, this%nblocks
      r1 = this%offset(s) + 1
      r2 = this%offset(s + 1)
      call stiffness_matvec(subs, s, this%v(r1:r2), x(r1:r2))
    end do
    do i = 1, this%ndof
      if (this%interior(i) > 0) x(i) = 0
    end do
  end subroutine apply

  !> Bytes of the factors of the K_ii.
  integer(i8) function factor_bytes(this)
    class(schur_complement_t), intent(in) :: this
    factor_bytes = 0
    if (this%factorized) factor_bytes = this%solver%factor_bytes()
  end function factor_bytes

  subroutine free(this)
    class(schur_complement_t), intent(inout) :: this
    if (this%factorized) call this%solver%free()
    this%factorized = .false.
    if (allocated(this%offset)) deallocate (this%offset)
    if (allocated(this%interior)) deallocate (this%interior)
    if (allocated(this%v)) deallocate (this%v, this%t)
    if (allocated(this%wi)) deallocate (this%wi)
    this%nblocks = 0
    this%ndof = 0
    this%ninterior = 0
  end subroutine free

  !> sd = S = A_vv - A_vi A_ii^{-1} A_iv, dense (both triangles), of the
  !> symmetric matrix A of order `n` given by its upper triangle (irn, jcn, a)
  !> on the variables v = `dofs` (in their order); A_ii must be positive
  !> definite. All variables: sd = A(dofs, dofs). MUMPS's count of the
  !> elimination is added to `flops`.
  subroutine dense_schur(n, irn, jcn, a, dofs, sd, flops)
    integer(ip), intent(in) :: n
    integer(ip), intent(in) :: irn(:), jcn(:)
    real(dp), intent(in) :: a(:)
    integer(ip), intent(in) :: dofs(:)
    real(dp), allocatable, intent(out) :: sd(:, :)
    real(dp), intent(inout) :: flops
    integer(ip), allocatable :: cmap(:)
    type(mumps_t) :: m
    integer(ip) :: nv, i, j, k
    nv = size(dofs, kind=ip)
    allocate (sd(nv, nv))
    if (nv == 0) return
    if (nv == n) then
      allocate (cmap(n))
      cmap = 0
      do i = 1, nv
        cmap(dofs(i)) = i
      end do
      sd = 0
      do k = 1, size(a, kind=ip)
        i = cmap(irn(k))
        j = cmap(jcn(k))
        sd(i, j) = sd(i, j) + a(k)
        if (i /= j) sd(j, i) = sd(j, i) + a(k)
      end do
      return
    end if
    call m%init(MPI_COMM_SELF, spd=.true.)
    call m%set_centralized(n, irn, jcn, a)
    call m%set_ordering('amd')
    call m%set_schur(dofs)
    call m%factorize()
    call m%schur_complement(sd)
    flops = flops + m%factor_flops()
    call m%free()
  end subroutine dense_schur

  !> sd = the dense Schur complement of K of `sub` (K itself, not
  !> regularized) on its dofs `dofs` (dense_schur).
  subroutine stiffness_schur(sub, dofs, sd, flops)
    type(subdomain_t), intent(in) :: sub
    integer(ip), intent(in) :: dofs(:)
    real(dp), allocatable, intent(out) :: sd(:, :)
    real(dp), intent(inout) :: flops
    integer(ip), allocatable :: irn(:), jcn(:)
    real(dp), allocatable :: a(:)
    call sub%K%upper_coo(irn, jcn, a)
    call dense_schur(sub%ndof, irn, jcn, a, dofs, sd, flops)
  end subroutine stiffness_schur

  !> The subdomain whose K subdomain `s` reads: its own, or its class
  !> representative's (subdomain_t%k_of; times k_scale).
  pure integer(ip) function k_owner(subs, s) result(ks)
    type(subdomain_t), intent(in) :: subs(:)
    integer(ip), intent(in) :: s
    ks = s
    if (subs(s)%k_of /= 0) ks = subs(s)%k_of
  end function k_owner
end module schur_complement
