!> The dense part of the coarse problem's Schur mode (coarse_problem, init
!> with `schur_positions`).
!>
!> Contact rows touch only the coarse rows of the subdomains on the contact
!> face. Every face matrix G_M G_M^T of the polish and the G_A G_A^T of the
!> standard reconstruction differs from G G^T only there:
!>   G_M G_M^T = G G^T - sum over the contact rows r outside M of (G e_r)(G e_r)^T.
!> MUMPS eliminates every other coarse row once (the Schur complement S of
!> G G^T on the m contact-face rows); a face then costs the dense S - D_M
!> and its Cholesky factor (m^3/3 flops), and each solve a condensation, two
!> dense triangular solves and an expansion: no second sparse factorization,
!> no low-rank update solves.
!>
!> A contact row acts on the normal displacement of contact-face nodes only:
!> on one subdomain its 6 coarse values G e_r span (over all contact rows) a
!> space of dimension 3 at most (the normal translation and the two
!> tangential rotations). Each contact-face subdomain's 6 coarse rows are
!> rotated by an orthogonal Q_s (the eigenvectors of the sum of its g g^T,
!> that space first), and only its first r_s <= 3 rotated rows are Schur
!> rows: half the dense Schur complement, and fewer rows forced to the end
!> of MUMPS's pivot order.
!>
!> This module holds the rotations and what the host of a coarse group
!> keeps: S, the map from coarse positions to Schur slots, and Cholesky
!> factors of S - D. The contributions (G e_r restricted to one subdomain: 6
!> values, unrotated) arrive as "pieces" keyed by their row, from every rank.
module coarse_schur
  use kinds, only: dp, ip, i8
  use errors, only: fatal_error
  use sorting, only: sort_permutation
  use lapack_interfaces, only: dpotrf, dpotrs, dsyev, dtrsm, dgemm
  use mpi_f08, only: MPI_Comm, MPI_Bcast, MPI_DOUBLE_PRECISION
  implicit none
  private

  type, public :: coarse_schur_t
    integer(ip) :: m = 0                      !< Schur rows: r_s per contact-face subdomain s
    !> coarse position -> offset of its Schur rows in the Schur order (-1: none)
    integer(ip), allocatable :: slot(:)
    integer(ip), allocatable :: which(:)      !< coarse position -> index j of its rotation (0: none)
    real(dp), allocatable :: q(:, :, :)       !< (6, 6, j): the rotation Q_s, contact directions first
    integer(ip), allocatable :: r(:)          !< (j): Schur rows of the subdomain
    integer(ip), allocatable :: vars(:)       !< the Schur rows as global coarse rows, ascending
    real(dp), allocatable :: s(:, :)          !< host: the Schur complement of G G^T (full, symmetric)
  contains
    procedure :: init
    procedure :: downdated_factor
    procedure :: rotate
    procedure :: free
  end type coarse_schur_t

  !> A lower Cholesky factor of an m x m Schur matrix (on a group's host).
  type, public :: schur_factor_t
    integer(ip) :: m = 0
    real(dp), allocatable :: l(:, :)
    real(dp) :: seconds = 0                   !< forming and factorizing it
  contains
    procedure :: factor
    procedure :: factor_group
    procedure :: solve
  end type schur_factor_t

  !> Columns per block of factor_group (the block columns dealt to the
  !> group's ranks in turn).
  integer(ip), parameter :: group_block = 128
  !> factor_group is used from this many Schur rows on (group_factors):
  !> below, a factorization costs milliseconds on one rank and the
  !> broadcasts' synchronizations would cost more than they save (measured:
  !> m = 768 at 4096 subdomains, 2 ranks at load 20: 0.26 s on the host
  !> alone, 2.4 s on the pair); the host alone keeps LAPACK's dpotrf.
  integer(ip), parameter, public :: group_factor_rows = 1536

  public :: group_factors

contains

  !> The rotations and Schur rows of the subdomains at coarse `positions`
  !> (ascending, among `nsub`): gram(:, :, j) = sum of g g^T over the contact
  !> rows' pieces on the j-th of them.
  subroutine init(this, nsub, positions, gram)
    class(coarse_schur_t), intent(inout) :: this
    integer(ip), intent(in) :: nsub
    integer(ip), intent(in) :: positions(:)
    real(dp), intent(in) :: gram(:, :, :)
    integer(ip) :: j, k, n
    real(dp) :: a(6, 6), w(6), work(64)
    integer :: info
    call this%free()
    n = size(positions, kind=ip)
    allocate (this%slot(nsub), this%which(nsub), this%q(6, 6, n), this%r(n))
    this%slot = -1
    this%which = 0
    do j = 1, n
      if (j > 1) then
        if (positions(j) <= positions(j - 1)) call fatal_error('coarse_schur: positions must ascend')
      end if
      a = gram(:, :, j)
      call dsyev('V', 'U', 6, a, 6, w, work, size(work), info)
      if (info /= 0 .or. w(6) <= 0) call fatal_error('coarse_schur: no contact direction on a subdomain')
      ! descending: the contact directions first
      this%q(:, :, j) = a(:, 6:1:-1)
      this%r(j) = count(w > 1.0e-10_dp*w(6), kind=ip)
      this%which(positions(j)) = j
      this%slot(positions(j)) = this%m
      this%m = this%m + this%r(j)
    end do
    allocate (this%vars(this%m))
    do j = 1, n
      do k = 1, this%r(j)
        this%vars(this%slot(positions(j)) + k) = 6*(positions(j) - 1) + k
      end do
    end do
  end subroutine init

  !> v <- Q_s^T v (forward) or Q_s v for the subdomain at coarse position
  !> `pos` (unchanged without a rotation).
  pure subroutine rotate(this, pos, v, forward)
    class(coarse_schur_t), intent(in) :: this
    integer(ip), intent(in) :: pos
    real(dp), intent(inout) :: v(6)
    logical, intent(in) :: forward
    integer(ip) :: j
    j = this%which(pos)
    if (j == 0) return
    if (forward) then
      v = matmul(transpose(this%q(:, :, j)), v)
    else
      v = matmul(this%q(:, :, j), v)
    end if
  end subroutine rotate

  !> fac = Cholesky factor of S - D, D = sum over rows of v_r v_r^T, v_r the
  !> sum of the pieces of row r: piece p adds g(:, p) at the 6 Schur rows of
  !> coarse position pos(p). Host only.
  !> With `comm`, `rank` and `nranks` (a coarse group whose every rank holds
  !> S and the same pieces): the factor is computed by the group's ranks
  !> together (factor_group) and held by its rank 0. Collective over comm then.
  subroutine downdated_factor(this, keys, pos, g, fac, comm, rank, nranks)
    class(coarse_schur_t), intent(in) :: this
    integer(i8), intent(in) :: keys(:)
    integer(ip), intent(in) :: pos(:)
    real(dp), intent(in) :: g(:, :)
    type(schur_factor_t), intent(inout) :: fac
    type(MPI_Comm), intent(in), optional :: comm
    integer, intent(in), optional :: rank, nranks
    real(dp), allocatable :: a(:, :)
    integer(ip), allocatable :: perm(:)
    integer(ip) :: first, last, p, q, sp, sq, np, rp, rq
    integer :: i, j
    real(dp), allocatable :: gr(:, :)
    a = this%s
    gr = g
    do p = 1, size(keys, kind=ip)
      call this%rotate(pos(p), gr(:, p), .true.)
    end do
    np = size(keys, kind=ip)
    call sort_permutation(keys, perm)
    first = 1
    do while (first <= np)
      last = first
      do while (last < np)
        if (keys(perm(last + 1)) /= keys(perm(first))) exit
        last = last + 1
      end do
      ! every pair of pieces of one row (the row's copies on several subdomains)
      do p = first, last
        sp = this%slot(pos(perm(p)))
        if (sp < 0) call fatal_error('coarse_schur: a contact row touches a subdomain without Schur rows')
        rp = this%r(this%which(pos(perm(p))))
        do q = first, last
          sq = this%slot(pos(perm(q)))
          rq = this%r(this%which(pos(perm(q))))
          do j = 1, int(rq)
            do i = 1, int(rp)
              a(sp + i, sq + j) = a(sp + i, sq + j) - gr(i, perm(p))*gr(j, perm(q))
            end do
          end do
        end do
      end do
      first = last + 1
    end do
    if (present(comm)) then
      call fac%factor_group(a, 'a face matrix of the polish or the standard reconstruction', comm, rank, nranks)
    else
      call fac%factor(a, 'a face matrix of the polish or the standard reconstruction')
    end if
  end subroutine downdated_factor

  !> l = Cholesky factor of the symmetric positive definite `a` (its lower
  !> triangle is read); `what` names the matrix in the error message.
  subroutine factor(this, a, what)
    class(schur_factor_t), intent(inout) :: this
    real(dp), intent(in) :: a(:, :)
    character(len=*), intent(in) :: what
    integer :: info
    character(len=240) :: msg
    this%m = size(a, 1, kind=ip)
    this%l = a
    call dpotrf('L', int(this%m), this%l, int(this%m), info)
    if (info /= 0) then
      write (msg, '(3a,i0,a,i0,a)') 'coarse_schur: the Cholesky factorization of the Schur complement of ', &
        what, ' (dimension ', this%m, ') failed at pivot ', info, ': it is not positive definite'
      call fatal_error(trim(msg))
    end if
  end subroutine factor

  !> The lower Cholesky factor of `a` (symmetric positive definite, the same
  !> on every rank of `comm`, its lower triangle read) computed by the
  !> `nranks` ranks of comm together, kept on rank 0. Right-looking by block
  !> columns of group_block, dealt to the ranks in turn: the owner of a block
  !> column factorizes its diagonal block (dpotrf) and the panel below it
  !> (dtrsm) and broadcasts the panel; every rank updates the later block
  !> columns it owns (dgemm). m^3/3 flops over the ranks, m^2/2 values
  !> broadcast; the same factor as dpotrf's to rounding. Collective.
  subroutine factor_group(this, a, what, comm, rank, nranks)
    class(schur_factor_t), intent(inout) :: this
    real(dp), intent(inout) :: a(:, :)
    character(len=*), intent(in) :: what
    type(MPI_Comm), intent(in) :: comm
    integer, intent(in) :: rank, nranks
    this%m = size(a, 1, kind=ip)
    if (nranks <= 1) then
      if (rank == 0) call this%factor(a, what)
      return
    end if
    call group_cholesky(this%m, a, what, comm, rank, nranks)
    if (rank == 0) then
      this%l = a
    else if (allocated(this%l)) then
      deallocate (this%l)
    end if
  end subroutine factor_group

  !> The block loop of factor_group on a(m, m) (rank 0 ends with the whole
  !> lower factor, the other ranks with their own block columns).
  subroutine group_cholesky(m, a, what, comm, rank, nranks)
    integer(ip), intent(in) :: m
    real(dp), intent(inout) :: a(m, m)
    character(len=*), intent(in) :: what
    type(MPI_Comm), intent(in) :: comm
    integer, intent(in) :: rank, nranks
    real(dp), allocatable :: panel(:, :)
    integer(ip) :: nb, kb, k0, k1, w, jb, j0, j1, h
    integer :: info, ierr, owner
    character(len=240) :: msg
    nb = (m + group_block - 1)/group_block
    do kb = 1, nb
      k0 = (kb - 1)*group_block + 1
      k1 = min(kb*group_block, m)
      w = k1 - k0 + 1
      h = m - k0 + 1
      owner = int(mod(kb - 1, int(nranks, ip)))
      if (allocated(panel)) deallocate (panel)
      allocate (panel(h, w))
      if (rank == owner) then
        call dpotrf('L', int(w), a(k0, k0), int(m), info)
        if (info /= 0) then
          write (msg, '(3a,i0,a,i0,a)') 'coarse_schur: the Cholesky factorization of the Schur complement of ', &
            what, ' (dimension ', m, ') failed at pivot ', k0 - 1 + info, ': it is not positive definite'
          call fatal_error(trim(msg))
        end if
        if (k1 < m) call dtrsm('R', 'L', 'T', 'N', int(m - k1), int(w), 1.0_dp, a(k0, k0), int(m), &
                               a(k1 + 1, k0), int(m))
        panel = a(k0:m, k0:k1)
      end if
      call MPI_Bcast(panel, int(h*w), MPI_DOUBLE_PRECISION, owner, comm, ierr)
      if (rank == 0 .and. owner /= 0) a(k0:m, k0:k1) = panel
      do jb = kb + 1, nb
        if (mod(jb - 1, int(nranks, ip)) /= rank) cycle
        j0 = (jb - 1)*group_block + 1
        j1 = min(jb*group_block, m)
        call dgemm('N', 'T', int(m - j0 + 1), int(j1 - j0 + 1), int(w), -1.0_dp, panel(j0 - k0 + 1, 1), int(h), &
                   panel(j0 - k0 + 1, 1), int(h), 1.0_dp, a(j0, j0), int(m))
      end do
    end do
  end subroutine group_cholesky

  !> True when the dense factors of an m-row Schur complement are computed
  !> by a group of `nranks` ranks together (factor_group), false when by
  !> the group's host alone.
  pure logical function group_factors(m, nranks)
    integer(ip), intent(in) :: m
    integer, intent(in) :: nranks
    group_factors = nranks > 1 .and. m >= group_factor_rows
  end function group_factors

  !> r <- A^{-1} r with the factor.
  subroutine solve(this, r)
    class(schur_factor_t), intent(in) :: this
    real(dp), intent(inout) :: r(:)
    integer :: info
    call dpotrs('L', int(this%m), 1, this%l, int(this%m), r, int(this%m), info)
    if (info /= 0) call fatal_error('coarse_schur: LAPACK dpotrs failed')
  end subroutine solve

  subroutine free(this)
    class(coarse_schur_t), intent(inout) :: this
    this%m = 0
    if (allocated(this%slot)) deallocate (this%slot)
    if (allocated(this%which)) deallocate (this%which, this%q, this%r)
    if (allocated(this%vars)) deallocate (this%vars)
    if (allocated(this%s)) deallocate (this%s)
  end subroutine free
end module coarse_schur
