!> The linear system of one subdomain: material, stiffness K (CSR, full
!> symmetric storage, columns ascending), load f, kernel basis R; and what the
!> output needs from the element level (von Mises stress, tributary areas).
module assembly
  use kinds, only: dp, ip, name_len
  use errors, only: fatal_error
  use materials, only: material_settings_t
  use box_mesh, only: face_z0, face_z1
  use decomposition, only: decomposition_t
  use subdomain, only: subdomain_t
  use q1_element, only: element_stiffness, q1_face_load, q1_face_shape_integrals, element_centroid_stress, &
                        von_mises, q1_face_nodes
  use materials, only: subdomain_material
  use rigid_modes, only: rigid_body_modes
  use sorting, only: sort_ints, append_unmarked
  use settings_base, only: settings_t
  implicit none
  private

  public :: assemble_subdomain, assemble_stiffness, add_face_traction, subdomain_von_mises, &
            face_tributary_areas, element_displacements

  !> The settings of `&load` (docs/INPUT.md): the default and the namelist
  !> variables (params hands the group over).
  type, extends(settings_t), public :: load_settings_t
    real(dp) :: top_pressure = 0              !< pressure on z = Lz, positive pushes down [MPa]
  contains
    procedure :: group => load_settings_group
    procedure :: variables => load_settings_variables
    procedure :: read_namelist => load_settings_read
    procedure :: write_namelist => load_settings_write
  end type load_settings_t

contains

  !> The namelist group of these variables.
  function load_settings_group(self) result(name)
    class(load_settings_t), intent(in) :: self
    character(len=:), allocatable :: name
    name = 'load'
  end function load_settings_group

  !> The names of the namelist variables (those of read_namelist).
  subroutine load_settings_variables(self, names)
    class(load_settings_t), intent(in) :: self
    character(len=name_len), allocatable, intent(out) :: names(:)
    names = [character(len=name_len) :: 'top_pressure']
  end subroutine load_settings_variables

  !> Read the group text `group` ('&load ... /').
  subroutine load_settings_read(self, group, status, msg)
    class(load_settings_t), intent(inout) :: self
    character(len=*), intent(in) :: group
    integer, intent(out) :: status
    character(len=*), intent(out) :: msg
    real(dp) :: top_pressure
    namelist /load/ top_pressure
    top_pressure = self%top_pressure
    read (group, nml=load, iostat=status, iomsg=msg)
    if (status == 0) self%top_pressure = top_pressure
  end subroutine load_settings_read

  !> Write the group as the namelist '&load ... /'.
  subroutine load_settings_write(self, lines, status, msg)
    class(load_settings_t), intent(in) :: self
    character(len=*), intent(out) :: lines(:)
    integer, intent(out) :: status
    character(len=*), intent(out) :: msg
    real(dp) :: top_pressure
    namelist /load/ top_pressure
    top_pressure = self%top_pressure
    lines = ''
    write (lines, nml=load, delim='quote', iostat=status, iomsg=msg)
  end subroutine load_settings_write

  !> Material, K, f (pressure load%top_pressure on z = Lz, pushing in -z)
  !> and the orthonormal rigid body modes R (about sub%centroid) of `sub`,
  !> whose geometry build_subdomain has filled. `stiffness` false: all but K
  !> (a subdomain that shares the K of a congruent one).
  subroutine assemble_subdomain(material, load, dec, sub, stiffness)
    type(material_settings_t), intent(in) :: material
    type(load_settings_t), intent(in) :: load
    type(decomposition_t), intent(in) :: dec
    type(subdomain_t), intent(inout) :: sub
    logical, intent(in), optional :: stiffness
    logical :: with_k

    with_k = .true.
    if (present(stiffness)) with_k = stiffness
    if (allocated(sub%elem_young)) then
      ! a cluster of subdomains of several moduli (glued by faces): `young` is
      ! the reference modulus, the elements carry their own
      sub%young = material%young
      sub%poisson = material%poisson
    else
      call subdomain_material(material, dec, sub%id, sub%young, sub%poisson)
    end if
    sub%element = material%element_kind()
    if (with_k) call assemble_stiffness(sub)
    if (allocated(sub%f)) deallocate (sub%f)
    allocate (sub%f(sub%ndof))
    sub%f = 0
    if (load%top_pressure /= 0) &
      call add_face_traction(dec, sub, face_z1, [0.0_dp, 0.0_dp, -load%top_pressure], sub%f)
    if (allocated(sub%R)) deallocate (sub%R)
    allocate (sub%R(sub%ndof, 6))
    call rigid_body_modes(sub%coords, sub%centroid, sub%R)
  end subroutine assemble_subdomain

  !> K of `sub` with its material (sub%young, sub%poisson) and element
  !> formulation (sub%element). The pattern comes
  !> from the node adjacency (nodes sharing an element, 3x3 blocks), so the
  !> work is proportional to the number of elements.
  subroutine assemble_stiffness(sub)
    type(subdomain_t), intent(inout) :: sub
    integer(ip), allocatable :: nptr(:), nelems(:), adjptr(:), adj(:), marker(:)
    integer(ip) :: n, e, a, b, i, j, k, m, c, nadj, first, row, base, pos, ln(8)
    real(dp) :: ke(24, 24), x(3, 8), xrel(3, 8), xrel_prev(3, 8), same_shape, sc
    logical :: have_prev, reuse

    n = sub%nnodes
    ! node -> elements
    allocate (nptr(n + 1), nelems(8*sub%nelem))
    nptr = 0
    do e = 1, sub%nelem
      do i = 1, 8
        a = sub%elem_nodes(i, e)
        nptr(a + 1) = nptr(a + 1) + 1
      end do
    end do
    nptr(1) = 1
    do a = 1, n
      nptr(a + 1) = nptr(a + 1) + nptr(a)
    end do
    allocate (marker(n))
    marker = nptr(1:n)
    do e = 1, sub%nelem
      do i = 1, 8
        a = sub%elem_nodes(i, e)
        nelems(marker(a)) = e
        marker(a) = marker(a) + 1
      end do
    end do
    ! node adjacency (including the node itself), ascending
    allocate (adjptr(n + 1), adj(27*n))
    marker = 0
    nadj = 0
    adjptr(1) = 1
    do a = 1, n
      first = nadj + 1
      do k = nptr(a), nptr(a + 1) - 1
        do i = 1, 8
          call append_unmarked(adj, nadj, sub%elem_nodes(i, nelems(k)), marker, a)
        end do
      end do
      call sort_ints(adj(first:nadj))
      adjptr(a + 1) = nadj + 1
    end do
    ! CSR pattern: row 3(a-1)+c holds columns 3(b-1)+1..3 for b adjacent to a
    call sub%K%free()
    sub%K%nrows = 3*n
    sub%K%ncols = 3*n
    allocate (sub%K%rowptr(3*n + 1), sub%K%colind(9*nadj), sub%K%values(9*nadj))
    sub%K%rowptr(1) = 1
    do a = 1, n
      do c = 1, 3
        row = 3*(a - 1) + c
        base = sub%K%rowptr(row)
        do k = adjptr(a), adjptr(a + 1) - 1
          sub%K%colind(base:base + 2) = 3*(adj(k) - 1) + [1, 2, 3]
          base = base + 3
        end do
        sub%K%rowptr(row + 1) = base
      end do
    end do
    sub%K%values = 0
    ! element matrices; an element that is a translate of the previous one
    ! (node offsets equal to within the rounding of the coordinates, as in
    ! every undistorted box) reuses its matrix: K_e depends on the offsets only
    same_shape = 8*epsilon(1.0_dp)*max(1.0_dp, maxval(abs(sub%coords)))
    have_prev = .false.
    do e = 1, sub%nelem
      ln = sub%elem_nodes(:, e)
      x = sub%coords(:, ln)
      do i = 1, 8
        xrel(:, i) = x(:, i) - x(:, 1)
      end do
      reuse = have_prev
      if (reuse) reuse = maxval(abs(xrel - xrel_prev)) <= same_shape   ! (no short-circuit in Fortran)
      if (.not. reuse) then
        call element_stiffness(sub%element, x, sub%young, sub%poisson, ke)
        xrel_prev = xrel
        have_prev = .true.
      end if
      ! K_e is linear in E: an element of another modulus (elem_young) scales it
      sc = 1
      if (allocated(sub%elem_young)) sc = sub%elem_young(e)/sub%young
      do i = 1, 8
        a = ln(i)
        do j = 1, 8
          b = ln(j)
          pos = 0
          do m = adjptr(a), adjptr(a + 1) - 1
            if (adj(m) == b) then
              pos = m - adjptr(a)
              exit
            end if
          end do
          do c = 1, 3
            base = sub%K%rowptr(3*(a - 1) + c) + 3*pos
            sub%K%values(base:base + 2) = sub%K%values(base:base + 2) + &
                                          sc*ke(3*(i - 1) + c, 3*(j - 1) + 1:3*(j - 1) + 3)
          end do
        end do
      end do
    end do
  end subroutine assemble_stiffness


  !> f += consistent nodal forces of a uniform traction (force per area) on
  !> the element faces of `sub` that lie on box face `face` (face_x0 ... face_z1).
  subroutine add_face_traction(dec, sub, face, traction, f)
    type(decomposition_t), intent(in) :: dec
    type(subdomain_t), intent(in) :: sub
    integer(ip), intent(in) :: face
    real(dp), intent(in) :: traction(3)
    real(dp), intent(inout) :: f(:)
    integer(ip) :: e, m, a, fn(4)
    real(dp) :: fe(3, 4)
    do e = 1, sub%nelem
      if (.not. dec%mesh%element_on_face(sub%elem_gid(e), face)) cycle
      fn = sub%elem_nodes(q1_face_nodes(:, face), e)
      call q1_face_load(sub%coords(:, fn), traction, fe)
      do m = 1, 4
        a = fn(m)
        f(3*a - 2:3*a) = f(3*a - 2:3*a) + fe(:, m)
      end do
    end do
  end subroutine add_face_traction

  !> area(nnodes): the integral of each node's shape function over the part of
  !> box face `face` (default z = 0, the contact face) covered by `sub`; 0 for
  !> nodes not on it. Copies of a node in several subdomains each get their
  !> subdomain's share; the node's tributary area is the sum over copies.
  subroutine face_tributary_areas(dec, sub, area, face)
    type(decomposition_t), intent(in) :: dec
    type(subdomain_t), intent(in) :: sub
    real(dp), intent(out) :: area(:)
    integer(ip), intent(in), optional :: face
    integer(ip) :: e, fc, fn(4)
    real(dp) :: w(4)
    fc = face_z0
    if (present(face)) fc = face
    if (size(area) < sub%nnodes) call fatal_error('face_tributary_areas: area shorter than nnodes')
    area = 0
    do e = 1, sub%nelem
      if (.not. dec%mesh%element_on_face(sub%elem_gid(e), fc)) cycle
      fn = sub%elem_nodes(q1_face_nodes(:, fc), e)
      call q1_face_shape_integrals(sub%coords(:, fn), w)
      area(fn) = area(fn) + w
    end do
  end subroutine face_tributary_areas

  !> The 24 displacements of element e of `sub` from the subdomain vector u(ndof).
  pure function element_displacements(sub, e, u) result(ue)
    type(subdomain_t), intent(in) :: sub
    integer(ip), intent(in) :: e
    real(dp), intent(in) :: u(:)
    real(dp) :: ue(24)
    integer(ip) :: i, a
    do i = 1, 8
      a = sub%elem_nodes(i, e)
      ue(3*i - 2:3*i) = u(3*a - 2:3*a)
    end do
  end function element_displacements

  !> Von Mises stress vm(nelem) at the element centroids for the subdomain
  !> displacements u(ndof), with the stress of the subdomain's element formulation.
  subroutine subdomain_von_mises(sub, u, vm)
    type(subdomain_t), intent(in) :: sub
    real(dp), intent(in) :: u(:)
    real(dp), intent(out) :: vm(:)
    integer(ip) :: e
    real(dp) :: sigma(6), young
    if (size(u) < sub%ndof .or. size(vm) < sub%nelem) &
      call fatal_error('subdomain_von_mises: u or vm too short')
    young = sub%young
    do e = 1, sub%nelem
      if (allocated(sub%elem_young)) young = sub%elem_young(e)
      call element_centroid_stress(sub%element, sub%coords(:, sub%elem_nodes(:, e)), &
                                   element_displacements(sub, e, u), young, sub%poisson, sigma)
      vm(e) = von_mises(sigma)
    end do
  end subroutine subdomain_von_mises
end module assembly
