!> The TFETI dual contact problem of the paper, Eq. (8), as a QP:
!>
!>   min 1/2 nu^T (P F P + rho Q) nu - nu^T P (d - F lambda~)
!>   s.t. nu_I >= -lambda~_I  and  G~ nu = o,  G~ = L^{-1} G,  G G^T = L L^T,
!>
!> with lambda = nu + lambda~. The equality constraint is given in "hat" form
!> (see qp_problem): z = (G G^T)^{-1} G nu, ||G~ nu||^2 = (G nu)^T z and
!> G~^T mu = G^T muhat with muhat = L^{-T} mu, so the factor L is never needed.
!> The multiplier vector is distributed like the coarse vectors (the 6-blocks
!> of this rank's subdomains); SMALBE only scales and adds it.
!>
!> Scaling: the QP handed to the solver is the one above divided by
!> s = ||P F P|| (Hessian A/s, linear term b/s, penalty rho/s), so that its
!> Hessian has norm ~1 and the projected gradient and ||G~ nu|| are measured in
!> the same units (multipliers); without it the SMALBE stopping test compares a
!> displacement with a force. The minimizer nu is the same; the multiplier of
!> the scaled problem is muhat/s, and `unscaled_multiplier` gives muhat back.
!>
!> Preconditioner (`&solver preconditioner` 'lumped' | 'dirichlet', set by
!> set_preconditioner): with M^{-1} of dual_preconditioner (an approximate
!> inverse of F), the scaled Hessian A = (P F P + rho Q)/s gets
!>
!>     M_A^{-1} = s P M^{-1} P + (sigma/rho') Q,   rho' = rho/s = penalty(),
!>
!> so that M_A^{-1} A = P M^{-1} P F P + sigma Q: the spectrum of the FETI
!> preconditioned operator on Im P (about [1, C (1 + log H/h)^2] for
!> Dirichlet) and sigma = 1 on Im Q = Im G~^T, at the bottom of that
!> interval (docs/THEORY.md "Preconditioned MPRGP"). Two projections and one
!> M^{-1} per application; MPRGP uses it in the face only.
!>
!> 'auto' (set_preconditioner with a switch threshold kappa_s): M^{-1} starts
!> as 'lumped'; MPRGP reports the running Ritz estimate of the condition of
!> R_F M_A^{-1} R_F A after every preconditioned CG step
!> (the part prec: condition; the same on every rank), and the first
!> time it exceeds kappa_s the Dirichlet M^{-1} is set up (once) and used
!> from then on (MPRGP restarts its CG direction). `switch_at` is the count
!> of Hessian products (hessian and face_operator calls) at the switch,
!> -1 if none (docs/THEORY.md "Adaptive preconditioner").
!>
!> Stopping test: the projected gradient is (up to the factor 1/s) minus the
!> constraint violation B u - c of the displacements that the current
!> multipliers reconstruct (projected on the free rows), row i being
!> con%unit(i) times a displacement. With stop_weight = 1/con%unit, SMALBE's
!> per-component test bounds the largest violation in displacement units (jump
!> between copies, Dirichlet error, penetration) by tol times the
!> displacements of the data (stop_scale; docs/THEORY.md "Stopping test").
module dual_problem
  use kinds, only: dp, ip, i8, MPI_REAL_DP
  use errors, only: fatal_error
  use qp_problem, only: qp_problem_t, no_lower_bound
  use qp_equality, only: qp_equality_t, moved_other, moved_to_argument, moved_along_argument
  use qp_preconditioner, only: qp_preconditioner_t
  use qp_face, only: qp_face_t
  use feti_operators, only: feti_t, local_field_t
  use subdomain, only: subdomain_t, stiffness_max_abs
  use reconstruction, only: alpha_new, active_coarse_solve
  use coarse_problem, only: coarse_problem_t
  use dual_preconditioner, only: dual_preconditioner_t
  use mpi_f08, only: MPI_Allreduce, MPI_SUM, MPI_MAX, MPI_IN_PLACE, MPI_LAND, MPI_LOGICAL
  use timers, only: timer_start, timer_stop
  use logger, only: log_message
  implicit none
  private

  type, extends(qp_problem_t), public :: dual_problem_t
    type(feti_t), pointer :: op => null()
    real(dp) :: rho = 0                       !< penalty (regularization) of Eq. (8), unscaled
    real(dp) :: scale = 1                     !< s = ||P F P||: the QP is Eq. (8) divided by s
    real(dp), allocatable, private :: px(:), fpx(:), pfpx(:)
    !> G v and (G G^T)^{-1} G v of the last Hessian argument v (from its
    !> projection), and the same for the iterate x while the solver keeps them
    !> up to date (track_*): then eq_residual costs no coarse solve.
    real(dp), allocatable, private :: last_g(:), last_z(:), x_g(:), x_z(:)
    logical, private :: last_valid = .false., x_valid = .false.
    !> smallest force scale / E of eq_measure: the forces a displacement of the
    !> data's size makes, max_s max|K_s| / E_s x (stop_scale s)
    real(dp), private :: force_floor = 0
    type(dual_preconditioner_t) :: m_inv       !< M^{-1} (when use_prec)
    logical :: use_prec = .false.
    real(dp) :: prec_q_weight = 1              !< sigma: M_A^{-1} A = sigma on Im Q
    !> 'auto': lumped until the face condition estimate exceeds switch_kappa
    logical :: auto_mode = .false.             !< set_preconditioner was asked for 'auto'
    real(dp) :: switch_kappa = 0               !< the threshold kappa_s ('auto')
    real(dp), allocatable, private :: prec_weights(:)
    integer(ip) :: n_products = 0              !< hessian + face_operator calls since init
    integer(ip) :: switch_at = -1              !< n_products at the switch to 'dirichlet', -1: none
    real(dp) :: switch_estimate = 0            !< the estimate that triggered it
    real(dp), allocatable, private :: wp(:), wq(:), wm(:)
    !> G_F G_F^T of SMALBE's face solve (F: equality rows and free contact
    !> rows): the FETI operators' reusable masked instance (one MUMPS analysis
    !> per run, a numerical factorization per face; feti_t%masked_coarse)
    type(coarse_problem_t), pointer, private :: face_cp => null()
    logical, private :: face_ready = .false.
    !> the last face built (its free rows), its matrices and the masked instance's change count then:
    !> the same face again, the instance unchanged since, reuses them (a load history whose active
    !> set stays)
    type(coarse_problem_t), pointer, private :: face_kept => null()
    logical, allocatable, private :: face_mask(:)
    integer(i8), private :: face_masked_count = -1
    logical, private :: stop_violation = .true.   !< &solver stopping = 'violation'
  contains
    procedure :: init
    procedure :: prepare
    procedure :: form_rhs
    procedure :: apply_projector
    procedure :: hessian
    procedure :: penalty
    procedure :: set_penalty
    procedure :: eq_size
    procedure :: eq_residual
    procedure :: eq_apply_t
    procedure :: eq_measure
    procedure :: track_last
    procedure :: track_step
    procedure :: track_reset
    procedure :: make_parts
    procedure :: unscaled_multiplier
    procedure :: set_preconditioner
    procedure :: has_preconditioner
    procedure :: precondition
    procedure :: preconditioner_name
    procedure :: watches_condition
    procedure :: condition_estimate
    procedure :: has_face_solver
    procedure :: face_always_regular
    procedure :: face_init
    procedure :: face_coefficient
    procedure :: face_free
    procedure :: face_operator
    procedure :: face_lazy
    procedure :: face_operator_lazy
    procedure :: eq_range_coefficient
    procedure :: face_precondition
    procedure :: hessian_norm
    procedure :: refined_norm
    procedure :: alpha_bar
    procedure :: free
  end type dual_problem_t

  !> The parts of the QP (qp_problem: eq, prec, face) that the dual problem
  !> hands the solvers: each forwards to the procedures of its owner of the
  !> same role (the owner, a target, outlives them: its free releases them).
  type, extends(qp_equality_t) :: dual_equality_t
    class(dual_problem_t), pointer :: owner => null()
  contains
    procedure :: size => eq_part_size
    procedure :: residual => eq_part_residual
    procedure :: apply_t => eq_part_apply_t
    procedure :: penalty => eq_part_penalty
    procedure :: set_penalty => eq_part_set_penalty
    procedure :: measure => eq_part_measure
    procedure :: moved => eq_part_moved
  end type dual_equality_t

  type, extends(qp_preconditioner_t) :: dual_m_inverse_t
    class(dual_problem_t), pointer :: owner => null()
  contains
    procedure :: apply => prec_part_apply
    procedure :: watches => prec_part_watches
    procedure :: condition => prec_part_condition
  end type dual_m_inverse_t

  type, extends(qp_face_t) :: dual_face_t
    class(dual_problem_t), pointer :: owner => null()
  contains
    procedure :: init => face_part_init
    procedure :: coefficient => face_part_coefficient
    procedure :: apply => face_part_apply
    procedure :: release => face_part_release
    procedure :: precondition => face_part_precondition
    procedure :: regular => face_part_regular
    procedure :: lazy => face_part_lazy
    procedure :: apply_lazy => face_part_apply_lazy
    procedure :: range_coefficient => face_part_range_coefficient
  end type dual_face_t

contains

  !> The problem of `op` (set up) with rho = rho_scale * ||P F P||.
  !> `stopping`: &solver stopping, 'violation' (default) or 'norm'.
  subroutine init(self, op, rho_scale, stopping)
    class(dual_problem_t), intent(inout), target :: self
    type(feti_t), intent(inout), target :: op
    real(dp), intent(in) :: rho_scale
    character(len=*), intent(in), optional :: stopping
    integer(ip) :: n
    call self%free()
    self%op => op
    n = op%n_own()
    call self%init_base(op%comm(), n)
    self%rho = rho_scale*op%norm_pfp()
    if (.not. (op%norm_pfp() > 0 .and. op%norm_pfp() < huge(1.0_dp))) &
      call fatal_error('the norm of the dual operator P F P is not a positive finite number; '// &
                       '&material young (or &mesh lengths) is probably outside what double precision can handle')
    if (.not. self%rho > 0) call fatal_error('dual_problem: &solver rho_scale gives no positive penalty')
    self%scale = op%norm_pfp()
    allocate (self%px(n), self%fpx(n), self%pfpx(n))
    allocate (self%last_g(op%n_coarse()), self%last_z(op%n_coarse()), self%x_g(op%n_coarse()), &
              self%x_z(op%n_coarse()))
    self%last_valid = .false.
    self%x_valid = .false.
    self%n_products = 0
    call self%prepare()
    self%stop_violation = .true.
    if (present(stopping)) self%stop_violation = stopping == 'violation'
    call self%make_parts()
    call self%form_rhs()
  end subroutine init

  !> The data of the QP that the right-hand sides d, lambda~ of the FETI
  !> operators give: b = P (d - F lambda~)/s, the lower bounds and the
  !> stopping scale. After init, and again after a step of a load history
  !> changed them (feti_t%set_load). Collective.
  subroutine form_rhs(self)
    class(dual_problem_t), intent(inout) :: self
    logical :: violation
    integer(ip) :: n, ls
    real(dp) :: mine
    real(dp), allocatable :: unit(:), d(:)
    logical, allocatable :: contact(:)
    type(subdomain_t), pointer :: subs(:)
    integer :: ierr
    associate (op => self%op)
    n = op%n_own()
    ! b = P (d - F lambda~)
    call op%apply_f(op%lambda_tilde_vector(), self%fpx)
    self%fpx = op%dual_rhs() - self%fpx
    call self%apply_projector(self%fpx, self%b, .false.)
    self%b = self%b/self%scale
    self%lower = merge(op%lower_bounds(), no_lower_bound, op%is_contact())
    ! &solver stopping = 'violation': the stopping test measures g^P per row
    ! in displacement units (row i of B is unit(i) x a displacement; see
    ! qp_problem and docs/THEORY.md "Stopping test")
    ! and compares it with the displacements of the data: the largest
    ! |d_i|/unit_i over the equality rows (prescribed displacements, and the
    ! jumps of the subdomains deformed by their loads, B K^+ f), in the units
    ! of the scaled QP (/s). Not max |W b|: P mixes the Dirichlet values of
    ! the stiff subdomains, sqrt(E/young) times larger, into every row.
    violation = self%stop_violation
    if (violation) then
      unit = op%row_units()
      d = op%dual_rhs()
      contact = op%is_contact()
      if (allocated(self%stop_weight)) deallocate (self%stop_weight)
      allocate (self%stop_weight(n))
      self%stop_weight = 1/unit(1:n)
      mine = 0
      if (n > 0) mine = maxval(abs(d(1:n))/unit(1:n), mask=.not. contact(1:n))
      call MPI_Allreduce(mine, self%stop_scale, 1, MPI_REAL_DP, MPI_MAX, op%comm(), ierr)
      mine = 0
      subs => op%subdomains()
      do ls = 1, op%nlocal()
        mine = max(mine, stiffness_max_abs(subs, ls)/subs(ls)%young)
      end do
      call MPI_Allreduce(mine, self%force_floor, 1, MPI_REAL_DP, MPI_MAX, op%comm(), ierr)
      self%force_floor = self%force_floor*self%stop_scale
      self%stop_scale = self%stop_scale/self%scale
      self%eq%relative_measure = .true.
    end if
    end associate
  end subroutine form_rhs

  !> y = (P F P x + rho Q x)/s, with Q x = x - P x.
  subroutine hessian(self, x, y)
    class(dual_problem_t), intent(inout) :: self
    real(dp), intent(in) :: x(:)
    real(dp), intent(out) :: y(:)
    call self%apply_projector(x, self%px, .true.)
    call self%op%apply_f(self%px, self%fpx)
    call self%apply_projector(self%fpx, self%pfpx, .false.)
    y = (self%pfpx + self%rho*(x - self%px))/self%scale
    self%n_products = self%n_products + 1
  end subroutine hessian

  !> Use M_A^{-1} built on `kind` ('lumped' | 'dirichlet' | 'auto'; 'none':
  !> no preconditioner) with the subdomain weights w_s (dual_preconditioner).
  !> 'auto' starts with 'lumped' and switches to 'dirichlet' once the face
  !> condition estimate exceeds `switch_kappa` (required with 'auto'; see
  !> the module). After init. Collective.
  subroutine set_preconditioner(self, kind, weights, switch_kappa)
    class(dual_problem_t), intent(inout), target :: self
    character(len=*), intent(in) :: kind
    real(dp), intent(in) :: weights(:)
    real(dp), intent(in), optional :: switch_kappa
    call self%m_inv%free()
    self%use_prec = kind /= 'none'
    self%auto_mode = kind == 'auto'
    self%switch_at = -1
    self%switch_estimate = 0
    if (allocated(self%prec)) deallocate (self%prec)
    if (.not. self%use_prec) return
    allocate (dual_m_inverse_t :: self%prec)
    select type (part => self%prec)
    type is (dual_m_inverse_t)
      part%owner => self
    end select
    if (self%auto_mode) then
      if (.not. present(switch_kappa)) call fatal_error("dual_problem: preconditioner 'auto' needs switch_kappa")
      if (.not. switch_kappa > 1) call fatal_error("dual_problem: switch_kappa must be > 1")
      self%switch_kappa = switch_kappa
      self%prec_weights = weights
      if (self%op%dirichlet_from_factors() .or. self%op%glued_by_faces()) then
        ! the dense local solver's factors give S_s at no set-up cost, or clusters
        ! glued by faces: shared per class they take it per block of a class at
        ! about the set-up and application cost of 'lumped', and without classes
        ! (several moduli, distorted subdomains) it saves the most products:
        ! 'dirichlet' at once (recorded as a switch at 0 products with estimate 0;
        ! the set-up's log says so)
        call self%op%init_preconditioner(self%m_inv, 'dirichlet', weights)
        self%switch_at = 0
      else
        call self%op%init_preconditioner(self%m_inv, 'lumped', weights)
      end if
    else
      call self%op%init_preconditioner(self%m_inv, kind, weights)
    end if
    if (allocated(self%wp)) deallocate (self%wp, self%wq, self%wm)
    allocate (self%wp(self%n), self%wq(self%n), self%wm(self%n))
  end subroutine set_preconditioner

  !> 'auto' before its switch: the face condition estimate is watched.
  logical function watches_condition(self)
    class(dual_problem_t), intent(in) :: self
    watches_condition = self%auto_mode .and. self%switch_at < 0
  end function watches_condition

  !> 'auto': the first time the face condition estimate kappa exceeds
  !> switch_kappa, set up the Dirichlet M^{-1} in place of the lumped one
  !> (timer 'preconditioner setup'; the log says when) and answer
  !> switched = .true.; the solver then restarts its CG direction. kappa
  !> comes from the CG coefficients, globally reduced dot products that are
  !> the same on every rank (qp_problem's correctly rounded sums, on which
  !> the solvers already branch), so every rank decides alike without a
  !> reduction of its own. Collective (the set-up).
  subroutine condition_estimate(self, kappa, switched)
    class(dual_problem_t), intent(inout) :: self
    real(dp), intent(in) :: kappa
    logical, intent(out) :: switched
    character(len=200) :: line
    switched = .false.
    if (.not. self%watches_condition()) return
    if (.not. kappa > self%switch_kappa) return
    call timer_start('preconditioner setup')
    call self%m_inv%free()
    call self%op%init_preconditioner(self%m_inv, 'dirichlet', self%prec_weights)
    call timer_stop('preconditioner setup')
    self%switch_at = self%n_products
    self%switch_estimate = kappa
    switched = .true.
    write (line, '(a,i0,a,es10.3,a,es10.3,a)') "preconditioner 'auto': lumped -> dirichlet after ", &
      self%n_products, ' Hessian products (face condition estimate ', kappa, ' > ', self%switch_kappa, ')'
    call log_message(trim(line))
  end subroutine condition_estimate

  logical function has_preconditioner(self)
    class(dual_problem_t), intent(in) :: self
    has_preconditioner = self%use_prec
  end function has_preconditioner

  !> 'none', 'lumped' or 'dirichlet'.
  function preconditioner_name(self) result(name)
    class(dual_problem_t), intent(in) :: self
    character(len=:), allocatable :: name
    name = 'none'
    if (self%use_prec) name = self%m_inv%kind()
  end function preconditioner_name

  !> z = M_A^{-1} r = s P M^{-1} P r + (sigma/rho') (r - P r) (see the
  !> module); the identity without preconditioner.
  subroutine precondition(self, r, z)
    class(dual_problem_t), intent(inout) :: self
    real(dp), intent(in) :: r(:)
    real(dp), intent(out) :: z(:)
    if (.not. self%use_prec) then
      z(1:self%n) = r(1:self%n)
      return
    end if
    call self%apply_projector(r, self%wp, .false.)
    self%wq = r(1:self%n) - self%wp
    call self%m_inv%apply(self%wp, self%wm)
    call self%apply_projector(self%wm, self%wp, .false.)
    z(1:self%n) = self%scale*self%wp + (self%prec_q_weight/self%penalty())*self%wq
  end subroutine precondition

  !> The face solver of SMALBE's polish step (qp_problem): in hat form the
  !> factor L cancels, C_F^T (C_F C_F^T)^{-1} C = G_F^T (G_F G_F^T)^{-1} G,
  !> so c = (G_F G_F^T)^{-1} G y and eq_apply_t(c) = G^T c.
  logical function has_face_solver(self)
    class(dual_problem_t), intent(in) :: self
    has_face_solver = associated(self%op)
  end function has_face_solver

  !> The equality rows (gluing, Dirichlet) give a regular G_E G_E^T when the
  !> Dirichlet rows alone fix every rigid body motion (feti_t's test).
  logical function face_always_regular(self)
    class(dual_problem_t), intent(in) :: self
    face_always_regular = .false.
    if (associated(self%op)) face_always_regular = self%op%dirichlet_fixes_rigid_modes()
  end function face_always_regular

  !> Assemble and factorize G_F G_F^T over the rows in `free` (the equality
  !> rows are always free: their lower bound is no_lower_bound), reusing the
  !> MUMPS analysis of the first face; when `free` is the face built last and
  !> the masked instance still holds it (feti_t%masked_changes), its matrices
  !> as they are (`reused`). Collective.
  subroutine face_init(self, free, reused)
    class(dual_problem_t), intent(inout) :: self
    logical, intent(in) :: free(:)
    logical, intent(out), optional :: reused
    logical :: same
    integer :: ierr
    call self%face_free()
    same = associated(self%face_kept) .and. allocated(self%face_mask)
    if (same) same = self%op%masked_changes() == self%face_masked_count
    if (same) same = all(self%face_mask .eqv. free(1:self%n))
    call MPI_Allreduce(MPI_IN_PLACE, same, 1, MPI_LOGICAL, MPI_LAND, self%comm, ierr)
    if (same) then
      self%face_cp => self%face_kept
    else
      call timer_start('face: matrices')
      self%face_cp => self%op%masked_coarse(free, low_rank=.true.)
      call timer_stop('face: matrices')
      self%face_kept => self%face_cp
      self%face_mask = free(1:self%n)
      self%face_masked_count = self%op%masked_changes()
    end if
    self%face_ready = .true.
    if (present(reused)) reused = same
  end subroutine face_init


  !> c = (G_F G_F^T)^{-1} G y (local coarse blocks). Collective.
  subroutine face_coefficient(self, y, c)
    class(dual_problem_t), intent(inout) :: self
    real(dp), intent(in) :: y(:)
    real(dp), intent(out) :: c(:)
    if (.not. self%face_ready) call fatal_error('dual_problem: face_coefficient before face_init')
    call timer_start('face: solves')
    call active_coarse_solve(self%op, self%face_cp, y, c)
    call timer_stop('face: solves')
  end subroutine face_coefficient

  !> q = P F p / s = A p for p in Ker G (P p = p, Q p = 0): the Hessian
  !> without its first projection (one coarse solve instead of two).
  subroutine face_operator(self, p, q)
    class(dual_problem_t), intent(inout) :: self
    real(dp), intent(in) :: p(:)
    real(dp), intent(out) :: q(:)
    call self%op%apply_f(p, self%fpx)
    call self%apply_projector(self%fpx, q, .false.)
    q(1:self%n) = q(1:self%n)/self%scale
    self%n_products = self%n_products + 1
  end subroutine face_operator

  !> The face solve may use face_operator_lazy wherever it polishes.
  logical function face_lazy(self)
    class(dual_problem_t), intent(in) :: self
    face_lazy = self%has_face_solver()
  end function face_lazy

  !> q = F p / s for p in Ker G: A p = P F p / s plus G^T (G G^T)^{-1} G F p / s,
  !> a term in the range of G^T (no coarse solve; face_solve takes the sum of
  !> these terms out of its gradient by eq_range_coefficient every lazy_fold
  !> steps and at the end).
  subroutine face_operator_lazy(self, p, q)
    class(dual_problem_t), intent(inout) :: self
    real(dp), intent(in) :: p(:)
    real(dp), intent(out) :: q(:)
    call self%op%apply_f(p, q)
    q(1:self%n) = q(1:self%n)/self%scale
    self%n_products = self%n_products + 1
  end subroutine face_operator_lazy

  !> c = (G G^T)^{-1} G y (local coarse blocks, the form eq_apply_t takes):
  !> G^T c is the part of y that P removes. One coarse solve. Collective.
  subroutine eq_range_coefficient(self, y, c)
    class(dual_problem_t), intent(inout) :: self
    real(dp), intent(in) :: y(:)
    real(dp), intent(out) :: c(:)
    call self%op%project(y, self%pfpx, zx=c)
  end subroutine eq_range_coefficient

  !> z = s M^{-1} r (FETI's PCPG preconditioner without the projections of
  !> M_A^{-1}; P_F follows in face_solve), r itself without preconditioner.
  subroutine face_precondition(self, r, z)
    class(dual_problem_t), intent(inout) :: self
    real(dp), intent(in) :: r(:)
    real(dp), intent(out) :: z(:)
    if (.not. self%use_prec) then
      z(1:self%n) = r(1:self%n)
      return
    end if
    call self%m_inv%apply(r, z)
    z(1:self%n) = self%scale*z(1:self%n)
  end subroutine face_precondition

  !> The face matrix is no longer used (its instance stays with the FETI
  !> operators, for the next face and the standard reconstruction).
  subroutine face_free(self)
    class(dual_problem_t), intent(inout) :: self
    self%face_cp => null()
    self%face_ready = .false.
  end subroutine face_free

  !> The QP's parts the solvers see (qp_problem): the equality constraint
  !> and, where the problem has one, the face solver (the preconditioner:
  !> set_preconditioner). `self` must stay where it is while they live.
  subroutine make_parts(self)
    class(dual_problem_t), intent(inout), target :: self
    allocate (dual_equality_t :: self%eq)
    select type (part => self%eq)
    type is (dual_equality_t)
      part%owner => self
    end select
    if (.not. self%has_face_solver()) return
    allocate (dual_face_t :: self%face)
    select type (part => self%face)
    type is (dual_face_t)
      part%owner => self
    end select
  end subroutine make_parts

  !> Extra set-up of an extension before b is formed (none here).
  subroutine prepare(self)
    class(dual_problem_t), intent(inout) :: self
  end subroutine prepare

  !> y = P x with one coarse solve; with `keep`, G x and (G G^T)^{-1} G x are
  !> kept as those of the last Hessian argument (see track_*).
  subroutine apply_projector(self, x, y, keep)
    class(dual_problem_t), intent(inout) :: self
    real(dp), intent(in) :: x(:)
    real(dp), intent(inout) :: y(:)
    logical, intent(in) :: keep
    if (keep) then
      call self%op%project(x, y, self%last_g, self%last_z)
      self%last_valid = .true.
    else
      call self%op%project(x, y)
    end if
  end subroutine apply_projector

  !> x is now the argument of the last Hessian product.
  subroutine track_last(self)
    class(dual_problem_t), intent(inout) :: self
    self%x_valid = self%last_valid
    if (self%x_valid) then
      self%x_g = self%last_g
      self%x_z = self%last_z
    end if
  end subroutine track_last

  !> x moved to x - alpha v, v the argument of the last Hessian product.
  subroutine track_step(self, alpha)
    class(dual_problem_t), intent(inout) :: self
    real(dp), intent(in) :: alpha
    if (.not. (self%x_valid .and. self%last_valid)) then
      self%x_valid = .false.
      return
    end if
    self%x_g = self%x_g - alpha*self%last_g
    self%x_z = self%x_z - alpha*self%last_z
  end subroutine track_step

  !> x changed in a way the tracking cannot follow.
  subroutine track_reset(self)
    class(dual_problem_t), intent(inout) :: self
    self%x_valid = .false.
  end subroutine track_reset

  !> The penalty of the scaled QP: rho/s.
  real(dp) function penalty(self)
    class(dual_problem_t), intent(in) :: self
    penalty = self%rho/self%scale
  end function penalty

  !> Set the penalty of the scaled QP to rho (that of Eq. (8): rho s), e.g.
  !> when SMALBE raises it; hessian_norm follows.
  subroutine set_penalty(self, rho)
    class(dual_problem_t), intent(inout) :: self
    real(dp), intent(in) :: rho
    if (.not. rho > 0) call fatal_error('dual_problem: set_penalty needs rho > 0')
    self%rho = rho*self%scale
  end subroutine set_penalty

  !> ||A|| of the scaled QP, for the MPRGP step length: P F P and rho Q act on
  !> complementary subspaces, so ||A|| = max(||P F P||, rho)/s.
  real(dp) function hessian_norm(self)
    class(dual_problem_t), intent(in) :: self
    hessian_norm = max(self%op%norm_pfp(), self%rho)/self%scale
  end function hessian_norm

  !> ||A|| with the Lanczos estimate of ||P F P|| continued to its stopping
  !> rule (feti_t%refine_norm_pfp; set-up made its first steps only, whose
  !> value is the scale s). Collective.
  real(dp) function refined_norm(self)
    class(dual_problem_t), intent(inout) :: self
    call self%op%refine_norm_pfp()
    refined_norm = self%hessian_norm()
  end function refined_norm

  !> The rigid body amplitudes by the new formula for this form of the
  !> equality constraint, from the dual gradient g and the multiplier of the
  !> scaled QP: Eq. 24, alpha_bar = (G G^T)^{-1} G g - muhat (hat form; the
  !> explicit G~ overrides it with Eq. 25).
  subroutine alpha_bar(self, g, mu_scaled, alpha)
    class(dual_problem_t), intent(inout) :: self
    real(dp), intent(in) :: g(:), mu_scaled(:)
    real(dp), intent(out) :: alpha(:)
    call alpha_new(self%op, g, self%unscaled_multiplier(mu_scaled), alpha)
  end subroutine alpha_bar

  !> muhat of Eq. (8) from the multiplier of the scaled QP.
  function unscaled_multiplier(self, muhat_scaled) result(muhat)
    class(dual_problem_t), intent(in) :: self
    real(dp), intent(in) :: muhat_scaled(:)
    real(dp) :: muhat(size(muhat_scaled))
    muhat = self%scale*muhat_scaled
  end function unscaled_multiplier

  !> Length of this rank's part of the multiplier: 6 per local subdomain.
  integer(ip) function eq_size(self)
    class(dual_problem_t), intent(in) :: self
    eq_size = self%op%n_coarse()
  end function eq_size

  !> z = (G G^T)^{-1} G x and cnorm = ||G~ x|| = sqrt((G x)^T z); from the
  !> tracked values when the solver kept them up to date, else one coarse solve.
  subroutine eq_residual(self, x, z, cnorm)
    class(dual_problem_t), intent(inout) :: self
    real(dp), intent(in) :: x(:)
    real(dp), intent(out) :: z(:)
    real(dp), intent(out) :: cnorm
    real(dp) :: mine, total
    integer :: ierr
    if (.not. self%x_valid) then
      call self%op%apply_g(x, self%x_g)
      call self%op%coarse_solve(self%x_g, self%x_z)
      self%x_valid = .true.
    end if
    z = self%x_z
    mine = dot_product(self%x_g, self%x_z)
    call MPI_Allreduce(mine, total, 1, MPI_REAL_DP, MPI_SUM, self%comm, ierr)
    cnorm = sqrt(max(total, 0.0_dp))
  end subroutine eq_residual

  !> C x = 0 of the per-component stopping test. G nu = R^T (B^T lambda - f)
  !> per subdomain (lambda = nu + lambda~, G lambda~ = R^T f) is the force that
  !> the subdomain's rigid modes do not balance. Its displacement effect is
  !> inversely proportional to the subdomain's Young's modulus E_s, so it is
  !> measured as max_s ||(G nu)_s|| / E_s relative to max_s F_s / E_s,
  !> F_s = max(||B_s^T lambda||, ||f_s||): a relative force imbalance for one
  !> material, in which a soft subdomain's imbalance counts as much as it moves
  !> that subdomain, and a stiff one's as little. The denominator is at least
  !> the forces a displacement of the data's size makes (max |K_s| S), so that
  !> a solution without forces (a rigid motion) compares its round-off with
  !> a force, not with round-off. One G and one B^T
  !> application (G x is computed here: an extension may keep no G x).
  real(dp) function eq_measure(self, x, cnorm)
    class(dual_problem_t), intent(inout) :: self
    real(dp), intent(in) :: x(:)
    real(dp), intent(in) :: cnorm
    type(local_field_t), allocatable :: btl(:)
    real(dp), allocatable :: lambda(:), gx(:)
    real(dp) :: mine(2), total(2)
    integer(ip) :: ls
    type(subdomain_t), pointer :: subs(:)
    integer :: ierr
    associate (op => self%op)
      allocate (btl(op%nlocal()), lambda(self%n))
      allocate (gx(op%n_coarse()))
      call op%apply_g(x, gx)
      lambda = x(1:self%n) + op%lambda_tilde_vector()
      call op%apply_bt(lambda, btl)
      mine = 0
      subs => op%subdomains()
      do ls = 1, op%nlocal()
        associate (sub => subs(ls))
          mine(1) = max(mine(1), norm2(gx(6*ls - 5:6*ls))/sub%young)
          mine(2) = max(mine(2), max(norm2(btl(ls)%v), norm2(sub%f))/sub%young)
        end associate
      end do
      call MPI_Allreduce(mine, total, 2, MPI_REAL_DP, MPI_MAX, self%comm, ierr)
    end associate
    total(2) = max(total(2), self%force_floor)
    eq_measure = 0
    if (total(2) > 0) eq_measure = total(1)/total(2)
    if (total(2) <= 0 .and. total(1) > 0) eq_measure = huge(1.0_dp)
  end function eq_measure

  !> y = G~^T mu = G^T muhat.
  subroutine eq_apply_t(self, muhat, y)
    class(dual_problem_t), intent(inout) :: self
    real(dp), intent(in) :: muhat(:)
    real(dp), intent(out) :: y(:)
    call self%op%apply_gt(muhat, y)
  end subroutine eq_apply_t

  subroutine free(self)
    class(dual_problem_t), intent(inout) :: self
    call self%free_base()
    if (allocated(self%px)) deallocate (self%px, self%fpx, self%pfpx)
    if (allocated(self%last_g)) deallocate (self%last_g, self%last_z, self%x_g, self%x_z)
    call self%m_inv%free()
    self%use_prec = .false.
    self%auto_mode = .false.
    if (allocated(self%wp)) deallocate (self%wp, self%wq, self%wm)
    call self%face_free()
    self%face_kept => null()
    self%face_masked_count = -1
    self%op => null()
  end subroutine free

  ! ---- the parts: each forwards to its owner --------------------------------

  integer(ip) function eq_part_size(self)
    class(dual_equality_t), intent(in) :: self
    eq_part_size = self%owner%eq_size()
  end function eq_part_size

  subroutine eq_part_residual(self, x, z, cnorm)
    class(dual_equality_t), intent(inout) :: self
    real(dp), intent(in) :: x(:)
    real(dp), intent(out) :: z(:)
    real(dp), intent(out) :: cnorm
    call self%owner%eq_residual(x, z, cnorm)
  end subroutine eq_part_residual

  subroutine eq_part_apply_t(self, muhat, y)
    class(dual_equality_t), intent(inout) :: self
    real(dp), intent(in) :: muhat(:)
    real(dp), intent(out) :: y(:)
    call self%owner%eq_apply_t(muhat, y)
  end subroutine eq_part_apply_t

  real(dp) function eq_part_penalty(self)
    class(dual_equality_t), intent(in) :: self
    eq_part_penalty = self%owner%penalty()
  end function eq_part_penalty

  subroutine eq_part_set_penalty(self, rho)
    class(dual_equality_t), intent(inout) :: self
    real(dp), intent(in) :: rho
    call self%owner%set_penalty(rho)
  end subroutine eq_part_set_penalty

  real(dp) function eq_part_measure(self, x, cnorm)
    class(dual_equality_t), intent(inout) :: self
    real(dp), intent(in) :: x(:)
    real(dp), intent(in) :: cnorm
    eq_part_measure = self%owner%eq_measure(x, cnorm)
  end function eq_part_measure

  !> The tracking of G x (track_*).
  subroutine eq_part_moved(self, how, alpha)
    class(dual_equality_t), intent(inout) :: self
    integer, intent(in) :: how
    real(dp), intent(in), optional :: alpha
    select case (how)
    case (moved_to_argument)
      call self%owner%track_last()
    case (moved_along_argument)
      call self%owner%track_step(alpha)
    case default
      call self%owner%track_reset()
    end select
  end subroutine eq_part_moved

  subroutine prec_part_apply(self, r, z)
    class(dual_m_inverse_t), intent(inout) :: self
    real(dp), intent(in) :: r(:)
    real(dp), intent(out) :: z(:)
    call self%owner%precondition(r, z)
  end subroutine prec_part_apply

  logical function prec_part_watches(self)
    class(dual_m_inverse_t), intent(in) :: self
    prec_part_watches = self%owner%watches_condition()
  end function prec_part_watches

  subroutine prec_part_condition(self, kappa, switched)
    class(dual_m_inverse_t), intent(inout) :: self
    real(dp), intent(in) :: kappa
    logical, intent(out) :: switched
    call self%owner%condition_estimate(kappa, switched)
  end subroutine prec_part_condition

  subroutine face_part_init(self, free, reused)
    class(dual_face_t), intent(inout) :: self
    logical, intent(in) :: free(:)
    logical, intent(out), optional :: reused
    call self%owner%face_init(free, reused)
  end subroutine face_part_init

  subroutine face_part_coefficient(self, x, y)
    class(dual_face_t), intent(inout) :: self
    real(dp), intent(in) :: x(:)
    real(dp), intent(out) :: y(:)
    call self%owner%face_coefficient(x, y)
  end subroutine face_part_coefficient

  subroutine face_part_apply(self, x, y)
    class(dual_face_t), intent(inout) :: self
    real(dp), intent(in) :: x(:)
    real(dp), intent(out) :: y(:)
    call self%owner%face_operator(x, y)
  end subroutine face_part_apply

  subroutine face_part_release(self)
    class(dual_face_t), intent(inout) :: self
    call self%owner%face_free()
  end subroutine face_part_release

  !> s M^{-1} r (face_precondition; the problem's M_A^{-1} is not used).
  subroutine face_part_precondition(self, prec, r, z)
    class(dual_face_t), intent(inout) :: self
    class(qp_preconditioner_t), intent(inout) :: prec
    real(dp), intent(in) :: r(:)
    real(dp), intent(out) :: z(:)
    call self%owner%face_precondition(r, z)
  end subroutine face_part_precondition

  logical function face_part_regular(self)
    class(dual_face_t), intent(in) :: self
    face_part_regular = self%owner%face_always_regular()
  end function face_part_regular

  logical function face_part_lazy(self)
    class(dual_face_t), intent(in) :: self
    face_part_lazy = self%owner%face_lazy()
  end function face_part_lazy

  subroutine face_part_apply_lazy(self, p, q)
    class(dual_face_t), intent(inout) :: self
    real(dp), intent(in) :: p(:)
    real(dp), intent(out) :: q(:)
    call self%owner%face_operator_lazy(p, q)
  end subroutine face_part_apply_lazy

  subroutine face_part_range_coefficient(self, y, c)
    class(dual_face_t), intent(inout) :: self
    real(dp), intent(in) :: y(:)
    real(dp), intent(out) :: c(:)
    call self%owner%eq_range_coefficient(y, c)
  end subroutine face_part_range_coefficient
end module dual_problem
