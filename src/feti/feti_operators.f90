!> The TFETI dual operators of the paper, Eq. (4)-(8), on distributed data,
!> as one object the transform layer (src/dual) uses: F = B K^+ B^T
!> (f_operator), B, B^T, G = R^T B^T and G^T (b_operator), the coarse solve
!> (G G^T)^{-1} and P = I - G^T (G G^T)^{-1} G (projector); the vectors
!> d = B K^+ f - c, e = R^T f, lambda~ = G^T (G G^T)^{-1} e, an estimate of
!> ||P F P||, and the primal map u = K^+ (f - B^T lambda) + R alpha.
!>
!> Dual vectors: the multipliers this rank owns (length n_own()).
!> Coarse vectors: the 6-blocks of this rank's subdomains (length n_coarse()),
!> in the order of the decomposition's local_subdomains (see coarse_problem).
!>
!> `setup` is the builder (submodule feti_builder). All components are
!> private: the layers above use the operators and the accessors below,
!> never the data behind them.
module feti_operators
  use kinds, only: dp, ip, i8, name_len, MPI_REAL_DP
  use logger, only: log_message
  use timers, only: timer_start, timer_stop
  use feti_settings, only: feti_settings_t
  use local_settings, only: local_ordering_for, local_solver_for
  use decomposition, only: decomposition_t
  use subdomain, only: subdomain_t
  use box_mesh, only: box_mesh_t
  use b_operator, only: b_operator_t, local_field_t
  use f_operator, only: f_operator_t
  use projector, only: projector_t
  use coarse_problem, only: coarse_problem_t
  use orthonormal_coarse, only: orthonormal_coarse_t
  use dual_preconditioner, only: dual_preconditioner_t
  use constraints, only: row_dirichlet, row_contact
  use mpi_f08, only: MPI_Comm, MPI_Allreduce, MPI_SUM, MPI_MIN, MPI_IN_PLACE, MPI_INTEGER
  implicit none
  private

  public :: local_field_t

  !> Sizes of the decomposition and of the dual problem (all ranks).
  type, public :: feti_sizes_t
    integer(ip) :: nsubdomains = 0, coarse_dim = 0
    integer(i8) :: primal_dofs = 0
    integer(ip) :: dual_dofs = 0, gluing_rows = 0, dirichlet_rows = 0, contact_rows = 0
  end type feti_sizes_t

  type, public :: feti_t
    private
    type(MPI_Comm) :: communicator
    type(decomposition_t) :: dec                 !< the FETI units: subdomains, or clusters (hybrid)
    type(decomposition_t) :: sub_dec             !< hybrid TFETI (&mesh cluster): the subdomains
    logical :: hybrid = .false.
    logical :: young_rows = .true.               !< &solver scaling = 'young' (B's rows weighted by moduli)
    type(subdomain_t), allocatable :: subs(:)
    type(b_operator_t) :: b                      !< B, B^T, G, G^T
    type(f_operator_t) :: f                      !< F = B K^+ B^T
    type(projector_t) :: proj                    !< (G G^T)^{-1}, P
    integer(ip) :: n_local_subs = 0              !< subdomains of this rank
    integer(i8) :: n_primal_dofs = 0             !< sum of subdomain dofs, all ranks
    real(dp), allocatable :: d(:)                !< (n_own) B K^+ f - c
    real(dp), allocatable :: lambda_tilde(:)     !< (n_own) G^T (G G^T)^{-1} e
    real(dp), allocatable :: lower(:)            !< (n_own) bounds of nu: -lambda~ on contact rows
    logical, allocatable :: contact(:)           !< (n_own) the row is a contact row
    real(dp), allocatable :: e(:)                !< (6*nlocal) R^T f
    real(dp) :: pfp_norm = 0                     !< estimate of ||P F P||
    !> the Lanczos process of the estimate, kept for its continuation
    !> (refine_norm_pfp): the last two basis vectors, T's coefficients, steps made
    real(dp), allocatable :: lz_v(:), lz_vold(:), lz_alpha(:), lz_beta(:)
    real(dp) :: lz_previous = 0
    integer(ip) :: lz_steps = 0, lz_max = 0
    logical :: lz_done = .true.                  !< converged (or stopped): nothing to refine
    !> the Dirichlet rows alone fix every rigid body motion of the body (setup, dirichlet_rigid_test)
    logical :: dirichlet_holds = .false.
    real(dp), allocatable :: xall(:)             !< work: concatenated primal vector
    !> `&solver f_action = 'auto'` without classes: the explicit local operators
    !> are built before F action number f_build_at + 1 (0: no build pending;
    !> feti_builder's choose_f_action), with these settings
    integer(i8) :: f_build_at = 0
    integer(i8) :: f_built_after = -1            !< F actions before the deferred build (-1: none made)
    real(dp) :: f_regularization = 1
    character(len=name_len) :: f_storage = 'packed'   !< &solver f_storage (the same length)
    !> the ordering of the subdomain factorizations used ('amd' | 'metis'; `&solver local_ordering`,
    !> resolved by local_settings::local_ordering_for from the largest subdomain of the run)
    character(len=8) :: ordering_used = ''
    !> the local solver asked of f_operator ('dense' | 'block' | 'subdomain'; `&solver local_solver`,
    !> resolved by local_settings::local_solver_for; classes of congruent subdomains override it)
    character(len=10) :: solver_used = ''
    !> a load history (set_load): f (concatenated) and c of the set-up, the
    !> load factor 1 and the obstacle where the input puts it
    real(dp), allocatable :: f_unit(:), c_unit(:)
  contains
    procedure :: setup
    procedure :: apply_f
    procedure :: apply_g
    procedure :: apply_gt
    procedure :: coarse_solve
    procedure :: project
    procedure :: dot
    procedure :: norm
    procedure :: primal
    procedure :: apply_bt
    procedure :: apply_b
    procedure :: local_solve
    procedure :: bytes_per_f_action
    procedure :: flops_per_f_action
    procedure :: keyed_random
    procedure :: init_active_coarse
    procedure :: masked_coarse
    procedure :: masked_changes
    procedure :: init_orthonormal
    procedure :: init_preconditioner
    ! accessors
    procedure :: comm
    procedure :: nlocal
    procedure :: n_own
    procedure :: n_coarse
    procedure :: sizes
    procedure :: mesh
    procedure :: subdomains
    procedure :: dual_rhs
    procedure :: lambda_tilde_vector
    procedure :: rigid_rhs
    procedure :: lower_bounds
    procedure :: is_contact
    procedure :: force_scale
    procedure :: gap_rhs
    procedure :: row_keys
    procedure :: row_offset
    procedure :: row_node_gid
    procedure :: row_coordinates
    procedure :: row_kind
    procedure :: row_units
    procedure :: largest_copy_spread
    procedure :: norm_pfp
    procedure :: refine_norm_pfp
    procedure :: norm_pfp_refined
    procedure :: f_applications
    procedure :: f_explicit
    procedure :: f_explicit_pending
    procedure :: f_explicit_after
    procedure :: local_ordering
    procedure :: local_solver
    procedure :: dirichlet_from_factors
    procedure :: dirichlet_by_blocks
    procedure :: glued_by_faces
    procedure :: f_shared
    procedure :: f_classes
    procedure :: f_local_operator
    procedure :: setup_flops
    procedure :: coarse_solves
    procedure :: coarse_factor
    procedure :: dirichlet_fixes_rigid_modes
    procedure :: hybrid_units
    procedure :: set_load
    procedure :: settle_f_action
    procedure :: free
  end type feti_t

  interface
    !> Everything before the dual solve: decomposition, subdomains, K^+, B, G,
    !> the coarse problem, d, e, lambda~ and ||P F P|| (submodule feti_builder).
    !> Collective over `comm`.
    module subroutine setup(this, settings, comm, units)
      class(feti_t), intent(inout) :: this
      type(feti_settings_t), intent(in) :: settings
      type(MPI_Comm), intent(in) :: comm
      type(decomposition_t), intent(in), optional :: units
    end subroutine setup
    !> Continue the Lanczos estimate of ||P F P|| that set-up began (its
    !> first steps scale the dual problem) until its stopping rule holds:
    !> made when MPRGP first needs its step length (submodule feti_builder).
    !> Nothing when it has converged already. Collective.
    module subroutine refine_norm_pfp(this)
      class(feti_t), intent(inout) :: this
    end subroutine refine_norm_pfp
  end interface

contains

  !> y = F x = B K^+ B^T x. With a deferred build pending (`f_action =
  !> 'auto'`, feti_builder's choose_f_action), the explicit local operators
  !> are built once the implicit actions have cost about what the build does
  !> (F actions are collective, so every rank builds at the same call).
  subroutine apply_f(this, x, y)
    class(feti_t), intent(inout) :: this
    real(dp), intent(in) :: x(:)
    real(dp), intent(inout) :: y(:)
    character(len=160) :: line
    if (this%f_build_at > 0) then
      if (this%f%n_applications() >= this%f_build_at) then
        call timer_start('explicit F')
        call this%f%build_explicit(this%b, this%subs, this%f_regularization, this%f_storage)
        call timer_stop('explicit F')
        this%f_built_after = this%f%n_applications()
        this%f_build_at = 0
        write (line, '(3a,i0,a)') "F action 'auto': implicit -> explicit local operators (", &
          trim(this%f_storage), ') after ', this%f_built_after, ' F actions'
        call log_message(trim(line))
      end if
    end if
    call this%f%apply(this%b, x, y)
  end subroutine apply_f

  !> z = G x (local coarse blocks).
  subroutine apply_g(this, x, z)
    class(feti_t), intent(inout) :: this
    real(dp), intent(in) :: x(:)
    real(dp), intent(out) :: z(:)
    call this%b%apply_g(x, z)
  end subroutine apply_g

  !> y = G^T z for local coarse blocks z.
  subroutine apply_gt(this, z, y)
    class(feti_t), intent(inout) :: this
    real(dp), intent(in) :: z(:)
    real(dp), intent(inout) :: y(:)
    call this%b%apply_gt(z, y)
  end subroutine apply_gt

  !> x = (G G^T)^{-1} b on local coarse blocks.
  subroutine coarse_solve(this, b, x)
    class(feti_t), intent(inout) :: this
    real(dp), intent(in) :: b(:)
    real(dp), intent(out) :: x(:)
    call this%proj%solve(b, x)
  end subroutine coarse_solve

  !> y = P x (y may not be x); optionally also G x and (G G^T)^{-1} G x.
  subroutine project(this, x, y, gx, zx)
    class(feti_t), intent(inout) :: this
    real(dp), intent(in) :: x(:)
    real(dp), intent(inout) :: y(:)
    real(dp), intent(out), optional :: gx(:), zx(:)
    call this%proj%project(this%b, x, y, gx, zx)
  end subroutine project

  !> Global dot product of dual vectors.
  real(dp) function dot(this, x, y)
    class(feti_t), intent(in) :: this
    real(dp), intent(in) :: x(:), y(:)
    real(dp) :: mine
    integer :: ierr
    mine = dot_product(x(1:this%b%n_own()), y(1:this%b%n_own()))
    call MPI_Allreduce(mine, dot, 1, MPI_REAL_DP, MPI_SUM, this%communicator, ierr)
  end function dot

  real(dp) function norm(this, x)
    class(feti_t), intent(in) :: this
    real(dp), intent(in) :: x(:)
    norm = sqrt(this%dot(x, x))
  end function norm

  !> u^s = K^+ (f^s - B^s^T lambda) + R^s alpha^s for every local subdomain.
  subroutine primal(this, lambda, alpha, u)
    class(feti_t), intent(inout) :: this
    real(dp), intent(in) :: lambda(:), alpha(:)
    type(local_field_t), intent(inout) :: u(:)
    integer(ip) :: ls, r(2)
    do ls = 1, this%n_local_subs
      r = this%b%dof_range(ls)
      this%xall(r(1):r(2)) = this%subs(ls)%f
    end do
    call this%b%add_transpose(lambda, -1.0_dp, this%xall)
    call this%f%local_solve(this%xall)
    do ls = 1, this%n_local_subs
      r = this%b%dof_range(ls)
      if (.not. allocated(u(ls)%v)) allocate (u(ls)%v(this%subs(ls)%ndof))
      u(ls)%v = this%xall(r(1):r(2)) + matmul(this%subs(ls)%R, alpha(6*ls - 5:6*ls))
    end do
  end subroutine primal

  !> u^s = B^s^T x for every local subdomain.
  subroutine apply_bt(this, x, u)
    class(feti_t), intent(inout) :: this
    real(dp), intent(in) :: x(:)
    type(local_field_t), intent(inout) :: u(:)
    call this%b%apply_bt(x, u)
  end subroutine apply_bt

  !> y = B u (owned rows).
  subroutine apply_b(this, u, y)
    class(feti_t), intent(inout) :: this
    type(local_field_t), intent(in) :: u(:)
    real(dp), intent(inout) :: y(:)
    call this%b%apply_b(u, y)
  end subroutine apply_b

  !> x <- K^+ x for the concatenated vector of all local subdomains.
  subroutine local_solve(this, x)
    class(feti_t), intent(inout) :: this
    real(dp), intent(inout) :: x(:)
    call this%f%local_solve(x)
  end subroutine local_solve

  !> Bytes one F action must read on this rank (see f_operator).
  integer(i8) function bytes_per_f_action(this)
    class(feti_t), intent(in) :: this
    bytes_per_f_action = this%f%bytes_per_action(this%b)
  end function bytes_per_f_action

  !> Flops of one F action on this rank when it is one dgemm per class
  !> (shared explicit operators); 0 otherwise.
  real(dp) function flops_per_f_action(this)
    class(feti_t), intent(in) :: this
    flops_per_f_action = this%f%flops_per_action()
  end function flops_per_f_action

  !> A dual vector with entries in [-1, 1] that depend only on the rows'
  !> canonical keys (the same on any number of ranks).
  subroutine keyed_random(this, seed, x)
    class(feti_t), intent(in) :: this
    integer, intent(in) :: seed
    real(dp), intent(out) :: x(:)
    call this%b%keyed_random(seed, x)
  end subroutine keyed_random

  !> G_A G_A^T assembled and factorized anew for the rows in `mask` (the
  !> standard reconstruction, Eq. 10). Collective.
  subroutine init_active_coarse(this, cp, mask)
    class(feti_t), intent(inout) :: this
    type(coarse_problem_t), intent(inout) :: cp
    logical, intent(in) :: mask(:)
    call this%proj%init_active_coarse(this%dec, this%b, cp, mask)
  end subroutine init_active_coarse

  !> G_M G_M^T for the rows in `mask` in the projector's reusable instance
  !> (one MUMPS analysis per run; see projector%masked_coarse); valid until
  !> the next call. Collective.
  !> `low_rank`: the matrix may be G_E G_E^T plus a low-rank update when
  !> that is cheaper (SMALBE's faces; not the standard reconstruction, which
  !> factorizes G_A G_A^T as a conventional code does).
  !> `force_low_rank` (tests): the low-rank way whenever it applies.
  !> `own_view`: a Schur view in an instance of its own, the reusable one
  !> keeping what it holds (projector%masked_coarse).
  function masked_coarse(this, mask, low_rank, force_low_rank, own_view) result(cp)
    class(feti_t), intent(inout), target :: this
    logical, intent(in) :: mask(:)
    logical, intent(in) :: low_rank
    logical, intent(in), optional :: force_low_rank, own_view
    type(coarse_problem_t), pointer :: cp
    cp => this%proj%masked_coarse(this%dec, this%b, mask, this%dirichlet_fixes_rigid_modes(), low_rank, &
                                  force_low_rank, own_view)
  end function masked_coarse

  !> How many times masked_coarse's reusable instance has changed (the same
  !> count before and after: it holds the same matrix).
  integer(i8) function masked_changes(this)
    class(feti_t), intent(in) :: this
    masked_changes = this%proj%masked_changes()
  end function masked_changes

  !> The explicit G~ = L^{-1} G of `&solver coarse = 'orthonormal'`. Collective.
  subroutine init_orthonormal(this, orth)
    class(feti_t), intent(inout) :: this
    type(orthonormal_coarse_t), intent(inout) :: orth
    call this%proj%init_orthonormal(this%dec, this%b, orth)
  end subroutine init_orthonormal

  !> The preconditioner M^{-1} = sum_s B_D^s A_s B_D^s^T of `&solver
  !> preconditioner` ('lumped' | 'dirichlet'), w_s = weights(ls) for the
  !> local subdomain ls (dual_preconditioner). `this` must be a target and
  !> outlive `prec`. Collective.
  subroutine init_preconditioner(this, prec, kind, weights)
    class(feti_t), intent(inout), target :: this
    type(dual_preconditioner_t), intent(inout) :: prec
    character(len=*), intent(in) :: kind
    real(dp), intent(in) :: weights(:)
    integer(ip) :: ls
    ! clusters of several moduli (glued by faces): B_D = B diag(1/w) with the
    ! weight of every dof's subdomain, applied per cluster (not per class)
    if (this%young_rows .and. any([(allocated(this%subs(ls)%elem_young), ls = 1, this%n_local_subs)])) then
      call prec%init(kind, this%b, this%subs, weights, dof_weights=dof_weights())
      return
    end if
    if (this%f%is_shared()) then
      call prec%init(kind, this%b, this%subs, weights, this%f%classes_found())
      return
    end if
    ! 'dirichlet' from the dense local solver's factors when every rank has them
    ! (the same exchanges on every rank)
    if (kind == 'dirichlet' .and. this%dirichlet_from_factors()) then
      call prec%init(kind, this%b, this%subs, weights, dense=this%f)
    else
      call prec%init(kind, this%b, this%subs, weights)
    end if
  contains
    !> weights(ls) E_e/E_s of an element e holding the dof, for every dof of the
    !> concatenated vector (E_s = sub%young; a node's elements are of one subdomain)
    function dof_weights() result(wd)
      real(dp), allocatable :: wd(:)
      integer(ip) :: r(2), e, a
      allocate (wd(this%b%n_concat()))
      do ls = 1, this%n_local_subs
        r = this%b%dof_range(ls)
        wd(r(1):r(2)) = weights(ls)
        if (.not. allocated(this%subs(ls)%elem_young)) cycle
        do e = 1, this%subs(ls)%nelem
          do a = 1, 8
            associate (n => this%subs(ls)%elem_nodes(a, e))
              wd(r(1) + 3*(n - 1):r(1) + 3*n - 1) = weights(ls)*this%subs(ls)%elem_young(e)/this%subs(ls)%young
            end associate
          end do
        end do
      end do
    end function dof_weights
  end subroutine init_preconditioner

  !> True when the Dirichlet preconditioner can take S_s of every subdomain
  !> from the dense local solver's factors (no set-up, one pair of packed
  !> triangular products per subdomain and application), on every rank.
  !> Collective.
  logical function dirichlet_from_factors(this)
    class(feti_t), intent(in) :: this
    integer :: ready, ierr
    ready = merge(1, 0, this%f%dense_schur_ready())
    call MPI_Allreduce(MPI_IN_PLACE, ready, 1, MPI_INTEGER, MPI_MIN, this%communicator, ierr)
    dirichlet_from_factors = ready == 1
  end function dirichlet_from_factors

  !> True when the Dirichlet preconditioner is applied per class of clusters
  !> glued by faces, one dense Schur block per subdomain of the cluster
  !> (dual_preconditioner: set up with one small elimination per block of a
  !> class, applied by one dgemm per block of a class), on every rank: the
  !> clusters are shared per class, with one modulus per cluster. Collective.
  logical function dirichlet_by_blocks(this)
    class(feti_t), intent(in) :: this
    integer :: ready, ierr
    integer(ip) :: ls
    ready = 0
    if (this%f%is_shared() .and. this%n_local_subs > 0 .and. units_glued(this)) then
      ready = 1
      do ls = 1, this%n_local_subs
        if (this%young_rows .and. allocated(this%subs(ls)%elem_young)) ready = 0
      end do
    end if
    call MPI_Allreduce(MPI_IN_PLACE, ready, 1, MPI_INTEGER, MPI_MIN, this%communicator, ierr)
    dirichlet_by_blocks = ready == 1
  end function dirichlet_by_blocks

  ! ---- accessors ----

  !> The communicator of the distributed vectors.
  type(MPI_Comm) function comm(this)
    class(feti_t), intent(in) :: this
    comm = this%communicator
  end function comm

  !> Subdomains of this rank.
  integer(ip) function nlocal(this)
    class(feti_t), intent(in) :: this
    nlocal = this%n_local_subs
  end function nlocal

  !> Length of a dual vector on this rank (owned rows).
  integer(ip) function n_own(this)
    class(feti_t), intent(in) :: this
    n_own = this%b%n_own()
  end function n_own

  !> Length of a vector of local coarse blocks on this rank (6 per subdomain).
  integer(ip) function n_coarse(this)
    class(feti_t), intent(in) :: this
    n_coarse = 6*this%n_local_subs
  end function n_coarse

  type(feti_sizes_t) function sizes(this)
    class(feti_t), intent(in) :: this
    integer(ip) :: rows(4)
    rows = this%b%row_counts()
    sizes%nsubdomains = this%dec%nsubdomains
    if (this%hybrid) sizes%nsubdomains = this%sub_dec%nsubdomains
    sizes%coarse_dim = 6*this%dec%nsubdomains
    sizes%primal_dofs = this%n_primal_dofs
    sizes%dual_dofs = rows(1)
    sizes%gluing_rows = rows(2)
    sizes%dirichlet_rows = rows(3)
    sizes%contact_rows = rows(4)
  end function sizes

  !> The global box mesh (index arithmetic only).
  type(box_mesh_t) function mesh(this)
    class(feti_t), intent(in) :: this
    mesh = this%dec%mesh
  end function mesh

  !> The local subdomains (geometry, K, f, R), read-only by convention;
  !> `this` must be a target.
  function subdomains(this) result(subs)
    class(feti_t), intent(inout), target :: this
    type(subdomain_t), pointer :: subs(:)
    subs => this%subs
  end function subdomains

  !> d = B K^+ f - c (owned rows).
  function dual_rhs(this) result(v)
    class(feti_t), intent(in) :: this
    real(dp), allocatable :: v(:)
    v = this%d
  end function dual_rhs

  !> lambda~ = G^T (G G^T)^{-1} e (owned rows).
  function lambda_tilde_vector(this) result(v)
    class(feti_t), intent(in) :: this
    real(dp), allocatable :: v(:)
    v = this%lambda_tilde
  end function lambda_tilde_vector

  !> e = R^T f (local coarse blocks).
  function rigid_rhs(this) result(v)
    class(feti_t), intent(in) :: this
    real(dp), allocatable :: v(:)
    v = this%e
  end function rigid_rhs

  !> Lower bounds of nu = lambda - lambda~: -lambda~ on contact rows, -huge elsewhere.
  function lower_bounds(this) result(v)
    class(feti_t), intent(in) :: this
    real(dp), allocatable :: v(:)
    v = this%lower
  end function lower_bounds

  !> Which owned rows are contact rows.
  function is_contact(this) result(v)
    class(feti_t), intent(in) :: this
    logical, allocatable :: v(:)
    v = this%contact
  end function is_contact

  !> force = scale * multiplier (owned rows; 1 unless &solver scaling).
  function force_scale(this) result(v)
    class(feti_t), intent(in) :: this
    real(dp), allocatable :: v(:)
    v = this%b%force_scale()
  end function force_scale

  !> c, the right-hand side of B u <= c (owned rows).
  function gap_rhs(this) result(v)
    class(feti_t), intent(in) :: this
    real(dp), allocatable :: v(:)
    v = this%b%gap_rhs()
  end function gap_rhs

  !> Canonical keys of the owned rows (the same on any number of ranks).
  function row_keys(this) result(v)
    class(feti_t), intent(in) :: this
    integer(i8), allocatable :: v(:)
    v = this%b%row_keys()
  end function row_keys

  !> Global id of owned row i: row_offset() + i.
  integer(ip) function row_offset(this)
    class(feti_t), intent(in) :: this
    row_offset = this%b%row_offset()
  end function row_offset

  !> Node gid of each owned row.
  function row_node_gid(this) result(v)
    class(feti_t), intent(in) :: this
    integer(ip), allocatable :: v(:)
    v = this%b%row_node_gid()
  end function row_node_gid

  !> Coordinates (3, n_own) of the node of each owned row.
  function row_coordinates(this) result(x)
    class(feti_t), intent(in) :: this
    real(dp), allocatable :: x(:, :)
    x = this%b%row_coordinates(this%subs)
  end function row_coordinates

  !> The kind of each owned row: row_gluing, row_dirichlet or row_contact (constraints).
  function row_kind(this) result(v)
    class(feti_t), intent(in) :: this
    integer(ip), allocatable :: v(:)
    v = this%b%row_kind()
  end function row_kind

  !> Row i of B is unit(i) times a displacement (owned rows).
  function row_units(this) result(v)
    class(feti_t), intent(in) :: this
    real(dp), allocatable :: v(:)
    v = this%b%row_units()
  end function row_units

  !> The largest difference between the copies of a glued node component,
  !> sqrt(2 sum_c (u_c - mean)^2), over all nodes of all ranks (see b_operator).
  real(dp) function largest_copy_spread(this, u)
    class(feti_t), intent(inout) :: this
    type(local_field_t), intent(in) :: u(:)
    largest_copy_spread = this%b%largest_copy_spread(u)
  end function largest_copy_spread

  !> The current estimate of ||P F P|| (a lower bound; refine_norm_pfp
  !> raises it to the converged Lanczos value).
  real(dp) function norm_pfp(this)
    class(feti_t), intent(in) :: this
    norm_pfp = this%pfp_norm
  end function norm_pfp

  !> True when the Lanczos estimate has met its stopping rule.
  logical function norm_pfp_refined(this)
    class(feti_t), intent(in) :: this
    norm_pfp_refined = this%lz_done
  end function norm_pfp_refined

  integer(i8) function f_applications(this)
    class(feti_t), intent(in) :: this
    f_applications = this%f%n_applications()
  end function f_applications

  !> True when F is applied with the explicit local operators.
  logical function f_explicit(this)
    class(feti_t), intent(in) :: this
    f_explicit = this%f%is_explicit()
  end function f_explicit

  !> True while F is applied implicitly with a deferred explicit build pending
  !> (`f_action = 'auto'`; it comes after f_explicit_after() actions).
  logical function f_explicit_pending(this)
    class(feti_t), intent(in) :: this
    f_explicit_pending = this%f_build_at > 0
  end function f_explicit_pending

  !> The F action count at which the explicit operators are (pending) or were
  !> (made) built by `f_action = 'auto'`'s deferred build; -1 when none.
  integer(i8) function f_explicit_after(this)
    class(feti_t), intent(in) :: this
    f_explicit_after = this%f_built_after
    if (this%f_build_at > 0) f_explicit_after = this%f_build_at
  end function f_explicit_after

  !> The ordering of the subdomain factorizations this run used ('amd' or 'metis').
  function local_ordering(this) result(name)
    class(feti_t), intent(in) :: this
    character(len=8) :: name
    name = this%ordering_used
  end function local_ordering

  !> The local solver this run used: 'shared' (per class of congruent
  !> subdomains), 'dense', 'block' or 'subdomain'.
  function local_solver(this) result(name)
    class(feti_t), intent(in) :: this
    character(len=10) :: name
    name = this%solver_used
    if (this%f%is_shared()) name = 'shared'
  end function local_solver

  !> True when K^+ (and the explicit operators) are shared per class of
  !> congruent subdomains (`&solver share_subdomains`).
  logical function f_shared(this)
    class(feti_t), intent(in) :: this
    f_shared = this%f%is_shared()
  end function f_shared

  !> Classes of congruent subdomains on this rank (= the local subdomains
  !> without sharing).
  integer(ip) function f_classes(this)
    class(feti_t), intent(in) :: this
    f_classes = this%f%n_classes()
  end function f_classes

  !> The dense F^s of local subdomain `ls` on its local dual rows `rows`
  !> (explicit F only; for tests).
  subroutine f_local_operator(this, ls, rows, fs)
    class(feti_t), intent(in) :: this
    integer(ip), intent(in) :: ls
    integer(ip), allocatable, intent(out) :: rows(:)
    real(dp), allocatable, intent(out) :: fs(:, :)
    call this%f%local_operator(ls, rows, fs)
  end subroutine f_local_operator

  !> Floating-point operations on this rank of the factorization of K^+ and
  !> of the explicit local operators' build (0 if implicit).
  function setup_flops(this) result(v)
    class(feti_t), intent(in) :: this
    real(dp) :: v(2)
    v = [this%f%factor_flops(), this%f%build_flops()]
  end function setup_flops

  integer(i8) function coarse_solves(this)
    class(feti_t), intent(in) :: this
    coarse_solves = this%proj%n_solves()
  end function coarse_solves

  !> The factorized G G^T of the projector (groups, sizes, memory).
  function coarse_factor(this) result(cp)
    class(feti_t), intent(in), target :: this
    type(coarse_problem_t), pointer :: cp
    cp => this%proj%coarse_problem()
  end function coarse_factor

  !> True when the Dirichlet rows alone fix every rigid body motion of the
  !> glued body (feti_builder's dirichlet_rigid_test): then every free-row
  !> coarse matrix G_F G_F^T (equality rows plus any contact rows) is regular.
  logical function dirichlet_fixes_rigid_modes(this)
    class(feti_t), intent(in) :: this
    dirichlet_fixes_rigid_modes = this%dirichlet_holds
  end function dirichlet_fixes_rigid_modes

  !> True when the units are clusters glued by faces, on every rank. Collective.
  logical function glued_by_faces(this)
    class(feti_t), intent(in) :: this
    integer :: glued, ierr
    glued = merge(1, 0, units_glued(this))
    call MPI_Allreduce(MPI_IN_PLACE, glued, 1, MPI_INTEGER, MPI_MIN, this%communicator, ierr)
    glued_by_faces = glued == 1
  end function glued_by_faces

  !> This rank's units are clusters glued by faces: every node of a cluster
  !> keeps one copy per subdomain.
  logical function units_glued(this)
    class(feti_t), intent(in) :: this
    integer(ip) :: ls
    units_glued = this%hybrid
    do ls = 1, this%n_local_subs
      if (.not. units_glued) return
      if (.not. allocated(this%subs(ls)%node_copy)) then
        units_glued = .false.
      else
        units_glued = all(this%subs(ls)%node_copy >= 1)
      end if
    end do
  end function units_glued

  !> Hybrid TFETI (&mesh cluster): the FETI units are clusters of subdomains.
  logical function hybrid_units(this)
    class(feti_t), intent(in) :: this
    hybrid_units = this%hybrid
  end function hybrid_units

  !> The right-hand sides of a step of a load history: f and the prescribed
  !> displacements (Dirichlet values of c) of the set-up times `factor`, the
  !> obstacle moved by `gap_shift` (contact values of c), then d = B K^+ f - c,
  !> e = R^T f, lambda~ = G^T (G G^T)^{-1} e and the bounds, as the set-up
  !> forms them. Every operator stays. Collective.
  subroutine set_load(this, factor, gap_shift)
    class(feti_t), intent(inout) :: this
    real(dp), intent(in) :: factor, gap_shift
    integer(ip) :: ls, r(2)
    integer(ip), allocatable :: kind(:)
    real(dp), allocatable :: c(:), unit(:), z(:)
    if (.not. allocated(this%f_unit)) then
      allocate (this%f_unit(size(this%xall)))
      do ls = 1, this%n_local_subs
        r = this%b%dof_range(ls)
        this%f_unit(r(1):r(2)) = this%subs(ls)%f
      end do
      this%c_unit = this%b%gap_rhs()
    end if
    kind = this%b%row_kind()
    unit = this%b%row_units()
    c = this%c_unit
    where (kind == row_dirichlet) c = factor*this%c_unit
    where (kind == row_contact) c = this%c_unit + gap_shift*unit
    call this%b%set_gap_rhs(c)
    do ls = 1, this%n_local_subs
      r = this%b%dof_range(ls)
      this%subs(ls)%f = factor*this%f_unit(r(1):r(2))
      this%xall(r(1):r(2)) = this%subs(ls)%f
      this%e(6*ls - 5:6*ls) = matmul(this%subs(ls)%f, this%subs(ls)%R)
    end do
    call this%f%local_solve(this%xall)
    call this%b%apply_concat(this%xall, this%d)
    this%d = this%d - c
    allocate (z(6*this%n_local_subs))
    call this%proj%solve(this%e, z)
    call this%b%apply_gt(z, this%lambda_tilde)
    this%lower = -huge(1.0_dp)
    where (this%contact) this%lower = -this%lambda_tilde
  end subroutine set_load

  !> `&solver f_action = 'auto'` with a deferred build pending: build the
  !> explicit local operators now, so that every later solve (a step of a
  !> history, or one after a restart) sees the same F whatever it follows.
  !> Collective.
  subroutine settle_f_action(this)
    class(feti_t), intent(inout) :: this
    if (this%f_build_at <= 0) return
    call timer_start('explicit F')
    call this%f%build_explicit(this%b, this%subs, this%f_regularization, this%f_storage)
    call timer_stop('explicit F')
    this%f_built_after = this%f%n_applications()
    this%f_build_at = 0
    call log_message("F action 'auto': explicit local operators built before the load history")
  end subroutine settle_f_action

  subroutine free(this)
    class(feti_t), intent(inout) :: this
    call this%f%free()
    call this%proj%free()
    call this%b%free()
    if (allocated(this%subs)) deallocate (this%subs)
    if (allocated(this%d)) deallocate (this%d, this%lambda_tilde, this%lower, this%contact, this%e)
    if (allocated(this%xall)) deallocate (this%xall)
    if (allocated(this%f_unit)) deallocate (this%f_unit, this%c_unit)
    this%n_local_subs = 0
    this%pfp_norm = 0
    if (allocated(this%lz_v)) deallocate (this%lz_v, this%lz_vold, this%lz_alpha, this%lz_beta)
    this%lz_steps = 0
    this%lz_done = .true.
    this%f_build_at = 0
    this%f_built_after = -1
  end subroutine free
end module feti_operators
