!> METIS 5 through its C API (Debian's libmetis-dev: 32-bit idx_t and real_t).
!> The only module that calls METIS. All arrays are 1-based (METIS is told so
!> with METIS_OPTION_NUMBERING = 1), and every call uses a fixed seed so that
!> every rank computes the same partition from the same graph.
module metis_wrapper
  use, intrinsic :: iso_c_binding, only: c_int, c_ptr, c_null_ptr, c_loc
  use kinds, only: ip
  use errors, only: fatal_error
  implicit none
  private

  public :: metis_part_graph_kway, metis_node_nd

  integer, parameter :: metis_noptions = 40
  integer, parameter :: metis_ok = 1
  ! option positions (C enum value + 1)
  integer, parameter :: opt_seed = 9, opt_contig = 12, opt_numbering = 18

  interface
    integer(c_int) function c_set_default_options(options) bind(C, name='METIS_SetDefaultOptions')
      import :: c_int
      integer(c_int), intent(inout) :: options(*)
    end function c_set_default_options

    integer(c_int) function c_part_graph_kway(nvtxs, ncon, xadj, adjncy, vwgt, vsize, adjwgt, &
                                              nparts, tpwgts, ubvec, options, objval, part) &
      bind(C, name='METIS_PartGraphKway')
      import :: c_int, c_ptr
      integer(c_int), intent(in) :: nvtxs, ncon, nparts
      integer(c_int), intent(in) :: xadj(*), adjncy(*)
      type(c_ptr), value :: vwgt, vsize, adjwgt, tpwgts, ubvec
      integer(c_int), intent(in) :: options(*)
      integer(c_int), intent(out) :: objval
      integer(c_int), intent(out) :: part(*)
    end function c_part_graph_kway

    integer(c_int) function c_node_nd(nvtxs, xadj, adjncy, vwgt, options, perm, iperm) &
      bind(C, name='METIS_NodeND')
      import :: c_int, c_ptr
      integer(c_int), intent(in) :: nvtxs
      integer(c_int), intent(in) :: xadj(*), adjncy(*)
      type(c_ptr), value :: vwgt
      integer(c_int), intent(in) :: options(*)
      integer(c_int), intent(out) :: perm(*), iperm(*)
    end function c_node_nd
  end interface

contains

  subroutine default_options(options, contiguous)
    integer(c_int), intent(out) :: options(metis_noptions)
    logical, intent(in) :: contiguous
    integer(c_int) :: status
    status = c_set_default_options(options)
    if (status /= metis_ok) call fatal_error('METIS_SetDefaultOptions failed')
    options(opt_numbering) = 1
    options(opt_seed) = 1
    if (contiguous) options(opt_contig) = 1
  end subroutine default_options

  !> Partition a graph (1-based CSR xadj(n+1), adjncy, no self loops) into
  !> `nparts` parts; optional vertex weights. part(n): 1..nparts.
  subroutine metis_part_graph_kway(n, xadj, adjncy, nparts, part, vertex_weights)
    integer(ip), intent(in) :: n, nparts
    integer(ip), intent(in) :: xadj(:), adjncy(:)
    integer(ip), intent(out) :: part(:)
    integer(ip), intent(in), optional, target :: vertex_weights(:)
    integer(c_int) :: options(metis_noptions), objval, status
    type(c_ptr) :: vwgt

    if (nparts == 1) then
      part(1:n) = 1
      return
    end if
    call default_options(options, .false.)
    vwgt = c_null_ptr
    if (present(vertex_weights)) vwgt = c_loc(vertex_weights)
    status = c_part_graph_kway(n, 1_c_int, xadj, adjncy, vwgt, c_null_ptr, c_null_ptr, nparts, &
                               c_null_ptr, c_null_ptr, options, objval, part)
    if (status /= metis_ok) call fatal_error('METIS_PartGraphKway failed')
  end subroutine metis_part_graph_kway

  !> Nested-dissection fill-reducing ordering of a graph (1-based CSR, no self
  !> loops). perm(k) is the vertex eliminated k-th ... in METIS's words,
  !> A(perm, perm) is the reordered matrix; iperm is its inverse.
  subroutine metis_node_nd(n, xadj, adjncy, perm, iperm)
    integer(ip), intent(in) :: n
    integer(ip), intent(in) :: xadj(:), adjncy(:)
    integer(ip), intent(out) :: perm(:), iperm(:)
    integer(c_int) :: options(metis_noptions), status
    integer(ip) :: k

    if (n <= 2) then
      perm(1:n) = [(k, k = 1, n)]
      iperm(1:n) = perm(1:n)
      return
    end if
    call default_options(options, .false.)
    status = c_node_nd(n, xadj, adjncy, c_null_ptr, options, perm, iperm)
    if (status /= metis_ok) call fatal_error('METIS_NodeND failed')
  end subroutine metis_node_nd
end module metis_wrapper
