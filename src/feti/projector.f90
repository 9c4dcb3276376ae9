!> The coarse problem of TFETI and the projector built on it: (G G^T)^{-1}
!> (coarse_problem, MUMPS on groups of `&solver coarse_ranks` ranks) and
!> P = I - G^T (G G^T)^{-1} G. G is applied through
!> the B operator that holds its entries (b_operator), which is passed in.
!> Timer 'coarse solve'.
module projector
  use kinds, only: dp, i8, ip, MPI_INT_IP, MPI_REAL_DP
  use timers, only: timer_start, timer_stop
  use decomposition, only: decomposition_t
  use constraints, only: constraints_t, row_contact
  use coarse_problem, only: coarse_problem_t, coarse_layout_t, build_coarse_layout, coarse_options_t, &
                            choose_coarse_ranks, ranks_per_node, dense_for, gathered_counts, &
                            estimated_factor_bytes
  use sorting, only: sort_permutation
  use coarse_settings, only: coarse_settings_t
  use errors, only: collective_error, exit_input_error
  use logger, only: log_message
  use orthonormal_coarse, only: orthonormal_coarse_t
  use b_operator, only: b_operator_t
  use mpi_f08, only: MPI_Comm, MPI_Comm_size, MPI_Comm_rank, MPI_Allreduce, MPI_Exscan, MPI_SUM, MPI_LAND, &
                     MPI_LOGICAL, MPI_IN_PLACE, MPI_Allgather, MPI_Allgatherv, MPI_INTEGER, MPI_INTEGER8
  implicit none
  private

  integer, parameter :: masked_base = 1          !< G_E G_E^T, the base of low-rank updates
  integer, parameter :: masked_refactorized = 2  !< G_M G_M^T of the last mask
  integer, parameter :: masked_view = 3          !< a Schur view of the coarse problem (coarse_schur)

  !> The coarse problem's decisions for a run, made before any set-up work
  !> (plan_coarse): what the checks report and what the projector builds.
  type, public :: coarse_plan_t
    integer :: group_ranks = 1                 !< ranks per coarse group
    logical :: dense = .false.                 !< G G^T by the dense LAPACK factor (groups of one rank)
    real(dp) :: factor_bytes = 0               !< estimated bytes of the coarse factor per rank
    character(len=300) :: refusal = ''         !< not empty: the settings do not fit these ranks (an input error)
  end type coarse_plan_t

  public :: plan_coarse

  type, public :: projector_t
    private
    type(MPI_Comm) :: comm
    type(coarse_layout_t) :: layout                  !< where each subdomain's 6-block goes
    type(coarse_problem_t) :: coarse                 !< (G G^T)^{-1}
    type(coarse_options_t) :: options                !< rank groups, BLR, out-of-core (also for G_A G_A^T)
    !> G_M G_M^T of masked_coarse: analysed once (on the pattern of G G^T), refactorized per mask
    type(coarse_problem_t) :: masked
    integer :: masked_mode = 0                       !< masked holds: 0 nothing, masked_base, masked_refactorized
    !> bumped whenever `masked` changes: a caller that kept its matrix knows whether it still holds it
    integer(i8) :: masked_generation = 0
    !> a second Schur view (own_view: the standard reconstruction's G_A G_A^T beside the last face)
    type(coarse_problem_t) :: own
    real(dp), allocatable :: cwork(:), cwork2(:)     !< work: local coarse blocks
    integer(i8) :: solves = 0
  contains
    procedure :: init
    procedure :: solve
    procedure :: project
    procedure :: init_active_coarse
    procedure :: masked_coarse
    procedure :: masked_changes
    procedure :: init_orthonormal
    procedure :: n_solves
    procedure :: coarse_problem
    procedure :: free
  end type projector_t

contains

  !> Assemble and factorize G G^T for the subdomains of `dec` and the B (and
  !> G) of `b`, on the rank groups `s` asks for (coarse_ranks,
  !> coarse_placement; BLR and out-of-core by coarse_blr, coarse_ooc). A
  !> value that cannot be used on this many ranks stops every rank with an
  !> input error. Collective.
  subroutine init(this, dec, b, comm, s, regular_base)
    class(projector_t), intent(inout) :: this
    type(decomposition_t), intent(in) :: dec
    type(b_operator_t), intent(inout), target :: b
    type(MPI_Comm), intent(in) :: comm
    type(coarse_settings_t), intent(in) :: s
    logical, intent(in) :: regular_base
    type(constraints_t), pointer :: con
    integer(ip), allocatable :: schur_positions(:)
    real(dp), allocatable :: schur_gram(:, :, :)
    type(coarse_plan_t) :: plan
    integer :: nranks, ierr
    character(len=300) :: msg
    call this%free()
    this%comm = comm
    call MPI_Comm_size(comm, nranks, ierr)
    plan = plan_coarse(s, nranks, dec%nsubdomains, ranks_per_node(comm))
    if (len_trim(plan%refusal) > 0) call collective_error(plan%refusal, comm, exit_input_error)
    this%options = coarse_options_t(plan%group_ranks, s%coarse_blr, s%coarse_ooc, s%coarse_factor)
    con => b%constraints()
    call build_coarse_layout(dec, comm, this%layout)
    call contact_face_subdomains(this, dec, con, regular_base, schur_positions, schur_gram)
    if (size(schur_positions) > 0) then
      call this%coarse%init(dec, con, this%layout, comm, options=this%options, schur_positions=schur_positions, &
                            schur_gram=schur_gram)
    else
      call this%coarse%init(dec, con, this%layout, comm, options=this%options)
    end if
    associate (mb => this%coarse%mumps_memory_mb())
      if (this%coarse%is_dense()) then
        write (msg, '(a,i0,a,i0,3a,i0,a)') 'coarse problem: dimension ', 6*dec%nsubdomains, ', ', &
          this%coarse%groups(), ' group(s) of 1 rank, dense LAPACK Cholesky factor (coarse_factor ''', &
          trim(s%coarse_factor), '''), ', mb(1), ' MB per rank'
      else
        write (msg, '(a,i0,a,i0,a,i0,a,es9.2,a,l1,a,i0,a,i0,a,i0,a,i0,a)') 'coarse problem: dimension ', &
          6*dec%nsubdomains, ', ', this%coarse%groups(), ' group(s) of ', this%coarse%ranks_per_group(), &
          ' rank(s) (BLR ', s%coarse_blr, ', out-of-core ', s%coarse_ooc, '); factor entries ', &
          this%coarse%factor_entries(), ' (after BLR ', this%coarse%factor_entries_effective(), &
          '), MUMPS factorization memory ', mb(1), ' MB max per rank, ', mb(2), ' MB per group'
      end if
    end associate
    call log_message(msg)
    if (this%coarse%has_schur()) then
      write (msg, '(a,i0,a)') 'coarse problem: the ', this%coarse%schur_rows(), ' rows of the subdomains '// &
        'under contact kept as a dense Schur complement (face matrices without a second factorization)'
      call log_message(msg)
    end if
    allocate (this%cwork(6*this%layout%nlocal), this%cwork2(6*this%layout%nlocal))
  end subroutine init

  !> The decisions of the coarse problem of `nunits` subdomains (clusters) on
  !> `nranks` ranks, `node_ranks` of them per node (ranks_per_node): the
  !> ranks per group (choose_coarse_ranks; one with coarse_factor 'dense',
  !> whose factor lives on every rank), the factor kind (dense_for) and its
  !> memory per rank (dense 8 n^2, n = 6 units, on a one-rank group or with
  !> the explicit G~; else the MUMPS estimate shared by the group's ranks).
  !> `refusal` names a value these ranks cannot take. The checks before a
  !> run and `init` both decide here.
  function plan_coarse(s, nranks, nunits, node_ranks) result(plan)
    type(coarse_settings_t), intent(in) :: s
    integer, intent(in) :: nranks, node_ranks
    integer(ip), intent(in) :: nunits
    type(coarse_plan_t) :: plan
    real(dp) :: n
    call choose_coarse_ranks(s%coarse_ranks, s%coarse_placement, nranks, nunits, plan%group_ranks, plan%refusal, &
                             node_ranks=node_ranks)
    if (s%coarse_factor == 'dense') plan%group_ranks = 1
    plan%dense = dense_for(s%coarse_factor, 6*nunits, plan%group_ranks)
    n = 6*real(nunits, dp)
    if (s%coarse == 'orthonormal' .or. plan%dense) then
      plan%factor_bytes = 8*n*n
    else
      plan%factor_bytes = real(estimated_factor_bytes(nunits), dp)/max(plan%group_ranks, 1)
    end if
  end function plan_coarse

  !> x = (G G^T)^{-1} rhs on local coarse blocks.
  subroutine solve(this, rhs, x)
    class(projector_t), intent(inout) :: this
    real(dp), intent(in) :: rhs(:)
    real(dp), intent(out) :: x(:)
    call timer_start('coarse solve')
    call this%coarse%solve(rhs, x)
    this%solves = this%solves + 1
    call timer_stop('coarse solve')
  end subroutine solve

  !> y = P x = x - G^T (G G^T)^{-1} G x (y may not be x); optionally also
  !> G x and (G G^T)^{-1} G x, which the dual problem keeps (see dual_problem).
  subroutine project(this, b, x, y, gx, zx)
    class(projector_t), intent(inout) :: this
    type(b_operator_t), intent(inout) :: b
    real(dp), intent(in) :: x(:)
    real(dp), intent(inout) :: y(:)
    real(dp), intent(out), optional :: gx(:), zx(:)
    call b%apply_g(x, this%cwork)
    call this%solve(this%cwork, this%cwork2)
    call b%apply_gt(this%cwork2, y)
    y = x - y
    if (present(gx)) gx = this%cwork
    if (present(zx)) zx = this%cwork2
  end subroutine project

  !> G_A G_A^T assembled and factorized anew for the rows in `mask` (the
  !> standard reconstruction, Eq. 10). Collective.
  subroutine init_active_coarse(this, dec, b, cp, mask)
    class(projector_t), intent(in) :: this
    type(decomposition_t), intent(in) :: dec
    type(b_operator_t), intent(inout), target :: b
    type(coarse_problem_t), intent(inout) :: cp
    logical, intent(in) :: mask(:)
    type(constraints_t), pointer :: con
    con => b%constraints()
    call cp%init(dec, con, this%layout, this%comm, mask, this%options)
  end subroutine init_active_coarse

  !> G_M G_M^T for the rows in `mask` in the projector's one reusable
  !> instance (valid until the next call: SMALBE's faces, then the standard
  !> reconstruction's G_A G_A^T). The first way that applies:
  !> - every row in `mask`: G G^T itself (an alias, nothing factorized);
  !> - the coarse problem has Schur rows (coarse_schur), `regular_base` (the
  !>   Dirichlet rows fix every rigid body motion) and every equality row is
  !>   in `mask`: a view of G G^T's factors with a dense factor of S - D_M;
  !> - `low_rank` (faces), `regular_base`, every equality row in `mask` and
  !>   few contact rows in it: G_M G_M^T = G_E G_E^T + V V^T, V = the columns
  !>   G e_r of the k contact rows r in `mask`. G_E G_E^T is factorized once
  !>   per run; each call builds V and applies Woodbury's formula
  !>   (coarse_problem%set_update: one solve with k right-hand sides, a k x k
  !>   Cholesky factor). "Few": the k solves cost less than a numerical
  !>   factorization, 4 k (factor entries) <= flops;
  !> - otherwise the numerical factorization of G_M G_M^T on the pattern and
  !>   with the MUMPS analysis of the instance's first factorization (the
  !>   instance is assembled on the pattern of G G^T, rows outside the mask
  !>   as explicit zeros; coarse_problem%refactorize).
  !> Collective.
  !> `force_low_rank` (tests): the low-rank way whenever it applies, whatever k.
  !> `own_view`: a Schur view goes into a second instance, so that the
  !> reusable one keeps what it holds (the last face of the solve); the other
  !> ways still use the reusable instance (masked_changes counts its changes).
  function masked_coarse(this, dec, b, mask, regular_base, low_rank, force_low_rank, own_view) result(cp)
    class(projector_t), intent(inout), target :: this
    type(decomposition_t), intent(in) :: dec
    type(b_operator_t), intent(inout), target :: b
    logical, intent(in) :: mask(:)
    logical, intent(in) :: regular_base, low_rank
    logical, intent(in), optional :: force_low_rank, own_view
    type(coarse_problem_t), pointer :: cp
    type(constraints_t), pointer :: con
    logical, allocatable :: contact(:)
    integer(ip) :: k
    integer(ip) :: local(2), total(2)
    integer :: ierr
    real(dp) :: flops, entries
    logical :: cheap

    con => b%constraints()
    contact = con%kind(1:con%n_own) == row_contact
    cp => this%masked
    ! k: contact rows in the mask; local(2): equality rows outside it
    local(1) = count(mask(1:con%n_own) .and. contact, kind=ip)
    local(2) = count(.not. (mask(1:con%n_own) .or. contact), kind=ip)
    call MPI_Allreduce(local, total, 2, MPI_INT_IP, MPI_SUM, this%comm, ierr)
    k = total(1)
    if (all_rows(mask, con%n_own)) then
      cp => this%own
      if (.not. present_and_true(own_view)) then
        cp => this%masked
        this%masked_generation = this%masked_generation + 1
        this%masked_mode = masked_view
      end if
      call cp%make_alias(this%coarse)
      return
    end if
    ! cost model: the main factorization's figures (the same pattern)
    flops = this%coarse%factor_flops()
    entries = real(this%coarse%factor_entries(), dp)
    cheap = 4*real(k, dp)*entries <= flops
    if (present(force_low_rank)) cheap = cheap .or. force_low_rank
    ! one decision on every rank (each coarse group has its own MUMPS figures)
    call MPI_Allreduce(MPI_IN_PLACE, cheap, 1, MPI_LOGICAL, MPI_LAND, this%comm, ierr)
    if (this%coarse%has_schur() .and. regular_base .and. total(2) == 0) then
      if (present_and_true(own_view)) then
        cp => this%own
        call schur_view(this, dec, con, mask, contact, this%own)
        return
      end if
      call schur_view(this, dec, con, mask, contact, this%masked)
      this%masked_mode = masked_view
      this%masked_generation = this%masked_generation + 1
      return
    end if
    this%masked_generation = this%masked_generation + 1
    if (low_rank .and. regular_base .and. total(2) == 0 .and. cheap) then
      if (this%masked_mode /= masked_base) then
        if (this%masked%is_reusable()) then
          call this%masked%refactorize(dec, con, .not. contact)
        else
          call this%masked%init(dec, con, this%layout, this%comm, .not. contact, this%options, reusable=.true.)
        end if
        this%masked_mode = masked_base
      end if
      call low_rank_update(this, con, mask, contact, local(1), k)
    else
      if (this%masked%is_reusable()) then
        call this%masked%refactorize(dec, con, mask)
      else
        call this%masked%init(dec, con, this%layout, this%comm, mask, this%options, reusable=.true.)
      end if
      this%masked_mode = masked_refactorized
    end if
  contains

    pure logical function present_and_true(flag)
      logical, intent(in), optional :: flag
      present_and_true = .false.
      if (present(flag)) present_and_true = flag
    end function present_and_true

    !> Every row of every rank in the mask. Collective.
    logical function all_rows(mask, n)
      logical, intent(in) :: mask(:)
      integer(ip), intent(in) :: n
      all_rows = all(mask(1:n))
      call MPI_Allreduce(MPI_IN_PLACE, all_rows, 1, MPI_LOGICAL, MPI_LAND, this%comm, ierr)
    end function all_rows
  end function masked_coarse

  !> The low-rank update of masked_coarse: G_M G_M^T = G_E G_E^T + V V^T with
  !> V's column j = G e_r for the j-th contact row r of `mask` (global order:
  !> rank, then row), `k_mine` of them on this rank, `k` in all. Collective.
  subroutine low_rank_update(this, con, mask, contact, k_mine, k)
    class(projector_t), intent(inout) :: this
    type(constraints_t), intent(inout) :: con
    logical, intent(in) :: mask(:), contact(:)
    integer(ip), intent(in) :: k_mine, k
    real(dp), allocatable :: col(:), wloc(:), v(:, :)
    integer(ip) :: ls, e, offset, c_mine, c_offset, c, i, j
    integer(i8), allocatable :: my_keys(:), keys(:)
    integer :: ierr, rank
    ! V: column j is G e_r for the j-th contact row r of the mask (global order: rank, then row)
    offset = 0
    call MPI_Exscan(k_mine, offset, 1, MPI_INT_IP, MPI_SUM, this%comm, ierr)
    call MPI_Comm_rank(this%comm, rank, ierr)
    if (rank == 0) offset = 0                  ! MPI_Exscan leaves rank 0's result undefined
    ! keys: the global ordinal of each contact row (rank, then row), so that the update of
    ! the next face finds the columns of this one (coarse_problem%set_update)
    c_mine = count(contact, kind=ip)
    c_offset = 0
    call MPI_Exscan(c_mine, c_offset, 1, MPI_INT_IP, MPI_SUM, this%comm, ierr)
    if (rank == 0) c_offset = 0
    allocate (col(con%n_own), wloc(con%n_local), v(6*this%layout%nlocal, k), my_keys(k_mine))
    col = 0
    j = offset
    c = c_offset
    do i = 1, con%n_own
      if (contact(i)) c = c + 1
      if (mask(i) .and. contact(i)) then
        j = j + 1
        col(i) = real(j, dp)
        my_keys(j - offset) = int(c, i8)
      end if
    end do
    keys = gather_keys(this%comm, my_keys, k)
    call con%exchange%gather(col, wloc)
    v = 0
    do ls = 1, size(con%b, kind=ip)
      associate (bs => con%b(ls))
        do e = 1, bs%nentries
          j = nint(wloc(bs%row(e)), ip)
          if (j > 0) v(6*ls - 5:6*ls, j) = v(6*ls - 5:6*ls, j) + bs%g(:, e)
        end do
      end associate
    end do
    call timer_start('face: update')
    call this%masked%set_update(v, keys)
    call timer_stop('face: update')
  end subroutine low_rank_update

  !> The keys of all ranks of `comm` in rank order (k of them in all). Collective.
  function gather_keys(comm, mine, k) result(all)
    type(MPI_Comm), intent(in) :: comm
    integer(i8), intent(in) :: mine(:)
    integer(ip), intent(in) :: k
    integer(i8) :: all(k)
    integer :: n_mine, ierr
    integer, allocatable :: counts(:), displs(:)
    n_mine = size(mine)
    call gathered_counts(n_mine, comm, counts, displs)
    call MPI_Allgatherv(mine, n_mine, MPI_INTEGER8, all, counts, displs, MPI_INTEGER8, comm, ierr)
  end function gather_keys

  !> The coarse positions (ascending, the same on every rank) of the
  !> subdomains that contact rows touch, and for each the sum of g g^T over
  !> the contact rows' pieces on it, when the coarse problem should keep their
  !> rows as a Schur complement (coarse_schur): MUMPS factors, the equality
  !> rows alone fixing every rigid body motion (the face matrices are then
  !> positive definite), and at most a quarter of the subdomains under
  !> contact. Otherwise none. Collective.
  subroutine contact_face_subdomains(this, dec, con, regular_base, positions, gram)
    class(projector_t), intent(in) :: this
    type(decomposition_t), intent(in) :: dec
    type(constraints_t), intent(inout) :: con
    logical, intent(in) :: regular_base
    integer(ip), allocatable, intent(out) :: positions(:)
    real(dp), allocatable, intent(out) :: gram(:, :, :)
    real(dp), allocatable :: col(:), wloc(:), my_gram(:, :, :)
    integer(ip), allocatable :: mine(:), order(:)
    real(dp) :: gs(6, 6)
    integer(ip) :: ls, e, n_mine, n, k
    integer, allocatable :: counts(:), displs(:)
    integer :: ierr, cnt
    logical :: touched
    allocate (positions(0), gram(6, 6, 0))
    if (.not. regular_base .or. con%n_contact_global == 0) return
    if (dense_for(this%options%factor, 6*this%layout%nsub, this%options%ranks_per_group)) return
    allocate (col(con%n_own), wloc(con%n_local))
    col = merge(1.0_dp, 0.0_dp, con%kind(1:con%n_own) == row_contact)
    call con%exchange%gather(col, wloc)
    allocate (mine(size(con%b)), my_gram(6, 6, size(con%b)))
    n_mine = 0
    do ls = 1, size(con%b, kind=ip)
      touched = .false.
      gs = 0
      associate (bs => con%b(ls))
        do e = 1, bs%nentries
          if (wloc(bs%row(e)) <= 0) cycle
          touched = .true.
          do k = 1, 6
            gs(:, k) = gs(:, k) + bs%g(:, e)*bs%g(k, e)
          end do
        end do
      end associate
      if (touched) then
        n_mine = n_mine + 1
        mine(n_mine) = this%layout%position(dec%local_subdomains(ls))
        my_gram(:, :, n_mine) = gs
      end if
    end do
    cnt = int(n_mine)
    call gathered_counts(cnt, this%comm, counts, displs)
    n = sum(counts)
    if (4*n > this%layout%nsub) return
    deallocate (positions, gram)
    allocate (positions(n), gram(6, 6, n))
    call MPI_Allgatherv(mine(1:n_mine), cnt, MPI_INT_IP, positions, counts, displs, MPI_INT_IP, this%comm, ierr)
    call MPI_Allgatherv(my_gram(:, :, 1:n_mine), 36*cnt, MPI_REAL_DP, gram, 36*counts, 36*displs, MPI_REAL_DP, &
                        this%comm, ierr)
    call sort_permutation(positions, order)
    positions = positions(order)
    gram = gram(:, :, order)
  end subroutine contact_face_subdomains

  !> `view` holds G_M G_M^T as a view of the coarse problem's Schur factors:
  !> every row outside the mask is a contact row. Collective.
  subroutine schur_view(this, dec, con, mask, contact, view)
    class(projector_t), intent(in) :: this
    type(decomposition_t), intent(in) :: dec
    type(constraints_t), intent(inout) :: con
    logical, intent(in) :: mask(:), contact(:)
    type(coarse_problem_t), intent(inout) :: view
    real(dp), allocatable :: col(:), wloc(:), g(:, :)
    integer(i8), allocatable :: keys(:)
    integer(ip), allocatable :: pos(:)
    integer(ip) :: ls, e, i, c, c_offset, np
    integer :: rank, ierr
    ! the global ordinal of each contact row outside the mask (rank, then row), on every copy
    c = count(contact, kind=ip)
    c_offset = 0
    call MPI_Exscan(c, c_offset, 1, MPI_INT_IP, MPI_SUM, this%comm, ierr)
    call MPI_Comm_rank(this%comm, rank, ierr)
    if (rank == 0) c_offset = 0
    allocate (col(con%n_own), wloc(con%n_local))
    col = 0
    c = c_offset
    do i = 1, con%n_own
      if (.not. contact(i)) cycle
      c = c + 1
      if (.not. mask(i)) col(i) = real(c, dp)
    end do
    call con%exchange%gather(col, wloc)
    np = 0
    do ls = 1, size(con%b, kind=ip)
      np = np + count(nint(wloc(con%b(ls)%row(1:con%b(ls)%nentries)), ip) > 0, kind=ip)
    end do
    allocate (keys(np), pos(np), g(6, np))
    np = 0
    do ls = 1, size(con%b, kind=ip)
      associate (bs => con%b(ls))
        do e = 1, bs%nentries
          c = nint(wloc(bs%row(e)), ip)
          if (c <= 0) cycle
          np = np + 1
          keys(np) = int(c, i8)
          pos(np) = this%layout%position(dec%local_subdomains(ls))
          g(:, np) = bs%g(:, e)
        end do
      end associate
    end do
    call view%make_view(this%coarse, keys, pos, g)
  end subroutine schur_view

  !> How many times the reusable masked instance has changed (masked_coarse
  !> without own_view): equal before and after means it holds the same matrix.
  integer(i8) function masked_changes(this)
    class(projector_t), intent(in) :: this
    masked_changes = this%masked_generation
  end function masked_changes

  !> The explicit G~ = L^{-1} G of `&solver coarse = 'orthonormal'`. Collective.
  subroutine init_orthonormal(this, dec, b, orth)
    class(projector_t), intent(in) :: this
    type(decomposition_t), intent(in) :: dec
    type(b_operator_t), intent(inout), target :: b
    type(orthonormal_coarse_t), intent(inout) :: orth
    type(constraints_t), pointer :: con
    con => b%constraints()
    call orth%init(dec, con, this%layout, this%comm)
  end subroutine init_orthonormal

  integer(i8) function n_solves(this)
    class(projector_t), intent(in) :: this
    n_solves = this%solves
  end function n_solves

  !> The factorized G G^T (sizes, groups, memory for the report).
  function coarse_problem(this) result(cp)
    class(projector_t), intent(in), target :: this
    type(coarse_problem_t), pointer :: cp
    cp => this%coarse
  end function coarse_problem

  subroutine free(this)
    class(projector_t), intent(inout) :: this
    call this%coarse%free()
    call this%masked%free()
    call this%own%free()
    this%masked_mode = 0
    if (allocated(this%cwork)) deallocate (this%cwork, this%cwork2)
    this%solves = 0
  end subroutine free
end module projector
