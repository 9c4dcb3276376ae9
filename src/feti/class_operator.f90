!> Dual operators of the form
!>
!>     y = sum_s a_s B^_s M_c(s) B^_s^T x,
!>
!> with one dense symmetric matrix M_c per class c of congruent subdomains
!> (subdomain_classes) on the union U_c of the dofs that B touches in the
!> class (n_c of them, the representative's local numbering), and a factor
!> a_s per subdomain. B^_s: the entries of B^s with the dofs numbered in U_c.
!> One application: gather the dual rows (neighbour exchange), per class the
!> members' a_s B^_s^T x as the columns of X (n_c x m_c), Y = M_c X by ONE
!> dgemm, y_s += B^_s Y(:, s), scatter-add. Used by f_operator (M_c = S^_c,
!> the inverse of K_reg's Schur complement, a_s = 1/c_s) and by
!> dual_preconditioner ('lumped': M_c = K_r(U_c, U_c), a_s = c_s / w_s^2).
!> The class's matrix is read once per application for all its members, so
!> the work is compute bound (dgemm) instead of memory bound. A sparse M_c
!> (set_sparse: CSR, the lumped preconditioner's K_r(U_c, U_c)) is applied
!> with the members' vectors as the rows of X^T (m_c x n_c): one contiguous
!> axpy of length m_c per entry of M_c.
!>
!> Extensions (add_extension, dense M_c only): for the members of a class
!> whose B^_s touch only the dofs a of U_c (e = U_c \ a), the column of X is
!> completed before the dgemm by X(e, s) = W X(a, s), one dgemm per group
!> of such members. With M_c = S_U (a Schur complement on U_c) and
!> W = -S_ee^{-1} S_ea, (M_c X)(a) = (S_aa - S_ae S_ee^{-1} S_ea) X(a): the
!> Schur complement on a itself (the quotient property), which is what the
!> Dirichlet preconditioner needs for a member that touches fewer dofs than
!> its class (dual_preconditioner).
!>
!> Parts (init_parts): when every class's matrix is block diagonal over a
!> split of its dofs into parts (a cluster glued by faces: K_bd =
!> blockdiag(K_s), and so its Schur complement on the dofs B touches), the
!> operator's classes are the pairs (class, part) and its members the pairs
!> (subdomain, part); M_k lives on the part's touched dofs U_k alone, and
!> one application costs sum_k 2 n_k^2 m_k flops instead of 2 n_c^2 m_c
!> (a cluster of 8 subdomains: 8 times less).
module class_operator
  use kinds, only: dp, ip, i8
  use lapack_interfaces, only: dgemm
  use errors, only: fatal_error
  use b_operator, only: b_operator_t
  use sorting, only: sort_unique
  use subdomain_classes, only: subdomain_classes_t
  use csr_matrix, only: csr_t
  implicit none
  private

  public :: sandwich

  !> The parts of one class's dofs (init_parts): of(d) = the part (1..) of
  !> the class's local dof d, 0 for a dof of no part.
  type, public :: class_parts_t
    integer(ip), allocatable :: of(:)
  end type class_parts_t

  !> X(e, cols) = w X(a, cols) for the members `cols` (1..m_c) of class c.
  type :: extension_t
    integer(ip) :: c = 0
    integer(ip), allocatable :: cols(:), a(:), e(:)
    real(dp), allocatable :: w(:, :)             !< n_e x n_a
  end type extension_t

  type, public :: class_operator_t
    type(subdomain_classes_t) :: classes
    integer(ip), allocatable :: cn(:)             !< (nclass) n_c
    integer(i8), allocatable :: coff(:)           !< (nclass+1) offsets of M_c (n_c x n_c, full) in mat
    real(dp), allocatable :: mat(:)
    real(dp), allocatable :: factor(:)            !< (nsub) a_s
    integer(ip), allocatable :: eoff(:)           !< (nsub+1) offsets of the entries of B^_s
    integer(ip), allocatable :: erow(:), edof(:)  !< local dual row, dof in U_c (1..n_c)
    real(dp), allocatable :: eval(:)
    integer(ip) :: n_local_rows = 0
    logical :: sparse = .false.                   !< M_c in CSR (set_sparse) instead of dense
    type(csr_t), allocatable :: smat(:)           !< (nclass) sparse M_c
    type(extension_t), allocatable :: ext(:)       !< add_extension
    integer(ip) :: next = 0
    real(dp), allocatable, private :: xa(:), xe(:)
    real(dp), allocatable, private :: xw(:), yw(:), wloc(:), wloc2(:)
    !> init_parts only: the operator's class k is part part_of_class(k) of class
    !> parent_of_class(k) of the classes given; unit u (member) is of subdomain
    !> sub_of_unit(u); U_k in the class's local numbering: udof(uoff(k)+1:uoff(k+1))
    integer(ip), allocatable :: parent_of_class(:), part_of_class(:), sub_of_unit(:)
    integer(ip), allocatable :: uoff(:), udof(:)
  contains
    procedure :: init
    procedure :: init_parts
    procedure :: class_dofs
    procedure :: set_matrix
    procedure :: set_sparse
    procedure :: add_extension
    procedure :: apply
    procedure :: local_matrix
    procedure :: bytes_per_action
    procedure :: flops_per_action
    procedure :: free
  end type class_operator_t

contains

  !> The union dofs and the entries of B^_s per class of `classes` (from B);
  !> the matrices are set afterwards by set_matrix, a_s = `factor(s)`.
  subroutine init(this, b, classes, factor)
    class(class_operator_t), intent(inout) :: this
    type(b_operator_t), intent(in) :: b
    type(subdomain_classes_t), intent(in) :: classes
    real(dp), intent(in) :: factor(:)
    integer(ip), allocatable :: row(:), dof(:), dofs(:), cmap(:)
    real(dp), allocatable :: val(:)
    integer(ip) :: nsub, s, c, n, ne, kk, e, wmax, i
    call this%free()
    this%classes = classes
    nsub = size(classes%class_of, kind=ip)
    if (size(factor, kind=ip) /= nsub) call fatal_error('class_operator%init: one factor per subdomain')
    this%factor = factor
    this%n_local_rows = b%n_local_rows()
    allocate (this%cn(classes%nclass), this%coff(classes%nclass + 1), this%eoff(nsub + 1))
    ne = 0
    this%eoff(1) = 0
    do s = 1, nsub
      call b%subdomain_entries(s, row, dof, val)
      ne = ne + size(row, kind=ip)
      this%eoff(s + 1) = ne
    end do
    allocate (this%erow(ne), this%edof(ne), this%eval(ne))
    this%coff(1) = 0
    wmax = 1
    do c = 1, classes%nclass
      call this%class_dofs(b, c, dofs)
      n = size(dofs, kind=ip)
      this%cn(c) = n
      this%coff(c + 1) = this%coff(c) + int(n, i8)*n
      wmax = max(wmax, n*(classes%moff(c + 1) - classes%moff(c)))
      allocate (cmap(maxval([0_ip, dofs])))
      cmap = 0
      do i = 1, n
        cmap(dofs(i)) = i
      end do
      do kk = classes%moff(c) + 1, classes%moff(c + 1)
        s = classes%member(kk)
        call b%subdomain_entries(s, row, dof, val)
        do e = 1, size(row, kind=ip)
          this%erow(this%eoff(s) + e) = row(e)
          this%edof(this%eoff(s) + e) = cmap(dof(e))
          this%eval(this%eoff(s) + e) = val(e)
        end do
      end do
      deallocate (cmap)
    end do
    ! the dense M_c are allocated by the first set_matrix: a sparse operator
    ! (set_sparse) never holds them, not even for a moment
    allocate (this%xw(wmax), this%yw(wmax))
    allocate (this%wloc(max(1, this%n_local_rows)), this%wloc2(max(1, this%n_local_rows)))
  end subroutine init

  !> As init, with the dofs of every class c of `classes` split into parts
  !> (parts(c)%of, see class_parts_t; every dof B touches must be in a part):
  !> the operator's classes are the pairs (c, p) with p = 1..maxval(parts(c)%of)
  !> in that order, its members the pairs (s, p) of the members s of c, with
  !> a_(s,p) = factor(s) (parent_of_class, part_of_class, sub_of_unit).
  subroutine init_parts(this, b, classes, factor, parts)
    class(class_operator_t), intent(inout) :: this
    type(b_operator_t), intent(in) :: b
    type(subdomain_classes_t), intent(in) :: classes
    real(dp), intent(in) :: factor(:)
    type(class_parts_t), intent(in) :: parts(:)
    integer(ip), allocatable :: row(:), dof(:), cmap(:), first(:), fill(:), raw(:), tmp(:)
    real(dp), allocatable :: val(:)
    integer(ip) :: nsub, c, p, np, k, u, kk, s, e, m, n, ne, nk, wmax, i
    call this%free()
    nsub = size(classes%class_of, kind=ip)
    if (size(factor, kind=ip) /= nsub) call fatal_error('class_operator%init_parts: one factor per subdomain')
    if (size(parts, kind=ip) /= classes%nclass) call fatal_error('class_operator%init_parts: one split per class')
    nk = 0
    do c = 1, classes%nclass
      nk = nk + maxval([0_ip, parts(c)%of])
    end do
    ! the classes (c, p) and their members (s, p), numbered class by class
    associate (pc => this%classes)
      pc%nclass = nk
      allocate (pc%rep(nk), pc%moff(nk + 1), this%parent_of_class(nk), this%part_of_class(nk), first(classes%nclass))
      pc%moff(1) = 0
      k = 0
      do c = 1, classes%nclass
        first(c) = k
        m = classes%moff(c + 1) - classes%moff(c)
        do p = 1, maxval([0_ip, parts(c)%of])
          k = k + 1
          this%parent_of_class(k) = c
          this%part_of_class(k) = p
          pc%moff(k + 1) = pc%moff(k) + m
          pc%rep(k) = pc%moff(k) + 1
        end do
      end do
      u = pc%moff(nk + 1)
      allocate (pc%class_of(u), pc%member(u), pc%column(u), pc%scale(u), this%sub_of_unit(u), this%factor(u))
      pc%member = [(i, i=1, u)]
      do k = 1, nk
        c = this%parent_of_class(k)
        do kk = classes%moff(c) + 1, classes%moff(c + 1)
          u = pc%moff(k) + kk - classes%moff(c)
          s = classes%member(kk)
          pc%class_of(u) = k
          pc%column(u) = kk - classes%moff(c)
          pc%scale(u) = classes%scale(s)
          this%sub_of_unit(u) = s
          this%factor(u) = factor(s)
        end do
      end do
      pc%max_deviation = classes%max_deviation
      ! the entries of B^s by part: counted, then filled (raw: the class's local dof)
      allocate (this%eoff(size(pc%member) + 1), fill(size(pc%member)))
      this%eoff = 0
      do c = 1, classes%nclass
        do kk = classes%moff(c) + 1, classes%moff(c + 1)
          call b%subdomain_entries(classes%member(kk), row, dof, val)
          do e = 1, size(dof, kind=ip)
            p = 0
            if (dof(e) <= size(parts(c)%of)) p = parts(c)%of(dof(e))
            if (p < 1) call fatal_error('class_operator%init_parts: B touches a dof of no part')
            u = pc%moff(first(c) + p) + kk - classes%moff(c)
            this%eoff(u + 1) = this%eoff(u + 1) + 1
          end do
        end do
      end do
      do u = 1, size(pc%member, kind=ip)
        this%eoff(u + 1) = this%eoff(u + 1) + this%eoff(u)
      end do
      ne = this%eoff(size(pc%member) + 1)
      allocate (this%erow(ne), this%edof(ne), this%eval(ne), raw(ne))
      fill = this%eoff(1:size(pc%member))
      do c = 1, classes%nclass
        do kk = classes%moff(c) + 1, classes%moff(c + 1)
          call b%subdomain_entries(classes%member(kk), row, dof, val)
          do e = 1, size(dof, kind=ip)
            u = pc%moff(first(c) + parts(c)%of(dof(e))) + kk - classes%moff(c)
            fill(u) = fill(u) + 1
            this%erow(fill(u)) = row(e)
            raw(fill(u)) = dof(e)
            this%eval(fill(u)) = val(e)
          end do
        end do
      end do
      ! U_k and the entries' positions in it
      this%n_local_rows = b%n_local_rows()
      allocate (this%cn(nk), this%coff(nk + 1), this%uoff(nk + 1), this%udof(0))
      this%coff(1) = 0
      this%uoff(1) = 0
      wmax = 1
      do k = 1, nk
        tmp = raw(this%eoff(pc%moff(k) + 1) + 1:this%eoff(pc%moff(k + 1) + 1))
        call sort_unique(tmp, n)
        this%udof = [this%udof, tmp(1:n)]
        this%uoff(k + 1) = this%uoff(k) + n
        this%cn(k) = n
        this%coff(k + 1) = this%coff(k) + int(n, i8)*n
        wmax = max(wmax, n*(pc%moff(k + 1) - pc%moff(k)))
        allocate (cmap(maxval([0_ip, tmp(1:n)])))
        cmap = 0
        do i = 1, n
          cmap(tmp(i)) = i
        end do
        do e = this%eoff(pc%moff(k) + 1) + 1, this%eoff(pc%moff(k + 1) + 1)
          this%edof(e) = cmap(raw(e))
        end do
        deallocate (cmap)
      end do
    end associate
    allocate (this%xw(wmax), this%yw(wmax))
    allocate (this%wloc(max(1, this%n_local_rows)), this%wloc2(max(1, this%n_local_rows)))
  end subroutine init_parts

  !> U_c: the union over the members of class `c` of the dofs B^s touches
  !> (ascending, local numbering of the class).
  subroutine class_dofs(this, b, c, dofs)
    class(class_operator_t), intent(in) :: this
    type(b_operator_t), intent(in) :: b
    integer(ip), intent(in) :: c
    integer(ip), allocatable, intent(out) :: dofs(:)
    integer(ip), allocatable :: row(:), dof(:), all(:)
    real(dp), allocatable :: val(:)
    integer(ip) :: k, n, total
    if (allocated(this%udof)) then
      dofs = this%udof(this%uoff(c) + 1:this%uoff(c + 1))
      return
    end if
    total = 0
    do k = this%classes%moff(c) + 1, this%classes%moff(c + 1)
      call b%subdomain_entries(this%classes%member(k), row, dof, val)
      total = total + size(dof, kind=ip)
    end do
    allocate (all(total))
    total = 0
    do k = this%classes%moff(c) + 1, this%classes%moff(c + 1)
      call b%subdomain_entries(this%classes%member(k), row, dof, val)
      all(total + 1:total + size(dof)) = dof
      total = total + size(dof, kind=ip)
    end do
    call sort_unique(all, n)
    dofs = all(1:n)
  end subroutine class_dofs

  !> M_c = `m` (n_c x n_c, symmetric, both triangles).
  subroutine set_matrix(this, c, m)
    class(class_operator_t), intent(inout) :: this
    integer(ip), intent(in) :: c
    real(dp), intent(in) :: m(:, :)
    integer(ip) :: n
    n = this%cn(c)
    if (size(m, 1) /= n .or. size(m, 2) /= n) call fatal_error('class_operator%set_matrix: n_c x n_c expected')
    if (this%sparse) call fatal_error('class_operator%set_matrix: the classes are set sparse')
    if (.not. allocated(this%mat)) allocate (this%mat(this%coff(this%classes%nclass + 1)))
    this%mat(this%coff(c) + 1:this%coff(c + 1)) = reshape(m, [int(n, i8)*n])
  end subroutine set_matrix

  !> M_c = `m` (n_c x n_c CSR, symmetric, both triangles); then every class
  !> must be set this way.
  subroutine set_sparse(this, c, m)
    class(class_operator_t), intent(inout) :: this
    integer(ip), intent(in) :: c
    type(csr_t), intent(in) :: m
    if (m%nrows /= this%cn(c) .or. m%ncols /= this%cn(c)) call fatal_error('class_operator%set_sparse: n_c x n_c expected')
    if (allocated(this%mat)) call fatal_error('class_operator%set_sparse: the classes are set dense')
    if (.not. allocated(this%smat)) allocate (this%smat(this%classes%nclass))
    this%smat(c) = m
    this%sparse = .true.
  end subroutine set_sparse

  !> Before the dgemm of class `c`, complete the columns `cols` (positions
  !> among the class's members) of X by X(e, cols) = w X(a, cols) (a, e:
  !> disjoint positions in U_c; w: n_e x n_a). Dense M_c only.
  subroutine add_extension(this, c, cols, a, e, w)
    class(class_operator_t), intent(inout) :: this
    integer(ip), intent(in) :: c, cols(:), a(:), e(:)
    real(dp), intent(in) :: w(:, :)
    type(extension_t), allocatable :: tmp(:)
    integer(ip) :: na, ne
    if (this%sparse) call fatal_error('class_operator%add_extension: dense classes only')
    if (size(w, 1) /= size(e) .or. size(w, 2) /= size(a)) call fatal_error('class_operator%add_extension: w is n_e x n_a')
    if (.not. allocated(this%ext)) allocate (this%ext(4))
    if (this%next == size(this%ext)) then
      allocate (tmp(2*this%next))
      tmp(1:this%next) = this%ext
      call move_alloc(tmp, this%ext)
    end if
    this%next = this%next + 1
    this%ext(this%next)%c = c
    this%ext(this%next)%cols = cols
    this%ext(this%next)%a = a
    this%ext(this%next)%e = e
    this%ext(this%next)%w = w
    na = size(a, kind=ip)*size(cols, kind=ip)
    ne = size(e, kind=ip)*size(cols, kind=ip)
    if (.not. allocated(this%xa)) allocate (this%xa(1), this%xe(1))
    if (size(this%xa) < na) then
      deallocate (this%xa)
      allocate (this%xa(na))
    end if
    if (size(this%xe) < ne) then
      deallocate (this%xe)
      allocate (this%xe(ne))
    end if
  end subroutine add_extension

  !> y = sum_s a_s B^_s M_c(s) B^_s^T x (dual vectors, owned rows). Collective
  !> (the neighbour exchange of B).
  subroutine apply(this, b, x, y)
    class(class_operator_t), intent(inout) :: this
    type(b_operator_t), intent(inout) :: b
    real(dp), intent(in) :: x(:)
    real(dp), intent(inout) :: y(:)
    integer(ip) :: c, n, m, kk, s, e, j
    integer(i8) :: o
    real(dp) :: w
    call b%gather_rows(x, this%wloc)
    this%wloc2 = 0
    associate (cl => this%classes)
      do c = 1, cl%nclass
        n = this%cn(c)
        m = cl%moff(c + 1) - cl%moff(c)
        if (n == 0) cycle
        if (this%sparse) then
          call apply_sparse(c, n, m, this%xw, this%yw)
          cycle
        end if
        this%xw(1:n*m) = 0
        do kk = cl%moff(c) + 1, cl%moff(c + 1)
          s = cl%member(kk)
          o = int(kk - cl%moff(c) - 1, i8)*n
          w = this%factor(s)
          do e = this%eoff(s) + 1, this%eoff(s + 1)
            j = this%edof(e)
            this%xw(o + j) = this%xw(o + j) + w*this%eval(e)*this%wloc(this%erow(e))
          end do
        end do
        do j = 1, this%next
          if (this%ext(j)%c == c) call extend(this%ext(j), n)
        end do
        call dgemm('N', 'N', n, m, n, 1.0_dp, this%mat(this%coff(c) + 1), n, this%xw, n, 0.0_dp, this%yw, n)
        do kk = cl%moff(c) + 1, cl%moff(c + 1)
          s = cl%member(kk)
          o = int(kk - cl%moff(c) - 1, i8)*n
          do e = this%eoff(s) + 1, this%eoff(s + 1)
            this%wloc2(this%erow(e)) = this%wloc2(this%erow(e)) + this%eval(e)*this%yw(o + this%edof(e))
          end do
        end do
      end do
    end associate
    call b%scatter_rows(this%wloc2, y)
  contains
    !> X(e, cols) = w X(a, cols) for one extension of the current class.
    subroutine extend(ex, n)
      type(extension_t), intent(in) :: ex
      integer(ip), intent(in) :: n
      integer(ip) :: na, ne, mp, q, i
      integer(i8) :: oo
      na = size(ex%a, kind=ip)
      ne = size(ex%e, kind=ip)
      mp = size(ex%cols, kind=ip)
      do q = 1, mp
        oo = int(ex%cols(q) - 1, i8)*n
        do i = 1, na
          this%xa((q - 1)*na + i) = this%xw(oo + ex%a(i))
        end do
      end do
      call dgemm('N', 'N', ne, mp, na, 1.0_dp, ex%w, ne, this%xa, na, 0.0_dp, this%xe, ne)
      do q = 1, mp
        oo = int(ex%cols(q) - 1, i8)*n
        do i = 1, ne
          this%xw(oo + ex%e(i)) = this%xe((q - 1)*ne + i)
        end do
      end do
    end subroutine extend

    !> Class c with a sparse M_c: X^T and Y^T are m x n (member, dof).
    subroutine apply_sparse(c, n, m, xt, yt)
      integer(ip), intent(in) :: c, n, m
      real(dp), intent(inout) :: xt(m, n), yt(m, n)
      integer(ip) :: i, k, col
      associate (cl => this%classes, a => this%smat(c))
        xt = 0
        do kk = cl%moff(c) + 1, cl%moff(c + 1)
          s = cl%member(kk)
          col = kk - cl%moff(c)
          w = this%factor(s)
          do e = this%eoff(s) + 1, this%eoff(s + 1)
            j = this%edof(e)
            xt(col, j) = xt(col, j) + w*this%eval(e)*this%wloc(this%erow(e))
          end do
        end do
        do i = 1, n
          yt(:, i) = 0
          do k = a%rowptr(i), a%rowptr(i + 1) - 1
            yt(:, i) = yt(:, i) + a%values(k)*xt(:, a%colind(k))
          end do
        end do
        do kk = cl%moff(c) + 1, cl%moff(c + 1)
          s = cl%member(kk)
          col = kk - cl%moff(c)
          do e = this%eoff(s) + 1, this%eoff(s + 1)
            this%wloc2(this%erow(e)) = this%wloc2(this%erow(e)) + this%eval(e)*yt(col, this%edof(e))
          end do
        end do
      end associate
    end subroutine apply_sparse
  end subroutine apply

  !> The dense a_s B^_s M_c B^_s^T of local subdomain `s` on its local dual
  !> rows `rows` (for tests).
  subroutine local_matrix(this, s, rows, fs)
    class(class_operator_t), intent(in) :: this
    integer(ip), intent(in) :: s
    integer(ip), allocatable, intent(out) :: rows(:)
    real(dp), allocatable, intent(out) :: fs(:, :)
    integer(ip) :: c, n
    integer(i8) :: o
    c = this%classes%class_of(s)
    n = this%cn(c)
    o = this%coff(c)
    if (this%sparse) call fatal_error('class_operator%local_matrix: dense storage only')
    call sandwich(this%erow(this%eoff(s) + 1:this%eoff(s + 1)), this%edof(this%eoff(s) + 1:this%eoff(s + 1)), &
                  this%eval(this%eoff(s) + 1:this%eoff(s + 1)), &
                  this%factor(s)*reshape(this%mat(o + 1:o + int(n, i8)*n), [n, n]), rows, fs)
  end subroutine local_matrix

  !> fs = B^ m B^^T on the rows of B^'s entries (erow, edof, eval: row, dof
  !> of m, value), rows = erow: the dense local dual operator of one
  !> subdomain from a matrix m on its touched dofs (for tests).
  subroutine sandwich(erow, edof, eval, m, rows, fs)
    integer(ip), intent(in) :: erow(:), edof(:)
    real(dp), intent(in) :: eval(:), m(:, :)
    integer(ip), allocatable, intent(out) :: rows(:)
    real(dp), allocatable, intent(out) :: fs(:, :)
    integer(ip) :: i, j, nb
    nb = size(erow, kind=ip)
    rows = erow
    allocate (fs(nb, nb))
    do j = 1, nb
      do i = 1, nb
        fs(i, j) = eval(i)*m(edof(i), edof(j))*eval(j)
      end do
    end do
  end subroutine sandwich

  !> Bytes one application reads and writes on this rank: every M_c once
  !> (n_c^2 values: dgemm reads the full square), the entries of B twice (16
  !> bytes each), 4 passes over the local dual rows and X, Y (zeroed, added
  !> to, written by dgemm, read: 4 n_c m_c values per class), every W of the
  !> extensions once.
  integer(i8) function bytes_per_action(this)
    class(class_operator_t), intent(in) :: this
    integer(ip) :: c
    bytes_per_action = 2*16*int(size(this%erow), i8) + 4*8*int(this%n_local_rows, i8)
    do c = 1, this%next
      bytes_per_action = bytes_per_action + 8*int(size(this%ext(c)%e), i8)*size(this%ext(c)%a)
    end do
    do c = 1, this%classes%nclass
      if (this%sparse) then
        bytes_per_action = bytes_per_action + 12*int(this%smat(c)%nnz(), i8) + &
                           4*8*int(this%cn(c), i8)*(this%classes%moff(c + 1) - this%classes%moff(c))
        cycle
      end if
      bytes_per_action = bytes_per_action + 8*int(this%cn(c), i8)*this%cn(c) + &
                         4*8*int(this%cn(c), i8)*(this%classes%moff(c + 1) - this%classes%moff(c))
    end do
  end function bytes_per_action

  !> Flops of one application on this rank: 2 n_c^2 m_c per class (dgemm),
  !> 2 n_e n_a per member of an extension.
  real(dp) function flops_per_action(this)
    class(class_operator_t), intent(in) :: this
    integer(ip) :: c
    flops_per_action = 0
    do c = 1, this%next
      flops_per_action = flops_per_action + 2*real(size(this%ext(c)%e), dp)*size(this%ext(c)%a)*size(this%ext(c)%cols)
    end do
    do c = 1, this%classes%nclass
      if (this%sparse) then
        flops_per_action = flops_per_action + 2*real(this%smat(c)%nnz(), dp)*(this%classes%moff(c + 1) - &
                                                                              this%classes%moff(c))
        cycle
      end if
      flops_per_action = flops_per_action + 2*real(this%cn(c), dp)**2*(this%classes%moff(c + 1) - this%classes%moff(c))
    end do
  end function flops_per_action

  subroutine free(this)
    class(class_operator_t), intent(inout) :: this
    if (allocated(this%cn)) deallocate (this%cn, this%coff)
    if (allocated(this%mat)) deallocate (this%mat)
    if (allocated(this%factor)) deallocate (this%factor)
    if (allocated(this%eoff)) deallocate (this%eoff, this%erow, this%edof, this%eval)
    if (allocated(this%xw)) deallocate (this%xw, this%yw, this%wloc, this%wloc2)
    if (allocated(this%smat)) deallocate (this%smat)
    if (allocated(this%ext)) deallocate (this%ext)
    if (allocated(this%xa)) deallocate (this%xa, this%xe)
    if (allocated(this%parent_of_class)) deallocate (this%parent_of_class, this%part_of_class, this%sub_of_unit)
    if (allocated(this%udof)) deallocate (this%udof, this%uoff)
    this%next = 0
    this%sparse = .false.
    this%classes = subdomain_classes_t()
    this%n_local_rows = 0
  end subroutine free
end module class_operator
