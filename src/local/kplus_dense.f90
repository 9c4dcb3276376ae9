!> K^+ of small subdomains by dense linear algebra, split along the dofs
!> that B touches (`&solver local_solver = 'dense'`; docs/THEORY.md "Dense
!> local solver").
!>
!> For each subdomain, K_reg = K + rho_f Q_F Q_F^T as kplus builds it
!> (kplus::regularized_system, the fixing nodes chosen among the nodes whose
!> three dofs are touched when they fix the rigid body motions) is split into
!> the dofs D that B touches (the interface, Dirichlet and contact dofs) and
!> the others I:
!>
!>   K_reg = [K_II K_ID; K_DI K_DD] = U^T U,  U = [U_I W; 0 U_S],
!>   U_I^T U_I = K_II,  W = U_I^{-T} K_ID,
!>   U_S^T U_S = S = K_DD - W^T W   (the Schur complement on D, SPD),
!>
!> one dense Cholesky factorization (LAPACK dpotrf) of K_reg with the
!> interior dofs ordered first gives all three blocks; U_I and U_S are kept
!> as packed upper triangles, W is not kept (K_reg's I x D block, sparse,
!> serves instead). Then
!> - the F action needs (K_reg^{-1})_DD = S^{-1} only: t <- U_S^{-1} U_S^{-T} t
!>   (two packed triangular solves, `solve_touched`), reading n_d (n_d+1)/2
!>   values twice and never the interior;
!> - a full solve K_reg u = b (the right-hand side d, the reconstruction) is
!>   z_I = K_II^{-1} b_I, u_D = S^{-1} (b_D - K_DI z_I),
!>   u_I = K_II^{-1} (b_I - K_ID u_D), K_II^{-1} by U_I.
!> On subdomains of a few hundred dofs the fill of a sparse factor is nearly
!> dense anyway, and one dense factorization per subdomain costs a fraction
!> of MUMPS's per-matrix analysis and assembly of small fronts (measured in
!> docs/RESULTS.md "Dense local solver"). Memory per subdomain:
!> n_I (n_I+1)/2 + n_D (n_D+1)/2 values and the nonzeros of K_ID; the
!> factorization costs n^3/3 flops, so it is meant for small subdomains
!> (`local_solver = 'auto'` takes it up to `local_settings::dense_max_dofs`).
!> With the fixing block inside D x D (schur_ok), S of K itself is
!> U_S^T U_S minus that block: `schur_product`, the Dirichlet
!> preconditioner's local operator at no set-up cost.
!> Local: no communication.
module kplus_dense
  use kinds, only: dp, ip, i8
  use errors, only: fatal_error
  use subdomain, only: subdomain_t
  use kplus, only: regularized_system
  use local_inverse, only: local_inverse_t
  use lapack_interfaces, only: dpotrf, dtpsv, dtpmv
  implicit none
  private

  type, extends(local_inverse_t), public :: kplus_dense_t
    integer(ip) :: nblocks = 0
    integer(ip), allocatable :: offset(:)       !< (nblocks+1) dof offsets in the concatenated vector
    integer(ip), allocatable :: ni(:), nd(:)    !< (nblocks) interior and touched dofs
    integer(ip), allocatable :: iptr(:), dptr(:) !< (nblocks+1) offsets into idof, ddof
    integer(ip), allocatable :: idof(:), ddof(:) !< local dof numbers of I and D (ascending)
    integer(i8), allocatable :: uoff(:), soff(:) !< (nblocks+1) offsets into ui, us
    real(dp), allocatable :: ui(:)              !< U_I, packed upper triangle
    real(dp), allocatable :: us(:)              !< U_S, packed upper triangle
    !> K_reg's I x D block in CSR (rows: interior positions of all blocks,
    !> kptr(iptr(s)+1 : iptr(s+1)+1); columns: touched positions 1..n_D of the block)
    integer(i8), allocatable :: kptr(:)
    integer(ip), allocatable :: kcol(:)
    real(dp), allocatable :: kval(:)
    real(dp) :: flops = 0                       !< flops of the factorizations
    !> the fixing block rho_f Q_F Q_F^T of each K_reg when all its dofs are
    !> touched (schur_ok): positions in the touched numbering and the dense
    !> block, so that S of K itself is U_S^T U_S minus it (schur_product)
    logical, allocatable :: schur_ok(:)
    integer(ip), allocatable :: fptr(:), fpos(:)
    integer(i8), allocatable :: fboff(:)
    real(dp), allocatable :: fblock(:)
    real(dp), allocatable :: yi(:), yd(:), zi(:) !< work
  contains
    procedure :: init
    procedure :: init_split
    procedure :: solve
    procedure :: solve_touched
    procedure :: schur_product
    procedure :: all_schur_ok
    procedure :: schur_factor
    procedure :: factor_bytes
    procedure :: factor_flops
    procedure :: free
  end type kplus_dense_t

contains

  !> All dofs touched (no interior): a dense Cholesky factor of each K_reg.
  !> `ordering` is not used (dense).
  subroutine init(this, subs, regularization, ordering)
    class(kplus_dense_t), intent(inout) :: this
    type(subdomain_t), intent(in) :: subs(:)
    real(dp), intent(in) :: regularization
    character(len=*), intent(in) :: ordering
    integer(ip), allocatable :: ptr(:), dofs(:)
    integer(ip) :: s, i, k
    if (ordering == '') continue   ! dense: no ordering
    allocate (ptr(size(subs) + 1))
    ptr(1) = 0
    do s = 1, size(subs, kind=ip)
      ptr(s + 1) = ptr(s) + subs(s)%ndof
    end do
    allocate (dofs(ptr(size(subs) + 1)))
    k = 0
    do s = 1, size(subs, kind=ip)
      do i = 1, subs(s)%ndof
        k = k + 1
        dofs(k) = i
      end do
    end do
    call this%init_split(subs, regularization, ptr, dofs)
  end subroutine init

  !> The sizes and offsets of the split blocks of `subs` (the touched dofs of
  !> subdomain s: tptr(s)+1:tptr(s+1)) and the arrays that hold them.
  subroutine split_layout(this, subs, tptr)
    type(kplus_dense_t), intent(inout) :: this
    type(subdomain_t), intent(in) :: subs(:)
    integer(ip), intent(in) :: tptr(:)
    integer(ip) :: s, n, ni, nd, nimax, ndmax
    this%nblocks = size(subs, kind=ip)
    if (size(tptr) /= this%nblocks + 1) call fatal_error('kplus_dense%init_split: tptr must have nblocks+1 entries')
    allocate (this%offset(this%nblocks + 1), this%ni(this%nblocks), this%nd(this%nblocks), &
              this%iptr(this%nblocks + 1), this%dptr(this%nblocks + 1), this%uoff(this%nblocks + 1), &
              this%soff(this%nblocks + 1))
    this%offset(1) = 0
    this%iptr(1) = 0
    this%dptr(1) = 0
    this%uoff(1) = 0
    this%soff(1) = 0
    do s = 1, this%nblocks
      n = subs(s)%ndof
      nd = tptr(s + 1) - tptr(s)
      if (nd < 0 .or. nd > n) call fatal_error('kplus_dense%init_split: touched dofs out of range')
      ni = n - nd
      this%offset(s + 1) = this%offset(s) + n
      this%ni(s) = ni
      this%nd(s) = nd
      this%iptr(s + 1) = this%iptr(s) + ni
      this%dptr(s + 1) = this%dptr(s) + nd
      this%uoff(s + 1) = this%uoff(s) + int(ni, i8)*(ni + 1)/2
      this%soff(s + 1) = this%soff(s) + int(nd, i8)*(nd + 1)/2
    end do
    allocate (this%idof(this%iptr(this%nblocks + 1)), this%ddof(this%dptr(this%nblocks + 1)), &
              this%ui(this%uoff(this%nblocks + 1)), this%kptr(this%iptr(this%nblocks + 1) + 1), &
              this%us(this%soff(this%nblocks + 1)))
    nimax = maxval([1_ip, this%ni])
    ndmax = maxval([1_ip, this%nd])
    allocate (this%yi(nimax), this%yd(ndmax), this%zi(nimax))
    this%kptr(1) = 0
    allocate (this%kcol(0), this%kval(0))
    allocate (this%schur_ok(this%nblocks), this%fptr(this%nblocks + 1), this%fboff(this%nblocks + 1))
    allocate (this%fpos(0), this%fblock(0))
    this%fptr(1) = 0
    this%fboff(1) = 0
  end subroutine split_layout

  !> The split of block `s` (n dofs): is_d(i) whether dof i is touched, pos(i)
  !> its position in I (1..ni) or D (1..nd); this%idof and this%ddof filled.
  subroutine split_positions(this, s, n, tptr, touched, is_d, pos)
    type(kplus_dense_t), intent(inout) :: this
    integer(ip), intent(in) :: s, n, tptr(:), touched(:)
    logical, allocatable, intent(inout) :: is_d(:)
    integer(ip), allocatable, intent(inout) :: pos(:)
    integer(ip) :: i, k
    if (allocated(is_d)) deallocate (is_d, pos)
    allocate (is_d(n), pos(n))
    is_d = .false.
    do k = 1, this%nd(s)
      i = touched(tptr(s) + k)
      if (i < 1 .or. i > n) call fatal_error('kplus_dense%init_split: touched dof out of range')
      if (is_d(i)) call fatal_error('kplus_dense%init_split: a touched dof is listed twice')
      if (k > 1) then
        if (i < touched(tptr(s) + k - 1)) call fatal_error('kplus_dense%init_split: touched dofs must ascend')
      end if
      is_d(i) = .true.
      pos(i) = k
      this%ddof(this%dptr(s) + k) = i
    end do
    k = 0
    do i = 1, n
      if (is_d(i)) cycle
      k = k + 1
      pos(i) = k
      this%idof(this%iptr(s) + k) = i
    end do
  end subroutine split_positions

  !> Factorize every subdomain's K_reg split along its touched dofs: those of
  !> subdomain s are touched(tptr(s)+1:tptr(s+1)), ascending local dof numbers.
  subroutine init_split(this, subs, regularization, tptr, touched)
    class(kplus_dense_t), intent(inout) :: this
    type(subdomain_t), intent(in) :: subs(:)
    real(dp), intent(in) :: regularization
    integer(ip), intent(in) :: tptr(:), touched(:)
    integer(ip), allocatable :: irn(:), jcn(:), perm(:), pos(:), fdofs(:)
    real(dp), allocatable :: a(:), kd(:, :), fblk(:, :)
    logical, allocatable :: is_d(:), allowed(:)
    integer(ip) :: s, n, ni, nd, i, j, k, e
    integer(i8) :: o
    integer :: info

    call this%free()
    call split_layout(this, subs, tptr)

    do s = 1, this%nblocks
      n = subs(s)%ndof
      ni = this%ni(s)
      nd = this%nd(s)
      call split_positions(this, s, n, tptr, touched, is_d, pos)
      ! fixing nodes among the nodes whose three dofs are touched, where
      ! they fix the rigid body motions: then K_reg differs from K on D x D
      ! only, and S of K is U_S^T U_S minus the fixing block (schur_product)
      allowed = [(all(is_d(3*k - 2:3*k)), k=1, subs(s)%nnodes)]
      call regularized_system(subs(s), regularization, 'amd', irn, jcn, a, perm, allowed, fdofs, fblk)
      this%schur_ok(s) = all(is_d(fdofs))
      this%fptr(s + 1) = this%fptr(s)
      this%fboff(s + 1) = this%fboff(s)
      if (this%schur_ok(s)) call append_fixing(this, pos(fdofs), fblk, s)
      ! K_reg, dense, in the order (I, D): its Cholesky factor is then
      ! [U_I W; 0 U_S] (one dpotrf for all three blocks)
      do k = 1, n
        if (is_d(k)) pos(k) = pos(k) + ni
      end do
      if (allocated(kd)) then
        if (size(kd, 1) < n) deallocate (kd)
      end if
      if (.not. allocated(kd)) allocate (kd(n, n))
      kd(1:n, 1:n) = 0
      do e = 1, size(a)
        i = min(pos(irn(e)), pos(jcn(e)))
        j = max(pos(irn(e)), pos(jcn(e)))
        kd(i, j) = kd(i, j) + a(e)
      end do
      ! K_reg's I x D block (rows of I, the upper part of kd), kept sparse for
      ! the full solves instead of the dense W = U_I^{-T} K_ID
      call append_kid(kd, ni, nd, this%iptr(s))
      call dpotrf('U', n, kd, size(kd, 1), info)
      if (info /= 0) call fatal_error('kplus_dense: K_reg is not positive definite (LAPACK dpotrf failed)')
      o = this%uoff(s)
      do j = 1, ni
        this%ui(o + int(j, i8)*(j - 1)/2 + 1:o + int(j, i8)*(j + 1)/2) = kd(1:j, j)
      end do
      o = this%soff(s)
      do j = 1, nd
        this%us(o + int(j, i8)*(j - 1)/2 + 1:o + int(j, i8)*(j + 1)/2) = kd(ni + 1:ni + j, ni + j)
      end do
      this%flops = this%flops + real(ni, dp)**3/3 + real(ni, dp)**2*nd + real(nd, dp)**2*ni + &
                   real(nd, dp)**3/3
    end do
  contains

    !> The nonzeros of kd(1:ni, ni+1:ni+nd) by rows into kptr/kcol/kval,
    !> rows after `row0` (the block's first interior position - 1).
    subroutine append_kid(kd, ni, nd, row0)
      real(dp), intent(in) :: kd(:, :)
      integer(ip), intent(in) :: ni, nd, row0
      integer(ip) :: r, c
      integer(i8) :: nz, k0
      k0 = this%kptr(row0 + 1)
      nz = count(kd(1:ni, ni + 1:ni + nd) /= 0, kind=i8)
      if (k0 + nz > size(this%kcol, kind=i8)) call grow_kid(max(k0 + nz, 2*size(this%kcol, kind=i8)))
      nz = k0
      do r = 1, ni
        do c = 1, nd
          if (kd(r, ni + c) == 0) cycle
          nz = nz + 1
          this%kcol(nz) = c
          this%kval(nz) = kd(r, ni + c)
        end do
        this%kptr(row0 + r + 1) = nz
      end do
    end subroutine append_kid


    subroutine grow_kid(cap)
      integer(i8), intent(in) :: cap
      integer(ip), allocatable :: tc(:)
      real(dp), allocatable :: tv(:)
      allocate (tc(cap), tv(cap))
      tc(1:size(this%kcol)) = this%kcol
      tv(1:size(this%kval)) = this%kval
      call move_alloc(tc, this%kcol)
      call move_alloc(tv, this%kval)
    end subroutine grow_kid
  end subroutine init_split

  !> The fixing block of block s on its touched positions, appended to
  !> fpos/fblock (grown by doubling: one append per subdomain).
  subroutine append_fixing(this, fp, blk, s)
    class(kplus_dense_t), intent(inout) :: this
    integer(ip), intent(in) :: fp(:), s
    real(dp), intent(in) :: blk(:, :)
    integer(ip), allocatable :: tp(:)
    real(dp), allocatable :: tb(:)
    integer(ip) :: nf
    integer(i8) :: nb
    nf = size(fp, kind=ip)
    nb = int(nf, i8)*nf
    if (this%fptr(s) + nf > size(this%fpos)) then
      allocate (tp(max(this%fptr(s) + nf, 2*size(this%fpos, kind=ip))))
      tp(1:this%fptr(s)) = this%fpos(1:this%fptr(s))
      call move_alloc(tp, this%fpos)
    end if
    if (this%fboff(s) + nb > size(this%fblock, kind=i8)) then
      allocate (tb(max(this%fboff(s) + nb, 2*size(this%fblock, kind=i8))))
      tb(1:this%fboff(s)) = this%fblock(1:this%fboff(s))
      call move_alloc(tb, this%fblock)
    end if
    this%fpos(this%fptr(s) + 1:this%fptr(s) + nf) = fp
    this%fblock(this%fboff(s) + 1:this%fboff(s) + nb) = reshape(blk, [nb])
    this%fptr(s + 1) = this%fptr(s) + nf
    this%fboff(s + 1) = this%fboff(s) + nb
  end subroutine append_fixing

  !> x <- K^+ x for the concatenated vector of all blocks.
  subroutine solve(this, x)
    class(kplus_dense_t), intent(inout) :: this
    real(dp), intent(inout) :: x(:)
    integer(ip) :: s, ni, nd, o, k
    if (this%nblocks == 0) return
    if (size(x) /= this%offset(this%nblocks + 1)) call fatal_error('kplus_dense%solve: x must have ndof entries')
    do s = 1, this%nblocks
      ni = this%ni(s)
      nd = this%nd(s)
      o = this%offset(s)
      do k = 1, ni
        this%yi(k) = x(o + this%idof(this%iptr(s) + k))
      end do
      do k = 1, nd
        this%yd(k) = x(o + this%ddof(this%dptr(s) + k))
      end do
      if (ni > 0) then
        ! z_I = K_II^{-1} b_I, y_D = b_D - K_DI z_I
        this%zi(1:ni) = this%yi(1:ni)
        call packed_cholesky_solve(ni, this%ui(this%uoff(s) + 1:this%uoff(s + 1)), this%zi)
        if (nd > 0) call kid_product(this, s, this%zi, this%yd, transposed=.true.)
      end if
      if (nd > 0) call packed_cholesky_solve(nd, this%us(this%soff(s) + 1:this%soff(s + 1)), this%yd)
      if (ni > 0) then
        ! u_I = K_II^{-1} (b_I - K_ID u_D)
        if (nd > 0) call kid_product(this, s, this%yd, this%yi, transposed=.false.)
        call packed_cholesky_solve(ni, this%ui(this%uoff(s) + 1:this%uoff(s + 1)), this%yi)
      end if
      do k = 1, ni
        x(o + this%idof(this%iptr(s) + k)) = this%yi(k)
      end do
      do k = 1, nd
        x(o + this%ddof(this%dptr(s) + k)) = this%yd(k)
      end do
    end do
  end subroutine solve

  !> transposed: y_D -= K_DI v_I; else y_I -= K_ID v_D (block s).
  subroutine kid_product(this, s, v, y, transposed)
    class(kplus_dense_t), intent(in) :: this
    integer(ip), intent(in) :: s
    real(dp), intent(in) :: v(:)
    real(dp), intent(inout) :: y(:)
    logical, intent(in) :: transposed
    integer(ip) :: r, row0
    integer(i8) :: e
    row0 = this%iptr(s)
    do r = 1, this%ni(s)
      if (transposed) then
        do e = this%kptr(row0 + r) + 1, this%kptr(row0 + r + 1)
          y(this%kcol(e)) = y(this%kcol(e)) - this%kval(e)*v(r)
        end do
      else
        do e = this%kptr(row0 + r) + 1, this%kptr(row0 + r + 1)
          y(r) = y(r) - this%kval(e)*v(this%kcol(e))
        end do
      end if
    end do
  end subroutine kid_product

  !> t <- S_s^{-1} t = ((K_reg^s)^{-1})_DD t for block s, t on its touched
  !> dofs in ascending order (length n_d).
  subroutine solve_touched(this, s, t)
    class(kplus_dense_t), intent(in) :: this
    integer(ip), intent(in) :: s
    real(dp), intent(inout) :: t(:)
    integer(ip) :: nd
    nd = this%nd(s)
    if (nd == 0) return
    if (size(t) < nd) call fatal_error('kplus_dense%solve_touched: t shorter than the touched dofs')
    call packed_cholesky_solve(nd, this%us(this%soff(s) + 1:this%soff(s + 1)), t)
  end subroutine solve_touched

  !> u = S_s t for block s, S_s the Schur complement of K itself (not K_reg)
  !> on the touched dofs, t and u on them in ascending order (length n_d):
  !> S_s = U_S^T U_S - (the fixing block on its positions), valid when all
  !> the fixing dofs are touched (schur_ok). Two packed triangular products.
  subroutine schur_product(this, s, t, u)
    class(kplus_dense_t), intent(in) :: this
    integer(ip), intent(in) :: s
    real(dp), intent(in) :: t(:)
    real(dp), intent(inout) :: u(:)
    integer(ip) :: nd, nf, i, j
    integer(i8) :: o
    nd = this%nd(s)
    if (nd == 0) return
    if (.not. this%schur_ok(s)) call fatal_error('kplus_dense%schur_product: a fixing node of this subdomain '// &
                                                 'is not touched')
    u(1:nd) = t(1:nd)
    call dtpmv('U', 'N', 'N', nd, this%us(this%soff(s) + 1:this%soff(s + 1)), u, 1)
    call dtpmv('U', 'T', 'N', nd, this%us(this%soff(s) + 1:this%soff(s + 1)), u, 1)
    nf = this%fptr(s + 1) - this%fptr(s)
    o = this%fboff(s)
    do j = 1, nf
      do i = 1, nf
        u(this%fpos(this%fptr(s) + i)) = u(this%fpos(this%fptr(s) + i)) - &
                                         this%fblock(o + int(j - 1, i8)*nf + i)*t(this%fpos(this%fptr(s) + j))
      end do
    end do
  end subroutine schur_product

  !> True when every block can give S of K (schur_ok).
  logical function all_schur_ok(this)
    class(kplus_dense_t), intent(in) :: this
    all_schur_ok = .true.
    if (allocated(this%schur_ok)) all_schur_ok = all(this%schur_ok)
  end function all_schur_ok

  !> t(1:n) <- (U^T U)^{-1} t(1:n), U upper triangular in packed storage.
  subroutine packed_cholesky_solve(n, up, t)
    integer(ip), intent(in) :: n
    real(dp), intent(in) :: up(:)
    real(dp), intent(inout) :: t(:)
    call dtpsv('U', 'T', 'N', n, up, t, 1)
    call dtpsv('U', 'N', 'N', n, up, t, 1)
  end subroutine packed_cholesky_solve

  !> The packed upper triangle of U_S of block s (for the explicit inverse).
  function schur_factor(this, s) result(u)
    class(kplus_dense_t), intent(in) :: this
    integer(ip), intent(in) :: s
    real(dp), allocatable :: u(:)
    u = this%us(this%soff(s) + 1:this%soff(s + 1))
  end function schur_factor

  !> Bytes of the stored factors (U_I, W, U_S).
  integer(i8) function factor_bytes(this)
    class(kplus_dense_t), intent(in) :: this
    factor_bytes = 0
    if (.not. allocated(this%ui)) return
    factor_bytes = 8*(size(this%ui, kind=i8) + size(this%us, kind=i8)) + 12*size(this%kval, kind=i8) + &
                   8*size(this%kptr, kind=i8)
  end function factor_bytes

  !> Flops of the factorizations (n_I^3/3 + n_I^2 n_D + n_D^2 n_I + n_D^3/3 per block).
  real(dp) function factor_flops(this)
    class(kplus_dense_t), intent(in) :: this
    factor_flops = this%flops
  end function factor_flops

  subroutine free(this)
    class(kplus_dense_t), intent(inout) :: this
    if (allocated(this%offset)) deallocate (this%offset, this%ni, this%nd, this%iptr, this%dptr, this%uoff, &
                                            this%soff)
    if (allocated(this%idof)) deallocate (this%idof, this%ddof, this%ui, this%us, this%kptr)
    if (allocated(this%kcol)) deallocate (this%kcol, this%kval)
    if (allocated(this%yi)) deallocate (this%yi, this%yd, this%zi)
    if (allocated(this%schur_ok)) deallocate (this%schur_ok, this%fptr, this%fboff, this%fpos, this%fblock)
    this%nblocks = 0
    this%flops = 0
  end subroutine free
end module kplus_dense
