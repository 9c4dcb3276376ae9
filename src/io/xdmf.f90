!> The XDMF (version 3) description of the HDF5 file written by hdf5_output,
!> so that ParaView (and VisIt) can open the fields.
!>
!> Two uniform grids in one domain:
!> - "mesh": Hexahedron topology from /connectivity (nelem x 8, 0-based),
!>   XYZ geometry from /coordinates (nnodes x 3), node attribute displacement
!>   (Vector), cell attributes subdomain and von_mises (Scalar);
!> - "contact" (only when there are contact nodes): Polyvertex topology, one
!>   vertex per contact node from /contact_vertices (0, 1, ...), geometry from
!>   /contact_coordinates (ncontact x 3), node attributes contact_pressure and
!>   contact_gap.
!> Shapes are written as HDF5 (C order) sees them; the Fortran arrays are the
!> transposes, e.g. coordinates(3, nnodes).
module xdmf
  use kinds, only: i8, dp
  use text, only: str
  implicit none
  private

  public :: write_xdmf, write_xdmf_series

contains

  !> Write the XDMF file `path` for the HDF5 file `h5_name` (a name relative
  !> to the directory of `path`) holding `nnodes` nodes, `nelem` hexahedra and
  !> `ncontact` contact nodes. `status` is non-zero on an I/O error, with `msg`.
  subroutine write_xdmf(path, h5_name, nnodes, nelem, ncontact, status, msg)
    character(len=*), intent(in) :: path, h5_name
    integer(i8), intent(in) :: nnodes, nelem, ncontact
    integer, intent(out) :: status
    character(len=*), intent(out) :: msg
    character(len=:), allocatable :: h5
    integer :: u

    msg = ''
    h5 = xml_escape(trim(h5_name))
    open (newunit=u, file=path, status='replace', action='write', iostat=status, iomsg=msg)
    if (status /= 0) return
    write (u, '(a)', iostat=status, iomsg=msg) '<?xml version="1.0" ?>', &
      '<!DOCTYPE Xdmf SYSTEM "Xdmf.dtd" []>', &
      '<Xdmf Version="3.0" xmlns:xi="http://www.w3.org/2001/XInclude">', &
      '  <Domain>'
    if (status /= 0) return
    call write_grids(u, h5, nnodes, nelem, ncontact, status, msg)
    if (status /= 0) return
    write (u, '(a)', iostat=status, iomsg=msg) '  </Domain>', '</Xdmf>'
    if (status /= 0) return
    close (u, iostat=status, iomsg=msg)
  end subroutine write_xdmf

  !> Write the temporal XDMF file `path` of a series of HDF5 files
  !> `h5_names(k)` (names relative to the directory of `path`, each as
  !> write_xdmf describes it) at times `times(k)`: one Temporal collection per
  !> grid ("mesh", and "contact" with contact nodes) whose members, one per
  !> step, carry the grid's own name: ParaView's time slider shows the same
  !> named grids at every step.
  subroutine write_xdmf_series(path, h5_names, times, nnodes, nelem, ncontact, status, msg)
    character(len=*), intent(in) :: path, h5_names(:)
    real(dp), intent(in) :: times(:)
    integer(i8), intent(in) :: nnodes, nelem, ncontact
    integer, intent(out) :: status
    character(len=*), intent(out) :: msg
    character(len=*), parameter :: names(2) = ['mesh   ', 'contact']
    character(len=32) :: t
    integer :: u, k, part

    msg = ''
    open (newunit=u, file=path, status='replace', action='write', iostat=status, iomsg=msg)
    if (status /= 0) return
    write (u, '(a)', iostat=status, iomsg=msg) '<?xml version="1.0" ?>', &
      '<!DOCTYPE Xdmf SYSTEM "Xdmf.dtd" []>', &
      '<Xdmf Version="3.0" xmlns:xi="http://www.w3.org/2001/XInclude">', &
      '  <Domain>'
    do part = 1, merge(2, 1, ncontact > 0)
      if (status /= 0) return
      write (u, '(a)', iostat=status, iomsg=msg) &
        '    <Grid Name="'//trim(names(part))//'" GridType="Collection" CollectionType="Temporal">'
      do k = 1, size(h5_names)
        if (status /= 0) return
        write (t, '(es23.15e3)') times(k)
        call write_grids(u, xml_escape(trim(h5_names(k))), nnodes, nelem, ncontact, status, msg, part, &
                         '      <Time Value="'//trim(adjustl(t))//'" />')
      end do
      if (status /= 0) return
      write (u, '(a)', iostat=status, iomsg=msg) '    </Grid>'
    end do
    if (status /= 0) return
    write (u, '(a)', iostat=status, iomsg=msg) '  </Domain>', '</Xdmf>'
    if (status /= 0) return
    close (u, iostat=status, iomsg=msg)
  end subroutine write_xdmf_series

  !> The grids of one HDF5 file `h5` (escaped) on unit u: "mesh" (hexahedra with the
  !> displacement, subdomain and von Mises) and, with contact nodes, "contact" (vertices with
  !> the contact pressure and gap). `part`: 1 the mesh only, 2 the contact only (default
  !> both); `time`: a Time element written inside each grid.
  subroutine write_grids(u, h5, nnodes, nelem, ncontact, status, msg, part, time)
    integer, intent(in) :: u
    character(len=*), intent(in) :: h5
    integer(i8), intent(in) :: nnodes, nelem, ncontact
    integer, intent(out) :: status
    character(len=*), intent(inout) :: msg
    integer, intent(in), optional :: part
    character(len=*), intent(in), optional :: time
    character(len=:), allocatable :: when
    logical :: mesh, contact
    mesh = .true.
    contact = .true.
    if (present(part)) then
      mesh = part == 1
      contact = part == 2
    end if
    when = ''
    if (present(time)) when = time//new_line('a')
    status = 0
    if (mesh) write (u, '(a)', iostat=status, iomsg=msg) &
      '    <Grid Name="mesh" GridType="Uniform">', &
      when//'      <Topology TopologyType="Hexahedron" NumberOfElements="'//str(nelem)//'" NodesPerElement="8">', &
      data_item(h5, 'connectivity', nelem, 8, 'Int', 4), &
      '      </Topology>', &
      geometry(h5, 'coordinates', nnodes), &
      attribute(h5, 'displacement', 'Vector', 'Node', nnodes, 3, 'Float', 8), &
      attribute(h5, 'subdomain', 'Scalar', 'Cell', nelem, 0, 'Int', 4), &
      attribute(h5, 'von_mises', 'Scalar', 'Cell', nelem, 0, 'Float', 8), &
      '    </Grid>'
    if (status /= 0 .or. ncontact <= 0 .or. .not. contact) return
    write (u, '(a)', iostat=status, iomsg=msg) &
      '    <Grid Name="contact" GridType="Uniform">', &
      when//'      <Topology TopologyType="Polyvertex" NumberOfElements="'//str(ncontact)//'" NodesPerElement="1">', &
      data_item(h5, 'contact_vertices', ncontact, 0, 'Int', 4), &
      '      </Topology>', &
      geometry(h5, 'contact_coordinates', ncontact), &
      attribute(h5, 'contact_pressure', 'Scalar', 'Node', ncontact, 0, 'Float', 8), &
      attribute(h5, 'contact_gap', 'Scalar', 'Node', ncontact, 0, 'Float', 8), &
      '    </Grid>'
  end subroutine write_grids

  !> The Geometry element (XYZ) from dataset /`name` of `rows` x 3.
  function geometry(h5, name, rows) result(lines)
    character(len=*), intent(in) :: h5, name
    integer(i8), intent(in) :: rows
    character(len=:), allocatable :: lines
    lines = '      <Geometry GeometryType="XYZ">'//new_line('a')//data_item(h5, name, rows, 3, 'Float', 8)// &
            new_line('a')//'      </Geometry>'
  end function geometry

  !> An Attribute element `name` (`kind` Scalar or Vector, `center` Node or
  !> Cell) from the dataset of the same name.
  function attribute(h5, name, kind, center, rows, columns, number_type, precision) result(lines)
    character(len=*), intent(in) :: h5, name, kind, center, number_type
    integer(i8), intent(in) :: rows
    integer, intent(in) :: columns, precision
    character(len=:), allocatable :: lines
    lines = '      <Attribute Name="'//name//'" AttributeType="'//kind//'" Center="'//center//'">'// &
            new_line('a')//data_item(h5, name, rows, columns, number_type, precision)//new_line('a')// &
            '      </Attribute>'
  end function attribute

  !> One DataItem line for dataset /`name` of `rows` x `columns` (a vector
  !> of `rows` when `columns` is 0).
  function data_item(h5, name, rows, columns, number_type, precision) result(line)
    character(len=*), intent(in) :: h5, name, number_type
    integer(i8), intent(in) :: rows
    integer, intent(in) :: columns, precision
    character(len=:), allocatable :: line, dims
    dims = str(rows)
    if (columns > 0) dims = dims//' '//str(int(columns, i8))
    line = '        <DataItem Dimensions="'//dims//'" NumberType="'//number_type//'" Precision="'// &
           str(int(precision, i8))//'" Format="HDF">'//h5//':/'//name//'</DataItem>'
  end function data_item


  !> `s` with the characters XML reserves replaced by entities.
  function xml_escape(s) result(r)
    character(len=*), intent(in) :: s
    character(len=:), allocatable :: r
    integer :: i
    r = ''
    do i = 1, len(s)
      select case (s(i:i))
      case ('&')
        r = r//'&amp;'
      case ('<')
        r = r//'&lt;'
      case ('>')
        r = r//'&gt;'
      case ('"')
        r = r//'&quot;'
      case ("'")
        r = r//'&apos;'
      case default
        r = r//s(i:i)
      end select
    end do
  end function xml_escape
end module xdmf
