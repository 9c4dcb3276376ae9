!> The TFETI dual operators of the paper, Eq. (4)-(8), on distributed data:
!> F = B K^+ B^T, G = R^T B^T and G^T, the coarse solve (G G^T)^{-1}, the
!> projector P = I - G^T (G G^T)^{-1} G, d = B K^+ f - c, e = R^T f,
!> lambda~ = G^T (G G^T)^{-1} e, an estimate of ||P F P||, and the primal
!> map u = K^+ (f - B^T lambda) + R alpha that the reconstruction uses.
!>
!> Dual vectors: the multipliers this rank owns (length con%n_own).
!> Coarse vectors: the 6-blocks of this rank's subdomains (length 6*nlocal),
!> in the order of dec%local_subdomains (see coarse_problem).
!> Work arrays are allocated once in `setup`; the operators allocate nothing.
!>
!> `setup` is the builder (mesh, assembly, K^+, B and G, coarse problem, d, e,
!> lambda~, ||P F P||). All components are private: the layers above (the
!> dual problem, the reconstruction, the KKT check, the output) use the
!> operators and the accessors below, never the data behind them.
module feti_operators
  use kinds, only: dp, ip, i8, MPI_REAL_DP, MPI_INT_I8
  use logger, only: log_message
  use timers, only: timer_start, timer_stop
  use params, only: params_t
  use decomposition, only: decomposition_t, build_decomposition
  use subdomain, only: subdomain_t, build_subdomain
  use assembly, only: assemble_subdomain
  use box_mesh, only: box_mesh_t
  use local_inverse, only: local_inverse_t
  use kplus_block, only: kplus_block_t
  use kplus_set, only: kplus_set_t
  use constraints, only: constraints_t, build_constraints, row_contact
  use coarse_problem, only: coarse_problem_t, coarse_layout_t, build_coarse_layout
  use orthonormal_coarse, only: orthonormal_coarse_t
  use mpi_f08, only: MPI_Comm, MPI_Allreduce, MPI_SUM
  implicit none
  private

  !> One vector per local subdomain (displacements, loads).
  type, public :: local_field_t
    real(dp), allocatable :: v(:)
  end type local_field_t

  !> Sizes of the decomposition and of the dual problem (all ranks).
  type, public :: feti_sizes_t
    integer(ip) :: nsubdomains = 0, coarse_dim = 0
    integer(i8) :: primal_dofs = 0
    integer(ip) :: dual_dofs = 0, gluing_rows = 0, dirichlet_rows = 0, contact_rows = 0
  end type feti_sizes_t

  type, public :: feti_t
    private
    type(MPI_Comm) :: communicator
    type(decomposition_t) :: dec
    type(subdomain_t), allocatable :: subs(:)
    class(local_inverse_t), allocatable :: kinv  !< K^+ of all local subdomains (&solver local_solver)
    integer(ip), allocatable :: offset(:)        !< (nlocal+1) dof offsets in concatenated local vectors
    type(constraints_t) :: con                   !< B, c and G^T = B R (build_constraints)
    type(coarse_layout_t) :: layout
    type(coarse_problem_t) :: coarse             !< (G G^T)^{-1}
    integer(ip) :: n_local_subs = 0              !< subdomains of this rank
    integer(i8) :: n_primal_dofs = 0             !< sum of subdomain dofs, all ranks
    real(dp), allocatable :: d(:)                !< (n_own) B K^+ f - c
    real(dp), allocatable :: lambda_tilde(:)     !< (n_own) G^T (G G^T)^{-1} e
    real(dp), allocatable :: lower(:)            !< (n_own) bounds of nu: -lambda~ on contact rows
    logical, allocatable :: contact(:)           !< (n_own) the row is a contact row
    real(dp), allocatable :: e(:)                !< (6*nlocal) R^T f
    real(dp) :: pfp_norm = 0                     !< estimate of ||P F P||
    integer(i8) :: n_f_applications = 0, n_coarse_solves = 0
    ! work space
    real(dp), allocatable :: wloc(:), wloc2(:), xall(:), cwork(:), cwork2(:)
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
    procedure :: apply_abs_b
    procedure :: estimate_norm_pfp
    procedure :: local_solve
    procedure :: bytes_per_f_action
    procedure, private :: add_bt
    procedure, private :: b_times
    procedure :: keyed_random
    procedure :: init_active_coarse
    procedure :: init_orthonormal
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
    procedure :: norm_pfp
    procedure :: f_applications
    procedure :: coarse_solves
    procedure :: free
  end type feti_t

contains

  !> Everything before the dual solve: decomposition, subdomains, K^+, B, G,
  !> the coarse problem, d, e, lambda~ and ||P F P||. Collective over `comm`.
  subroutine setup(this, p, comm)
    class(feti_t), intent(inout) :: this
    type(params_t), intent(in) :: p
    type(MPI_Comm), intent(in) :: comm
    integer(ip) :: ls
    integer :: ierr
    integer(i8) :: mydofs

    call this%free()
    this%communicator = comm

    call timer_start('mesh')
    call build_decomposition(p, comm, this%dec)
    this%n_local_subs = size(this%dec%local_subdomains, kind=ip)
    allocate (this%subs(this%n_local_subs))
    do ls = 1, this%n_local_subs
      call build_subdomain(this%dec, this%dec%local_subdomains(ls), this%subs(ls))
    end do
    call timer_stop('mesh')

    call timer_start('assembly')
    do ls = 1, this%n_local_subs
      call assemble_subdomain(p, this%dec, this%subs(ls))
    end do
    call timer_stop('assembly')

    allocate (this%offset(this%n_local_subs + 1))
    this%offset(1) = 0
    do ls = 1, this%n_local_subs
      this%offset(ls + 1) = this%offset(ls) + this%subs(ls)%ndof
    end do
    call timer_start('factorization')
    if (p%solver%local_solver == 'block') then
      allocate (kplus_block_t :: this%kinv)
    else
      allocate (kplus_set_t :: this%kinv)
    end if
    call this%kinv%init(this%subs, p%solver%regularization, p%solver%local_ordering)
    call timer_stop('factorization')

    call timer_start('B and G')
    call build_constraints(p, this%dec, this%subs, comm, this%con)
    mydofs = this%offset(this%n_local_subs + 1)
    call MPI_Allreduce(mydofs, this%n_primal_dofs, 1, MPI_INT_I8, MPI_SUM, comm, ierr)
    allocate (this%wloc(this%con%n_local), this%wloc2(this%con%n_local), &
              this%xall(this%offset(this%n_local_subs + 1)), this%cwork(6*this%n_local_subs), this%cwork2(6*this%n_local_subs))
    call timer_stop('B and G')

    call timer_start('coarse setup')
    call build_coarse_layout(this%dec, comm, this%layout)
    call this%coarse%init(this%dec, this%con, this%layout, comm, placement=p%solver%coarse_placement)
    call timer_stop('coarse setup')

    call timer_start('dual setup')
    associate (n => this%con%n_own)
      allocate (this%d(n), this%lambda_tilde(n), this%lower(n), this%contact(n), this%e(6*this%n_local_subs))
      ! d = B K^+ f - c, e = R^T f
      do ls = 1, this%n_local_subs
        this%xall(this%offset(ls) + 1:this%offset(ls + 1)) = this%subs(ls)%f
        this%e(6*ls - 5:6*ls) = matmul(this%subs(ls)%f, this%subs(ls)%R)
      end do
      call this%local_solve(this%xall)
      call this%b_times(this%xall, this%wloc2)
      call this%con%exchange%scatter_add(this%wloc2, this%d)
      this%d = this%d - this%con%c
      ! lambda~ = G^T (G G^T)^{-1} e
      call this%coarse_solve(this%e, this%cwork2)
      call this%apply_gt(this%cwork2, this%lambda_tilde)
      this%contact = this%con%kind == row_contact
      this%lower = -huge(1.0_dp)
      where (this%contact) this%lower = -this%lambda_tilde
    end associate
    call this%estimate_norm_pfp(p%solver%power_iterations)
    call timer_stop('dual setup')
  end subroutine setup

  !> y = F x = B K^+ B^T x.
  subroutine apply_f(this, x, y)
    class(feti_t), intent(inout) :: this
    real(dp), intent(in) :: x(:)
    real(dp), intent(inout) :: y(:)

    call timer_start('F action')
    call this%con%exchange%gather(x, this%wloc)
    this%xall = 0
    call this%add_bt(this%wloc, 1.0_dp, this%xall)
    call this%local_solve(this%xall)
    call this%b_times(this%xall, this%wloc2)
    call this%con%exchange%scatter_add(this%wloc2, y)
    this%n_f_applications = this%n_f_applications + 1
    call timer_stop('F action')
  end subroutine apply_f

  !> z = G x (local coarse blocks).
  subroutine apply_g(this, x, z)
    class(feti_t), intent(inout) :: this
    real(dp), intent(in) :: x(:)
    real(dp), intent(out) :: z(:)
    integer(ip) :: ls, e
    call this%con%exchange%gather(x, this%wloc)
    do ls = 1, this%n_local_subs
      z(6*ls - 5:6*ls) = 0
      associate (bs => this%con%b(ls))
        do e = 1, bs%nentries
          z(6*ls - 5:6*ls) = z(6*ls - 5:6*ls) + bs%g(:, e)*this%wloc(bs%row(e))
        end do
      end associate
    end do
  end subroutine apply_g

  !> y = G^T z for local coarse blocks z.
  subroutine apply_gt(this, z, y)
    class(feti_t), intent(inout) :: this
    real(dp), intent(in) :: z(:)
    real(dp), intent(inout) :: y(:)
    integer(ip) :: ls, e
    this%wloc2 = 0
    do ls = 1, this%n_local_subs
      associate (bs => this%con%b(ls))
        do e = 1, bs%nentries
          this%wloc2(bs%row(e)) = this%wloc2(bs%row(e)) + dot_product(bs%g(:, e), z(6*ls - 5:6*ls))
        end do
      end associate
    end do
    call this%con%exchange%scatter_add(this%wloc2, y)
  end subroutine apply_gt

  !> x = (G G^T)^{-1} b on local coarse blocks.
  subroutine coarse_solve(this, b, x)
    class(feti_t), intent(inout) :: this
    real(dp), intent(in) :: b(:)
    real(dp), intent(out) :: x(:)
    call timer_start('coarse solve')
    call this%coarse%solve(b, x)
    this%n_coarse_solves = this%n_coarse_solves + 1
    call timer_stop('coarse solve')
  end subroutine coarse_solve

  !> y = P x = x - G^T (G G^T)^{-1} G x (y may not be x); optionally also
  !> G x and (G G^T)^{-1} G x, which the dual problem keeps (see dual_problem).
  subroutine project(this, x, y, gx, zx)
    class(feti_t), intent(inout) :: this
    real(dp), intent(in) :: x(:)
    real(dp), intent(inout) :: y(:)
    real(dp), intent(out), optional :: gx(:), zx(:)   !< G x and (G G^T)^{-1} G x on the way
    call this%apply_g(x, this%cwork)
    call this%coarse_solve(this%cwork, this%cwork2)
    call this%apply_gt(this%cwork2, y)
    y = x - y
    if (present(gx)) gx = this%cwork
    if (present(zx)) zx = this%cwork2
  end subroutine project

  !> Global dot product of dual vectors.
  real(dp) function dot(this, x, y)
    class(feti_t), intent(in) :: this
    real(dp), intent(in) :: x(:), y(:)
    real(dp) :: mine
    integer :: ierr
    mine = dot_product(x(1:this%con%n_own), y(1:this%con%n_own))
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
    integer(ip) :: ls
    call this%con%exchange%gather(lambda, this%wloc)
    do ls = 1, this%n_local_subs
      this%xall(this%offset(ls) + 1:this%offset(ls + 1)) = this%subs(ls)%f
    end do
    call this%add_bt(this%wloc, -1.0_dp, this%xall)
    call this%local_solve(this%xall)
    do ls = 1, this%n_local_subs
      if (.not. allocated(u(ls)%v)) allocate (u(ls)%v(this%subs(ls)%ndof))
      u(ls)%v = this%xall(this%offset(ls) + 1:this%offset(ls + 1)) + matmul(this%subs(ls)%R, alpha(6*ls - 5:6*ls))
    end do
  end subroutine primal

  !> Bytes one F action must read on this rank: the factors of K_reg twice
  !> (forward and backward substitution) and the entries of B twice (B^T,
  !> then B; 16 bytes each: value, row, dof). Vectors are not counted.
  integer(i8) function bytes_per_f_action(this)
    class(feti_t), intent(in) :: this
    integer(ip) :: ls
    integer(i8) :: factors, entries
    factors = this%kinv%factor_bytes()
    entries = 0
    do ls = 1, this%n_local_subs
      entries = entries + this%con%b(ls)%nentries
    end do
    bytes_per_f_action = 2*factors + 2*16*entries
  end function bytes_per_f_action

  !> x <- K^+ x for the concatenated vector of all local subdomains.
  subroutine local_solve(this, x)
    class(feti_t), intent(inout) :: this
    real(dp), intent(inout) :: x(:)
    call this%kinv%solve(x)
  end subroutine local_solve

  !> u^s = B^s^T x for every local subdomain.
  subroutine apply_bt(this, x, u)
    class(feti_t), intent(inout) :: this
    real(dp), intent(in) :: x(:)
    type(local_field_t), intent(inout) :: u(:)
    integer(ip) :: ls
    call this%con%exchange%gather(x, this%wloc)
    this%xall = 0
    call this%add_bt(this%wloc, 1.0_dp, this%xall)
    do ls = 1, this%n_local_subs
      u(ls)%v = this%xall(this%offset(ls) + 1:this%offset(ls + 1))
    end do
  end subroutine apply_bt

  !> y = B u = sum over subdomains of B^s u^s (owned rows).
  subroutine apply_b(this, u, y)
    class(feti_t), intent(inout) :: this
    type(local_field_t), intent(in) :: u(:)
    real(dp), intent(inout) :: y(:)
    integer(ip) :: ls
    do ls = 1, this%n_local_subs
      this%xall(this%offset(ls) + 1:this%offset(ls + 1)) = u(ls)%v
    end do
    call this%b_times(this%xall, this%wloc2)
    call this%con%exchange%scatter_add(this%wloc2, y)
  end subroutine apply_b

  !> xall += scale * B^T lam_local on the concatenated local subdomain vector.
  subroutine add_bt(this, lam_local, scale, xall)
    class(feti_t), intent(in) :: this
    real(dp), intent(in) :: lam_local(:), scale
    real(dp), intent(inout) :: xall(:)
    integer(ip) :: ls, e
    do ls = 1, this%n_local_subs
      associate (bs => this%con%b(ls), o => this%offset(ls))
        do e = 1, bs%nentries
          xall(o + bs%dof(e)) = xall(o + bs%dof(e)) + scale*bs%val(e)*lam_local(bs%row(e))
        end do
      end associate
    end do
  end subroutine add_bt

  !> y_local = B xall (local rows: owned and ghosts, before the scatter-add).
  subroutine b_times(this, xall, y_local)
    class(feti_t), intent(in) :: this
    real(dp), intent(in) :: xall(:)
    real(dp), intent(out) :: y_local(:)
    integer(ip) :: ls, e
    y_local = 0
    do ls = 1, this%n_local_subs
      associate (bs => this%con%b(ls), o => this%offset(ls))
        do e = 1, bs%nentries
          y_local(bs%row(e)) = y_local(bs%row(e)) + bs%val(e)*xall(o + bs%dof(e))
        end do
      end associate
    end do
  end subroutine b_times

  !> A dual vector with entries in [-1, 1] that depend only on the rows'
  !> canonical keys, so that it is the same on any number of ranks.
  subroutine keyed_random(this, seed, x)
    class(feti_t), intent(in) :: this
    integer, intent(in) :: seed
    real(dp), intent(out) :: x(:)
    integer(ip) :: i
    integer(i8) :: h
    do i = 1, this%con%n_own
      h = mix(this%con%key(i) + 1000003_i8*seed)
      x(i) = real(mod(h, 2000001_i8), dp)/1000000.0_dp - 1
    end do
  contains
    pure integer(i8) function mix(k)
      integer(i8), intent(in) :: k
      integer(i8) :: z
      z = ieor(k, ishft(k, -13))
      z = mod(abs(z)*48271_i8, 2147483647_i8)
      z = mod(z*48271_i8 + 12345_i8, 2147483647_i8)
      mix = mod(z*16807_i8, 2147483647_i8)
    end function mix
  end subroutine keyed_random

  !> ||P F P|| by the power method on Im P, from a keyed random start. It
  !> stops when the estimate changes by less than 1e-3 relative or after
  !> `max_iterations`. The estimate is ||P F P x|| for the last unit x, a lower
  !> bound that converges from below; it only scales the dual problem and sets
  !> the MPRGP step 1.9/||A||, which tolerates an underestimate of 5%.
  subroutine estimate_norm_pfp(this, max_iterations)
    class(feti_t), intent(inout) :: this
    integer(ip), intent(in) :: max_iterations
    real(dp), allocatable :: x(:), y(:), z(:)
    real(dp) :: previous, nrm
    integer(ip) :: it
    character(len=100) :: line
    allocate (x(this%con%n_own), y(this%con%n_own), z(this%con%n_own))
    call this%keyed_random(7, z)
    call this%project(z, x)
    nrm = this%norm(x)
    this%pfp_norm = 0
    if (nrm == 0) return
    x = x/nrm
    previous = 0
    do it = 1, max_iterations
      call this%apply_f(x, z)
      call this%project(z, y)            ! y = P F P x, since P x = x
      nrm = this%norm(y)
      if (nrm == 0) exit
      x = y/nrm
      this%pfp_norm = nrm
      if (abs(nrm - previous) <= 1.0e-3_dp*nrm) exit
      previous = nrm
    end do
    write (line, '(a,es12.5,a,i0,a)') '||P F P|| ~ ', this%pfp_norm, ' (power method, ', min(it, max_iterations), &
      ' iterations)'
    call log_message(line)
  end subroutine estimate_norm_pfp

  !> y = |B| |u|: the size of the terms of each row of B u (owned rows).
  subroutine apply_abs_b(this, absu, y)
    class(feti_t), intent(inout) :: this
    type(local_field_t), intent(in) :: absu(:)
    real(dp), intent(inout) :: y(:)
    integer(ip) :: ls, e
    this%wloc2 = 0
    do ls = 1, this%n_local_subs
      associate (bs => this%con%b(ls))
        do e = 1, bs%nentries
          this%wloc2(bs%row(e)) = this%wloc2(bs%row(e)) + abs(bs%val(e))*absu(ls)%v(bs%dof(e))
        end do
      end associate
    end do
    call this%con%exchange%scatter_add(this%wloc2, y)
  end subroutine apply_abs_b

  !> (G_A G_A^T) assembled and factorized anew for the rows in `mask` (the
  !> standard reconstruction, Eq. 10). Collective.
  subroutine init_active_coarse(this, cp, mask)
    class(feti_t), intent(inout) :: this
    type(coarse_problem_t), intent(inout) :: cp
    logical, intent(in) :: mask(:)
    call cp%init(this%dec, this%con, this%layout, this%communicator, mask)
  end subroutine init_active_coarse

  !> The explicit G~ = L^{-1} G of `&solver coarse = 'cholesky'`. Collective.
  subroutine init_orthonormal(this, orth)
    class(feti_t), intent(inout) :: this
    type(orthonormal_coarse_t), intent(inout) :: orth
    call orth%init(this%dec, this%con, this%layout, this%communicator)
  end subroutine init_orthonormal

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
    n_own = this%con%n_own
  end function n_own

  !> Length of a vector of local coarse blocks on this rank (6 per subdomain).
  integer(ip) function n_coarse(this)
    class(feti_t), intent(in) :: this
    n_coarse = 6*this%n_local_subs
  end function n_coarse

  type(feti_sizes_t) function sizes(this)
    class(feti_t), intent(in) :: this
    sizes%nsubdomains = this%dec%nsubdomains
    sizes%coarse_dim = 6*this%dec%nsubdomains
    sizes%primal_dofs = this%n_primal_dofs
    sizes%dual_dofs = this%con%n_global
    sizes%gluing_rows = this%con%n_gluing_global
    sizes%dirichlet_rows = this%con%n_dirichlet_global
    sizes%contact_rows = this%con%n_contact_global
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
    v = this%con%scale
  end function force_scale

  !> c, the right-hand side of B u <= c (owned rows).
  function gap_rhs(this) result(v)
    class(feti_t), intent(in) :: this
    real(dp), allocatable :: v(:)
    v = this%con%c
  end function gap_rhs

  !> Canonical keys of the owned rows (the same on any number of ranks).
  function row_keys(this) result(v)
    class(feti_t), intent(in) :: this
    integer(i8), allocatable :: v(:)
    v = this%con%key(1:this%con%n_own)
  end function row_keys

  !> Global id of owned row i: row_offset() + i.
  integer(ip) function row_offset(this)
    class(feti_t), intent(in) :: this
    row_offset = this%con%offset
  end function row_offset

  !> Node gid of each owned row.
  function row_node_gid(this) result(v)
    class(feti_t), intent(in) :: this
    integer(ip), allocatable :: v(:)
    v = this%con%node
  end function row_node_gid

  !> Coordinates (3, n_own) of the node of each owned row.
  function row_coordinates(this) result(x)
    class(feti_t), intent(in) :: this
    real(dp), allocatable :: x(:, :)
    integer(ip) :: i
    allocate (x(3, this%con%n_own))
    do i = 1, this%con%n_own
      x(:, i) = this%subs(this%con%row_sub(i))%coords(:, this%con%row_node(i))
    end do
  end function row_coordinates

  real(dp) function norm_pfp(this)
    class(feti_t), intent(in) :: this
    norm_pfp = this%pfp_norm
  end function norm_pfp

  integer(i8) function f_applications(this)
    class(feti_t), intent(in) :: this
    f_applications = this%n_f_applications
  end function f_applications

  integer(i8) function coarse_solves(this)
    class(feti_t), intent(in) :: this
    coarse_solves = this%n_coarse_solves
  end function coarse_solves

  subroutine free(this)
    class(feti_t), intent(inout) :: this
    if (allocated(this%kinv)) then
      call this%kinv%free()
      deallocate (this%kinv)
    end if
    if (allocated(this%offset)) deallocate (this%offset)
    if (allocated(this%subs)) deallocate (this%subs)
    call this%coarse%free()
    call this%con%exchange%free()
    if (allocated(this%d)) deallocate (this%d, this%lambda_tilde, this%lower, this%contact, this%e)
    if (allocated(this%wloc)) deallocate (this%wloc, this%wloc2, this%xall, this%cwork, this%cwork2)
    this%n_f_applications = 0
    this%n_coarse_solves = 0
  end subroutine free
end module feti_operators
