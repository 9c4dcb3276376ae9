!> Where the solution leaves the range of small-strain linear elasticity: the
!> largest strain (the largest absolute principal strain at an element
!> centroid) above `strain_limit`, or the largest displacement above
!> `displacement_share` of the body's smallest length. Each a warning
!> sentence for the log and report.json's `warnings`; the numbers stand, the
!> model behind them does not.
module model_validity
  use kinds, only: dp, ip, MPI_REAL_DP
  use feti_operators, only: feti_t, local_field_t
  use subdomain, only: subdomain_t
  use q1_element, only: q1_centroid_strain
  use lapack_interfaces, only: dsyev
  use logger, only: log_message
  use mpi_f08, only: MPI_Allreduce, MPI_MAX
  implicit none
  private

  public :: validity_warnings, add_validity_warnings

  real(dp), parameter, public :: strain_limit = 1.0e-2_dp        !< small strains: |eps| <= 1e-2
  real(dp), parameter, public :: displacement_share = 0.1_dp     !< small displacements: |u| <= 0.1 min(L)
  integer, parameter :: line_len = 1024

contains

  !> The warnings of the displacements `u` (one field per local subdomain of
  !> `op`) of a body of `lengths`. Collective over op%comm().
  function validity_warnings(op, u, lengths) result(w)
    type(feti_t), intent(inout), target :: op
    type(local_field_t), intent(in) :: u(:)
    real(dp), intent(in) :: lengths(3)
    character(len=line_len), allocatable :: w(:)
    type(subdomain_t), pointer :: subs(:)
    character(len=line_len) :: line
    real(dp) :: mine(2), worst(2)
    integer(ip) :: ls
    integer :: ierr

    subs => op%subdomains()
    mine = 0
    do ls = 1, size(subs, kind=ip)
      mine(1) = max(mine(1), largest_strain(subs(ls), u(ls)%v))
      if (size(u(ls)%v) > 0) mine(2) = max(mine(2), maxval(norm2(reshape(u(ls)%v, [3, subs(ls)%nnodes]), 1)))
    end do
    call MPI_Allreduce(mine, worst, 2, MPI_REAL_DP, MPI_MAX, op%comm(), ierr)
    allocate (w(0))
    if (worst(1) > strain_limit) then
      write (line, '(a,es10.3,a)') 'largest strain ', worst(1), ' exceeds 1e-2: small-strain linear '// &
        'elasticity does not describe this deformation (check the units of &material young, &mesh '// &
        'lengths and &boundary top_displacement / &load top_pressure)'
      w = [character(len=line_len) :: w, line]
    end if
    if (worst(2) > displacement_share*minval(lengths)) then
      write (line, '(a,es10.3,a,es10.3,a)') 'largest displacement ', worst(2), ' exceeds a tenth of the '// &
        'body''s smallest length ', minval(lengths), ': the small-displacement (linear) model and its '// &
        'contact condition do not hold'
      w = [character(len=line_len) :: w, line]
    end if
  end function validity_warnings

  !> validity_warnings logged (as the input's warnings are) and appended to
  !> `warnings` (report.json's list). Collective.
  subroutine add_validity_warnings(op, u, lengths, warnings)
    type(feti_t), intent(inout), target :: op
    type(local_field_t), intent(in) :: u(:)
    real(dp), intent(in) :: lengths(3)
    character(len=*), allocatable, intent(inout) :: warnings(:)
    character(len=line_len), allocatable :: w(:)
    integer :: i
    w = validity_warnings(op, u, lengths)
    do i = 1, size(w)
      call log_message('feticontact: WARNING: '//trim(w(i)))
    end do
    if (size(w) > 0) warnings = [character(len=len(warnings)) :: warnings, w]
  end subroutine add_validity_warnings

  !> The largest absolute principal strain at the element centroids of `sub`.
  real(dp) function largest_strain(sub, u) result(worst)
    type(subdomain_t), intent(in) :: sub
    real(dp), intent(in) :: u(:)
    real(dp) :: eps(6), t(3, 3), ev(3), work(16), ue(24)
    integer(ip) :: e, i, a
    integer :: info
    worst = 0
    do e = 1, sub%nelem
      do i = 1, 8
        a = sub%elem_nodes(i, e)
        ue(3*i - 2:3*i) = u(3*a - 2:3*a)
      end do
      call q1_centroid_strain(sub%coords(:, sub%elem_nodes(:, e)), ue, eps)
      t = reshape([eps(1), eps(4)/2, eps(6)/2, eps(4)/2, eps(2), eps(5)/2, eps(6)/2, eps(5)/2, eps(3)], [3, 3])
      call dsyev('N', 'U', 3, t, 3, ev, work, size(work), info)
      if (info == 0) worst = max(worst, maxval(abs(ev)))
    end do
  end function largest_strain
end module model_validity
