!> The FETI preconditioners of the dual operator F = B K^+ B^T (`&solver
!> preconditioner`):
!>
!>     M^{-1} = sum_s B_D^s A_s B_D^s^T,   B_D^s = B^s / w_s,
!>
!> with w_s = E_s/young the weight of subdomain s that the rows of B use
!> with `&solver scaling = 'young'` (1 with 'none'), so that
!> B diag(1/w) B^T = I per node on the gluing and Dirichlet rows, and
!> - 'lumped':    A_s = K_s, one sparse product with the local K;
!> - 'dirichlet': A_s = S_s, the Schur complement of K_s on the dofs that B
!>   touches (schur_complement: one K_ii solve of all the rank's subdomains
!>   and two products with K per application).
!> Applied like F: dual vector -> B^T (neighbour exchange) -> local ->
!> B (exchange back).
!>
!> Contact rows: a contact row r that sits on one copy of its node is not
!> orthogonal to the node's gluing rows g_k in the diag(1/w) inner product
!> (kappa_k = r W^{-1} g_k^T /= 0), and M^{-1} built on such rows has
!> eigenvalues near 1 - sqrt(sum kappa^2)^2 ~ 0.02 once contact rows are
!> free (measured: docs/RESULTS.md). The preconditioner therefore works in
!> the basis B'' = L^{-1} B in which the contact row is replaced by its part
!> orthogonal to the gluing rows, normalized, r'' = gamma (r - sum_k kappa_k
!> g_k), gamma = 1/sqrt(r W^{-1} r^T - sum_k kappa_k^2) (the contact row
!> spread over all copies with the gluing weights): M^{-1} = T^T B_D A B_D^T T
!> with T = L^{-T}, (T x)_k = x_k - gamma kappa_k x_c on the gluing rows,
!> (T x)_c = gamma x_c, so that M^{-1} F is similar to the same product in
!> the orthonormal basis. All rows involved belong to the node's first copy
!> and are owned by its rank: T is local. With contact rows that are already
!> orthogonal to the gluing rows, kappa = 0, gamma = 1 and T = I. M^{-1} is symmetric positive semidefinite, and positive
!> definite on the range of P (docs/THEORY.md "Preconditioned MPRGP").
!> Timer 'preconditioner'.
module dual_preconditioner
  use kinds, only: dp, ip, i8, name_len
  use errors, only: fatal_error
  use timers, only: timer_start, timer_stop
  use subdomain, only: subdomain_t
  use b_operator, only: b_operator_t
  use constraints, only: constraints_t, row_contact, row_gluing
  use schur_complement, only: schur_complement_t
  implicit none
  private

  type, public :: dual_preconditioner_t
    private
    character(len=name_len) :: kind_name = 'none'
    type(b_operator_t), pointer :: b => null()
    type(subdomain_t), pointer :: subs(:) => null()
    real(dp), allocatable :: inv_w(:)           !< (nlocal) 1/w_s
    real(dp), allocatable :: xall(:), yall(:)   !< work: concatenated primal vectors
    type(schur_complement_t) :: schur
    integer(i8) :: applications = 0
    !> T = L^{-T} (see the module): one entry per (contact row, gluing row)
    !> pair sharing a dof, owned row indices; gamma per owned row (1 elsewhere)
    integer(ip), allocatable :: t_contact(:), t_gluing(:)
    real(dp), allocatable :: t_kappa(:), gamma(:), tx(:)
  contains
    procedure :: init
    procedure :: apply
    procedure :: kind
    procedure :: n_applications
    procedure :: factor_bytes
    procedure :: free
  end type dual_preconditioner_t

contains

  !> `kind`: 'lumped' or 'dirichlet'; `b` and `subs` (K assembled) must
  !> outlive the preconditioner; `weights(ls)` = w_s of local subdomain ls.
  subroutine init(this, kind, b, subs, weights)
    class(dual_preconditioner_t), intent(inout) :: this
    character(len=*), intent(in) :: kind
    type(b_operator_t), intent(inout), target :: b
    type(subdomain_t), intent(in), target :: subs(:)
    real(dp), intent(in) :: weights(:)
    type(constraints_t), pointer :: con
    logical, allocatable :: on_interface(:)
    integer(ip) :: ls, e, r(2)

    call this%free()
    if (kind /= 'lumped' .and. kind /= 'dirichlet') &
      call fatal_error("dual_preconditioner: kind must be 'lumped' or 'dirichlet', got '"//trim(kind)//"'")
    if (size(weights) /= size(subs)) call fatal_error('dual_preconditioner: one weight per local subdomain')
    if (any(.not. weights > 0)) call fatal_error('dual_preconditioner: the subdomain weights must be > 0')
    this%kind_name = kind
    this%b => b
    this%subs => subs
    this%inv_w = 1/weights
    allocate (this%xall(b%n_concat()), this%yall(b%n_concat()))
    call contact_basis(this, b, size(subs, kind=ip))
    if (kind == 'dirichlet') then
      ! the interface: every dof with an entry of B (gluing, Dirichlet, contact)
      con => b%constraints()
      allocate (on_interface(b%n_concat()))
      on_interface = .false.
      do ls = 1, size(subs, kind=ip)
        r = b%dof_range(ls)
        do e = 1, con%b(ls)%nentries
          on_interface(r(1) - 1 + con%b(ls)%dof(e)) = .true.
        end do
      end do
      call this%schur%init(subs, on_interface)
    end if
  end subroutine init

  !> y = M^{-1} x (dual vectors, owned rows). Collective.
  subroutine apply(this, x, y)
    class(dual_preconditioner_t), intent(inout) :: this
    real(dp), intent(in) :: x(:)
    real(dp), intent(inout) :: y(:)
    integer(ip) :: ls, r(2)
    if (.not. associated(this%b)) call fatal_error('dual_preconditioner: apply before init')
    call timer_start('preconditioner')
    call apply_t(this, x, this%tx)
    this%xall = 0
    call this%b%add_transpose(this%tx, 1.0_dp, this%xall)
    do ls = 1, size(this%subs, kind=ip)
      r = this%b%dof_range(ls)
      this%xall(r(1):r(2)) = this%inv_w(ls)*this%xall(r(1):r(2))
    end do
    if (this%kind_name == 'dirichlet') then
      call this%schur%apply(this%subs, this%xall)
      this%yall = this%xall
    else
      do ls = 1, size(this%subs, kind=ip)
        r = this%b%dof_range(ls)
        call this%subs(ls)%K%matvec(this%xall(r(1):r(2)), this%yall(r(1):r(2)))
      end do
    end if
    do ls = 1, size(this%subs, kind=ip)
      r = this%b%dof_range(ls)
      this%yall(r(1):r(2)) = this%inv_w(ls)*this%yall(r(1):r(2))
    end do
    call this%b%apply_concat(this%yall, this%tx)
    call apply_tt(this, this%tx, y)
    this%applications = this%applications + 1
    call timer_stop('preconditioner')
  end subroutine apply

  !> The pairs (contact row c, gluing row k) that share a dof, kappa =
  !> sum over the shared dofs of B_c B_k / w_s, and gamma_c (see the module).
  subroutine contact_basis(this, b, nlocal)
    class(dual_preconditioner_t), intent(inout) :: this
    type(b_operator_t), intent(inout), target :: b
    integer(ip), intent(in) :: nlocal
    type(constraints_t), pointer :: con
    integer(ip), allocatable :: first(:), members(:), fill(:), pc(:), pk(:)
    real(dp), allocatable :: pv(:), rr(:), ss(:)
    integer(ip) :: ls, e, f, d, nd, np, rc, rk, i, j
    con => b%constraints()
    allocate (this%gamma(con%n_own), this%tx(con%n_own), rr(con%n_own), ss(con%n_own))
    this%gamma = 1
    rr = 0
    ss = 0
    np = 0
    allocate (pc(16), pk(16), pv(16))
    do ls = 1, nlocal
      associate (bs => con%b(ls))
        ! the entries of B^s grouped by dof
        nd = 0
        if (bs%nentries > 0) nd = maxval(bs%dof(1:bs%nentries))
        allocate (first(nd + 1), fill(nd), members(bs%nentries))
        first = 0
        do e = 1, bs%nentries
          first(bs%dof(e) + 1) = first(bs%dof(e) + 1) + 1
        end do
        first(1) = 1
        do d = 1, nd
          first(d + 1) = first(d + 1) + first(d)
        end do
        fill = first(1:nd)
        do e = 1, bs%nentries
          members(fill(bs%dof(e))) = e
          fill(bs%dof(e)) = fill(bs%dof(e)) + 1
        end do
        do d = 1, nd
          do i = first(d), first(d + 1) - 1
            e = members(i)
            rc = bs%row(e)
            if (rc > con%n_own) cycle
            if (con%kind(rc) /= row_contact) cycle
            rr(rc) = rr(rc) + bs%val(e)**2*this%inv_w(ls)
            do j = first(d), first(d + 1) - 1
              f = members(j)
              rk = bs%row(f)
              if (rk > con%n_own .or. f == e) cycle
              if (con%kind(rk) /= row_gluing) cycle
              call push(rc, rk, bs%val(e)*bs%val(f)*this%inv_w(ls))
            end do
          end do
        end do
        deallocate (first, fill, members)
      end associate
    end do
    do i = 1, np
      ss(pc(i)) = ss(pc(i)) + pv(i)**2
    end do
    do i = 1, con%n_own
      if (rr(i) > 0 .and. ss(i) > 0 .and. rr(i) - ss(i) > 1.0e-8_dp*rr(i)) &
        this%gamma(i) = 1/sqrt(rr(i) - ss(i))
      if (rr(i) > 0 .and. .not. ss(i) > 0) this%gamma(i) = 1/sqrt(rr(i))
    end do
    this%t_contact = pc(1:np)
    this%t_gluing = pk(1:np)
    this%t_kappa = pv(1:np)
  contains
    subroutine push(c, k, v)
      integer(ip), intent(in) :: c, k
      real(dp), intent(in) :: v
      integer(ip) :: q
      integer(ip), allocatable :: ti(:)
      real(dp), allocatable :: tv(:)
      ! the pairs of c were pushed last (a contact row's entries are visited together)
      do q = np, 1, -1
        if (pc(q) /= c) exit
        if (pk(q) == k) then
          pv(q) = pv(q) + v
          return
        end if
      end do
      if (np == size(pc)) then
        allocate (ti(2*np))
        ti(1:np) = pc(1:np)
        call move_alloc(ti, pc)
        allocate (ti(2*np))
        ti(1:np) = pk(1:np)
        call move_alloc(ti, pk)
        allocate (tv(2*np))
        tv(1:np) = pv(1:np)
        call move_alloc(tv, pv)
      end if
      np = np + 1
      pc(np) = c
      pk(np) = k
      pv(np) = v
    end subroutine push
  end subroutine contact_basis

  !> y = T x (owned rows).
  subroutine apply_t(this, x, y)
    class(dual_preconditioner_t), intent(in) :: this
    real(dp), intent(in) :: x(:)
    real(dp), intent(inout) :: y(:)
    integer(ip) :: q, n
    n = size(this%gamma, kind=ip)
    y(1:n) = this%gamma*x(1:n)
    do q = 1, size(this%t_contact, kind=ip)
      associate (c => this%t_contact(q), k => this%t_gluing(q))
        y(k) = y(k) - this%gamma(c)*this%t_kappa(q)*x(c)
      end associate
    end do
  end subroutine apply_t

  !> y = T^T x (owned rows).
  subroutine apply_tt(this, x, y)
    class(dual_preconditioner_t), intent(in) :: this
    real(dp), intent(in) :: x(:)
    real(dp), intent(inout) :: y(:)
    integer(ip) :: q, n
    n = size(this%gamma, kind=ip)
    y(1:n) = this%gamma*x(1:n)
    do q = 1, size(this%t_contact, kind=ip)
      associate (c => this%t_contact(q), k => this%t_gluing(q))
        y(c) = y(c) - this%gamma(c)*this%t_kappa(q)*x(k)
      end associate
    end do
  end subroutine apply_tt

  !> 'none' before init, else 'lumped' or 'dirichlet'.
  function kind(this) result(name)
    class(dual_preconditioner_t), intent(in) :: this
    character(len=:), allocatable :: name
    name = trim(this%kind_name)
  end function kind

  integer(i8) function n_applications(this)
    class(dual_preconditioner_t), intent(in) :: this
    n_applications = this%applications
  end function n_applications

  !> Bytes of the K_ii factors ('dirichlet'; 0 otherwise).
  integer(i8) function factor_bytes(this)
    class(dual_preconditioner_t), intent(in) :: this
    factor_bytes = this%schur%factor_bytes()
  end function factor_bytes

  subroutine free(this)
    class(dual_preconditioner_t), intent(inout) :: this
    call this%schur%free()
    if (allocated(this%inv_w)) deallocate (this%inv_w)
    if (allocated(this%xall)) deallocate (this%xall, this%yall)
    if (allocated(this%gamma)) deallocate (this%gamma, this%tx)
    if (allocated(this%t_contact)) deallocate (this%t_contact, this%t_gluing, this%t_kappa)
    this%b => null()
    this%subs => null()
    this%kind_name = 'none'
    this%applications = 0
  end subroutine free
end module dual_preconditioner
