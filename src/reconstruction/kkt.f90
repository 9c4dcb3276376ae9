!> The KKT conditions of the primal contact problem (docs/CASES.md), checked on
!> the reconstructed displacements u and the multipliers lambda, in the terms an
!> engineer reads them; U = max |u| over all copies of all nodes:
!> - gluing:           the largest difference between the copies of a node,
!>                     sqrt(2 sum_c (u_c - mean)^2) per node and component (the
!>                     jump |u_1 - u_2| for two copies), / U;
!> - dirichlet:        the largest |u_i - prescribed value| on Dirichlet rows / U;
!> - penetration:      the largest max(-u_z - gap, 0) on contact rows / U;
!> - equilibrium:      per subdomain s, ||K u - f + B^T lambda||_s / max(||K u||_s,
!>                     ||f||_s, ||B^T lambda||_s, max|K_s| U), the largest over
!>                     s: every subdomain is measured against its own forces,
!>                     not those of its neighbours, or, where they are smaller,
!>                     against the forces a displacement U makes in it (so an
!>                     imbalance counts by the displacement it causes);
!> - dual_feasibility: ||min(lambda_I, 0)|| / ||lambda_I|| (contact forces >= 0);
!> - complementarity:  max_i |force_i| |gap_i(u)| / (max_i |force_i| U) on the
!>                     contact rows (force = row scale x multiplier).
!> The constraint rows are divided by their scale (&solver scaling), so that
!> the violations are displacements whatever the weighting of the rows.
!> `equality` = max(gluing, dirichlet) and `feasibility` = penetration are kept
!> as the names of report.json. 0/0 counts as 0.
module kkt
  use kinds, only: dp, ip, i8, MPI_REAL_DP
  use feti_operators, only: feti_t, local_field_t
  use subdomain, only: subdomain_t
  use constraints, only: row_gluing, row_dirichlet, row_contact
  use mpi_f08, only: MPI_Allreduce, MPI_SUM, MPI_MAX, MPI_IN_PLACE
  implicit none
  private

  public :: check_kkt

  type, public :: kkt_residuals_t
    real(dp) :: equilibrium = 0, gluing = 0, dirichlet = 0, penetration = 0, dual_feasibility = 0, &
                complementarity = 0
    real(dp) :: equality = 0, feasibility = 0   !< max(gluing, dirichlet) and penetration
  contains
    procedure :: worst
  end type kkt_residuals_t

contains

  !> The largest of the residuals.
  real(dp) function worst(this)
    class(kkt_residuals_t), intent(in) :: this
    worst = max(this%equilibrium, this%gluing, this%dirichlet, this%penetration, this%dual_feasibility, &
                this%complementarity)
  end function worst

  !> Residuals of (u, lambda). Collective.
  function check_kkt(op, u, lambda) result(res)
    type(feti_t), intent(inout) :: op
    type(local_field_t), intent(in) :: u(:)
    real(dp), intent(in) :: lambda(:)
    type(kkt_residuals_t) :: res
    type(local_field_t), allocatable :: btl(:)
    real(dp), allocatable :: ku(:), bu(:), r(:), force(:)
    real(dp) :: mx(6), sm(2), e(4), umax, fmax
    integer(ip) :: ls, n
    integer :: ierr

    n = op%con%n_own
    allocate (btl(op%nlocal), bu(n), r(n), force(n))
    call op%apply_bt(lambda, btl)
    ! U, then the per-subdomain equilibrium
    mx = 0
    do ls = 1, op%nlocal
      if (op%subs(ls)%ndof > 0) mx(2) = max(mx(2), maxval(abs(u(ls)%v)))
    end do
    call MPI_Allreduce(MPI_IN_PLACE, mx(2), 1, MPI_REAL_DP, MPI_MAX, op%comm, ierr)
    do ls = 1, op%nlocal
      associate (sub => op%subs(ls))
        allocate (ku(sub%ndof))
        call sub%K%matvec(u(ls)%v, ku)
        e(1) = sum((ku - sub%f + btl(ls)%v)**2)
        ! the subdomain's own forces, and at least the forces that a
        ! displacement U makes in it (max |K_s| U): an imbalance then counts by
        ! the displacement it causes, E_s-weighted like the stopping test, and
        ! a force-free rigid motion compares its round-off with a force
        e(2) = max(sum(ku**2), sum(sub%f**2), sum(btl(ls)%v**2), (maxval(abs(sub%K%values))*mx(2))**2)
        mx(1) = max(mx(1), ratio(sqrt(e(1)), sqrt(e(2))))
        deallocate (ku)
      end associate
    end do
    ! constraint violations in displacement units (rows divided by their scale)
    call op%apply_b(u, bu)
    r = (bu - op%con%c)/op%con%scale(1:n)
    force = op%con%scale(1:n)*lambda(1:n)
    mx(3) = maxval(abs(r), mask=op%con%kind(1:n) == row_dirichlet .and. n > 0)
    mx(4) = maxval(max(r, 0.0_dp), mask=op%con%kind(1:n) == row_contact .and. n > 0)
    mx(5) = maxval(abs(force), mask=op%con%kind(1:n) == row_contact .and. n > 0)
    mx(6) = maxval(abs(force*r), mask=op%con%kind(1:n) == row_contact .and. n > 0)
    mx = max(mx, 0.0_dp)
    sm(1) = sum(min(lambda(1:n), 0.0_dp)**2, mask=op%is_contact(1:n))
    sm(2) = sum(lambda(1:n)**2, mask=op%is_contact(1:n))
    call MPI_Allreduce(MPI_IN_PLACE, mx, 6, MPI_REAL_DP, MPI_MAX, op%comm, ierr)
    call MPI_Allreduce(MPI_IN_PLACE, sm, 2, MPI_REAL_DP, MPI_SUM, op%comm, ierr)
    umax = mx(2)
    fmax = mx(5)
    res%equilibrium = mx(1)
    res%gluing = ratio(largest_copy_spread(op, u), umax)
    res%dirichlet = ratio(mx(3), umax)
    res%penetration = ratio(mx(4), umax)
    res%dual_feasibility = ratio(sqrt(sm(1)), sqrt(sm(2)))
    res%complementarity = ratio(mx(6), fmax*umax)
    res%equality = max(res%gluing, res%dirichlet)
    res%feasibility = res%penetration
  end function check_kkt

  !> max over nodes and components of sqrt(2 sum_c (u_c - mean)^2) over the
  !> copies c of a glued node component. Every copy of such a component has
  !> an entry in the node's last gluing row (Helmert row m-1 touches all m
  !> copies; it is the copy's gluing row with the largest key), which carries
  !> the sums: sum_c u_c and the number of copies, then the mean back to the
  !> copies, then sum_c (u_c - mean)^2 (two-pass: no cancellation).
  real(dp) function largest_copy_spread(op, u) result(spread)
    type(feti_t), intent(inout) :: op
    type(local_field_t), intent(in) :: u(:)
    type(local_field_t), allocatable :: anchor(:)
    real(dp), allocatable :: loc(:), own(:), cnt(:), mean_loc(:)
    real(dp) :: mine
    integer(ip) :: ls, e, row, dof
    integer :: ierr
    allocate (anchor(op%nlocal), loc(op%con%n_local), own(op%con%n_own), cnt(op%con%n_own), &
              mean_loc(op%con%n_local))
    ! the anchor row of every glued dof (stored as a real for local_field_t)
    do ls = 1, op%nlocal
      associate (bs => op%con%b(ls))
        allocate (anchor(ls)%v(op%subs(ls)%ndof))
        anchor(ls)%v = 0
        do e = 1, bs%nentries
          row = bs%row(e)
          if (key_kind(op%con%key(row)) /= row_gluing) cycle
          dof = bs%dof(e)
          if (anchor(ls)%v(dof) == 0) then
            anchor(ls)%v(dof) = row
          else if (op%con%key(row) > op%con%key(int(anchor(ls)%v(dof), ip))) then
            anchor(ls)%v(dof) = row
          end if
        end do
      end associate
    end do
    ! number of copies and mean per anchor row
    loc = 0
    call accumulate(1)
    call op%con%exchange%scatter_add(loc, cnt)
    loc = 0
    call accumulate(2)
    call op%con%exchange%scatter_add(loc, own)
    own = merge(own/max(cnt, 1.0_dp), 0.0_dp, cnt > 0)
    call op%con%exchange%gather(own, mean_loc)
    loc = 0
    call accumulate(3)
    call op%con%exchange%scatter_add(loc, own)
    mine = 0
    if (op%con%n_own > 0) mine = sqrt(2*maxval(own))
    call MPI_Allreduce(mine, spread, 1, MPI_REAL_DP, MPI_MAX, op%comm, ierr)
  contains
    !> loc(anchor) += 1, u, or (u - mean)^2 over all glued dofs of all copies here.
    subroutine accumulate(what)
      integer, intent(in) :: what
      integer(ip) :: ls2, d, a
      do ls2 = 1, op%nlocal
        do d = 1, op%subs(ls2)%ndof
          a = int(anchor(ls2)%v(d), ip)
          if (a == 0) cycle
          select case (what)
          case (1)
            loc(a) = loc(a) + 1
          case (2)
            loc(a) = loc(a) + u(ls2)%v(d)
          case default
            loc(a) = loc(a) + (u(ls2)%v(d) - mean_loc(a))**2
          end select
        end do
      end do
    end subroutine accumulate
  end function largest_copy_spread

  !> The row kind (row_gluing, row_dirichlet, row_contact) encoded in a key
  !> (constraints::row_key).
  pure integer(ip) function key_kind(key)
    integer(i8), intent(in) :: key
    key_kind = int(mod(key/8, 4_i8), ip)
  end function key_kind

  pure real(dp) function ratio(a, b)
    real(dp), intent(in) :: a, b
    if (b > 0) then
      ratio = a/b
    else
      ratio = merge(0.0_dp, huge(1.0_dp), a == 0)
    end if
  end function ratio
end module kkt
