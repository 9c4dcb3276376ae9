!> The KKT conditions of the primal contact problem (docs/CASES.md), checked on
!> the reconstructed displacements u and the multipliers lambda, in the terms an
!> engineer reads them; U = max |u| over all copies of all nodes:
!> - gluing:           the largest difference between the copies of a node,
!>                     sqrt(2 sum_c (u_c - mean)^2) per node and component (the
!>                     jump |u_1 - u_2| for two copies), / U;
!> - dirichlet:        the largest |u_i - prescribed value| on Dirichlet rows / U;
!> - penetration:      the largest max(-u_z - gap, 0) on contact rows / U, u_z
!>                     the mean of the node's copies weighted as the contact row
!>                     (constraints; the copies' spread is the gluing residual);
!> - equilibrium:      per subdomain s, ||K u - f + B^T lambda||_s / max(||K u||_s,
!>                     ||f||_s, ||B^T lambda||_s, max|K_s| U), the largest over
!>                     s: every subdomain is measured against its own forces,
!>                     not those of its neighbours, or, where they are smaller,
!>                     against the forces a displacement U makes in it (so an
!>                     imbalance counts by the displacement it causes); for
!>                     a cluster glued by faces (hybrid TFETI) the residual r
!>                     less C^T (C C^T)^{-1} C r, the part the face moments'
!>                     multipliers carry (K u - f + B^T lambda = -C^T mu);
!> - dual_feasibility: ||min(lambda_I, 0)|| / ||lambda_I|| (contact forces >= 0);
!> - complementarity:  max_i |force_i| |gap_i(u)| / (max_i |force_i| U) on the
!>                     contact rows (force = row scale x multiplier = the sum
!>                     over the node's copies of (B^T lambda)_z, up to sign).
!> The constraint rows are divided by their scale (&solver scaling), so that
!> the violations are displacements whatever the weighting of the rows.
!> `equality` = max(gluing, dirichlet) and `feasibility` = penetration are kept
!> as the names of report.json. 0/0 counts as 0.
module kkt
  use kinds, only: dp, ip, MPI_REAL_DP
  use feti_operators, only: feti_t, local_field_t
  use subdomain, only: subdomain_t, stiffness_matvec, stiffness_max_abs
  use face_gluing, only: gluing_gram, gluing_gram_t, remove_gluing_forces
  use constraints, only: row_dirichlet, row_contact
  use mpi_f08, only: MPI_Allreduce, MPI_SUM, MPI_MAX, MPI_IN_PLACE
  implicit none
  private

  public :: check_kkt

  !> a factor of C C^T (face_gluing::gluing_gram), kept per class of clusters
  type :: gram_t
    logical :: ready = .false.
    type(gluing_gram_t) :: g
  end type gram_t

  type, public :: kkt_residuals_t
    real(dp) :: equilibrium = 0, gluing = 0, dirichlet = 0, penetration = 0, dual_feasibility = 0, &
                complementarity = 0
    real(dp) :: equality = 0, feasibility = 0   !< max(gluing, dirichlet) and penetration
  contains
    procedure :: worst
    procedure :: worst_name
  end type kkt_residuals_t

contains

  !> The largest of the residuals.
  real(dp) function worst(this)
    class(kkt_residuals_t), intent(in) :: this
    worst = max(this%equilibrium, this%gluing, this%dirichlet, this%penetration, this%dual_feasibility, &
                this%complementarity)
  end function worst

  !> The name of the largest residual (as the log's KKT line writes it).
  function worst_name(this) result(name)
    class(kkt_residuals_t), intent(in) :: this
    character(len=:), allocatable :: name
    real(dp) :: v(6)
    character(len=24), parameter :: names(6) = [character(len=24) :: 'equilibrium', 'gluing jump', 'Dirichlet', &
                                                 'penetration', 'dual feasibility', 'complementarity']
    v = [this%equilibrium, this%gluing, this%dirichlet, this%penetration, this%dual_feasibility, this%complementarity]
    name = trim(names(maxloc(v, 1)))
  end function worst_name

  !> Residuals of (u, lambda). Collective.
  function check_kkt(op, u, lambda) result(res)
    type(feti_t), intent(inout), target :: op
    type(local_field_t), intent(in) :: u(:)
    real(dp), intent(in) :: lambda(:)
    type(kkt_residuals_t) :: res
    type(local_field_t), allocatable :: btl(:)
    type(subdomain_t), pointer :: subs(:)
    real(dp), allocatable :: ku(:), bu(:), r(:), force(:), scale(:), rr(:)
    type(gram_t), allocatable :: gram(:)
    integer(ip), allocatable :: kind(:)
    logical, allocatable :: contact(:)
    real(dp) :: mx(6), sm(2), e(4), umax, fmax
    integer(ip) :: ls, n
    integer :: ierr

    n = op%n_own()
    subs => op%subdomains()
    kind = op%row_kind()
    scale = op%force_scale()
    contact = op%is_contact()
    allocate (btl(op%nlocal()), bu(n), r(n), force(n), gram(op%nlocal()))
    call op%apply_bt(lambda, btl)
    ! U, then the per-subdomain equilibrium
    mx = 0
    do ls = 1, op%nlocal()
      if (subs(ls)%ndof > 0) mx(2) = max(mx(2), maxval(abs(u(ls)%v)))
    end do
    call MPI_Allreduce(MPI_IN_PLACE, mx(2), 1, MPI_REAL_DP, MPI_MAX, op%comm(), ierr)
    do ls = 1, op%nlocal()
      associate (sub => subs(ls))
        allocate (ku(sub%ndof))
        call stiffness_matvec(subs, ls, u(ls)%v, ku)
        ! a cluster glued by faces is in equilibrium up to its face moments' forces C^T mu
        allocate (rr(sub%ndof))
        rr = ku - sub%f + btl(ls)%v
        if (sub%C%nrows > 0) call remove_gluing_forces(sub, gram(gram_of(subs, ls, gram))%g, rr)
        e(1) = sum(rr**2)
        deallocate (rr)
        ! the subdomain's own forces, and at least the forces that a
        ! displacement U makes in it (max |K_s| U): an imbalance then counts by
        ! the displacement it causes, E_s-weighted like the stopping test, and
        ! a force-free rigid motion compares its round-off with a force
        e(2) = max(sum(ku**2), sum(sub%f**2), sum(btl(ls)%v**2), (stiffness_max_abs(subs, ls)*mx(2))**2)
        mx(1) = max(mx(1), ratio(sqrt(e(1)), sqrt(e(2))))
        deallocate (ku)
      end associate
    end do
    ! constraint violations in displacement units (rows divided by their scale)
    call op%apply_b(u, bu)
    r = (bu - op%gap_rhs())/scale(1:n)
    force = scale(1:n)*lambda(1:n)
    mx(3) = maxval(abs(r), mask=kind(1:n) == row_dirichlet .and. n > 0)
    mx(4) = maxval(max(r, 0.0_dp), mask=kind(1:n) == row_contact .and. n > 0)
    mx(5) = maxval(abs(force), mask=kind(1:n) == row_contact .and. n > 0)
    mx(6) = maxval(abs(force*r), mask=kind(1:n) == row_contact .and. n > 0)
    mx = max(mx, 0.0_dp)
    sm(1) = sum(min(lambda(1:n), 0.0_dp)**2, mask=contact(1:n))
    sm(2) = sum(lambda(1:n)**2, mask=contact(1:n))
    call MPI_Allreduce(MPI_IN_PLACE, mx, 6, MPI_REAL_DP, MPI_MAX, op%comm(), ierr)
    call MPI_Allreduce(MPI_IN_PLACE, sm, 2, MPI_REAL_DP, MPI_SUM, op%comm(), ierr)
    umax = mx(2)
    fmax = mx(5)
    res%equilibrium = mx(1)
    res%gluing = ratio(op%largest_copy_spread(u), umax)
    res%dirichlet = ratio(mx(3), umax)
    res%penetration = ratio(mx(4), umax)
    res%dual_feasibility = ratio(sqrt(sm(1)), sqrt(sm(2)))
    res%complementarity = ratio(mx(6), fmax*umax)
    res%equality = max(res%gluing, res%dirichlet)
    res%feasibility = res%penetration
  end function check_kkt


  !> a/b, with 0/0 = 0 and a/0 = huge for a > 0.
  !> The local index whose gram(.)%g holds the factor of C C^T for cluster
  !> `ls`: that of its class representative (k_of) when both have the same C
  !> (congruent clusters do, up to the rounding of their coordinates: the
  !> factor then differs by that rounding, far below what the check
  !> measures), formed on first use; else its own.
  integer(ip) function gram_of(subs, ls, gram) result(g)
    type(subdomain_t), intent(in) :: subs(:)
    integer(ip), intent(in) :: ls
    type(gram_t), intent(inout) :: gram(:)
    g = ls
    if (subs(ls)%k_of > 0) then
      if (same_rows(subs(ls), subs(subs(ls)%k_of))) g = subs(ls)%k_of
    end if
    if (.not. gram(g)%ready) call gluing_gram(subs(g), gram(g)%g)
    gram(g)%ready = .true.
  end function gram_of

  !> Whether the gluing rows of a and b are the same matrix, to 1e-12 of its
  !> largest entry.
  logical function same_rows(a, b)
    type(subdomain_t), intent(in) :: a, b
    real(dp), parameter :: rel = 1e-12_dp
    same_rows = .false.
    if (a%C%nrows /= b%C%nrows .or. b%C%nrows == 0) return
    if (size(a%C%values) /= size(b%C%values)) return
    if (any(a%C%rowptr /= b%C%rowptr)) return
    if (any(a%C%colind /= b%C%colind)) return
    same_rows = maxval(abs(a%C%values - b%C%values)) <= rel*maxval(abs(b%C%values))
  end function same_rows

  pure real(dp) function ratio(a, b)
    real(dp), intent(in) :: a, b
    if (b > 0) then
      ratio = a/b
    else
      ratio = merge(0.0_dp, huge(1.0_dp), a == 0)
    end if
  end function ratio
end module kkt
