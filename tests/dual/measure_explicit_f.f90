!> Not a test: compares the explicit local dual operators (`&solver f_action =
!> 'explicit'`) with the implicit F = B K^+ B^T on the case of test_kkt_check
!> (2x2x2 subdomains of 2^3, checkerboard of Young's moduli with contrast
!> 1e6, SMALBE at tol = 1e-10) and prints (docs/RESULTS.md, "Speed (issue 16)"):
!> - ||F_exp x - F_imp x|| / ||F_imp x|| for keyed random x, for P x and for
!>   the solution nu;
!> - the symmetry defect |x^T F y - y^T F x| / (||x|| ||F y|| ...) of both;
!> - the SMALBE run with each at `tol` (default 1e-10; outer, Hessian
!>   multiplications, measures; a cap of 20000 Hessian multiplications, so
!>   that a tol below the attainable floor shows where each stalls);
!> - the equality measure at the solution and of a one-ulp perturbation;
!>   mpirun -n 1 build-debug/tests/bin/measure_explicit_f [contrast [storage [tol]]]
program measure_explicit_f
  use kinds, only: dp, ip
  use logger, only: logger_init
  use params, only: params_t, feti_settings_of
  use feti_operators, only: feti_t
  use dual_problem, only: dual_problem_t
  use smalbe, only: smalbe_t, smalbe_settings_t
  use feti_test_support, only: small_case
  use mpi_f08, only: MPI_Init, MPI_Finalize, MPI_COMM_WORLD, MPI_Comm_rank
  implicit none
  integer :: ierr, rank
  type(params_t) :: p
  character(len=32) :: arg, storage
  real(dp) :: contrast, tol

  call MPI_Init(ierr)
  call MPI_Comm_rank(MPI_COMM_WORLD, rank, ierr)
  call logger_init()
  contrast = 1.0e6_dp
  if (command_argument_count() >= 1) then
    call get_command_argument(1, arg)
    read (arg, *) contrast
  end if
  storage = 'packed'
  if (command_argument_count() >= 2) call get_command_argument(2, storage)
  tol = 1.0e-10_dp
  if (command_argument_count() >= 3) then
    call get_command_argument(3, arg)
    read (arg, *) tol
  end if
  p = small_case('cube', [2_ip, 2_ip, 2_ip], [2_ip, 2_ip, 2_ip], 'box', 0.0_dp)
  p%boundary%top_displacement = [0.0_dp, 0.0_dp, -0.025_dp]
  if (contrast > 1) then
    p%material%variation = 'checkerboard'
    p%material%contrast = contrast
  end if
  p%solver%f_action%f_storage = storage
  if (rank == 0) write (*, '(2a)') 'explicit storage ', trim(storage)
  call compare(p)
  call MPI_Finalize(ierr)

contains

  subroutine compare(p)
    type(params_t), intent(in) :: p
    type(params_t) :: pi, pe
    type(feti_t), target :: opi, ope
    real(dp), allocatable :: x(:), y(:), px(:), fi(:), fe(:), fyi(:), fye(:), nui(:), nue(:)
    integer(ip) :: n, k
    pi = p
    pi%solver%f_action%f_action = 'implicit'
    pe = p
    pe%solver%f_action%f_action = 'explicit'
    call opi%setup(feti_settings_of(pi), MPI_COMM_WORLD)
    call ope%setup(feti_settings_of(pe), MPI_COMM_WORLD)
    n = opi%n_own()
    allocate (x(n), y(n), px(n), fi(n), fe(n), fyi(n), fye(n))
    if (rank == 0) write (*, '(a,es10.3,a,es10.3)') 'contrast ', p%material%contrast, '  ||PFP|| implicit/explicit - 1: ', &
      opi%norm_pfp()/ope%norm_pfp() - 1
    do k = 1, 3
      call opi%keyed_random(10 + k, x)
      call opi%keyed_random(20 + k, y)
      call opi%apply_f(x, fi)
      call ope%apply_f(x, fe)
      call opi%apply_f(y, fyi)
      call ope%apply_f(y, fye)
      call report('random x', x, fi, fe)
      if (rank == 0) write (*, '(a,2es11.3)') '   symmetry |x.Fy - y.Fx|/(|x||Fy|): implicit, explicit ', &
        abs(opi%dot(x, fyi) - opi%dot(y, fi))/(opi%norm(x)*opi%norm(fyi)), &
        abs(ope%dot(x, fye) - ope%dot(y, fe))/(opi%norm(x)*opi%norm(fye))
      call opi%project(x, px)
      call opi%apply_f(px, fi)
      call ope%apply_f(px, fe)
      call report('P x', px, fi, fe)
      call opi%project(fi, x)
      call ope%project(fe, y)
      call report('P F P x', px, x, y)
    end do
    call solve(pi, opi, 'implicit', nui)
    call solve(pe, ope, 'explicit', nue)
    call opi%apply_f(nui, fi)
    call ope%apply_f(nui, fe)
    call report('nu (implicit solution)', nui, fi, fe)
    x = nue - nui
    if (rank == 0) write (*, '(a,es11.3)') '||nu_exp - nu_imp|| / ||nu_imp|| ', opi%norm(x)/opi%norm(nui)
    call floor_of_eq_measure(opi, nui)
    call opi%free()
    call ope%free()
  end subroutine compare

  !> The equality measure of dual_problem%eq_measure (max_s ||(G nu)_s||/E_s
  !> over max_s max(||B_s^T lambda||, ||f_s||)/E_s) for nu itself and for a
  !> perturbation of every entry of nu by one rounding, nu_i eps r_i with r_i
  !> keyed random in [-1, 1]: no vector within one ulp of nu per entry has a
  !> smaller measure in general, so the second is a floor of what SMALBE's
  !> outer test can reach (eps = 2^-53). Also max |nu|, ||nu||.
  subroutine floor_of_eq_measure(op, nu)
    use feti_operators, only: local_field_t
    use subdomain, only: subdomain_t
    use mpi_f08, only: MPI_Allreduce, MPI_IN_PLACE, MPI_MAX, MPI_DOUBLE_PRECISION
    type(feti_t), intent(inout), target :: op
    real(dp), intent(in) :: nu(:)
    type(local_field_t), allocatable :: btl(:)
    type(subdomain_t), pointer :: subs(:)
    real(dp), allocatable :: r(:), gx(:), gd(:), lambda(:)
    real(dp) :: m(3)
    integer(ip) :: ls
    integer :: ierr2
    allocate (r(size(nu)), gx(op%n_coarse()), gd(op%n_coarse()), btl(op%nlocal()))
    call op%keyed_random(99, r)
    r = nu*r*epsilon(1.0_dp)/2
    call op%apply_g(nu, gx)
    call op%apply_g(r, gd)
    lambda = nu + op%lambda_tilde_vector()
    call op%apply_bt(lambda, btl)
    subs => op%subdomains()
    m = 0
    do ls = 1, op%nlocal()
      m(1) = max(m(1), norm2(gx(6*ls - 5:6*ls))/subs(ls)%young)
      m(2) = max(m(2), norm2(gd(6*ls - 5:6*ls))/subs(ls)%young)
      m(3) = max(m(3), max(norm2(btl(ls)%v), norm2(subs(ls)%f))/subs(ls)%young)
    end do
    call MPI_Allreduce(MPI_IN_PLACE, m, 3, MPI_DOUBLE_PRECISION, MPI_MAX, MPI_COMM_WORLD, ierr2)
    if (rank == 0) write (*, '(a,es11.3,a,es11.3,a,es11.3,a,es11.3)') 'equality measure at nu ', m(1)/m(3), &
      ', of a one-ulp perturbation of nu ', m(2)/m(3), ';  max|nu| ', maxval(abs(nu)), ', ||nu|| ', op%norm(nu)
  end subroutine floor_of_eq_measure

  subroutine report(label, x, fi, fe)
    character(len=*), intent(in) :: label
    real(dp), intent(in) :: x(:), fi(:), fe(:)
    real(dp), allocatable :: d(:)
    real(dp) :: nd, nf
    d = fe - fi
    nd = sqrt(global_sum(d**2))
    nf = sqrt(global_sum(fi**2))
    if (rank == 0) write (*, '(a,a,es11.3,a,es11.3)') label, ': ||F_exp x - F_imp x|| / ||F_imp x|| ', nd/nf, &
      '   ||x|| ', sqrt(global_sum(x**2))
  end subroutine report

  real(dp) function global_sum(v)
    real(dp), intent(in) :: v(:)
    global_sum = sum(v)
    call sum_all(global_sum)
  end function global_sum

  subroutine sum_all(s)
    use mpi_f08, only: MPI_Allreduce, MPI_IN_PLACE, MPI_SUM, MPI_DOUBLE_PRECISION
    real(dp), intent(inout) :: s
    integer :: ierr2
    call MPI_Allreduce(MPI_IN_PLACE, s, 1, MPI_DOUBLE_PRECISION, MPI_SUM, MPI_COMM_WORLD, ierr2)
  end subroutine sum_all

  subroutine solve(p, op, label, nu)
    type(params_t), intent(in) :: p
    type(feti_t), intent(inout), target :: op
    character(len=*), intent(in) :: label
    real(dp), allocatable, intent(out) :: nu(:)
    type(dual_problem_t) :: hat
    type(smalbe_t) :: solver
    type(smalbe_settings_t) :: sp
    call hat%init(op, p%solver%dual%rho_scale)
    sp = p%solver%smalbe
    sp%tol = tol
    sp%max_hessian = 20000
    sp%max_outer = 2000
    sp%monitor = .false.
    call solver%init_with(sp, max(op%norm_pfp(), hat%rho)/hat%scale)
    allocate (nu(op%n_own()))
    nu = 0
    call solver%solve(hat, nu)
    if (rank == 0) write (*, '(a,a,a)') label, ': ', trim(solver%message)
    call solver%free()
    call hat%free()
  end subroutine solve
end program measure_explicit_f
