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
module feti_operators
  use kinds, only: dp, ip, i8, MPI_REAL_DP, MPI_INT_I8
  use logger, only: log_message
  use timers, only: timer_start, timer_stop
  use params, only: params_t
  use decomposition, only: decomposition_t, build_decomposition
  use subdomain, only: subdomain_t, build_subdomain
  use assembly, only: assemble_subdomain
  use kplus, only: kplus_t
  use kplus_block, only: kplus_block_t
  use constraints, only: constraints_t, build_constraints, row_contact
  use coarse_problem, only: coarse_problem_t, coarse_layout_t, build_coarse_layout
  use mpi_f08, only: MPI_Comm, MPI_Allreduce, MPI_SUM
  implicit none
  private

  !> One vector per local subdomain (displacements, loads).
  type, public :: local_field_t
    real(dp), allocatable :: v(:)
  end type local_field_t

  type, public :: feti_t
    type(MPI_Comm) :: comm
    type(params_t) :: p
    type(decomposition_t) :: dec
    type(subdomain_t), allocatable :: subs(:)
    type(kplus_t), allocatable :: kplus(:)       !< local_solver 'subdomain': one per subdomain
    type(kplus_block_t) :: kblock                !< local_solver 'block': all local subdomains
    logical :: block_solver = .true.
    integer(ip), allocatable :: offset(:)        !< (nlocal+1) dof offsets in concatenated local vectors
    type(constraints_t) :: con
    type(coarse_layout_t) :: layout
    type(coarse_problem_t) :: coarse
    integer(ip) :: nlocal = 0                    !< subdomains of this rank
    integer(i8) :: primal_dofs = 0               !< sum of subdomain dofs, all ranks
    real(dp), allocatable :: d(:)                !< (n_own) B K^+ f - c
    real(dp), allocatable :: lambda_tilde(:)     !< (n_own) G^T (G G^T)^{-1} e
    real(dp), allocatable :: lower(:)            !< (n_own) bounds of nu: -lambda~ on contact rows
    logical, allocatable :: is_contact(:)        !< (n_own)
    real(dp), allocatable :: e(:)                !< (6*nlocal) R^T f
    real(dp) :: norm_pfp = 0                     !< estimate of ||P F P||
    integer(i8) :: f_applications = 0, coarse_solves = 0
    ! work space
    real(dp), allocatable, private :: wloc(:), wloc2(:), xall(:), cwork(:), cwork2(:)
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
    procedure :: estimate_norm_pfp
    procedure :: local_solve
    procedure :: bytes_per_f_action
    procedure, private :: add_bt
    procedure, private :: b_times
    procedure :: keyed_random
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
    this%comm = comm
    this%p = p

    call timer_start('mesh')
    call build_decomposition(p, comm, this%dec)
    this%nlocal = size(this%dec%local_subdomains, kind=ip)
    allocate (this%subs(this%nlocal))
    do ls = 1, this%nlocal
      call build_subdomain(this%dec, this%dec%local_subdomains(ls), this%subs(ls))
    end do
    call timer_stop('mesh')

    call timer_start('assembly')
    do ls = 1, this%nlocal
      call assemble_subdomain(p, this%dec, this%subs(ls))
    end do
    call timer_stop('assembly')

    allocate (this%offset(this%nlocal + 1))
    this%offset(1) = 0
    do ls = 1, this%nlocal
      this%offset(ls + 1) = this%offset(ls) + this%subs(ls)%ndof
    end do
    call timer_start('factorization')
    this%block_solver = p%solver%local_solver == 'block'
    if (this%block_solver) then
      call this%kblock%init(this%subs, p%solver%regularization, p%solver%local_ordering)
    else
      allocate (this%kplus(this%nlocal))
      do ls = 1, this%nlocal
        call this%kplus(ls)%init(this%subs(ls), p%solver%regularization, p%solver%local_ordering)
      end do
    end if
    call timer_stop('factorization')

    call timer_start('B and G')
    call build_constraints(p, this%dec, this%subs, comm, this%con)
    mydofs = this%offset(this%nlocal + 1)
    call MPI_Allreduce(mydofs, this%primal_dofs, 1, MPI_INT_I8, MPI_SUM, comm, ierr)
    allocate (this%wloc(this%con%n_local), this%wloc2(this%con%n_local), &
              this%xall(this%offset(this%nlocal + 1)), this%cwork(6*this%nlocal), this%cwork2(6*this%nlocal))
    call timer_stop('B and G')

    call timer_start('coarse setup')
    call build_coarse_layout(this%dec, comm, this%layout)
    call this%coarse%init(this%dec, this%con, this%layout, comm, placement=p%solver%coarse_placement)
    call timer_stop('coarse setup')

    call timer_start('dual setup')
    associate (n => this%con%n_own)
      allocate (this%d(n), this%lambda_tilde(n), this%lower(n), this%is_contact(n), this%e(6*this%nlocal))
      ! d = B K^+ f - c, e = R^T f
      do ls = 1, this%nlocal
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
      this%is_contact = this%con%kind == row_contact
      this%lower = -huge(1.0_dp)
      where (this%is_contact) this%lower = -this%lambda_tilde
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
    this%f_applications = this%f_applications + 1
    call timer_stop('F action')
  end subroutine apply_f

  !> z = G x (local coarse blocks).
  subroutine apply_g(this, x, z)
    class(feti_t), intent(inout) :: this
    real(dp), intent(in) :: x(:)
    real(dp), intent(out) :: z(:)
    integer(ip) :: ls, e
    call this%con%exchange%gather(x, this%wloc)
    do ls = 1, this%nlocal
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
    do ls = 1, this%nlocal
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
    this%coarse_solves = this%coarse_solves + 1
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
    call MPI_Allreduce(mine, dot, 1, MPI_REAL_DP, MPI_SUM, this%comm, ierr)
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
    do ls = 1, this%nlocal
      this%xall(this%offset(ls) + 1:this%offset(ls + 1)) = this%subs(ls)%f
    end do
    call this%add_bt(this%wloc, -1.0_dp, this%xall)
    call this%local_solve(this%xall)
    do ls = 1, this%nlocal
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
    factors = 0
    if (this%block_solver) then
      factors = this%kblock%factor_bytes()
    else
      do ls = 1, this%nlocal
        factors = factors + this%kplus(ls)%factor_bytes()
      end do
    end if
    entries = 0
    do ls = 1, this%nlocal
      entries = entries + this%con%b(ls)%nentries
    end do
    bytes_per_f_action = 2*factors + 2*16*entries
  end function bytes_per_f_action

  !> x <- K^+ x for the concatenated vector of all local subdomains.
  subroutine local_solve(this, x)
    class(feti_t), intent(inout) :: this
    real(dp), intent(inout) :: x(:)
    integer(ip) :: ls
    if (this%block_solver) then
      call this%kblock%solve(x)
    else
      do ls = 1, this%nlocal
        call this%kplus(ls)%solve(x(this%offset(ls) + 1:this%offset(ls + 1)))
      end do
    end if
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
    do ls = 1, this%nlocal
      u(ls)%v = this%xall(this%offset(ls) + 1:this%offset(ls + 1))
    end do
  end subroutine apply_bt

  !> y = B u = sum over subdomains of B^s u^s (owned rows).
  subroutine apply_b(this, u, y)
    class(feti_t), intent(inout) :: this
    type(local_field_t), intent(in) :: u(:)
    real(dp), intent(inout) :: y(:)
    integer(ip) :: ls
    do ls = 1, this%nlocal
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
    do ls = 1, this%nlocal
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
    do ls = 1, this%nlocal
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
    this%norm_pfp = 0
    if (nrm == 0) return
    x = x/nrm
    previous = 0
    do it = 1, max_iterations
      call this%apply_f(x, z)
      call this%project(z, y)            ! y = P F P x, since P x = x
      nrm = this%norm(y)
      if (nrm == 0) exit
      x = y/nrm
      this%norm_pfp = nrm
      if (abs(nrm - previous) <= 1.0e-3_dp*nrm) exit
      previous = nrm
    end do
    write (line, '(a,es12.5,a,i0,a)') '||P F P|| ~ ', this%norm_pfp, ' (power method, ', min(it, max_iterations), &
      ' iterations)'
    call log_message(line)
  end subroutine estimate_norm_pfp

  subroutine free(this)
    class(feti_t), intent(inout) :: this
    integer(ip) :: ls
    if (allocated(this%kplus)) then
      do ls = 1, size(this%kplus, kind=ip)
        call this%kplus(ls)%free()
      end do
      deallocate (this%kplus)
    end if
    call this%kblock%free()
    if (allocated(this%offset)) deallocate (this%offset)
    if (allocated(this%subs)) deallocate (this%subs)
    call this%coarse%free()
    call this%con%exchange%free()
    if (allocated(this%d)) deallocate (this%d, this%lambda_tilde, this%lower, this%is_contact, this%e)
    if (allocated(this%wloc)) deallocate (this%wloc, this%wloc2, this%xall, this%cwork, this%cwork2)
    this%f_applications = 0
    this%coarse_solves = 0
  end subroutine free
end module feti_operators
