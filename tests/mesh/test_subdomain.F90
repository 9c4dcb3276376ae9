#include "assertions.h"
!> Subdomain geometry on a distorted mesh: nodes ascending, coordinates from
!> the global mesh, element connectivity, centroid, local_node; copies of every
!> node agree in coordinates across subdomains and ranks, and the number of
!> copies is the node's multiplicity.
program test_subdomain
  use kinds, only: dp, ip, MPI_REAL_DP, MPI_INT_IP
  use params, only: params_t, default_params
  use decomposition, only: decomposition_t, build_decomposition
  use subdomain, only: subdomain_t, build_subdomain, local_node
  use mpi_f08, only: MPI_Init, MPI_COMM_WORLD, MPI_Allreduce, MPI_SUM, MPI_MIN, MPI_MAX
  use assertions, only: assert_true, assert_equal, assert_below, test_finish
  implicit none
  integer :: ierr

  call MPI_Init(ierr)
  call check_case('box', [2, 2, 2], [3, 2, 2])
  call check_case('box', [4, 1, 1], [1, 1, 1])
  call check_case('metis', [2, 2, 2], [3, 3, 2])
  call test_finish()

contains

  subroutine check_case(method, nsub, nel)
    character(len=*), intent(in) :: method
    integer, intent(in) :: nsub(3), nel(3)
    type(params_t) :: p
    type(decomposition_t) :: dec
    type(subdomain_t) :: sub
    integer(ip) :: nn, k, a, e, g, i, nodes(8)
    real(dp), allocatable :: cmin(:, :), cmax(:, :), gmin(:, :), gmax(:, :)
    integer(ip), allocatable :: cnt(:), gcnt(:)
    logical :: ok_sorted, ok_coords, ok_conn, ok_local, ok_mult
    real(dp) :: centroid(3), centroid_err

    p = default_params()
    p%mesh%nsub = nsub
    p%mesh%nel = nel
    p%mesh%decomposition = method
    p%mesh%distortion = 0.3_dp
    p%mesh%lengths = [1.0_dp, 2.0_dp, 0.5_dp]
    call build_decomposition(p, MPI_COMM_WORLD, dec)
    nn = dec%mesh%num_nodes()
    allocate (cmin(3, nn), cmax(3, nn), gmin(3, nn), gmax(3, nn), cnt(nn), gcnt(nn))
    cmin = huge(1.0_dp)
    cmax = -huge(1.0_dp)
    cnt = 0
    ok_sorted = .true.
    ok_coords = .true.
    ok_conn = .true.
    ok_local = .true.
    centroid_err = 0
    do k = 1, size(dec%local_subdomains)
      call build_subdomain(dec, dec%local_subdomains(k), sub)
      call assert_equal(dec%local_subdomains(k), sub%id, method//': id', HERE)
      call assert_equal(dec%subdomain_nelements(sub%id), sub%nelem, method//': nelem', HERE)
      call assert_equal(3*sub%nnodes, sub%ndof, method//': ndof', HERE)
      if (method == 'box') then
        call assert_equal(int(product(nel + 1), ip), sub%nnodes, 'box: nnodes', HERE)
      end if
      do a = 2, sub%nnodes
        ok_sorted = ok_sorted .and. sub%node_gid(a - 1) < sub%node_gid(a)
      end do
      centroid = 0
      do a = 1, sub%nnodes
        g = sub%node_gid(a)
        ok_coords = ok_coords .and. all(sub%coords(:, a) == dec%mesh%node_coords(g))
        ok_local = ok_local .and. local_node(sub, g) == a
        cmin(:, g) = min(cmin(:, g), sub%coords(:, a))
        cmax(:, g) = max(cmax(:, g), sub%coords(:, a))
        cnt(g) = cnt(g) + 1
        centroid = centroid + sub%coords(:, a)
      end do
      centroid_err = max(centroid_err, maxval(abs(centroid/sub%nnodes - sub%centroid)))
      do e = 1, sub%nelem
        nodes = dec%mesh%element_nodes(sub%elem_gid(e))
        ok_conn = ok_conn .and. dec%subdomain_of_element(sub%elem_gid(e)) == sub%id
        ok_conn = ok_conn .and. all(sub%node_gid(sub%elem_nodes(:, e)) == nodes)
      end do
      ! nodes of elements of other subdomains that this one does not hold
      do e = 1, dec%mesh%num_elements(), 7
        nodes = dec%mesh%element_nodes(e)
        do i = 1, 8
          if (.not. any(dec%node_subdomains(nodes(i)) == sub%id)) &
            ok_local = ok_local .and. local_node(sub, nodes(i)) == 0
        end do
      end do
    end do
    call assert_true(ok_sorted, method//': node_gid ascending', HERE)
    call assert_true(ok_coords, method//': coords from the global mesh', HERE)
    call assert_true(ok_conn, method//': elem_nodes match the global connectivity', HERE)
    call assert_true(ok_local, method//': local_node', HERE)
    call assert_below(centroid_err, 1e-14_dp, method//': centroid = mean of node coordinates', HERE)

    call MPI_Allreduce(cmin, gmin, 3*nn, MPI_REAL_DP, MPI_MIN, MPI_COMM_WORLD, ierr)
    call MPI_Allreduce(cmax, gmax, 3*nn, MPI_REAL_DP, MPI_MAX, MPI_COMM_WORLD, ierr)
    call MPI_Allreduce(cnt, gcnt, nn, MPI_INT_IP, MPI_SUM, MPI_COMM_WORLD, ierr)
    call assert_true(all(gmax == gmin), method//': copies of a node agree across subdomains', HERE)
    ok_mult = .true.
    do g = 1, nn
      ok_mult = ok_mult .and. gcnt(g) == size(dec%node_subdomains(g))
    end do
    call assert_true(ok_mult, method//': copies = multiplicity', HERE)
    call assert_true(all(gcnt >= 1), method//': every node held', HERE)
    ! the mesh really is distorted and inner nodes stay inside the box
    if (all(dec%mesh%ng >= 2)) &
      call assert_true(any(gmin(1, :) /= real(nint(gmin(1, :)/dec%mesh%h(1)), dp)*dec%mesh%h(1)), &
                       method//': mesh distorted', HERE)
    call assert_true(all(gmin >= 0) .and. all(gmax(1, :) <= 1) .and. all(gmax(2, :) <= 2) .and. &
                     all(gmax(3, :) <= 0.5_dp), method//': nodes inside the box', HERE)
  end subroutine check_case
end program test_subdomain
