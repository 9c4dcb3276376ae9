!> Reconstruction of the displacements from the multipliers, the inverse step
!> of the dualization (paper Eq. 9):
!>
!>   u = K^+ (f - B^T lambda) + R alpha_bar.
!>
!> The rigid body amplitudes alpha_bar by two formulas (docs/THEORY.md, with a
!> right-hand side c; g = F lambda - d is the dual gradient):
!> - new (Eq. 14 + 24): alpha = (G G^T)^{-1} G g with the coarse factorization
!>   already at hand, then alpha_bar = alpha - muhat, muhat = L^{-T} mu the
!>   SMALBE multiplier in hat form: one coarse solve and a vector subtraction;
!> - standard (Eq. 10): A = equality rows + contact rows with lambda_i >
!>   active_tol * max(lambda_I); G_A G_A^T assembled anew (distributed) and
!>   factorized by MUMPS, alpha_bar = (G_A G_A^T)^{-1} G_A g_A;
!> - new with the explicit G~ = L^{-1} G (Eq. 25, &solver coarse = 'orthonormal',
!>   mu carried directly): in the orthonormalized basis R~ = R L^{-T} of the
!>   kernel (B R~ = G~^T, G~ G~^T = I) Eq. 14 reads alpha~ = G~ g (one
!>   MPI_Allreduce of 6N values) and Eq. 25 is alpha~_bar = alpha~ - mu, a
!>   subtraction; u needs the amplitudes of the subdomains' own R, alpha_bar =
!>   L^{-T} alpha~_bar: one triangular solve with the replicated factor L on
!>   every rank (no assembly, no factorization, no communication).
!>   See docs/THEORY.md, "Reconstruction".
!> Timers 'rec new' and 'rec standard'; the standard formula's parts are
!> returned in standard_cost_t (assembly, factorization, solve).
module reconstruction
  use kinds, only: dp, ip, MPI_REAL_DP, MPI_INT_IP
  use timers, only: timer_start, timer_stop
  use feti_operators, only: feti_t
  use coarse_problem, only: coarse_problem_t
  use orthonormal_coarse, only: orthonormal_coarse_t
  use mpi_f08, only: MPI_Allreduce, MPI_SUM, MPI_MAX, MPI_Wtime
  implicit none
  private

  public :: dual_gradient, active_coarse_solve, alpha_new, alpha_orthonormal, alpha_standard, active_contact_mask, &
            coarse_vector_norm

  !> Seconds of the parts of the standard formula on this rank.
  type, public :: standard_cost_t
    real(dp) :: assembly = 0, factorization = 0, solve = 0, total = 0
    integer(ip) :: active_rows = 0         !< active contact rows in all
  end type standard_cost_t

contains

  !> g = F lambda - d (owned rows). SMALBE has it at hand at its end; it is
  !> computed here once and shared by both formulas.
  subroutine dual_gradient(op, lambda, g)
    type(feti_t), intent(inout) :: op
    real(dp), intent(in) :: lambda(:)
    real(dp), intent(out) :: g(:)
    call op%apply_f(lambda, g)
    g = g - op%dual_rhs()
  end subroutine dual_gradient

  !> alpha_bar = (G G^T)^{-1} G g - muhat (Eq. 14 and 24).
  subroutine alpha_new(op, g, muhat, alpha_bar)
    type(feti_t), intent(inout) :: op
    real(dp), intent(in) :: g(:), muhat(:)
    real(dp), intent(out) :: alpha_bar(:)
    real(dp), allocatable :: gz(:)
    call timer_start('rec new')
    allocate (gz(op%n_coarse()))
    call op%apply_g(g, gz)
    call op%coarse_solve(gz, alpha_bar)
    alpha_bar = alpha_bar - muhat
    call timer_stop('rec new')
  end subroutine alpha_new

  !> Eq. 25 with the explicit G~ (orth from dual_problem_orth, mu its SMALBE
  !> multiplier, unscaled, replicated): alpha~_bar = G~ g - mu in the basis
  !> R~ = R L^{-T}, returned in `alpha_tilde_bar` (replicated, optional), and
  !> alpha_bar = L^{-T} alpha~_bar as local coarse blocks for feti_t%primal.
  subroutine alpha_orthonormal(orth, g, mu, alpha_bar, alpha_tilde_bar)
    type(orthonormal_coarse_t), intent(inout) :: orth
    real(dp), intent(in) :: g(:), mu(:)
    real(dp), intent(out) :: alpha_bar(:)
    real(dp), intent(out), optional :: alpha_tilde_bar(:)
    real(dp), allocatable :: z(:)
    call timer_start('rec new')
    allocate (z(orth%dimension()))
    call orth%apply(g, z)                 ! alpha~ = G~ g          (Eq. 14, basis R~)
    z = z - mu                            ! alpha~_bar = alpha~ - mu (Eq. 25)
    if (present(alpha_tilde_bar)) alpha_tilde_bar = z
    call orth%backward_solve(z)           ! alpha_bar = L^{-T} alpha~_bar (basis R)
    call orth%to_local(z, alpha_bar)
    call timer_stop('rec new')
  end subroutine alpha_orthonormal

  !> The rows of A: every equality row, and the contact rows whose multiplier
  !> exceeds active_tol times the largest contact multiplier.
  subroutine active_contact_mask(op, lambda, active_tol, mask, nactive_contact)
    type(feti_t), intent(inout) :: op
    real(dp), intent(in) :: lambda(:)
    real(dp), intent(in) :: active_tol
    logical, intent(out) :: mask(:)
    integer(ip), intent(out) :: nactive_contact
    real(dp) :: mine, biggest, threshold
    real(dp), allocatable :: force(:)
    logical, allocatable :: contact(:)
    integer(ip) :: local
    integer :: ierr
    contact = op%is_contact()
    force = op%force_scale()*lambda
    mine = 0
    if (any(contact)) mine = maxval(force, mask=contact)
    call MPI_Allreduce(mine, biggest, 1, MPI_REAL_DP, MPI_MAX, op%comm(), ierr)
    threshold = active_tol*max(biggest, 0.0_dp)
    mask = (.not. contact) .or. (force > threshold .and. lambda > 0)
    local = count(contact .and. mask, kind=ip)
    call MPI_Allreduce(local, nactive_contact, 1, MPI_INT_IP, MPI_SUM, op%comm(), ierr)
  end subroutine active_contact_mask

  !> alpha_bar = (G_A G_A^T)^{-1} G_A g_A (Eq. 10), assembling and factorizing
  !> G_A G_A^T as a conventional code does, in the FETI operators' reusable
  !> masked instance (feti_t%masked_coarse): its MUMPS analysis is that of
  !> SMALBE's first face when a polish ran, else made here.
  subroutine alpha_standard(op, lambda, g, active_tol, alpha_bar, cost)
    type(feti_t), intent(inout) :: op
    real(dp), intent(in) :: lambda(:), g(:)
    real(dp), intent(in) :: active_tol
    real(dp), intent(out) :: alpha_bar(:)
    type(standard_cost_t), intent(out) :: cost
    logical, allocatable :: mask(:)
    real(dp), allocatable :: ga(:)
    type(coarse_problem_t), pointer :: active_cp
    real(dp) :: t0

    call timer_start('rec standard')
    allocate (mask(op%n_own()), ga(op%n_own()))
    t0 = MPI_Wtime()
    call active_contact_mask(op, lambda, active_tol, mask, cost%active_rows)
    active_cp => op%masked_coarse(mask, low_rank=.false., own_view=.true.)
    cost%factorization = active_cp%factorization_seconds()
    cost%assembly = MPI_Wtime() - t0 - cost%factorization
    t0 = MPI_Wtime()
    ga = merge(g, 0.0_dp, mask)
    call active_coarse_solve(op, active_cp, ga, alpha_bar)
    cost%solve = MPI_Wtime() - t0
    call timer_stop('rec standard')
    cost%total = cost%assembly + cost%factorization + cost%solve
  end subroutine alpha_standard

  !> z = (G_A G_A^T)^{-1} G v with the matrix `cp` of init_active_coarse: the
  !> standard formula's solve (v = g on A, 0 elsewhere), and SMALBE's face
  !> projector (dual_problem%face_coefficient, A = the free rows). Collective.
  subroutine active_coarse_solve(op, cp, v, z)
    type(feti_t), intent(inout) :: op
    type(coarse_problem_t), intent(inout) :: cp
    real(dp), intent(in) :: v(:)
    real(dp), intent(out) :: z(:)
    real(dp), allocatable :: gz(:)
    allocate (gz(op%n_coarse()))
    call op%apply_g(v, gz)
    call cp%solve(gz, z)
  end subroutine active_coarse_solve

  !> Global 2-norm of a vector of local coarse blocks.
  real(dp) function coarse_vector_norm(op, z)
    type(feti_t), intent(in) :: op
    real(dp), intent(in) :: z(:)
    real(dp) :: mine
    integer :: ierr
    mine = sum(z**2)
    call MPI_Allreduce(mine, coarse_vector_norm, 1, MPI_REAL_DP, MPI_SUM, op%comm(), ierr)
    coarse_vector_norm = sqrt(coarse_vector_norm)
  end function coarse_vector_norm
end module reconstruction
