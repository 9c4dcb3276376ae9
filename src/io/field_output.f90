!> The fields of a run to HDF5 + XDMF (hdf5_output): each rank's subdomains
!> (coordinates, displacement, connectivity, subdomain id, von Mises stress)
!> and its owned contact rows (coordinates, pressure, deformed gap (c - B u)/scale, a
!> displacement: the gap of the weighted mean of the node's copies).
module field_output
  use kinds, only: dp, ip
  use assembly, only: subdomain_von_mises
  use subdomain, only: subdomain_t
  use feti_operators, only: feti_t, local_field_t
  use contact_summary, only: contact_summary_t
  use hdf5_output, only: output_fields_t, write_fields
  implicit none
  private

  public :: write_run_fields

contains

  !> Write the fields of (u, lambda) of `op` to <directory>/<run_name>.h5 and
  !> .xdmf. Collective.
  subroutine write_run_fields(op, u, contact, directory, run_name)
    type(feti_t), intent(inout), target :: op
    type(local_field_t), intent(in) :: u(:)
    type(contact_summary_t), intent(in) :: contact
    character(len=*), intent(in) :: directory, run_name
    type(output_fields_t) :: fields
    type(subdomain_t), pointer :: subs(:)
    real(dp), allocatable :: bu(:), gap(:), x(:, :)
    logical, allocatable :: is_contact(:)
    integer(ip) :: ls, nn, ne, e, i, k

    subs => op%subdomains()
    nn = sum(subs(:)%nnodes)
    ne = sum(subs(:)%nelem)
    is_contact = op%is_contact()
    call fields%init(nn, ne, count(is_contact, kind=ip))
    nn = 0
    ne = 0
    do ls = 1, size(subs, kind=ip)
      associate (sub => subs(ls))
        fields%coordinates(:, nn + 1:nn + sub%nnodes) = sub%coords
        fields%displacement(:, nn + 1:nn + sub%nnodes) = reshape(u(ls)%v, [3, sub%nnodes])
        do e = 1, sub%nelem
          fields%connectivity(:, ne + e) = sub%elem_nodes(:, e) + nn
        end do
        fields%subdomain(ne + 1:ne + sub%nelem) = sub%id
        call subdomain_von_mises(sub, u(ls)%v, fields%von_mises(ne + 1:ne + sub%nelem))
        nn = nn + sub%nnodes
        ne = ne + sub%nelem
      end associate
    end do
    allocate (bu(op%n_own()))
    call op%apply_b(u, bu)
    gap = (op%gap_rhs() - bu)/op%force_scale()
    x = op%row_coordinates()
    k = 0
    do i = 1, op%n_own()
      if (.not. is_contact(i)) cycle
      k = k + 1
      fields%contact_coordinates(:, k) = x(:, i)
      fields%contact_pressure(k) = contact%pressure(i)
      fields%contact_gap(k) = gap(i)
    end do
    call write_fields(op%comm(), directory, run_name, fields)
    call fields%free()
  end subroutine write_run_fields
end module field_output
