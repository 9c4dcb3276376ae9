!> B, the signed Boolean gluing / Dirichlet / contact matrix of TFETI, and
!> G = R^T B^T, whose entries are stored with B's (G^T = B R, built with B
!> in build_constraints). The rows are distributed: each rank owns n_own of
!> them and holds ghost copies of the rows its subdomains touch (dual_exchange).
!>
!> Dual vectors: the rows this rank owns (length n_own). Primal vectors: one
!> local_field_t per local subdomain, or the concatenated vector of the
!> rank's subdomains (`concat`, subdomain s at offset(s)+1..offset(s+1)).
!> Coarse vectors: the 6-blocks of the local subdomains.
module b_operator
  use kinds, only: dp, ip, i8, MPI_REAL_DP
  use feti_settings, only: feti_settings_t
  use decomposition, only: decomposition_t
  use subdomain, only: subdomain_t
  use constraints, only: constraints_t, build_constraints, row_contact, row_gluing
  use mpi_f08, only: MPI_Comm, MPI_Allreduce, MPI_MAX
  implicit none
  private

  !> One vector per local subdomain (displacements, loads).
  type, public :: local_field_t
    real(dp), allocatable :: v(:)
  end type local_field_t

  type, public :: b_operator_t
    private
    type(constraints_t) :: con                  !< B, c, G^T = B R, the exchange pattern
    integer(ip) :: nlocal = 0                   !< subdomains of this rank
    integer(ip), allocatable :: offset(:)       !< (nlocal+1) dof offsets in concatenated vectors
    real(dp), allocatable :: wloc(:), wloc2(:), xall(:)   !< work: local rows (twice), concatenated
  contains
    procedure :: init
    procedure :: n_own
    procedure :: n_concat
    procedure :: dof_range
    procedure :: add_transpose
    procedure :: apply_concat
    procedure :: apply_b
    procedure :: apply_bt
    procedure :: apply_g
    procedure :: apply_gt
    procedure :: n_entries
    procedure :: n_local_rows
    procedure :: gather_rows
    procedure :: scatter_rows
    procedure :: subdomain_entries
    procedure :: constraints
    procedure :: row_counts
    procedure :: row_keys
    procedure :: row_offset
    procedure :: is_contact
    procedure :: force_scale
    procedure :: gap_rhs
    procedure :: set_gap_rhs
    procedure :: row_node_gid
    procedure :: row_coordinates
    procedure :: keyed_random
    procedure :: largest_copy_spread
    procedure :: row_kind
    procedure :: row_units
    procedure :: free
  end type b_operator_t

contains

  !> Build B, c and G^T = B R of the local subdomains `subs` (which hold
  !> their geometry and R). Collective over `comm`.
  subroutine init(this, settings, dec, subs, comm, sub_dec)
    class(b_operator_t), intent(inout) :: this
    type(feti_settings_t), intent(in) :: settings
    type(decomposition_t), intent(in) :: dec
    type(decomposition_t), intent(in), optional :: sub_dec   !< hybrid TFETI: the subdomains (constraints)
    type(subdomain_t), intent(in) :: subs(:)
    type(MPI_Comm), intent(in) :: comm
    integer(ip) :: ls
    call this%free()
    call build_constraints(settings, dec, subs, comm, this%con, sub_dec)
    this%nlocal = size(subs, kind=ip)
    allocate (this%offset(this%nlocal + 1))
    this%offset(1) = 0
    do ls = 1, this%nlocal
      this%offset(ls + 1) = this%offset(ls) + subs(ls)%ndof
    end do
    allocate (this%wloc(this%con%n_local), this%wloc2(this%con%n_local), this%xall(this%offset(this%nlocal + 1)))
  end subroutine init

  !> Rows this rank owns (the length of a dual vector).
  integer(ip) function n_own(this)
    class(b_operator_t), intent(in) :: this
    n_own = this%con%n_own
  end function n_own

  !> Length of the concatenated primal vector of the local subdomains.
  integer(ip) function n_concat(this)
    class(b_operator_t), intent(in) :: this
    n_concat = this%offset(this%nlocal + 1)
  end function n_concat

  !> The dofs of local subdomain `ls` in the concatenated vector: first:last.
  function dof_range(this, ls) result(r)
    class(b_operator_t), intent(in) :: this
    integer(ip), intent(in) :: ls
    integer(ip) :: r(2)
    r = [this%offset(ls) + 1, this%offset(ls + 1)]
  end function dof_range

  !> xall += scale * B^T x on the concatenated vector (x: owned rows).
  subroutine add_transpose(this, x, scale, xall)
    class(b_operator_t), intent(inout) :: this
    real(dp), intent(in) :: x(:), scale
    real(dp), intent(inout) :: xall(:)
    integer(ip) :: ls, e
    call this%con%exchange%gather(x, this%wloc)
    do ls = 1, this%nlocal
      associate (bs => this%con%b(ls), o => this%offset(ls))
        do e = 1, bs%nentries
          xall(o + bs%dof(e)) = xall(o + bs%dof(e)) + scale*bs%val(e)*this%wloc(bs%row(e))
        end do
      end associate
    end do
  end subroutine add_transpose

  !> y = B xall (owned rows) for the concatenated vector xall.
  subroutine apply_concat(this, xall, y)
    class(b_operator_t), intent(inout) :: this
    real(dp), intent(in) :: xall(:)
    real(dp), intent(inout) :: y(:)
    call local_rows(this, xall, this%wloc2)
    call this%con%exchange%scatter_add(this%wloc2, y)
  end subroutine apply_concat

  !> y_local = B xall on the local rows, owned
  !> and ghosts, before the scatter-add.
  subroutine local_rows(this, xall, y_local)
    class(b_operator_t), intent(in) :: this
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
  end subroutine local_rows

  !> y = B u = sum over subdomains of B^s u^s (owned rows).
  subroutine apply_b(this, u, y)
    class(b_operator_t), intent(inout) :: this
    type(local_field_t), intent(in) :: u(:)
    real(dp), intent(inout) :: y(:)
    integer(ip) :: ls
    do ls = 1, this%nlocal
      this%xall(this%offset(ls) + 1:this%offset(ls + 1)) = u(ls)%v
    end do
    call this%apply_concat(this%xall, y)
  end subroutine apply_b

  !> u^s = B^s^T x for every local subdomain.
  subroutine apply_bt(this, x, u)
    class(b_operator_t), intent(inout) :: this
    real(dp), intent(in) :: x(:)
    type(local_field_t), intent(inout) :: u(:)
    integer(ip) :: ls
    this%xall = 0
    call this%add_transpose(x, 1.0_dp, this%xall)
    do ls = 1, this%nlocal
      u(ls)%v = this%xall(this%offset(ls) + 1:this%offset(ls + 1))
    end do
  end subroutine apply_bt

  !> z = G x (local coarse blocks) for a dual vector x.
  subroutine apply_g(this, x, z)
    class(b_operator_t), intent(inout) :: this
    real(dp), intent(in) :: x(:)
    real(dp), intent(out) :: z(:)
    integer(ip) :: ls
    call this%con%exchange%gather(x, this%wloc)
    do ls = 1, this%nlocal
      associate (bs => this%con%b(ls))
        if (bs%nentries > 0) then
          call g_block(bs%nentries, bs%row, bs%g, this%wloc, z(6*ls - 5:6*ls))
        else
          z(6*ls - 5:6*ls) = 0
        end if
      end associate
    end do
  end subroutine apply_g

  !> y = G^T z for local coarse blocks z.
  subroutine apply_gt(this, z, y)
    class(b_operator_t), intent(inout) :: this
    real(dp), intent(in) :: z(:)
    real(dp), intent(inout) :: y(:)
    integer(ip) :: ls
    this%wloc2 = 0
    do ls = 1, this%nlocal
      associate (bs => this%con%b(ls))
        if (bs%nentries > 0) call gt_block(bs%nentries, bs%row, bs%g, z(6*ls - 5:6*ls), this%wloc2)
      end associate
    end do
    call this%con%exchange%scatter_add(this%wloc2, y)
  end subroutine apply_gt

  !> z = sum_e g(:, e) w(row(e)): the 6-block of G x of one subdomain (the
  !> hot loop of every projection; explicit-shape arrays, so that the
  !> compiler sees unit strides and no aliasing).
  pure subroutine g_block(n, row, g, w, z)
    integer(ip), intent(in) :: n, row(n)
    real(dp), intent(in) :: g(6, n), w(*)
    real(dp), intent(out) :: z(6)
    integer(ip) :: e
    real(dp) :: acc(6)
    acc = 0
    do e = 1, n
      acc = acc + g(:, e)*w(row(e))
    end do
    z = acc
  end subroutine g_block

  !> w(row(e)) += g(:, e) . z for every entry e of one subdomain: its part of
  !> G^T z (the dot product summed left to right, as dot_product does).
  pure subroutine gt_block(n, row, g, z, w)
    integer(ip), intent(in) :: n, row(n)
    real(dp), intent(in) :: g(6, n), z(6)
    real(dp), intent(inout) :: w(*)
    integer(ip) :: e
    do e = 1, n
      w(row(e)) = w(row(e)) + (g(1, e)*z(1) + g(2, e)*z(2) + g(3, e)*z(3) + &
                               g(4, e)*z(4) + g(5, e)*z(5) + g(6, e)*z(6))
    end do
  end subroutine gt_block

  !> Entries of B on this rank.
  integer(i8) function n_entries(this)
    class(b_operator_t), intent(in) :: this
    integer(ip) :: ls
    n_entries = 0
    do ls = 1, this%nlocal
      n_entries = n_entries + this%con%b(ls)%nentries
    end do
  end function n_entries

  !> Rows of the local dual vector: owned rows, then ghosts (dual_exchange).
  integer(ip) function n_local_rows(this)
    class(b_operator_t), intent(in) :: this
    n_local_rows = this%con%n_local
  end function n_local_rows

  !> wloc = x on the owned rows and the owners' values on the ghosts.
  subroutine gather_rows(this, x, wloc)
    class(b_operator_t), intent(inout) :: this
    real(dp), intent(in) :: x(:)
    real(dp), intent(inout) :: wloc(:)
    call this%con%exchange%gather(x, wloc)
  end subroutine gather_rows

  !> y = the owned part of wloc plus the ghost values other ranks hold for it.
  subroutine scatter_rows(this, wloc, y)
    class(b_operator_t), intent(inout) :: this
    real(dp), intent(in) :: wloc(:)
    real(dp), intent(inout) :: y(:)
    call this%con%exchange%scatter_add(wloc, y)
  end subroutine scatter_rows

  !> The entries of B^s of local subdomain `ls`: local row (1..n_local_rows),
  !> subdomain dof, value.
  subroutine subdomain_entries(this, ls, row, dof, val)
    class(b_operator_t), intent(in) :: this
    integer(ip), intent(in) :: ls
    integer(ip), allocatable, intent(out) :: row(:), dof(:)
    real(dp), allocatable, intent(out) :: val(:)
    associate (bs => this%con%b(ls))
      row = bs%row(1:bs%nentries)
      dof = bs%dof(1:bs%nentries)
      val = bs%val(1:bs%nentries)
    end associate
  end subroutine subdomain_entries

  !> The constraint data, for the coarse problems of the FETI layer (they
  !> assemble G G^T from it); `this` must be a target.
  function constraints(this) result(con)
    class(b_operator_t), intent(inout), target :: this
    type(constraints_t), pointer :: con
    con => this%con
  end function constraints

  !> Rows of all ranks: all, gluing, Dirichlet, contact.
  function row_counts(this) result(n)
    class(b_operator_t), intent(in) :: this
    integer(ip) :: n(4)
    n = [this%con%n_global, this%con%n_gluing_global, this%con%n_dirichlet_global, this%con%n_contact_global]
  end function row_counts

  !> Canonical keys of the owned rows (the same on any number of ranks).
  function row_keys(this) result(v)
    class(b_operator_t), intent(in) :: this
    integer(i8), allocatable :: v(:)
    v = this%con%key(1:this%con%n_own)
  end function row_keys

  !> Global id of owned row i: row_offset() + i.
  integer(ip) function row_offset(this)
    class(b_operator_t), intent(in) :: this
    row_offset = this%con%offset
  end function row_offset

  !> Which owned rows are contact rows.
  function is_contact(this) result(v)
    class(b_operator_t), intent(in) :: this
    logical, allocatable :: v(:)
    v = this%con%kind == row_contact
  end function is_contact

  !> force = scale * multiplier (owned rows; 1 unless &solver scaling).
  function force_scale(this) result(v)
    class(b_operator_t), intent(in) :: this
    real(dp), allocatable :: v(:)
    v = this%con%scale
  end function force_scale

  !> c, the right-hand side of B u <= c (owned rows).
  function gap_rhs(this) result(v)
    class(b_operator_t), intent(in) :: this
    real(dp), allocatable :: v(:)
    v = this%con%c
  end function gap_rhs

  !> Replace c (owned rows): a load history moves the prescribed values and
  !> the obstacle (the rows stay).
  subroutine set_gap_rhs(this, c)
    class(b_operator_t), intent(inout) :: this
    real(dp), intent(in) :: c(:)
    this%con%c(1:this%con%n_own) = c(1:this%con%n_own)
  end subroutine set_gap_rhs

  !> Node gid of each owned row.
  function row_node_gid(this) result(v)
    class(b_operator_t), intent(in) :: this
    integer(ip), allocatable :: v(:)
    v = this%con%node
  end function row_node_gid

  !> Coordinates (3, n_own) of the node of each owned row.
  function row_coordinates(this, subs) result(x)
    class(b_operator_t), intent(in) :: this
    type(subdomain_t), intent(in) :: subs(:)
    real(dp), allocatable :: x(:, :)
    integer(ip) :: i
    allocate (x(3, this%con%n_own))
    do i = 1, this%con%n_own
      x(:, i) = subs(this%con%row_sub(i))%coords(:, this%con%row_node(i))
    end do
  end function row_coordinates

  !> max over nodes and components of sqrt(2 sum_c (u_c - mean)^2) over the
  !> copies c of a glued node component. Every copy of such a component has
  !> an entry in the node's last gluing row (Helmert row m-1 touches all m
  !> copies; it is the copy's gluing row with the largest key), which carries
  !> the sums: sum_c u_c and the number of copies, then the mean back to the
  !> copies, then sum_c (u_c - mean)^2 (two-pass: no cancellation).
  real(dp) function largest_copy_spread(this, u) result(spread)
    class(b_operator_t), intent(inout) :: this
    type(local_field_t), intent(in) :: u(:)
    type(local_field_t), allocatable :: anchor(:)
    real(dp), allocatable :: loc(:), own(:), cnt(:), mean_loc(:)
    real(dp) :: mine
    integer(ip) :: ls, e, row, dof
    integer :: ierr
    allocate (anchor(this%nlocal), loc(this%con%n_local), own(this%con%n_own), cnt(this%con%n_own), &
              mean_loc(this%con%n_local))
    ! the anchor row of every glued dof (stored as a real for local_field_t)
    do ls = 1, this%nlocal
      associate (bs => this%con%b(ls))
        allocate (anchor(ls)%v(this%offset(ls + 1) - this%offset(ls)))
        anchor(ls)%v = 0
        do e = 1, bs%nentries
          row = bs%row(e)
          if (key_kind(this%con%key(row)) /= row_gluing) cycle
          dof = bs%dof(e)
          if (anchor(ls)%v(dof) == 0) then
            anchor(ls)%v(dof) = row
          else if (this%con%key(row) > this%con%key(int(anchor(ls)%v(dof), ip))) then
            anchor(ls)%v(dof) = row
          end if
        end do
      end associate
    end do
    ! number of copies and mean per anchor row
    loc = 0
    call accumulate(1)
    call this%con%exchange%scatter_add(loc, cnt)
    loc = 0
    call accumulate(2)
    call this%con%exchange%scatter_add(loc, own)
    own = merge(own/max(cnt, 1.0_dp), 0.0_dp, cnt > 0)
    call this%con%exchange%gather(own, mean_loc)
    loc = 0
    call accumulate(3)
    call this%con%exchange%scatter_add(loc, own)
    mine = 0
    if (this%con%n_own > 0) mine = sqrt(2*maxval(own))
    call MPI_Allreduce(mine, spread, 1, MPI_REAL_DP, MPI_MAX, this%con%comm, ierr)
  contains
    !> loc(anchor) += 1, u, or (u - mean)^2 over all glued dofs of all copies here.
    subroutine accumulate(what)
      integer, intent(in) :: what
      integer(ip) :: ls2, d, a
      do ls2 = 1, this%nlocal
        do d = 1, size(anchor(ls2)%v)
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


  !> The kind of each owned row: row_gluing, row_dirichlet or row_contact.
  function row_kind(this) result(v)
    class(b_operator_t), intent(in) :: this
    integer(ip), allocatable :: v(:)
    v = this%con%kind
  end function row_kind

  !> Row i of B is unit(i) times a displacement (owned rows; see constraints).
  function row_units(this) result(v)
    class(b_operator_t), intent(in) :: this
    real(dp), allocatable :: v(:)
    v = this%con%unit(1:this%con%n_own)
  end function row_units

  !> A dual vector with entries in [-1, 1] that depend only on the rows'
  !> canonical keys, so that it is the same on any number of ranks.
  subroutine keyed_random(this, seed, x)
    class(b_operator_t), intent(in) :: this
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

  subroutine free(this)
    class(b_operator_t), intent(inout) :: this
    call this%con%exchange%free()
    if (allocated(this%con%b)) deallocate (this%con%b)
    if (allocated(this%offset)) deallocate (this%offset)
    if (allocated(this%wloc)) deallocate (this%wloc, this%wloc2, this%xall)
    this%nlocal = 0
  end subroutine free
end module b_operator
