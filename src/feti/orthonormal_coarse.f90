!> The coarse space with explicitly orthonormalized rows (paper Eq. 8 with
!> T = L^{-1}; `&solver coarse = 'orthonormal'`): G G^T assembled dense and
!> replicated on every rank, its Cholesky factor G G^T = L L^T (LAPACK dpotrf),
!> and the columns of G~ = L^{-1} G that belong to this rank's owned
!> multipliers, formed once (dtrsm). Then G~ G~^T = I and
!>
!>   Q = G^T (G G^T)^{-1} G = G~^T G~,   P x = x - G~^T (G~ x),
!>
!> so that inside the iterations a projection costs one MPI_Allreduce of the
!> 6N values of G~ x plus two local dense products, and no coarse solve;
!> ||G~ x|| is the norm of that replicated vector.
!>
!> Vectors: dual vectors are the owned multipliers (length con%n_own); coarse
!> vectors here are REPLICATED (length n = 6N, global coarse positions of
!> coarse_problem's layout: rank-major, ascending subdomain id within a rank).
!> `to_local` converts to the local coarse blocks of
!> feti_operators (6 per local subdomain).
!>
!> Assembly: every owned row r adds g_r g_r^T, g_r = G e_r with one 6-block
!> per subdomain copy the row touches; the blocks of a row are summed at its
!> owner by one neighbour exchange (as in coarse_problem), the products go into
!> the dense matrix, and one MPI_Allreduce (in place, n^2 values) sums the
!> ranks' parts. Every rank factorizes the same matrix (redundantly: the
!> alternative, factorize on one rank and broadcast L, moves the same n^2
!> values again).
!>
!> Storage of G~ ("staircase"): L^{-1} is lower triangular, so a column of G~
!> is zero above the first block of the matching column of G. The owned
!> columns are sorted by that first block position p and kept as one dense
!> block per p, rows 6(p-1)+1..n only (about half of the dense 6N x n_own).
!> Apply costs about n n_own flops per product, memory 8 (n^2 + sum of the
!> blocks) bytes; both grow like N^2, hence the limit of
!> `orthonormal_max_subdomains` subdomains (coarse dimension 6144).
module orthonormal_coarse
  use kinds, only: dp, ip, i8, MPI_REAL_DP
  use lapack_interfaces, only: dpotrf, dtrsm, dtrsv, dgemv
  use errors, only: collective_error, exit_input_error, exit_internal
  use decomposition, only: decomposition_t
  use constraints, only: constraints_t
  use coarse_problem, only: coarse_layout_t, ensure_row_blocks, row_blocks
  use mpi_f08, only: MPI_Comm, MPI_Allreduce, MPI_IN_PLACE, MPI_SUM, MPI_MAX, MPI_Wtime, MPI_INTEGER
  implicit none
  private

  public :: check_orthonormal_size

  !> Most subdomains the dense variant accepts (coarse dimension 6144: L and
  !> the Allreduce of G G^T are 302 MB per rank).
  integer(ip), parameter, public :: orthonormal_max_subdomains = 1024


  !> G G^T = L L^T (replicated) and this rank's columns of G~ = L^{-1} G.
  !> Work arrays are allocated in `init`; the operators allocate nothing.
  type, public :: orthonormal_coarse_t
    private
    type(MPI_Comm) :: comm
    integer(ip) :: n = 0                          !< coarse dimension 6N
    integer(ip) :: nsub = 0                       !< N
    integer(ip) :: n_own = 0                      !< owned multipliers (columns of G~ kept here)
    integer(ip) :: nlocal = 0                     !< local subdomains
    real(dp), allocatable :: l(:, :)              !< (n, n) L in the lower triangle, 0 above
    integer(ip) :: ngroups = 0                    !< staircase blocks of G~ on this rank
    integer(ip), allocatable :: group_row(:)      !< (ngroups) first coarse row of a block, 6(p-1)+1
    integer(ip), allocatable :: group_col(:)      !< (ngroups+1) first stored column of a block
    integer(i8), allocatable :: group_offset(:)   !< (ngroups) values stored before a block
    integer(ip), allocatable :: column_row(:)     !< (n_own) stored column k -> owned multiplier
    real(dp), allocatable :: values(:)            !< the blocks, column-major, height n - group_row + 1
    integer(ip), allocatable :: local_position(:) !< (nlocal) coarse position of local subdomain ls
    integer, allocatable :: counts(:), displs(:)  !< per rank: 6*subdomains and offsets
    real(dp) :: seconds_assembly = 0              !< G G^T: exchange, products, Allreduce
    real(dp) :: seconds_factorization = 0         !< dpotrf
    real(dp) :: seconds_columns = 0               !< G~ columns (dtrsm)
    real(dp), allocatable :: xs(:), ys(:), zw(:)
  contains
    procedure :: init
    procedure :: dimension
    procedure :: summary
    procedure :: apply
    procedure :: apply_t
    procedure :: project
    procedure :: backward_solve
    procedure :: to_local
    procedure :: bytes
    procedure :: free
  end type orthonormal_coarse_t

contains

  !> Refuse (collectively, as an input error) a decomposition with more than
  !> orthonormal_max_subdomains subdomains.
  subroutine check_orthonormal_size(nsubdomains, comm)
    integer(ip), intent(in) :: nsubdomains
    type(MPI_Comm), intent(in) :: comm
    character(len=400) :: msg
    if (nsubdomains <= orthonormal_max_subdomains) return
    write (msg, '(a,i0,a,i0,a,i0,a,i0,a)') "group &solver, variable coarse: 'orthonormal' (G G^T dense and "// &
      'replicated, explicit G~ = L^{-1} G) is limited to ', orthonormal_max_subdomains, &
      ' subdomains (coarse dimension ', 6*orthonormal_max_subdomains, '); this case has ', nsubdomains, &
      ' subdomains (coarse dimension ', 6*nsubdomains, "): use coarse = 'mumps'"
    call collective_error(msg, comm, exit_input_error)
  end subroutine check_orthonormal_size

  !> Assemble G G^T, factorize it and form this rank's columns of G~.
  !> `con%b(:)%g` holds the entries of G^T (build_constraints fills them).
  !> Collective over `comm`.
  subroutine init(this, dec, con, layout, comm)
    class(orthonormal_coarse_t), intent(inout) :: this
    type(decomposition_t), intent(in) :: dec
    type(constraints_t), intent(inout) :: con
    type(coarse_layout_t), intent(in) :: layout
    type(MPI_Comm), intent(in) :: comm
    integer(ip), allocatable :: first(:), per_block(:), group_of_block(:)
    integer(ip) :: ls, i, j, a, b, k, g, p, nb, pos(8), r0, h, kk
    real(dp) :: blk(6, 8), t0
    integer(i8) :: total
    integer :: ierr, info, worst
    character(len=200) :: msg

    call this%free()
    call check_orthonormal_size(layout%nsub, comm)
    this%comm = comm
    this%nsub = layout%nsub
    this%n = 6*layout%nsub
    this%n_own = con%n_own
    this%nlocal = layout%nlocal
    this%counts = layout%counts
    this%displs = layout%displs
    allocate (this%local_position(this%nlocal))
    do ls = 1, this%nlocal
      this%local_position(ls) = layout%position(dec%local_subdomains(ls))
    end do

    ! 1. the 6-blocks of every row, by copy slot, summed at the row's owner
    t0 = MPI_Wtime()
    call ensure_row_blocks(dec, con)

    ! 2. G G^T = sum over rows of g_r g_r^T, dense; first block of every column
    allocate (this%l(this%n, this%n), first(this%n_own))
    this%l = 0
    do i = 1, this%n_own
      call row_blocks(con, layout, i, nb, pos, blk)
      first(i) = this%nsub
      if (nb > 0) first(i) = minval(pos(1:nb))
      do b = 1, nb
        do a = 1, nb
          do k = 1, 6
            this%l(6*pos(a) - 5:6*pos(a), 6*(pos(b) - 1) + k) = this%l(6*pos(a) - 5:6*pos(a), 6*(pos(b) - 1) + k) &
                                                                + blk(:, a)*blk(k, b)
          end do
        end do
      end do
    end do
    call MPI_Allreduce(MPI_IN_PLACE, this%l, this%n*this%n, MPI_REAL_DP, MPI_SUM, comm, ierr)
    this%seconds_assembly = MPI_Wtime() - t0

    ! 3. G G^T = L L^T
    t0 = MPI_Wtime()
    call dpotrf('L', this%n, this%l, this%n, info)
    call MPI_Allreduce(abs(info), worst, 1, MPI_INTEGER, MPI_MAX, comm, ierr)
    if (worst /= 0) then
      write (msg, '(a,i0,a)') 'orthonormal_coarse: G G^T is not positive definite (LAPACK dpotrf info = ', &
        worst, '): G has no full row rank (a subdomain whose rigid modes no constraint touches?)'
      call collective_error(msg, comm, exit_internal)
    end if
    do j = 2, this%n
      this%l(1:j - 1, j) = 0
    end do
    this%seconds_factorization = MPI_Wtime() - t0

    ! 4. columns of G sorted by their first block (counting sort), one dense
    !    block per first position p, rows 6(p-1)+1..n; then G~ = L^{-1} G per block
    t0 = MPI_Wtime()
    allocate (per_block(this%nsub), group_of_block(this%nsub))
    per_block = 0
    do i = 1, this%n_own
      per_block(first(i)) = per_block(first(i)) + 1
    end do
    this%ngroups = count(per_block > 0, kind=ip)
    allocate (this%group_row(this%ngroups), this%group_col(this%ngroups + 1), &
              this%group_offset(this%ngroups), this%column_row(this%n_own))
    g = 0
    total = 0
    this%group_col(1) = 1
    group_of_block = 0
    do p = 1, this%nsub
      if (per_block(p) == 0) cycle
      g = g + 1
      group_of_block(p) = g
      this%group_row(g) = 6*(p - 1) + 1
      this%group_offset(g) = total
      this%group_col(g + 1) = this%group_col(g) + per_block(p)
      total = total + int(this%n - this%group_row(g) + 1, i8)*per_block(p)
    end do
    allocate (this%values(total))
    this%values = 0
    per_block = 0                       ! now: columns placed so far per block
    do i = 1, this%n_own
      g = group_of_block(first(i))
      kk = per_block(first(i))
      per_block(first(i)) = kk + 1
      this%column_row(this%group_col(g) + kk) = i
      r0 = this%group_row(g)
      h = this%n - r0 + 1
      call row_blocks(con, layout, i, nb, pos, blk)
      do a = 1, nb
        this%values(this%group_offset(g) + int(kk, i8)*h + 6*pos(a) - 5 - r0 + 1: &
                    this%group_offset(g) + int(kk, i8)*h + 6*pos(a) - r0 + 1) = blk(:, a)
      end do
    end do
    do g = 1, this%ngroups
      r0 = this%group_row(g)
      h = this%n - r0 + 1
      call dtrsm('L', 'L', 'N', 'N', h, this%group_col(g + 1) - this%group_col(g), 1.0_dp, this%l(r0, r0), &
                 this%n, this%values(this%group_offset(g) + 1), h)
    end do
    this%seconds_columns = MPI_Wtime() - t0
    allocate (this%xs(this%n_own), this%ys(this%n_own), this%zw(this%n))
  end subroutine init

  !> z = G~ x (replicated, length n) for owned x: local products and one
  !> MPI_Allreduce of n values. Collective.
  subroutine apply(this, x, z)
    class(orthonormal_coarse_t), intent(inout) :: this
    real(dp), intent(in) :: x(:)
    real(dp), intent(out) :: z(:)
    integer(ip) :: k, g, r0, h
    integer :: ierr
    do k = 1, this%n_own
      this%xs(k) = x(this%column_row(k))
    end do
    z(1:this%n) = 0
    do g = 1, this%ngroups
      r0 = this%group_row(g)
      h = this%n - r0 + 1
      call dgemv('N', h, this%group_col(g + 1) - this%group_col(g), 1.0_dp, &
                 this%values(this%group_offset(g) + 1), h, this%xs(this%group_col(g)), 1, 1.0_dp, z(r0:this%n), 1)
    end do
    call MPI_Allreduce(MPI_IN_PLACE, z, this%n, MPI_REAL_DP, MPI_SUM, this%comm, ierr)
  end subroutine apply

  !> y = G~^T mu (owned rows) for replicated mu. Local, no communication.
  subroutine apply_t(this, mu, y)
    class(orthonormal_coarse_t), intent(inout) :: this
    real(dp), intent(in) :: mu(:)
    real(dp), intent(out) :: y(:)
    integer(ip) :: k, g, r0, h
    do g = 1, this%ngroups
      r0 = this%group_row(g)
      h = this%n - r0 + 1
      call dgemv('T', h, this%group_col(g + 1) - this%group_col(g), 1.0_dp, &
                 this%values(this%group_offset(g) + 1), h, mu(r0:this%n), 1, 0.0_dp, this%ys(this%group_col(g)), 1)
    end do
    do k = 1, this%n_own
      y(this%column_row(k)) = this%ys(k)
    end do
  end subroutine apply_t

  !> y = P x = x - G~^T (G~ x) (y may not be x). One MPI_Allreduce of n values.
  subroutine project(this, x, y)
    class(orthonormal_coarse_t), intent(inout) :: this
    real(dp), intent(in) :: x(:)
    real(dp), intent(inout) :: y(:)
    call this%apply(x, this%zw)
    call this%apply_t(this%zw, y)
    y(1:this%n_own) = x(1:this%n_own) - y(1:this%n_own)
  end subroutine project

  !> x <- L^{-T} x (replicated, length n). Local.
  subroutine backward_solve(this, x)
    class(orthonormal_coarse_t), intent(in) :: this
    real(dp), intent(inout) :: x(:)
    call dtrsv('L', 'T', 'N', this%n, this%l, this%n, x, 1)
  end subroutine backward_solve

  !> The local coarse blocks (6 per local subdomain, feti_operators' order)
  !> of a replicated coarse vector. Local.
  subroutine to_local(this, z, zloc)
    class(orthonormal_coarse_t), intent(in) :: this
    real(dp), intent(in) :: z(:)
    real(dp), intent(out) :: zloc(:)
    integer(ip) :: ls, p
    do ls = 1, this%nlocal
      p = this%local_position(ls)
      zloc(6*ls - 5:6*ls) = z(6*p - 5:6*p)
    end do
  end subroutine to_local

  !> The coarse dimension 6N (the length of the replicated multiplier).
  integer(ip) function dimension(this)
    class(orthonormal_coarse_t), intent(in) :: this
    dimension = this%n
  end function dimension

  !> One line on the set-up: dimension, the times of its parts, the memory.
  function summary(this) result(line)
    class(orthonormal_coarse_t), intent(in) :: this
    character(len=200) :: line
    write (line, '(a,i0,a,4(es9.2,a))') 'explicit G~ = L^{-1} G: coarse dimension ', this%n, &
      ', assembly ', this%seconds_assembly, ' s, Cholesky ', this%seconds_factorization, &
      ' s, columns ', this%seconds_columns, ' s, ', real(this%bytes(), dp)/2.0_dp**20, ' MiB (rank 0)'
  end function summary

  !> Bytes held on this rank (L and the blocks of G~).
  integer(i8) function bytes(this)
    class(orthonormal_coarse_t), intent(in) :: this
    bytes = 0
    if (allocated(this%l)) bytes = bytes + 8_i8*size(this%l, kind=i8)
    if (allocated(this%values)) bytes = bytes + 8_i8*size(this%values, kind=i8)
  end function bytes

  subroutine free(this)
    class(orthonormal_coarse_t), intent(inout) :: this
    if (allocated(this%l)) deallocate (this%l)
    if (allocated(this%group_row)) deallocate (this%group_row, this%group_col, this%group_offset, this%column_row)
    if (allocated(this%values)) deallocate (this%values)
    if (allocated(this%local_position)) deallocate (this%local_position)
    if (allocated(this%counts)) deallocate (this%counts, this%displs)
    if (allocated(this%xs)) deallocate (this%xs, this%ys, this%zw)
    this%n = 0
    this%nsub = 0
    this%n_own = 0
    this%nlocal = 0
    this%ngroups = 0
  end subroutine free
end module orthonormal_coarse
