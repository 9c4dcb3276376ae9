!> The KKT conditions of the primal contact problem (docs/CASES.md), checked on the
!> reconstructed displacements u and the multipliers lambda; each residual is
!> relative to the size of the terms it is made of:
!> - equilibrium:      ||K u - f + B^T lambda|| / max(||K u||, ||f||, ||B^T lambda||, || |K| |u| ||)
!> - equality:         ||B_E u - c_E|| / max(||c_E||, || |B_E| |u| ||, u_rms sqrt(n_E))
!> - feasibility:      ||max(B_I u - c_I, 0)|| / max(||c_I||, || |B_I| |u| ||, u_rms sqrt(n_I))
!> - dual_feasibility: ||min(lambda_I, 0)|| / ||lambda_I||
!> - complementarity:  sum |lambda_i (B_i u - c_i)| / (||lambda_I|| * the scale of feasibility)
!> where u_rms is the root mean square of all displacement components: a row
!> whose terms are all ~0 (a node in contact that does not move, with a zero
!> gap) is measured against the typical size of the displacements, not 0.
!> Likewise || |K| |u| || (|K| the entrywise absolute value) is the size of the
!> terms of K u: without it a stress-free solution (a rigid motion with
!> lambda = 0, e.g. no contact) compares round-off with round-off.
!> Norms are over all subdomains and rows of all ranks; 0/0 counts as 0.
module kkt
  use kinds, only: dp, ip, MPI_REAL_DP
  use feti_operators, only: feti_t, local_field_t, feti_sizes_t
  use subdomain, only: subdomain_t
  use mpi_f08, only: MPI_Allreduce, MPI_SUM
  implicit none
  private

  public :: check_kkt

  type, public :: kkt_residuals_t
    real(dp) :: equilibrium = 0, equality = 0, feasibility = 0, dual_feasibility = 0, complementarity = 0
  contains
    procedure :: worst
  end type kkt_residuals_t

contains

  !> The largest of the five residuals.
  real(dp) function worst(this)
    class(kkt_residuals_t), intent(in) :: this
    worst = max(this%equilibrium, this%equality, this%feasibility, this%dual_feasibility, &
                this%complementarity)
  end function worst

  !> Residuals of (u, lambda). Collective.
  function check_kkt(op, u, lambda) result(res)
    type(feti_t), intent(inout), target :: op
    type(local_field_t), intent(in) :: u(:)
    real(dp), intent(in) :: lambda(:)
    type(kkt_residuals_t) :: res
    type(local_field_t), allocatable :: btl(:), absu(:)
    real(dp), allocatable :: ku(:), bu(:), babs(:), r(:), c(:)
    type(subdomain_t), pointer :: subs(:)
    type(feti_sizes_t) :: sizes
    real(dp) :: s(17), u_rms2, n_equality, scale_i
    integer(ip) :: ls, n

    n = op%n_own()
    allocate (btl(op%nlocal()), absu(op%nlocal()), bu(n), babs(n), r(n))
    call op%apply_bt(lambda, btl)
    subs => op%subdomains()
    c = op%gap_rhs()
    s = 0
    do ls = 1, op%nlocal()
      associate (sub => subs(ls))
        allocate (ku(sub%ndof))
        call sub%K%matvec(u(ls)%v, ku)
        s(1) = s(1) + sum((ku - sub%f + btl(ls)%v)**2)
        s(2) = s(2) + sum(ku**2)
        s(3) = s(3) + sum(sub%f**2)
        s(4) = s(4) + sum(btl(ls)%v**2)
        s(17) = s(17) + abs_k_abs_u_squared(sub, u(ls)%v)
        deallocate (ku)
        absu(ls)%v = abs(u(ls)%v)
        s(14) = s(14) + sum(u(ls)%v**2)
        s(15) = s(15) + sub%ndof
      end associate
    end do
    call op%apply_b(u, bu)
    call op%apply_abs_b(absu, babs)
    r = bu - c
    associate (contact => op%is_contact())
      s(5) = sum(r**2, mask=.not. contact)
      s(6) = sum(c**2, mask=.not. contact)
      s(7) = sum(babs**2, mask=.not. contact)
      s(8) = sum(max(r, 0.0_dp)**2, mask=contact)
      s(9) = sum(c**2, mask=contact)
      s(10) = sum(babs**2, mask=contact)
      s(11) = sum(min(lambda, 0.0_dp)**2, mask=contact)
      s(12) = sum(lambda**2, mask=contact)
      s(13) = sum(abs(lambda*r), mask=contact)
      s(16) = count(contact)
    end associate
    call sum_all(op, s)
    res%equilibrium = ratio(sqrt(s(1)), sqrt(max(s(2), s(3), s(4), s(17))))
    u_rms2 = s(14)/max(s(15), 1.0_dp)
    sizes = op%sizes()
    n_equality = real(sizes%dual_dofs, dp) - s(16)
    res%equality = ratio(sqrt(s(5)), sqrt(max(s(6), s(7), u_rms2*n_equality)))
    scale_i = sqrt(max(s(9), s(10), u_rms2*s(16)))
    res%feasibility = ratio(sqrt(s(8)), scale_i)
    res%dual_feasibility = ratio(sqrt(s(11)), sqrt(s(12)))
    res%complementarity = ratio(s(13), sqrt(s(12))*scale_i)
  end function check_kkt

  !> || |K| |u| ||^2 over the rows of one subdomain.
  real(dp) function abs_k_abs_u_squared(sub, u) result(total)
    type(subdomain_t), intent(in) :: sub
    real(dp), intent(in) :: u(:)
    integer(ip) :: i, k
    real(dp) :: t
    total = 0
    do i = 1, sub%ndof
      t = 0
      do k = sub%K%rowptr(i), sub%K%rowptr(i + 1) - 1
        t = t + abs(sub%K%values(k))*abs(u(sub%K%colind(k)))
      end do
      total = total + t**2
    end do
  end function abs_k_abs_u_squared

  pure real(dp) function ratio(a, b)
    real(dp), intent(in) :: a, b
    if (b > 0) then
      ratio = a/b
    else
      ratio = merge(0.0_dp, huge(1.0_dp), a == 0)
    end if
  end function ratio

  subroutine sum_all(op, s)
    type(feti_t), intent(in) :: op
    real(dp), intent(inout) :: s(:)
    real(dp) :: total(size(s))
    integer :: ierr
    call MPI_Allreduce(s, total, size(s), MPI_REAL_DP, MPI_SUM, op%comm(), ierr)
    s = total
  end subroutine sum_all

end module kkt
