!> Classes of congruent subdomains on one rank: subdomains whose stiffness
!> matrices are the same matrix up to a factor, K^s = c_s K^r (r the class's
!> representative, c_r = 1). That is the case of identical boxes in local
!> numbering with the same Poisson ratio and Young's moduli differing by a
!> factor per subdomain (docs/THEORY.md "Shared local operators"). Then
!> K_reg^s = c_s K_reg^r (rho_f is relative to the mean diagonal, the fixing
!> nodes and R span the same kernel), so K^+ of s is K_reg^r^{-1} / c_s, and
!> one factorization (one explicit S^) serves the whole class.
!>
!> The test compares the matrices themselves, so it covers geometry, local
!> numbering, connectivity and material at once: the same order, the same
!> sparsity pattern (rowptr, colind), c_s = the ratio of the first diagonal
!> entries, and max |K^s - c_s K^r| <= tol max |K^s| with
!>
!>     tol = share_rounding_factor * eps * (max |x| / h_min + 1),
!>
!> x the node coordinates and h_min the shortest element edge of the
!> subdomain: the node coordinates carry an absolute rounding of eps max|x|,
!> which the Jacobians of the elements see relative to the edge length, so
!> two congruent boxes placed at different positions of the global mesh give
!> stiffness matrices that differ by that relative amount (times a small
!> factor for the quadrature's arithmetic). Anything larger (a distorted mesh,
!> METIS subdomains, per-element moduli) is a different class, and a rank
!> whose subdomains are all different has one class per subdomain: the
!> callers then take the per-subdomain paths.
module subdomain_classes
  use kinds, only: dp, ip
  use subdomain, only: subdomain_t
  use q1_element, only: element_stiffness
  implicit none
  private

  public :: find_classes, start_classes, add_congruent, add_to_classes, finish_classes, share_tolerance, stiffness_deviation

  !> Multiple of eps * (max|x| / h_min + 1) accepted between the members of a class.
  real(dp), parameter, public :: share_rounding_factor = 64
  !> At most this many classes are tried per subdomain (a rank with more
  !> distinct subdomains gets one class per subdomain without more comparisons).
  integer(ip), parameter :: max_classes = 64
  !> Sharing is used when nsub >= min_mean_members * nclass (see `shared`).
  integer(ip), parameter, public :: min_mean_members = 2

  type, public :: subdomain_classes_t
    integer(ip) :: nclass = 0
    integer(ip), allocatable :: class_of(:)   !< (nsub) class of each subdomain
    integer(ip), allocatable :: rep(:)        !< (nclass) representative (local subdomain index)
    integer(ip), allocatable :: moff(:)       !< (nclass+1) members of class c: member(moff(c)+1:moff(c+1))
    integer(ip), allocatable :: member(:)     !< (nsub) subdomains by class, ascending within a class
    integer(ip), allocatable :: column(:)     !< (nsub) position of s among its class's members
    real(dp), allocatable :: scale(:)         !< (nsub) c_s: K^s = c_s K^rep
    real(dp) :: max_deviation = 0             !< max over members of max|K^s - c_s K^r| / max|K^s|
  contains
    procedure :: shared
  end type subdomain_classes_t

contains

  !> Group `subs` (K assembled, coordinates set) into classes; `enabled`
  !> false gives one class per subdomain.
  subroutine find_classes(subs, classes, enabled)
    type(subdomain_t), intent(in) :: subs(:)
    type(subdomain_classes_t), intent(out) :: classes
    logical, intent(in) :: enabled
    integer(ip) :: s
    call start_classes(classes, size(subs, kind=ip))
    do s = 1, size(subs, kind=ip)
      call add_to_classes(subs, s, classes, enabled)
    end do
    call finish_classes(classes)
  end subroutine find_classes

  !> Empty classes for `n` subdomains, to be filled one subdomain at a time
  !> (add_to_classes, in order s = 1..n) and closed by finish_classes: the
  !> same classes as find_classes, while only the representatives need their
  !> K once their members are added (the set-up assembles and drops a
  !> member's K at once).
  subroutine start_classes(classes, n)
    type(subdomain_classes_t), intent(out) :: classes
    integer(ip), intent(in) :: n
    allocate (classes%class_of(n), classes%scale(n), classes%column(n), classes%member(n))
    allocate (classes%rep(n))
    classes%class_of = 0
    classes%scale = 1
    classes%nclass = 0
    classes%max_deviation = 0
  end subroutine start_classes

  !> Put subdomain `s` of `subs` (K assembled) in the class of the first
  !> representative it matches, or make it the representative of a new class.
  subroutine add_to_classes(subs, s, classes, enabled)
    type(subdomain_t), intent(in) :: subs(:)
    integer(ip), intent(in) :: s
    type(subdomain_classes_t), intent(inout) :: classes
    logical, intent(in) :: enabled
    integer(ip) :: c
    real(dp) :: dev, scale, tol, amax
    classes%class_of(s) = 0
    classes%scale(s) = 1
    if (enabled) then
      tol = share_tolerance(subs(s))
      amax = 0
      if (allocated(subs(s)%K%values)) amax = maxval(abs(subs(s)%K%values))
      do c = 1, min(classes%nclass, max_classes)
        ! (stops at the first entry beyond tol: a distorted or METIS subdomain is told apart at once)
        call stiffness_deviation(subs(s), subs(classes%rep(c)), scale, dev, tol, amax)
        if (dev <= tol) then
          classes%class_of(s) = c
          classes%scale(s) = scale
          classes%max_deviation = max(classes%max_deviation, dev)
          exit
        end if
      end do
    end if
    if (classes%class_of(s) == 0) then
      classes%nclass = classes%nclass + 1
      classes%rep(classes%nclass) = s
      classes%class_of(s) = classes%nclass
    end if
  end subroutine add_to_classes

  !> Put subdomain `s` of `subs` (geometry and material set, K not needed)
  !> in the class of the first representative whose geometry it repeats
  !> (congruent_geometry), with c_s = K_s(1,1) / K_r(1,1) (first_diagonal:
  !> one element matrix); `found` false when there is none (or `enabled` is
  !> false): the caller assembles K and calls add_to_classes. K is linear in
  !> E, so the class and c_s are those the comparison of the matrices finds,
  !> without assembling K_s.
  subroutine add_congruent(subs, s, classes, enabled, found)
    type(subdomain_t), intent(in) :: subs(:)
    integer(ip), intent(in) :: s
    type(subdomain_classes_t), intent(inout) :: classes
    logical, intent(in) :: enabled
    logical, intent(out) :: found
    integer(ip) :: c, r
    real(dp) :: kss
    found = .false.
    if (.not. enabled) return
    kss = first_diagonal(subs(s))
    if (.not. kss > 0) return
    do c = 1, min(classes%nclass, max_classes)
      r = classes%rep(c)
      if (.not. congruent_geometry(subs(s), subs(r))) cycle
      if (.not. allocated(subs(r)%K%values)) cycle
      if (subs(r)%K%colind(1) /= 1) cycle
      classes%class_of(s) = c
      classes%scale(s) = kss/subs(r)%K%values(1)
      found = .true.
      return
    end do
  end subroutine add_congruent

  !> K(1,1) of `sub` exactly as assemble_stiffness forms it when local node 1
  !> lies in element 1 alone (a box's corner: that element's matrix is the
  !> first one computed, from its own coordinates), so that c_s = K_s(1,1) /
  !> K_r(1,1) is the ratio the comparison of the matrices takes; -1 otherwise.
  real(dp) function first_diagonal(sub) result(k11)
    type(subdomain_t), intent(in) :: sub
    real(dp) :: ke(24, 24)
    integer(ip) :: i
    k11 = -1
    if (sub%nelem < 1) return
    if (count(sub%elem_nodes == 1) /= 1) return
    i = findloc(sub%elem_nodes(:, 1), 1, dim=1)
    if (i == 0) return
    call element_stiffness(sub%element, sub%coords(:, sub%elem_nodes(:, 1)), sub%young, sub%poisson, ke)
    k11 = ke(3*i - 2, 3*i - 2)
  end function first_diagonal

  !> True when `a` and `b` have the same local mesh (nodes, elements and
  !> their local nodes), node offsets from the first node equal to within
  !> the rounding of the coordinates (8 eps max(1, max|x|), as the assembly's
  !> reuse of an element matrix), the same Poisson ratio and positive
  !> Young's moduli: then K^a = (E_a / E_b) K^b up to that rounding.
  logical function congruent_geometry(a, b) result(same)
    type(subdomain_t), intent(in) :: a, b
    real(dp) :: tol
    integer(ip) :: k
    same = .false.
    if (a%nnodes /= b%nnodes .or. a%nelem /= b%nelem .or. a%nnodes < 1) return
    if (a%poisson /= b%poisson .or. .not. (a%young > 0 .and. b%young > 0)) return
    if (a%element /= b%element) return
    if (.not. allocated(a%coords) .or. .not. allocated(b%coords)) return
    tol = 8*epsilon(1.0_dp)*max(1.0_dp, maxval(abs(a%coords)), maxval(abs(b%coords)))
    do k = 1, a%nnodes
      if (maxval(abs((a%coords(:, k) - a%coords(:, 1)) - (b%coords(:, k) - b%coords(:, 1)))) > tol) return
    end do
    same = all(a%elem_nodes == b%elem_nodes)
  end function congruent_geometry

  !> The members by class (moff, member, column) once every subdomain is added.
  subroutine finish_classes(classes)
    type(subdomain_classes_t), intent(inout) :: classes
    integer(ip) :: n, s, c, k
    integer(ip), allocatable :: cnt(:)
    n = size(classes%class_of, kind=ip)
    classes%rep = classes%rep(1:classes%nclass)
    allocate (cnt(n + 1))
    cnt = 0
    do s = 1, n
      cnt(classes%class_of(s) + 1) = cnt(classes%class_of(s) + 1) + 1
    end do
    allocate (classes%moff(classes%nclass + 1))
    classes%moff(1) = 0
    do c = 1, classes%nclass
      classes%moff(c + 1) = classes%moff(c) + cnt(c + 1)
    end do
    cnt(1:classes%nclass) = 0
    do s = 1, n
      c = classes%class_of(s)
      cnt(c) = cnt(c) + 1
      k = classes%moff(c) + cnt(c)
      classes%member(k) = s
      classes%column(s) = cnt(c)
    end do
  end subroutine finish_classes

  !> True when sharing pays: the classes hold at least `min_mean_members`
  !> subdomains on average. A rank whose subdomains are almost all different
  !> (METIS subdomains made of blocks, of which a few are translates of each
  !> other: 250 classes for 256 subdomains measured) keeps the per-subdomain
  !> paths, whose cost models (`f_action = 'auto'`) know the size of each
  !> subdomain's operator; the shared paths store one operator per class on
  !> the union of its dofs touched by B and would hold one per subdomain.
  logical function shared(this)
    class(subdomain_classes_t), intent(in) :: this
    shared = .false.
    if (allocated(this%class_of)) shared = min_mean_members*this%nclass <= size(this%class_of, kind=ip)
  end function shared

  !> share_rounding_factor * eps * (max|x| / h_min + 1) of `sub` (see the module).
  real(dp) function share_tolerance(sub)
    type(subdomain_t), intent(in) :: sub
    real(dp) :: xmax, hmin, d
    integer(ip) :: e, k
    integer(ip), parameter :: other(3) = [2, 4, 5]   ! Q1 order: the edges from node 1
    xmax = maxval(abs(sub%coords))
    hmin = huge(1.0_dp)
    do e = 1, sub%nelem
      do k = 1, 3
        d = norm2(sub%coords(:, sub%elem_nodes(other(k), e)) - sub%coords(:, sub%elem_nodes(1, e)))
        hmin = min(hmin, d)
      end do
    end do
    share_tolerance = 0
    if (hmin > 0) share_tolerance = share_rounding_factor*epsilon(1.0_dp)*(xmax/hmin + 1)
  end function share_tolerance

  !> c = K^a(1,1) / K^b(1,1) and dev = max|K^a - c K^b| / max|K^a| when the
  !> two matrices have the same order and pattern; dev = huge otherwise. With
  !> `limit`, the comparison stops at the first entry whose difference exceeds
  !> limit max|K^a| and returns that entry's relative difference (> limit):
  !> enough for the test dev <= limit, in O(1) for matrices that differ early.
  !> `a_max`: max|K^a| when the caller has it (one subdomain against many).
  subroutine stiffness_deviation(a, b, c, dev, limit, a_max)
    type(subdomain_t), intent(in) :: a, b
    real(dp), intent(out) :: c, dev
    real(dp), intent(in), optional :: limit, a_max
    integer(ip) :: k, nrow
    real(dp) :: amax, bound, d
    c = 1
    dev = huge(1.0_dp)
    if (a%ndof /= b%ndof .or. a%nelem /= b%nelem) return
    if (.not. allocated(a%K%values) .or. .not. allocated(b%K%values)) return
    if (size(a%K%values) /= size(b%K%values)) return
    nrow = size(a%K%rowptr, kind=ip)
    if (size(b%K%rowptr, kind=ip) /= nrow) return
    if (.not. (a%K%values(1) > 0 .and. b%K%values(1) > 0)) return
    ! the first stored entry of row 1 is the diagonal when colind(1) = 1
    if (a%K%colind(1) /= 1) return
    c = a%K%values(1)/b%K%values(1)
    if (present(a_max)) then
      amax = a_max
    else
      amax = maxval(abs(a%K%values))
    end if
    bound = huge(1.0_dp)
    if (present(limit)) bound = limit*amax
    ! values and column indices in one pass (the row pointers after it: equal
    ! column indices in a different row split are still a different pattern)
    dev = 0
    do k = 1, size(a%K%values, kind=ip)
      if (a%K%colind(k) /= b%K%colind(k)) then
        dev = huge(1.0_dp)
        return
      end if
      d = abs(a%K%values(k) - c*b%K%values(k))
      dev = max(dev, d)
      if (dev > bound) exit
    end do
    if (any(a%K%rowptr /= b%K%rowptr)) then
      dev = huge(1.0_dp)
      return
    end if
    dev = dev/amax
  end subroutine stiffness_deviation
end module subdomain_classes
