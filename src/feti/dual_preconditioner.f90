!> The FETI preconditioners of the dual operator F = B K^+ B^T (`&solver
!> preconditioner`):
!>
!>     M^{-1} = D (sum_s B_D^s A_s B_D^s^T) D,   B_D^s = B^s / w_s,
!>
!> (D: the contact-row scaling below)
!> with w_s = E_s/young the weight of subdomain s that the rows of B use
!> with `&solver scaling = 'young'` (1 with 'none'), so that
!> B diag(1/w) B^T = I per node on the gluing and Dirichlet rows, and
!> - 'lumped':    A_s = K_s, one sparse product with the local K;
!> - 'dirichlet': A_s = S_s, the Schur complement of K_s on the dofs that B
!>   touches (schur_complement: one K_ii solve of all the rank's subdomains
!>   and two products with K per application).
!> Applied like F: dual vector -> B^T (neighbour exchange) -> local ->
!> B (exchange back). 'lumped' with classes of congruent subdomains
!> (`&solver share_subdomains`, K_s = c_s K_r): A_s restricted to the dofs B
!> touches is c_s K_r(U_c, U_c), applied to all the members of a class at
!> once (class_operator, K_r on the union U_c of the class's touched dofs in
!> CSR, read once per application for all members).
!>
!> Contact rows (constraints: spread over all copies of their node with the
!> gluing weights, entries v_c = -w_c/sqrt(S), S = sum_c w_c) are orthogonal
!> to the node's gluing rows in the diag(1/w) inner product and have unit
!> weighted norm, so B_D needs no change of basis for them. They get a
!> deliberate scaling instead: M^{-1} = D B_D A B_D^T D with D = diag(d),
!> d_r = sqrt(n_r) on contact rows and 1 on all others, where
!>
!>     n_r = (sum_c v_c)^2 / sum_c v_c^2 = S^2 / sum_c w_c^2,
!>
!> the effective number of copies of the node (n for n copies of equal
!> weight, 1 for a row on one copy, about the number of stiff copies across
!> a material jump). The contact row's diagonal of B_D A B_D^T is the
!> weighted mean of its copies' stiffnesses, sum_c A_c,zz / S; d_r^2 = n_r
!> makes it (n_r/S) sum_c A_c,zz, for equal weights (S = n_r = n) their sum,
!> the stiffness of the assembled node against a force on the node
!> (docs/THEORY.md "Preconditioned MPRGP"; the exponent is measured,
!> docs/RESULTS.md). D is positive, so M^{-1} stays symmetric positive
!> semidefinite and positive definite on the range of P (docs/THEORY.md).
!> Timer 'preconditioner'.
module dual_preconditioner
  use kinds, only: dp, ip, i8, name_len
  use errors, only: fatal_error
  use timers, only: timer_start, timer_stop
  use subdomain, only: subdomain_t
  use b_operator, only: b_operator_t
  use constraints, only: constraints_t, row_contact
  use schur_complement, only: schur_complement_t
  use subdomain_classes, only: subdomain_classes_t
  use class_operator, only: class_operator_t
  use csr_matrix, only: csr_t
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
    logical :: shared = .false.                 !< 'lumped' applied per class (class_operator)
    type(class_operator_t) :: shared_op
    integer(i8) :: applications = 0
    !> D of the module: d_r per owned row (sqrt(n_r) on contact rows, 1 elsewhere)
    real(dp), allocatable :: d(:), dx(:)
  contains
    procedure :: init
    procedure :: apply
    procedure :: kind => kind_label
    procedure :: n_applications
    procedure :: row_scaling
    procedure :: factor_bytes
    procedure :: free
  end type dual_preconditioner_t

contains

  !> `variant`: 'lumped' or 'dirichlet'; `b` and `subs` (K assembled) must
  !> outlive the preconditioner; `weights(ls)` = w_s of local subdomain ls.
  !> `classes` (optional): classes of congruent subdomains of `subs`; with
  !> 'lumped' and some class of two members or more, A_s is applied per class.
  subroutine init(this, variant, b, subs, weights, classes)
    class(dual_preconditioner_t), intent(inout) :: this
    character(len=*), intent(in) :: variant
    type(b_operator_t), intent(inout), target :: b
    type(subdomain_t), intent(in), target :: subs(:)
    real(dp), intent(in) :: weights(:)
    type(subdomain_classes_t), intent(in), optional :: classes
    type(constraints_t), pointer :: con
    logical, allocatable :: on_interface(:)
    integer(ip) :: ls, e, r(2)

    call this%free()
    if (variant /= 'lumped' .and. variant /= 'dirichlet') &
      call fatal_error("dual_preconditioner: variant must be 'lumped' or 'dirichlet', got '"//trim(variant)//"'")
    if (size(weights) /= size(subs)) call fatal_error('dual_preconditioner: one weight per local subdomain')
    if (any(.not. weights > 0)) call fatal_error('dual_preconditioner: the subdomain weights must be > 0')
    this%kind_name = variant
    this%b => b
    this%subs => subs
    this%inv_w = 1/weights
    allocate (this%xall(b%n_concat()), this%yall(b%n_concat()))
    call contact_scaling(this, b, size(subs, kind=ip))
    if (variant == 'dirichlet') then
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
    if (variant == 'lumped' .and. present(classes)) then
      if (classes%shared()) call init_shared(this, b, subs, classes)
    end if
  end subroutine init

  !> 'lumped' per class: M_c = K_r(U_c, U_c) in CSR, a_s = c_s / w_s^2.
  subroutine init_shared(this, b, subs, classes)
    class(dual_preconditioner_t), intent(inout) :: this
    type(b_operator_t), intent(in) :: b
    type(subdomain_t), intent(in) :: subs(:)
    type(subdomain_classes_t), intent(in) :: classes
    integer(ip), allocatable :: dofs(:), cmap(:)
    type(csr_t) :: m
    integer(ip) :: c, r, i, k, n, j, nz
    call this%shared_op%init(b, classes, classes%scale*this%inv_w**2)
    do c = 1, classes%nclass
      r = classes%rep(c)
      call this%shared_op%class_dofs(b, c, dofs)
      n = size(dofs, kind=ip)
      allocate (cmap(subs(r)%ndof))
      cmap = 0
      do i = 1, n
        cmap(dofs(i)) = i
      end do
      ! K_r(U_c, U_c): the rows of U_c, the columns in U_c renumbered (ascending stays ascending)
      m%nrows = n
      m%ncols = n
      allocate (m%rowptr(n + 1))
      m%rowptr(1) = 1
      do i = 1, n
        nz = 0
        do k = subs(r)%K%rowptr(dofs(i)), subs(r)%K%rowptr(dofs(i) + 1) - 1
          if (cmap(subs(r)%K%colind(k)) > 0) nz = nz + 1
        end do
        m%rowptr(i + 1) = m%rowptr(i) + nz
      end do
      allocate (m%colind(m%rowptr(n + 1) - 1), m%values(m%rowptr(n + 1) - 1))
      do i = 1, n
        nz = m%rowptr(i)
        do k = subs(r)%K%rowptr(dofs(i)), subs(r)%K%rowptr(dofs(i) + 1) - 1
          j = cmap(subs(r)%K%colind(k))
          if (j == 0) cycle
          m%colind(nz) = j
          m%values(nz) = subs(r)%K%values(k)
          nz = nz + 1
        end do
      end do
      call this%shared_op%set_sparse(c, m)
      call m%free()
      deallocate (cmap)
    end do
    this%shared = .true.
  end subroutine init_shared

  !> y = M^{-1} x (dual vectors, owned rows). Collective.
  subroutine apply(this, x, y)
    class(dual_preconditioner_t), intent(inout) :: this
    real(dp), intent(in) :: x(:)
    real(dp), intent(inout) :: y(:)
    integer(ip) :: ls, r(2)
    if (.not. associated(this%b)) call fatal_error('dual_preconditioner: apply before init')
    call timer_start('preconditioner')
    this%dx = this%d*x(1:size(this%d))
    if (this%shared) then
      call this%shared_op%apply(this%b, this%dx, y)
      y(1:size(this%d)) = this%d*y(1:size(this%d))
      this%applications = this%applications + 1
      call timer_stop('preconditioner')
      return
    end if
    this%xall = 0
    call this%b%add_transpose(this%dx, 1.0_dp, this%xall)
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
    call this%b%apply_concat(this%yall, this%dx)
    y(1:size(this%d)) = this%d*this%dx
    this%applications = this%applications + 1
    call timer_stop('preconditioner')
  end subroutine apply

  !> d_r = sqrt(n_r), n_r = (sum_c v_c)^2 / sum_c v_c^2 over the entries v_c
  !> of contact row r on all copies (all ranks: the sums over this rank's
  !> subdomains are added up on the owner by one reverse exchange); 1 on
  !> the other rows. Collective.
  subroutine contact_scaling(this, b, nlocal)
    class(dual_preconditioner_t), intent(inout) :: this
    type(b_operator_t), intent(inout), target :: b
    integer(ip), intent(in) :: nlocal
    type(constraints_t), pointer :: con
    real(dp), allocatable :: loc(:, :), own(:, :)
    integer(ip) :: ls, e, i
    con => b%constraints()
    allocate (this%d(con%n_own), this%dx(con%n_own))
    allocate (loc(2, b%n_local_rows()), own(2, con%n_own))
    loc = 0
    do ls = 1, nlocal
      associate (bs => con%b(ls))
        do e = 1, bs%nentries
          loc(1, bs%row(e)) = loc(1, bs%row(e)) + bs%val(e)
          loc(2, bs%row(e)) = loc(2, bs%row(e)) + bs%val(e)**2
        end do
      end associate
    end do
    call con%exchange%scatter_add_multi(2, loc, own)
    this%d = 1
    do i = 1, con%n_own
      if (con%kind(i) == row_contact .and. own(2, i) > 0) this%d(i) = sqrt(own(1, i)**2/own(2, i))
    end do
  end subroutine contact_scaling

  !> d_r of the owned rows (see the module): sqrt(n_r) on contact rows, 1 elsewhere.
  function row_scaling(this) result(d)
    class(dual_preconditioner_t), intent(in) :: this
    real(dp), allocatable :: d(:)
    d = this%d
  end function row_scaling

  !> 'none' before init, else 'lumped' or 'dirichlet'.
  function kind_label(this) result(name)
    class(dual_preconditioner_t), intent(in) :: this
    character(len=:), allocatable :: name
    name = trim(this%kind_name)
  end function kind_label

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
    call this%shared_op%free()
    this%shared = .false.
    if (allocated(this%inv_w)) deallocate (this%inv_w)
    if (allocated(this%xall)) deallocate (this%xall, this%yall)
    if (allocated(this%d)) deallocate (this%d, this%dx)
    this%b => null()
    this%subs => null()
    this%kind_name = 'none'
    this%applications = 0
  end subroutine free
end module dual_preconditioner
