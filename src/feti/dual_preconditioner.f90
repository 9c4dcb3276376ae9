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
!> B (exchange back). With classes of congruent subdomains
!> (`&solver share_subdomains`, K_s = c_s K_r), A_s restricted to the dofs B
!> touches is applied to all the members of a class at once (class_operator,
!> the class's matrix on the union U_c of the class's touched dofs, read
!> once per application for all members):
!> - 'lumped': c_s K_r(U_c, U_c), in CSR;
!> - 'dirichlet': c_s S_r, S_r the dense Schur complement of K_r on U_c
!>   (schur_complement::stiffness_schur, one MUMPS elimination per class at
!>   setup), by one dgemm. A member that touches only the dofs a of U_c
!>   (a subdomain on a free or symmetry face: e = U_c \ a is interior for
!>   it) needs the Schur complement on a, S_aa - S_ae S_ee^{-1} S_ea (the
!>   quotient property of Schur complements): its column of X is extended by
!>   X(e) = W X(a), W = -S_ee^{-1} S_ea (one Cholesky of S_ee per group of
!>   members with the same a, at setup), before the class's dgemm. The
!>   result is the per-subdomain preconditioner's, up to rounding.
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
  use subdomain, only: subdomain_t, stiffness_matvec
  use b_operator, only: b_operator_t
  use constraints, only: constraints_t, row_contact
  use schur_complement, only: schur_complement_t, stiffness_schur, dense_schur
  use lapack_interfaces, only: dpotrf, dtrsm
  use sorting, only: sort_unique, binary_search
  use subdomain_classes, only: subdomain_classes_t
  use f_operator, only: f_operator_t
  use class_operator, only: class_operator_t, class_parts_t
  use csr_matrix, only: csr_t
  implicit none
  private

  type, public :: dual_preconditioner_t
    private
    character(len=name_len) :: kind_name = 'none'
    type(b_operator_t), pointer :: b => null()
    type(subdomain_t), pointer :: subs(:) => null()
    real(dp), allocatable :: inv_w(:)           !< (nlocal) 1/w_s
    real(dp), allocatable :: inv_wd(:)          !< (n_concat) 1/w per dof (dof_weights), else unallocated
    real(dp), allocatable :: xall(:), yall(:)   !< work: concatenated primal vectors
    type(schur_complement_t) :: schur
    logical :: shared = .false.                 !< applied per class (class_operator)
    logical :: by_parts = .false.               !< 'dirichlet' per class with one block per subdomain of a cluster
    integer(i8) :: shared_bytes = 0             !< the dense S_r and W ('dirichlet' per class)
    real(dp) :: setup_flops = 0                 !< MUMPS eliminations and LAPACK of the shared setup
    type(class_operator_t) :: shared_op
    !> 'dirichlet' with the dense local solver: S_s from its factors (f_operator%apply_dense_schur)
    type(f_operator_t), pointer :: fop => null()
    real(dp), allocatable :: inv_w2(:)          !< 1/w_s^2 (dense path)
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
    procedure :: setup_flop_count
    procedure :: is_shared
    procedure :: is_by_parts
    procedure :: is_dense
    procedure :: free
  end type dual_preconditioner_t

contains

  !> `variant`: 'lumped' or 'dirichlet'; `b` and `subs` (K assembled) must
  !> outlive the preconditioner; `weights(ls)` = w_s of local subdomain ls.
  !> `classes` (optional): classes of congruent subdomains of `subs`; when
  !> they are shared (subdomain_classes_t%shared), A_s is applied per class.
  !> `dof_weights` (optional, one per dof of the concatenated vector): w per
  !> dof instead of per subdomain (clusters of several moduli); per unit then.
  subroutine init(this, variant, b, subs, weights, classes, dense, dof_weights)
    class(dual_preconditioner_t), intent(inout) :: this
    character(len=*), intent(in) :: variant
    type(b_operator_t), intent(inout), target :: b
    type(subdomain_t), intent(in), target :: subs(:)
    real(dp), intent(in) :: weights(:)
    type(subdomain_classes_t), intent(in), optional :: classes
    type(f_operator_t), intent(in), target, optional :: dense
    real(dp), intent(in), optional :: dof_weights(:)
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
    if (present(dof_weights)) then
      if (size(dof_weights) /= b%n_concat() .or. any(.not. dof_weights > 0)) &
        call fatal_error('dual_preconditioner: dof_weights must be > 0, one per dof')
      this%inv_wd = 1/dof_weights
    end if
    if (present(classes) .and. .not. present(dof_weights)) then
      if (classes%shared()) then
        if (variant == 'lumped') call init_shared(this, b, subs, classes)
        if (variant == 'dirichlet') call init_shared_dirichlet(this, b, subs, classes)
        return
      end if
    end if
    if (variant == 'dirichlet' .and. present(dense) .and. .not. present(dof_weights)) then
      ! S_s from the dense local solver's factors: nothing to set up
      this%fop => dense
      this%inv_w2 = this%inv_w**2
      return
    end if
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
  end subroutine init

  !> 'dirichlet' per class: M_c = S_r, the dense Schur complement of K_r on
  !> U_c, a_s = c_s / w_s^2; the members that touch only a part a of U_c
  !> get the extension X(e) = -S_ee^{-1} S_ea X(a) (see the module). With
  !> clusters glued by faces (units whose nodes are copies of several
  !> subdomains, none merged) K_r is block diagonal over the subdomains of
  !> the cluster, and so is S_r: one dense block per subdomain of the
  !> class's clusters (class_operator%init_parts), from the subdomain's
  !> block of K_r alone.
  subroutine init_shared_dirichlet(this, b, subs, classes)
    class(dual_preconditioner_t), intent(inout) :: this
    type(b_operator_t), intent(in) :: b
    type(subdomain_t), intent(in) :: subs(:)
    type(subdomain_classes_t), intent(in) :: classes
    type(class_parts_t), allocatable :: parts(:)
    integer(ip), allocatable :: dofs(:)
    real(dp), allocatable :: sd(:, :)
    real(dp) :: flops
    integer(ip) :: c, n, pc
    this%by_parts = subdomain_parts(subs, classes, parts)
    if (this%by_parts) then
      call this%shared_op%init_parts(b, classes, classes%scale*this%inv_w**2, parts)
    else
      call this%shared_op%init(b, classes, classes%scale*this%inv_w**2)
    end if
    flops = 0
    this%shared_bytes = 0
    do c = 1, this%shared_op%classes%nclass
      call this%shared_op%class_dofs(b, c, dofs)
      n = size(dofs, kind=ip)
      if (n == 0) cycle
      if (this%by_parts) then
        pc = this%shared_op%parent_of_class(c)
        call part_schur(subs(classes%rep(pc)), parts(pc)%of, this%shared_op%part_of_class(c), dofs, sd, flops)
      else
        call stiffness_schur(subs(this%shared_op%classes%rep(c)), dofs, sd, flops)
      end if
      call this%shared_op%set_matrix(c, sd)
      this%shared_bytes = this%shared_bytes + 8*int(n, i8)*n
      call add_extensions(this, c, n, sd, flops)
    end do
    this%setup_flops = flops
    this%shared = .true.
  end subroutine init_shared_dirichlet

  !> The members of class `c` of the shared operator (n = n_c, sd = S_c)
  !> that touch only a part a of U_c, grouped by a: X(e) = W X(a),
  !> W = -S_ee^{-1} S_ea per group (one Cholesky of S_ee).
  subroutine add_extensions(this, c, n, sd, flops)
    class(dual_preconditioner_t), intent(inout) :: this
    integer(ip), intent(in) :: c, n
    real(dp), intent(in) :: sd(:, :)
    real(dp), intent(inout) :: flops
    type :: group_t
      integer(ip), allocatable :: a(:), cols(:)
    end type group_t
    type(group_t), allocatable :: groups(:), tmp(:)
    integer(ip), allocatable :: pos(:), e(:), cols(:)
    logical, allocatable :: in_a(:)
    real(dp), allocatable :: see(:, :), w(:, :)
    integer(ip) :: kk, s, np, ng, g, na, ne, i
    integer :: info
    associate (cl => this%shared_op%classes)
      ! the members by the positions in U_c their B^_s touch
      allocate (groups(4))
      ng = 0
      do kk = cl%moff(c) + 1, cl%moff(c + 1)
        s = cl%member(kk)
        pos = this%shared_op%edof(this%shared_op%eoff(s) + 1:this%shared_op%eoff(s + 1))
        call sort_unique(pos, np)
        if (np == n) cycle
        do g = 1, ng
          if (size(groups(g)%a) /= np) cycle
          if (all(groups(g)%a == pos(1:np))) exit
        end do
        if (g > ng) then
          if (ng == size(groups)) then
            allocate (tmp(2*ng))
            tmp(1:ng) = groups
            call move_alloc(tmp, groups)
          end if
          ng = ng + 1
          groups(ng)%a = pos(1:np)
          allocate (groups(ng)%cols(0))
        end if
        groups(g)%cols = [groups(g)%cols, kk - cl%moff(c)]
      end do
    end associate
    do g = 1, ng
      na = size(groups(g)%a, kind=ip)
      allocate (in_a(n))
      in_a = .false.
      in_a(groups(g)%a) = .true.
      e = pack([(i, i=1, n)], .not. in_a)
      ne = size(e, kind=ip)
      see = sd(e, e)
      w = sd(e, groups(g)%a)
      call dpotrf('U', ne, see, ne, info)
      if (info /= 0) call fatal_error('dual_preconditioner: S_ee of a class is not positive definite '// &
                                      '(a subdomain whose touched dofs do not hold its rigid body motions)')
      ! W = -S_ee^{-1} S_ea = -U^{-1} U^{-T} S_ea
      call dtrsm('L', 'U', 'T', 'N', ne, na, -1.0_dp, see, ne, w, ne)
      call dtrsm('L', 'U', 'N', 'N', ne, na, 1.0_dp, see, ne, w, ne)
      flops = flops + real(ne, dp)**3/3 + 2*real(ne, dp)**2*na
      cols = groups(g)%cols
      call this%shared_op%add_extension(c, cols, groups(g)%a, e, w)
      this%shared_bytes = this%shared_bytes + 8*int(ne, i8)*na
      deallocate (in_a)
    end do
  end subroutine add_extensions

  !> The split of every class representative's dofs by the subdomain whose
  !> copy each node is (subdomain_t%node_copy: clusters glued by faces), in
  !> the order of the subdomain ids; false (no parts) unless every
  !> representative is such a cluster.
  logical function subdomain_parts(subs, classes, parts) result(yes)
    type(subdomain_t), intent(in) :: subs(:)
    type(subdomain_classes_t), intent(in) :: classes
    type(class_parts_t), allocatable, intent(out) :: parts(:)
    integer(ip), allocatable :: ids(:)
    integer(ip) :: c, a, n
    yes = .false.
    do c = 1, classes%nclass
      associate (rep => subs(classes%rep(c)))
        if (.not. allocated(rep%node_copy)) return
        if (any(rep%node_copy < 1)) return
      end associate
    end do
    allocate (parts(classes%nclass))
    do c = 1, classes%nclass
      associate (rep => subs(classes%rep(c)))
        ids = rep%node_copy
        call sort_unique(ids, n)
        allocate (parts(c)%of(rep%ndof))
        do a = 1, rep%nnodes
          parts(c)%of(3*a - 2:3*a) = binary_search(ids(1:n), rep%node_copy(a))
        end do
      end associate
    end do
    yes = .true.
  end function subdomain_parts

  !> sd = the dense Schur complement on `dofs` (the unit's local dofs, all of
  !> part `p` of `part_of`) of the block of K of `sub` on the dofs of part p.
  subroutine part_schur(sub, part_of, p, dofs, sd, flops)
    type(subdomain_t), intent(in) :: sub
    integer(ip), intent(in) :: part_of(:), p, dofs(:)
    real(dp), allocatable, intent(out) :: sd(:, :)
    real(dp), intent(inout) :: flops
    integer(ip), allocatable :: irn(:), jcn(:), loc(:), keep(:)
    real(dp), allocatable :: a(:)
    integer(ip) :: i, nb
    call sub%K%upper_coo(irn, jcn, a)
    allocate (loc(sub%ndof))
    loc = 0
    nb = 0
    do i = 1, sub%ndof
      if (part_of(i) /= p) cycle
      nb = nb + 1
      loc(i) = nb
    end do
    if (any(loc(dofs) == 0)) call fatal_error('dual_preconditioner: a touched dof outside its part')
    keep = pack([(i, i=1, size(irn, kind=ip))], loc(irn) > 0 .and. loc(jcn) > 0)
    if (any(loc(irn) > 0 .neqv. loc(jcn) > 0)) &
      call fatal_error('dual_preconditioner: K couples two parts of a cluster glued by faces')
    call dense_schur(nb, loc(irn(keep)), loc(jcn(keep)), a(keep), loc(dofs), sd, flops)
  end subroutine part_schur

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
    if (associated(this%fop)) then
      call this%fop%apply_dense_schur(this%b, this%dx, y, this%inv_w2)
      y(1:size(this%d)) = this%d*y(1:size(this%d))
      this%applications = this%applications + 1
      call timer_stop('preconditioner')
      return
    end if
    this%xall = 0
    call this%b%add_transpose(this%dx, 1.0_dp, this%xall)
    if (allocated(this%inv_wd)) then
      this%xall = this%inv_wd*this%xall
    else
      do ls = 1, size(this%subs, kind=ip)
        r = this%b%dof_range(ls)
        this%xall(r(1):r(2)) = this%inv_w(ls)*this%xall(r(1):r(2))
      end do
    end if
    if (this%kind_name == 'dirichlet') then
      call this%schur%apply(this%subs, this%xall)
      this%yall = this%xall
    else
      do ls = 1, size(this%subs, kind=ip)
        r = this%b%dof_range(ls)
        call stiffness_matvec(this%subs, ls, this%xall(r(1):r(2)), this%yall(r(1):r(2)))
      end do
    end if
    if (allocated(this%inv_wd)) then
      this%yall = this%inv_wd*this%yall
    else
      do ls = 1, size(this%subs, kind=ip)
        r = this%b%dof_range(ls)
        this%yall(r(1):r(2)) = this%inv_w(ls)*this%yall(r(1):r(2))
      end do
    end if
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

  !> Bytes of the K_ii factors ('dirichlet'), or of the dense S_r and W
  !> ('dirichlet' per class); 0 otherwise.
  integer(i8) function factor_bytes(this)
    class(dual_preconditioner_t), intent(in) :: this
    factor_bytes = this%schur%factor_bytes() + this%shared_bytes
  end function factor_bytes

  !> Flops of the setup of 'dirichlet' per class (MUMPS eliminations, LAPACK).
  real(dp) function setup_flop_count(this)
    class(dual_preconditioner_t), intent(in) :: this
    setup_flop_count = this%setup_flops
  end function setup_flop_count

  !> True when A_s is applied per class of congruent subdomains.
  !> True when 'dirichlet' takes S_s from the dense local solver's factors.
  logical function is_dense(this)
    class(dual_preconditioner_t), intent(in) :: this
    is_dense = associated(this%fop)
  end function is_dense

  !> 'dirichlet' per class of clusters glued by faces, one dense block per
  !> subdomain of a cluster (class_operator%init_parts).
  logical function is_by_parts(this)
    class(dual_preconditioner_t), intent(in) :: this
    is_by_parts = this%by_parts
  end function is_by_parts

  logical function is_shared(this)
    class(dual_preconditioner_t), intent(in) :: this
    is_shared = this%shared
  end function is_shared

  subroutine free(this)
    class(dual_preconditioner_t), intent(inout) :: this
    call this%schur%free()
    call this%shared_op%free()
    this%shared = .false.
    this%by_parts = .false.
    this%shared_bytes = 0
    this%setup_flops = 0
    if (allocated(this%inv_w)) deallocate (this%inv_w)
    if (allocated(this%inv_wd)) deallocate (this%inv_wd)
    if (allocated(this%xall)) deallocate (this%xall, this%yall)
    if (allocated(this%d)) deallocate (this%d, this%dx)
    if (allocated(this%inv_w2)) deallocate (this%inv_w2)
    this%fop => null()
    this%b => null()
    this%subs => null()
    this%kind_name = 'none'
    this%applications = 0
  end subroutine free
end module dual_preconditioner
