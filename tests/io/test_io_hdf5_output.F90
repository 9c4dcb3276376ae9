#include "assertions.h"
!> write_fields on a small hexahedral box split into 2 subdomains along x,
!> owned by the ranks in reverse order (on 3 ranks rank 0 owns nothing, on
!> 2 ranks rank 0 has no contact nodes). Values are known functions of the
!> coordinates. Rank 0 reads the file back with HDF5 and checks shapes,
!> the rank-ordered concatenation, the 0-based global connectivity, the
!> geometry of every hexahedron and the values; and that no temporary file
!> is left. A second run has no contact nodes at all.
!> Argument: the output root; files go to <root>/np<ranks>/.
program test_io_hdf5_output
  use kinds, only: dp, ip, path_len
  use assertions, only: assert_true, assert_equal, assert_close, test_finish
  use hdf5_output, only: output_fields_t, write_fields, check_output_directory
  use mpi_f08, only: MPI_Init, MPI_COMM_WORLD, MPI_Comm_rank, MPI_Comm_size
  use hdf5, only: hid_t, hsize_t, h5open_f, h5close_f, h5fopen_f, h5fclose_f, H5F_ACC_RDONLY_F, &
                  h5dopen_f, h5dclose_f, h5dget_space_f, h5sget_simple_extent_ndims_f, &
                  h5sget_simple_extent_dims_f, h5sclose_f, h5dread_f, h5kind_to_type, H5_REAL_KIND, &
                  H5_INTEGER_KIND
  implicit none

  integer, parameter :: nsub = 2                       ! subdomains along x
  integer, parameter :: nel(3) = [2, 2, 3]             ! elements per subdomain
  real(dp), parameter :: h(3) = [0.5_dp, 0.25_dp, 0.125_dp]
  integer, parameter :: nloc(3) = nel + 1              ! nodes per subdomain and direction

  type(output_fields_t) :: f, whole, part
  character(len=path_len) :: root
  character(len=:), allocatable :: dir, run
  integer :: rank, nranks, ierr, r
  integer(ip) :: node_base

  call MPI_Init(ierr)
  call MPI_Comm_rank(MPI_COMM_WORLD, rank, ierr)
  call MPI_Comm_size(MPI_COMM_WORLD, nranks, ierr)
  call get_command_argument(1, root)
  dir = trim(root)//'/np'//str(nranks)
  call check_output_directory(MPI_COMM_WORLD, dir)

  ! with contact nodes
  call build_fields(rank, nranks, .true., f)
  run = 'fields'
  call write_fields(MPI_COMM_WORLD, dir, run, f)
  if (rank == 0) then
    ! what the file must hold: the ranks' shares one after the other
    call whole%init(0, 0, 0)
    node_base = 0
    do r = 0, nranks - 1
      call build_fields(r, nranks, .true., part)
      call concatenate(whole, part, node_base)
      node_base = node_base + size(part%coordinates, 2)
    end do
    call check_file(dir//'/'//run//'.h5', whole)
    call assert_true(.not. exists(dir//'/'//run//'.h5.tmp'), 'no temporary .h5 left', HERE)
    call assert_true(.not. exists(dir//'/'//run//'.xdmf.tmp'), 'no temporary .xdmf left', HERE)
    call assert_true(exists(dir//'/'//run//'.xdmf'), 'the .xdmf exists', HERE)
  end if

  ! no contact nodes anywhere: empty contact datasets
  call build_fields(rank, nranks, .false., f)
  call write_fields(MPI_COMM_WORLD, dir, 'nocontact', f)
  if (rank == 0) then
    call whole%init(0, 0, 0)
    node_base = 0
    do r = 0, nranks - 1
      call build_fields(r, nranks, .false., part)
      call concatenate(whole, part, node_base)
      node_base = node_base + size(part%coordinates, 2)
    end do
    call check_file(dir//'/nocontact.h5', whole)
  end if
  call test_finish()

contains

  function str(n) result(s)
    integer, intent(in) :: n
    character(len=:), allocatable :: s
    character(len=12) :: buf
    write (buf, '(i0)') n
    s = trim(buf)
  end function str

  logical function exists(path)
    character(len=*), intent(in) :: path
    inquire (file=path, exist=exists)
  end function exists

  !> The rank owning subdomain s (1-based): reverse round robin.
  integer function owner(s, nranks)
    integer, intent(in) :: s, nranks
    owner = nranks - 1 - mod(s - 1, nranks)
  end function owner

  pure function displacement_of(x) result(u)
    real(dp), intent(in) :: x(3)
    real(dp) :: u(3)
    u = [x(1)*x(2) + 1, x(2) - 2*x(3), 3*x(1) + x(3)**2]
  end function displacement_of

  pure real(dp) function von_mises_of(c)
    real(dp), intent(in) :: c(3)
    von_mises_of = c(1) + 10*c(2) + 100*c(3)
  end function von_mises_of

  pure real(dp) function pressure_of(x)
    real(dp), intent(in) :: x(3)
    pressure_of = 1 + x(1) + x(2)**2
  end function pressure_of

  pure real(dp) function gap_of(x)
    real(dp), intent(in) :: x(3)
    gap_of = 0.5_dp*x(1) - x(2) + 0.25_dp
  end function gap_of

  !> The share of `rank`: its subdomains in ascending id, each with its own
  !> copy of its nodes; contact nodes are the bottom nodes of odd subdomains.
  subroutine build_fields(rank, nranks, with_contact, f)
    integer, intent(in) :: rank, nranks
    logical, intent(in) :: with_contact
    type(output_fields_t), intent(inout) :: f
    integer :: s, mine, nn, ne, nc, a, b, c, n, e, k, base_node, x0
    integer, parameter :: corner(3, 8) = reshape([0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0, &
                                                  0, 0, 1, 1, 0, 1, 1, 1, 1, 0, 1, 1], [3, 8])
    mine = 0
    nc = 0
    do s = 1, nsub
      if (owner(s, nranks) /= rank) cycle
      mine = mine + 1
      if (with_contact .and. mod(s, 2) == 1) nc = nc + nloc(1)*nloc(2)
    end do
    nn = mine*product(nloc)
    ne = mine*product(nel)
    call f%init(int(nn, ip), int(ne, ip), int(nc, ip))
    n = 0
    e = 0
    k = 0
    do s = 1, nsub
      if (owner(s, nranks) /= rank) cycle
      base_node = n
      x0 = (s - 1)*nel(1)
      do c = 0, nel(3)
        do b = 0, nel(2)
          do a = 0, nel(1)
            n = n + 1
            f%coordinates(:, n) = [(x0 + a)*h(1), b*h(2), c*h(3)]
            f%displacement(:, n) = displacement_of(f%coordinates(:, n))
            if (c == 0 .and. with_contact .and. mod(s, 2) == 1) then
              k = k + 1
              f%contact_coordinates(:, k) = f%coordinates(:, n)
              f%contact_pressure(k) = pressure_of(f%coordinates(:, n))
              f%contact_gap(k) = gap_of(f%coordinates(:, n))
            end if
          end do
        end do
      end do
      do c = 0, nel(3) - 1
        do b = 0, nel(2) - 1
          do a = 0, nel(1) - 1
            e = e + 1
            f%connectivity(:, e) = base_node + 1 + (a + corner(1, :)) + &
              nloc(1)*((b + corner(2, :)) + nloc(2)*(c + corner(3, :)))
            f%subdomain(e) = s
            f%von_mises(e) = von_mises_of([(x0 + a + 0.5_dp)*h(1), (b + 0.5_dp)*h(2), (c + 0.5_dp)*h(3)])
          end do
        end do
      end do
    end do
  end subroutine build_fields

  !> Append `part` to `whole`, its connectivity shifted by `node_base` and made
  !> 0-based (as the file holds it).
  subroutine concatenate(whole, part, node_base)
    type(output_fields_t), intent(inout) :: whole
    type(output_fields_t), intent(in) :: part
    integer(ip), intent(in) :: node_base
    whole%coordinates = reshape([whole%coordinates, part%coordinates], &
                              [3, size(whole%coordinates, 2) + size(part%coordinates, 2)])
    whole%displacement = reshape([whole%displacement, part%displacement], &
                               [3, size(whole%displacement, 2) + size(part%displacement, 2)])
    whole%connectivity = reshape([whole%connectivity, part%connectivity + node_base - 1], &
                               [8, size(whole%connectivity, 2) + size(part%connectivity, 2)])
    whole%subdomain = [whole%subdomain, part%subdomain]
    whole%von_mises = [whole%von_mises, part%von_mises]
    whole%contact_coordinates = reshape([whole%contact_coordinates, part%contact_coordinates], &
      [3, size(whole%contact_coordinates, 2) + size(part%contact_coordinates, 2)])
    whole%contact_pressure = [whole%contact_pressure, part%contact_pressure]
    whole%contact_gap = [whole%contact_gap, part%contact_gap]
  end subroutine concatenate

  !> The dimensions of dataset `name` in Fortran order.
  function dataset_dims(file, name) result(dims)
    integer(hid_t), intent(in) :: file
    character(len=*), intent(in) :: name
    integer(hsize_t), allocatable :: dims(:)
    integer(hsize_t) :: maxdims(2)
    integer(hid_t) :: dset, space
    integer :: err, ndims
    call h5dopen_f(file, name, dset, err)
    call assert_equal(0, err, 'open '//name, HERE)
    call h5dget_space_f(dset, space, err)
    call h5sget_simple_extent_ndims_f(space, ndims, err)
    allocate (dims(ndims))
    call h5sget_simple_extent_dims_f(space, dims, maxdims(1:ndims), err)
    call h5sclose_f(space, err)
    call h5dclose_f(dset, err)
  end function dataset_dims

  subroutine check_real_2d(file, name, expected)
    integer(hid_t), intent(in) :: file
    character(len=*), intent(in) :: name
    real(dp), intent(in) :: expected(:,:)
    real(dp), allocatable :: got(:,:)
    integer(hsize_t), allocatable :: dims(:)
    integer(hid_t) :: dset
    integer :: err
    dims = dataset_dims(file, name)
    call assert_equal(2, size(dims), name//' is two-dimensional', HERE)
    if (size(dims) /= 2) return
    call assert_true(all(dims == shape(expected, hsize_t)), name//' has shape (3, n) in Fortran order', HERE)
    if (.not. all(dims == shape(expected, hsize_t)) .or. size(expected) == 0) return
    allocate (got(dims(1), dims(2)))
    call h5dopen_f(file, name, dset, err)
    call h5dread_f(dset, h5kind_to_type(dp, H5_REAL_KIND), got, dims, err)
    call assert_equal(0, err, 'read '//name, HERE)
    call h5dclose_f(dset, err)
    call assert_true(all(got == expected), name//' holds the ranks'' rows in rank order', HERE)
  end subroutine check_real_2d

  subroutine check_real_1d(file, name, expected)
    integer(hid_t), intent(in) :: file
    character(len=*), intent(in) :: name
    real(dp), intent(in) :: expected(:)
    real(dp), allocatable :: got(:)
    integer(hsize_t), allocatable :: dims(:)
    integer(hid_t) :: dset
    integer :: err
    dims = dataset_dims(file, name)
    call assert_equal(1, size(dims), name//' is one-dimensional', HERE)
    if (size(dims) /= 1) return
    call assert_true(all(dims == shape(expected, hsize_t)), name//' has shape (n)', HERE)
    if (.not. all(dims == shape(expected, hsize_t)) .or. size(expected) == 0) return
    allocate (got(dims(1)))
    call h5dopen_f(file, name, dset, err)
    call h5dread_f(dset, h5kind_to_type(dp, H5_REAL_KIND), got, dims, err)
    call assert_equal(0, err, 'read '//name, HERE)
    call h5dclose_f(dset, err)
    call assert_true(all(got == expected), name//' holds the ranks'' values in rank order', HERE)
  end subroutine check_real_1d

  function read_int(file, name, expected_dims) result(got)
    integer(hid_t), intent(in) :: file
    character(len=*), intent(in) :: name
    integer(hsize_t), intent(in) :: expected_dims(:)
    integer(ip), allocatable :: got(:)
    integer(hsize_t), allocatable :: dims(:)
    integer(hid_t) :: dset
    integer :: err
    dims = dataset_dims(file, name)
    allocate (got(0))
    call assert_true(size(dims) == size(expected_dims), name//' rank', HERE)
    if (size(dims) /= size(expected_dims)) return
    call assert_true(all(dims == expected_dims), name//' shape', HERE)
    if (.not. all(dims == expected_dims) .or. product(dims) == 0) return
    deallocate (got)
    allocate (got(product(dims)))
    call h5dopen_f(file, name, dset, err)
    call h5dread_f(dset, h5kind_to_type(ip, H5_INTEGER_KIND), got, [product(dims)], err)
    call assert_equal(0, err, 'read '//name, HERE)
    call h5dclose_f(dset, err)
  end function read_int

  subroutine check_file(path, expected)
    character(len=*), intent(in) :: path
    type(output_fields_t), intent(in) :: expected
    integer(hid_t) :: file
    integer(ip), allocatable :: conn(:), sub(:), vertices(:)
    integer :: err, e, nnodes, nelem, ncontact, i
    real(dp) :: x(3, 8), centroid(3), offset(3, 8)
    integer, parameter :: corner(3, 8) = reshape([0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0, &
                                                  0, 0, 1, 1, 0, 1, 1, 1, 1, 0, 1, 1], [3, 8])

    nnodes = size(expected%coordinates, 2)
    nelem = size(expected%connectivity, 2)
    ncontact = size(expected%contact_coordinates, 2)
    call h5open_f(err)
    call h5fopen_f(path, H5F_ACC_RDONLY_F, file, err)
    call assert_equal(0, err, 'open '//path, HERE)
    if (err /= 0) return

    call check_real_2d(file, 'coordinates', expected%coordinates)
    call check_real_2d(file, 'displacement', expected%displacement)
    call check_real_1d(file, 'von_mises', expected%von_mises)
    call check_real_2d(file, 'contact_coordinates', expected%contact_coordinates)
    call check_real_1d(file, 'contact_pressure', expected%contact_pressure)
    call check_real_1d(file, 'contact_gap', expected%contact_gap)

    conn = read_int(file, 'connectivity', [8_hsize_t, int(nelem, hsize_t)])
    call assert_true(all(conn == pack(expected%connectivity, .true.)), &
                     'connectivity: 0-based global node rows', HERE)
    sub = read_int(file, 'subdomain', [int(nelem, hsize_t)])
    call assert_true(all(sub == expected%subdomain), 'subdomain ids in rank order', HERE)
    vertices = read_int(file, 'contact_vertices', [int(ncontact, hsize_t)])
    call assert_true(all(vertices == [(i, i = 0, ncontact - 1)]), 'contact_vertices = 0, 1, ...', HERE)

    ! independent of the construction: hexahedra in VTK order, fields from coordinates
    if (size(conn) == 8*nelem .and. nelem > 0) then
      call assert_true(minval(conn) == 0 .and. maxval(conn) == nnodes - 1, 'connectivity covers 0..n-1', HERE)
      do i = 1, 8
        offset(:, i) = corner(:, i)*h
      end do
      do e = 1, nelem
        x = expected%coordinates(:, conn(8*(e-1)+1:8*e) + 1)
        call assert_true(all(abs(x - spread(x(:, 1), 2, 8) - offset) < 1.0e-12_dp), &
                         'hexahedron '//str(e)//' in Q1/VTK order', HERE)
        centroid = sum(x, dim=2)/8
        call assert_close(von_mises_of(centroid), expected%von_mises(e), 1.0e-13_dp, 'von_mises(centroid)', HERE, &
                          atol=1.0e-13_dp)
        call assert_equal(int(1 + floor(centroid(1)/(nel(1)*h(1))), ip), sub(e), 'subdomain of the centroid', HERE)
      end do
    end if
    do i = 1, nnodes
      call assert_true(all(expected%displacement(:, i) == displacement_of(expected%coordinates(:, i))), &
                       'displacement(coordinates)', HERE)
    end do
    do i = 1, ncontact
      call assert_close(pressure_of(expected%contact_coordinates(:, i)), expected%contact_pressure(i), 0.0_dp, &
                        'contact_pressure(coordinates)', HERE)
      call assert_close(gap_of(expected%contact_coordinates(:, i)), expected%contact_gap(i), 0.0_dp, &
                        'contact_gap(coordinates)', HERE, atol=0.0_dp)
    end do
    call h5fclose_f(file, err)
    call h5close_f(err)
  end subroutine check_file
end program test_io_hdf5_output
