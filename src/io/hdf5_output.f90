!> Fields of a run to one parallel HDF5 file plus its XDMF description, and the
!> early check of the output directory. The only module that uses HDF5.
!>
!> Each rank hands in its share of the fields (its subdomains concatenated,
!> one node entry per subdomain copy of a node). `write_fields` writes
!> `<directory>/<run_name>.h5` with MPI-IO, every dataset collectively, each
!> rank into its own block of rows (offsets from MPI_Exscan of the counts),
!> and rank 0 writes `<directory>/<run_name>.xdmf` (see module xdmf).
!>
!> Datasets, with the shapes HDF5 / h5py / XDMF see (the Fortran arrays in
!> `output_fields_t` are their transposes):
!>
!> | dataset                | shape         | type    | what                                  |
!> |------------------------|---------------|---------|---------------------------------------|
!> | /coordinates           | (nnodes, 3)   | float64 | node coordinates                      |
!> | /displacement          | (nnodes, 3)   | float64 | node displacement                     |
!> | /connectivity          | (nelem, 8)    | int32   | 0-based global node rows, Q1/VTK order|
!> | /subdomain             | (nelem)       | int32   | subdomain id of each element          |
!> | /von_mises             | (nelem)       | float64 | von Mises stress of each element      |
!> | /contact_coordinates   | (ncontact, 3) | float64 | contact node coordinates              |
!> | /contact_pressure      | (ncontact)    | float64 | contact pressure                      |
!> | /contact_gap           | (ncontact)    | float64 | gap to the obstacle                   |
!> | /contact_vertices      | (ncontact)    | int32   | 0, 1, ..., ncontact-1 (XDMF Polyvertex)|
!>
!> Rows are ordered by rank, then as each rank gave them. Both files are
!> written under `<name>.tmp` and renamed when complete, so a reader never
!> sees a partial file under the final name.
module hdf5_output
  use, intrinsic :: iso_c_binding, only: c_ptr, c_loc, c_null_ptr
  use kinds, only: dp, ip, i8, MPI_INT_I8
  use errors, only: fatal_error, collective_error, exit_input_error
  use file_system, only: is_directory, make_directories, rename_file, process_id, could_create
  use xdmf, only: write_xdmf
  use mpi_f08, only: MPI_Comm, MPI_Comm_rank, MPI_Exscan, MPI_Allreduce, MPI_Bcast, MPI_Barrier, &
                     MPI_SUM, MPI_INTEGER, MPI_CHARACTER, MPI_INFO_NULL
  use hdf5, only: hid_t, hsize_t, h5open_f, h5close_f, h5kind_to_type, H5_REAL_KIND, H5_INTEGER_KIND, &
                  h5pcreate_f, h5pclose_f, H5P_FILE_ACCESS_F, H5P_DATASET_XFER_F, h5pset_fapl_mpio_f, &
                  h5pset_dxpl_mpio_f, H5FD_MPIO_COLLECTIVE_F, h5fcreate_f, h5fclose_f, H5F_ACC_TRUNC_F, &
                  h5screate_simple_f, h5sclose_f, h5sselect_hyperslab_f, h5sselect_none_f, H5S_SELECT_SET_F, &
                  h5dcreate_f, h5dclose_f, h5dwrite_f
  implicit none
  private

  public :: write_fields, check_output_directory

  integer, parameter :: msg_len = 1024

  interface write_dataset
    module procedure write_real_2d, write_real_1d, write_int_2d, write_int_1d
  end interface write_dataset

  !> This rank's share of the fields (plain arrays, filled by the caller).
  type, public :: output_fields_t
    real(dp), allocatable :: coordinates(:,:)          !< (3, nnodes)
    real(dp), allocatable :: displacement(:,:)         !< (3, nnodes)
    integer(ip), allocatable :: connectivity(:,:)      !< (8, nelem) 1-based rows of this rank's nodes
    integer(ip), allocatable :: subdomain(:)           !< (nelem) subdomain id
    real(dp), allocatable :: von_mises(:)              !< (nelem)
    real(dp), allocatable :: contact_coordinates(:,:)  !< (3, ncontact)
    real(dp), allocatable :: contact_pressure(:)       !< (ncontact)
    real(dp), allocatable :: contact_gap(:)            !< (ncontact)
  contains
    procedure :: init => fields_init
    procedure :: free => fields_free
  end type output_fields_t

  !> What one collective dataset write needs besides the data.
  type :: slab_t
    integer(hid_t) :: file = -1, xfer = -1
    integer(i8) :: offset = 0, total = 0, local = 0   !< rows before this rank, all rows, this rank's rows
    character(len=:), allocatable :: path              !< file name, for messages
    type(MPI_Comm) :: comm
  end type slab_t

contains

  !> Allocate every array for `nnodes` nodes, `nelem` elements and `ncontact`
  !> contact nodes (any of them may be 0), set to zero.
  subroutine fields_init(self, nnodes, nelem, ncontact)
    class(output_fields_t), intent(inout) :: self
    integer(ip), intent(in) :: nnodes, nelem, ncontact
    call self%free()
    allocate (self%coordinates(3, nnodes), self%displacement(3, nnodes), source=0.0_dp)
    allocate (self%connectivity(8, nelem), self%subdomain(nelem), source=0_ip)
    allocate (self%von_mises(nelem), source=0.0_dp)
    allocate (self%contact_coordinates(3, ncontact), source=0.0_dp)
    allocate (self%contact_pressure(ncontact), self%contact_gap(ncontact), source=0.0_dp)
  end subroutine fields_init

  !> Deallocate every array.
  subroutine fields_free(self)
    class(output_fields_t), intent(inout) :: self
    if (allocated(self%coordinates)) deallocate (self%coordinates)
    if (allocated(self%displacement)) deallocate (self%displacement)
    if (allocated(self%connectivity)) deallocate (self%connectivity)
    if (allocated(self%subdomain)) deallocate (self%subdomain)
    if (allocated(self%von_mises)) deallocate (self%von_mises)
    if (allocated(self%contact_coordinates)) deallocate (self%contact_coordinates)
    if (allocated(self%contact_pressure)) deallocate (self%contact_pressure)
    if (allocated(self%contact_gap)) deallocate (self%contact_gap)
  end subroutine fields_free

  !> Make sure `directory` exists and can be written, before any solving.
  !> Rank 0 creates it if missing (with its parents) and writes and deletes a
  !> small file in it (with `dry_run`: only checks that it could); on failure
  !> every rank of `comm` exits with status exit_input_error and rank 0
  !> prints which directory and why. Collective.
  subroutine check_output_directory(comm, directory, dry_run)
    type(MPI_Comm), intent(in) :: comm
    character(len=*), intent(in) :: directory
    !> check only (`--check`): create nothing, write nothing
    logical, intent(in), optional :: dry_run
    character(len=msg_len) :: reason, close_msg
    character(len=:), allocatable :: why, probe
    character(len=16) :: pid
    integer :: rank, ierr, status, close_status, unit
    logical :: dry

    dry = .false.
    if (present(dry_run)) dry = dry_run
    call MPI_Comm_rank(comm, rank, ierr)
    status = 0
    reason = ''
    if (rank == 0) then
      if (len_trim(directory) == 0) then
        status = 1
        reason = 'is empty'
      else if (dry) then
        call could_create(directory, status, why)
        if (status /= 0) reason = "cannot create '"//trim(directory)//"': "//why
      else if (.not. is_directory(directory)) then
        call make_directories(directory, status, why)
        if (status /= 0) reason = "cannot create '"//trim(directory)//"': "//why
      end if
      if (status == 0 .and. .not. dry) then
        write (pid, '(i0)') process_id()
        probe = trim(directory)//'/.feticontact_write_test.'//trim(pid)
        open (newunit=unit, file=probe, status='replace', action='write', iostat=status, iomsg=reason)
        if (status == 0) then
          write (unit, '(a)', iostat=status, iomsg=reason) 'feticontact'
          close (unit, status='delete', iostat=close_status, iomsg=close_msg)
          if (status == 0 .and. close_status /= 0) then
            status = close_status
            reason = close_msg
          end if
        end if
        if (status /= 0) reason = "'"//trim(directory)//"' is not writable: "//trim(reason)
      end if
    end if
    call MPI_Bcast(status, 1, MPI_INTEGER, 0, comm, ierr)
    if (status == 0) return
    call MPI_Bcast(reason, msg_len, MPI_CHARACTER, 0, comm, ierr)
    call collective_error('group &output, variable directory: '//trim(reason), comm, exit_input_error)
  end subroutine check_output_directory

  !> Write `fields` of all ranks of `comm` to `<directory>/<run_name>.h5` and
  !> `<directory>/<run_name>.xdmf`. Collective: every rank calls it, also one
  !> with no entries. The directory must exist (see check_output_directory).
  !> Any HDF5 or file error stops the run with a message naming the file.
  subroutine write_fields(comm, directory, run_name, fields)
    type(MPI_Comm), intent(in) :: comm
    character(len=*), intent(in) :: directory, run_name
    type(output_fields_t), intent(in) :: fields
    integer(i8) :: counts(3), offsets(3), totals(3)
    integer(ip), allocatable :: global_connectivity(:,:), vertices(:)
    character(len=:), allocatable :: base, h5_file, xdmf_file
    character(len=msg_len) :: msg
    integer(hid_t) :: access
    type(slab_t) :: s
    integer :: rank, ierr, hdferr, status, i

    call check_fields(fields)
    call MPI_Comm_rank(comm, rank, ierr)
    counts = [size(fields%coordinates, 2, i8), size(fields%connectivity, 2, i8), &
              size(fields%contact_coordinates, 2, i8)]
    call MPI_Exscan(counts, offsets, 3, MPI_INT_I8, MPI_SUM, comm, ierr)
    if (rank == 0) offsets = 0          ! MPI_Exscan leaves rank 0's result undefined
    call MPI_Allreduce(counts, totals, 3, MPI_INT_I8, MPI_SUM, comm, ierr)
    if (totals(1) > huge(0_ip) .or. totals(3) > huge(0_ip)) &
      call fatal_error('write_fields: more than 2^31-1 nodes cannot be indexed by int32 connectivity', comm)

    if (len_trim(directory) == 0) then
      base = trim(run_name)
    else
      base = trim(directory)//'/'//trim(run_name)
    end if
    h5_file = base//'.h5'
    xdmf_file = base//'.xdmf'

    ! node rows of this rank start at offsets(1): 0-based global rows for XDMF
    global_connectivity = fields%connectivity - 1_ip + int(offsets(1), ip)
    vertices = [(int(offsets(3), ip) + i, i = 0, int(counts(3)) - 1)]

    s%comm = comm
    s%path = h5_file//'.tmp'
    call h5open_f(hdferr)
    call h5check(hdferr, 'initialize the HDF5 library', s)
    call h5pcreate_f(H5P_FILE_ACCESS_F, access, hdferr)
    call h5check(hdferr, 'create a file access property list', s)
    call h5pset_fapl_mpio_f(access, comm%MPI_VAL, MPI_INFO_NULL%MPI_VAL, hdferr)
    call h5check(hdferr, 'select MPI-IO file access', s)
    call h5fcreate_f(s%path, H5F_ACC_TRUNC_F, s%file, hdferr, access_prp=access)
    call h5check(hdferr, 'create the file', s)
    call h5pclose_f(access, hdferr)
    call h5check(hdferr, 'close the file access property list', s)
    call h5pcreate_f(H5P_DATASET_XFER_F, s%xfer, hdferr)
    call h5check(hdferr, 'create a transfer property list', s)
    call h5pset_dxpl_mpio_f(s%xfer, H5FD_MPIO_COLLECTIVE_F, hdferr)
    call h5check(hdferr, 'select collective transfers', s)

    call set_rows(s, offsets(1), totals(1), counts(1))
    call write_dataset(s, 'coordinates', fields%coordinates)
    call write_dataset(s, 'displacement', fields%displacement)
    call set_rows(s, offsets(2), totals(2), counts(2))
    call write_dataset(s, 'connectivity', global_connectivity)
    call write_dataset(s, 'subdomain', fields%subdomain)
    call write_dataset(s, 'von_mises', fields%von_mises)
    call set_rows(s, offsets(3), totals(3), counts(3))
    call write_dataset(s, 'contact_coordinates', fields%contact_coordinates)
    call write_dataset(s, 'contact_pressure', fields%contact_pressure)
    call write_dataset(s, 'contact_gap', fields%contact_gap)
    call write_dataset(s, 'contact_vertices', vertices)

    call h5pclose_f(s%xfer, hdferr)
    call h5check(hdferr, 'close the transfer property list', s)
    call h5fclose_f(s%file, hdferr)
    call h5check(hdferr, 'close the file', s)
    call h5close_f(hdferr)
    call h5check(hdferr, 'close the HDF5 library', s)

    ! every rank has closed the file: it is complete
    call MPI_Barrier(comm, ierr)
    if (rank == 0) then
      call rename_file(h5_file//'.tmp', h5_file, status)
      if (status /= 0) call fatal_error('write_fields: cannot rename '//h5_file//'.tmp to '//h5_file, comm)
      call write_xdmf(xdmf_file//'.tmp', trim(run_name)//'.h5', totals(1), totals(2), totals(3), status, msg)
      if (status /= 0) call fatal_error('write_fields: cannot write '//xdmf_file//'.tmp: '//trim(msg), comm)
      call rename_file(xdmf_file//'.tmp', xdmf_file, status)
      if (status /= 0) call fatal_error('write_fields: cannot rename '//xdmf_file//'.tmp to '//xdmf_file, comm)
    end if
    ! no rank returns before both files are there
    call MPI_Barrier(comm, ierr)
  end subroutine write_fields

  !> Stop the run if this rank's fields are not allocated or not consistent.
  subroutine check_fields(f)
    type(output_fields_t), intent(in) :: f
    integer :: nnodes, nelem, ncontact

    if (.not. (allocated(f%coordinates) .and. allocated(f%displacement) .and. allocated(f%connectivity) &
               .and. allocated(f%subdomain) .and. allocated(f%von_mises) .and. &
               allocated(f%contact_coordinates) .and. allocated(f%contact_pressure) .and. &
               allocated(f%contact_gap))) &
      call fatal_error('write_fields: every array of output_fields_t must be allocated (size 0 is fine)')
    nnodes = size(f%coordinates, 2)
    nelem = size(f%connectivity, 2)
    ncontact = size(f%contact_coordinates, 2)
    if (size(f%coordinates, 1) /= 3 .or. any(shape(f%displacement) /= [3, nnodes])) &
      call fatal_error('write_fields: coordinates and displacement must both be (3, nnodes)')
    if (size(f%connectivity, 1) /= 8 .or. size(f%subdomain) /= nelem .or. size(f%von_mises) /= nelem) &
      call fatal_error('write_fields: connectivity must be (8, nelem), subdomain and von_mises (nelem)')
    if (size(f%contact_coordinates, 1) /= 3 .or. size(f%contact_pressure) /= ncontact .or. &
        size(f%contact_gap) /= ncontact) &
      call fatal_error('write_fields: contact_coordinates must be (3, ncontact), contact_pressure and '// &
                       'contact_gap (ncontact)')
    if (nelem > 0) then
      if (minval(f%connectivity) < 1 .or. maxval(f%connectivity) > nnodes) &
        call fatal_error('write_fields: connectivity refers to a node outside 1..nnodes of this rank')
    end if
  end subroutine check_fields

  subroutine set_rows(s, offset, total, local)
    type(slab_t), intent(inout) :: s
    integer(i8), intent(in) :: offset, total, local
    s%offset = offset
    s%total = total
    s%local = local
  end subroutine set_rows

  !> Stop all ranks if an HDF5 call failed (HDF5 has printed its error stack).
  subroutine h5check(hdferr, what, s)
    integer, intent(in) :: hdferr
    character(len=*), intent(in) :: what
    type(slab_t), intent(in) :: s
    if (hdferr < 0) call fatal_error('write_fields: HDF5 could not '//what//' ('//s%path//')', s%comm)
  end subroutine h5check

  !> Create dataset `name` of `s%total` rows of `ncomp` values (a vector when
  !> `ncomp` is 0) and select this rank's rows in the file (`filespace`) and
  !> in memory (`memspace`; nothing selected when the rank has no rows, and
  !> the caller then passes a one-element dummy buffer).
  subroutine open_slab(s, name, type_id, ncomp, dset, filespace, memspace)
    type(slab_t), intent(in) :: s
    character(len=*), intent(in) :: name
    integer(hid_t), intent(in) :: type_id
    integer, intent(in) :: ncomp
    integer(hid_t), intent(out) :: dset, filespace, memspace
    integer(hsize_t), allocatable :: global_dims(:), local_dims(:), start(:)
    integer :: hdferr

    if (ncomp > 0) then
      global_dims = [integer(hsize_t) :: ncomp, s%total]
      local_dims = [integer(hsize_t) :: ncomp, max(s%local, 1_i8)]
      start = [integer(hsize_t) :: 0, s%offset]
    else
      global_dims = [integer(hsize_t) :: s%total]
      local_dims = [integer(hsize_t) :: max(s%local, 1_i8)]
      start = [integer(hsize_t) :: s%offset]
    end if
    call h5screate_simple_f(size(global_dims), global_dims, filespace, hdferr)
    call h5check(hdferr, 'create the dataspace of /'//name, s)
    call h5dcreate_f(s%file, '/'//name, type_id, filespace, dset, hdferr)
    call h5check(hdferr, 'create dataset /'//name, s)
    call h5screate_simple_f(size(local_dims), local_dims, memspace, hdferr)
    call h5check(hdferr, 'create the memory dataspace of /'//name, s)
    if (s%local > 0) then
      local_dims(size(local_dims)) = int(s%local, hsize_t)
      call h5sselect_hyperslab_f(filespace, H5S_SELECT_SET_F, start, local_dims, hdferr)
      call h5check(hdferr, 'select the rows of this rank in /'//name, s)
    else
      call h5sselect_none_f(filespace, hdferr)
      call h5check(hdferr, 'select no rows in /'//name, s)
      call h5sselect_none_f(memspace, hdferr)
      call h5check(hdferr, 'select no memory for /'//name, s)
    end if
  end subroutine open_slab

  subroutine close_slab(s, name, dset, filespace, memspace)
    type(slab_t), intent(in) :: s
    character(len=*), intent(in) :: name
    integer(hid_t), intent(in) :: dset, filespace, memspace
    integer :: hdferr
    call h5sclose_f(memspace, hdferr)
    call h5check(hdferr, 'close the memory dataspace of /'//name, s)
    call h5sclose_f(filespace, hdferr)
    call h5check(hdferr, 'close the dataspace of /'//name, s)
    call h5dclose_f(dset, hdferr)
    call h5check(hdferr, 'close dataset /'//name, s)
  end subroutine close_slab

  ! The generic write_dataset: the specific procedures only name the HDF5 type
  ! and the number of components of the buffer; write_buffer does the rest.

  subroutine write_real_2d(s, name, values)
    type(slab_t), intent(in) :: s
    character(len=*), intent(in) :: name
    real(dp), intent(in), target, contiguous :: values(:,:)
    type(c_ptr) :: buffer
    buffer = c_null_ptr
    if (size(values) > 0) buffer = c_loc(values)
    call write_buffer(s, name, h5kind_to_type(dp, H5_REAL_KIND), size(values, 1), buffer)
  end subroutine write_real_2d

  subroutine write_real_1d(s, name, values)
    type(slab_t), intent(in) :: s
    character(len=*), intent(in) :: name
    real(dp), intent(in), target, contiguous :: values(:)
    type(c_ptr) :: buffer
    buffer = c_null_ptr
    if (size(values) > 0) buffer = c_loc(values)
    call write_buffer(s, name, h5kind_to_type(dp, H5_REAL_KIND), 0, buffer)
  end subroutine write_real_1d

  subroutine write_int_2d(s, name, values)
    type(slab_t), intent(in) :: s
    character(len=*), intent(in) :: name
    integer(ip), intent(in), target, contiguous :: values(:,:)
    type(c_ptr) :: buffer
    buffer = c_null_ptr
    if (size(values) > 0) buffer = c_loc(values)
    call write_buffer(s, name, h5kind_to_type(ip, H5_INTEGER_KIND), size(values, 1), buffer)
  end subroutine write_int_2d

  subroutine write_int_1d(s, name, values)
    type(slab_t), intent(in) :: s
    character(len=*), intent(in) :: name
    integer(ip), intent(in), target, contiguous :: values(:)
    type(c_ptr) :: buffer
    buffer = c_null_ptr
    if (size(values) > 0) buffer = c_loc(values)
    call write_buffer(s, name, h5kind_to_type(ip, H5_INTEGER_KIND), 0, buffer)
  end subroutine write_int_1d

  !> Dataset `name` of `s%total` rows of `ncomp` values of `type_id` (a vector
  !> when `ncomp` is 0) from this rank's rows at `buffer`. A rank without rows
  !> still takes part in the collective write (with a dummy buffer and nothing
  !> selected); a dataset with no rows at all is created and left empty
  !> (every rank knows the total, so every rank skips the write together).
  subroutine write_buffer(s, name, type_id, ncomp, buffer)
    type(slab_t), intent(in) :: s
    character(len=*), intent(in) :: name
    integer(hid_t), intent(in) :: type_id
    integer, intent(in) :: ncomp
    type(c_ptr), intent(in) :: buffer
    integer(hid_t) :: dset, filespace, memspace
    real(dp), target :: dummy(max(ncomp, 1))
    integer :: hdferr

    call open_slab(s, name, type_id, ncomp, dset, filespace, memspace)
    if (s%total > 0) then
      dummy = 0
      if (s%local > 0) then
        call h5dwrite_f(dset, type_id, buffer, hdferr, mem_space_id=memspace, file_space_id=filespace, &
                        xfer_prp=s%xfer)
      else
        call h5dwrite_f(dset, type_id, c_loc(dummy), hdferr, mem_space_id=memspace, file_space_id=filespace, &
                        xfer_prp=s%xfer)
      end if
      call h5check(hdferr, 'write dataset /'//name, s)
    end if
    call close_slab(s, name, dset, filespace, memspace)
  end subroutine write_buffer
end module hdf5_output
