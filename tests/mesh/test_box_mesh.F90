#include "assertions.h"
!> Index arithmetic of the global box mesh and its distortion.
program test_box_mesh
  use kinds, only: dp, ip
  use box_mesh, only: box_mesh_t, box_mesh_init, hash_unit, face_x0, face_x1, face_y0, face_y1, &
                      face_z0, face_z1
  use mpi_f08, only: MPI_Init
  use assertions, only: assert_true, assert_equal, assert_close, assert_below, test_finish
  implicit none
  type(box_mesh_t) :: m, plain, other
  integer :: ierr
  integer(ip) :: g, e, i, j, k, ijk(3), nodes(8), nmoved, nsame, f
  real(dp) :: x(3), x0(3), off(3), maxoff(3), mean, u
  logical :: ok_ijk, ok_nodes, ok_boundary, ok_bound, ok_det, ok_faces, ok_eface

  call MPI_Init(ierr)
  call box_mesh_init(m, [2_ip, 3_ip, 1_ip], [3_ip, 1_ip, 4_ip], [2.0_dp, 1.5_dp, 0.5_dp], 0.3_dp, 7_ip)
  call box_mesh_init(plain, [2_ip, 3_ip, 1_ip], [3_ip, 1_ip, 4_ip], [2.0_dp, 1.5_dp, 0.5_dp], 0.0_dp, 7_ip)
  call box_mesh_init(other, [2_ip, 3_ip, 1_ip], [3_ip, 1_ip, 4_ip], [2.0_dp, 1.5_dp, 0.5_dp], 0.3_dp, 8_ip)

  call assert_true(all(m%ng == [6, 3, 4]), 'ng = nsub*nel', HERE)
  call assert_equal(7_ip*4_ip*5_ip, m%num_nodes(), 'num_nodes', HERE)
  call assert_equal(6_ip*3_ip*4_ip, m%num_elements(), 'num_elements', HERE)

  ! node gid <-> (i,j,k), formula of ARCHITECTURE.md
  ok_ijk = .true.
  do k = 0, 4
    do j = 0, 3
      do i = 0, 6
        g = 1 + i + 7*(j + 4*k)
        ok_ijk = ok_ijk .and. all(m%node_ijk(g) == [i, j, k]) .and. m%node_gid([i, j, k]) == g
      end do
    end do
  end do
  call assert_true(ok_ijk, 'node gid <-> ijk', HERE)
  ok_ijk = .true.
  do k = 0, 3
    do j = 0, 2
      do i = 0, 5
        e = 1 + i + 6*(j + 3*k)
        ok_ijk = ok_ijk .and. all(m%element_ijk(e) == [i, j, k]) .and. m%element_gid([i, j, k]) == e
      end do
    end do
  end do
  call assert_true(ok_ijk, 'element gid <-> ijk', HERE)

  ! element nodes in Q1 order: offsets (0,0,0) (1,0,0) (1,1,0) (0,1,0), then at k+1
  ok_nodes = .true.
  do e = 1, m%num_elements()
    ijk = m%element_ijk(e)
    nodes = m%element_nodes(e)
    ok_nodes = ok_nodes .and. all(m%node_ijk(nodes(1)) == ijk) &
               .and. all(m%node_ijk(nodes(2)) == ijk + [1, 0, 0]) &
               .and. all(m%node_ijk(nodes(3)) == ijk + [1, 1, 0]) &
               .and. all(m%node_ijk(nodes(4)) == ijk + [0, 1, 0]) &
               .and. all(m%node_ijk(nodes(5)) == ijk + [0, 0, 1]) &
               .and. all(m%node_ijk(nodes(6)) == ijk + [1, 0, 1]) &
               .and. all(m%node_ijk(nodes(7)) == ijk + [1, 1, 1]) &
               .and. all(m%node_ijk(nodes(8)) == ijk + [0, 1, 1])
  end do
  call assert_true(ok_nodes, 'element nodes in Q1 order', HERE)

  ! undistorted coordinates; far faces exactly at L
  call assert_below(maxval(abs(plain%node_coords(plain%node_gid([3, 2, 1])) - &
                               [3*2.0_dp/6, 2*1.5_dp/3, 1*0.5_dp/4])), 1e-15_dp, 'plain coordinates', HERE)
  call assert_true(all(plain%node_coords(plain%num_nodes()) == [2.0_dp, 1.5_dp, 0.5_dp]), &
                   'last node at (Lx, Ly, Lz)', HERE)

  ! distortion: boundary nodes stay, inner nodes move by at most distortion*h,
  ! deterministic, depends on the seed
  ok_boundary = .true.
  ok_bound = .true.
  ok_det = .true.
  nmoved = 0
  nsame = 0
  maxoff = 0
  do g = 1, m%num_nodes()
    x = m%node_coords(g)
    x0 = plain%node_coords(g)
    off = x - x0
    ok_det = ok_det .and. all(m%node_coords(g) == x)
    if (m%node_on_boundary(g)) then
      ok_boundary = ok_boundary .and. all(x == x0)
    else
      ok_bound = ok_bound .and. all(abs(off) <= 0.3_dp*m%h*(1 + 1e-12_dp))
      if (all(off /= 0)) nmoved = nmoved + 1
      if (any(other%node_coords(g) == x)) nsame = nsame + 1
      maxoff = max(maxoff, abs(off)/m%h)
    end if
  end do
  call assert_true(ok_boundary, 'boundary nodes not moved', HERE)
  call assert_true(ok_bound, 'offsets within distortion*h', HERE)
  call assert_true(ok_det, 'coordinates deterministic', HERE)
  call assert_equal(5_ip*2_ip*3_ip, nmoved, 'every inner node moved in all components', HERE)
  call assert_equal(0_ip, nsame, 'another seed moves every inner node elsewhere', HERE)
  call assert_true(all(maxoff > 0.15_dp), 'offsets use a good part of the range', HERE)

  ! the hash is spread over [0,1): mean of many values near 1/2
  mean = 0
  do i = 1, 10000
    u = hash_unit(i, 2_ip, 5_ip)
    call assert_true(u >= 0 .and. u < 1, 'hash in [0,1)', HERE)
    mean = mean + u
  end do
  call assert_close(0.5_dp, mean/10000, 0.02_dp, 'hash mean', HERE)

  ! face helpers
  ok_faces = .true.
  do g = 1, m%num_nodes()
    ijk = m%node_ijk(g)
    ok_faces = ok_faces .and. (m%node_on_face(g, face_x0) .eqv. ijk(1) == 0) &
               .and. (m%node_on_face(g, face_x1) .eqv. ijk(1) == 6) &
               .and. (m%node_on_face(g, face_y0) .eqv. ijk(2) == 0) &
               .and. (m%node_on_face(g, face_y1) .eqv. ijk(2) == 3) &
               .and. (m%node_on_face(g, face_z0) .eqv. ijk(3) == 0) &
               .and. (m%node_on_face(g, face_z1) .eqv. ijk(3) == 4)
  end do
  call assert_true(ok_faces, 'node_on_face', HERE)
  ok_eface = .true.
  do e = 1, m%num_elements()
    nodes = m%element_nodes(e)
    do f = face_x0, face_z1
      ! an element touches a box face iff 4 of its nodes lie on it
      ok_eface = ok_eface .and. (m%element_on_face(e, f) .eqv. &
                                 count([(m%node_on_face(nodes(i), f), i=1, 8)]) == 4)
    end do
  end do
  call assert_true(ok_eface, 'element_on_face', HERE)
  ! box subdomain of an element: id 1 + I + Nx*(J + Ny*K)
  call assert_equal(1_ip + 1_ip + 2_ip*(2_ip + 3_ip*0_ip), m%box_subdomain(m%element_gid([4, 2, 3])), &
                    'box_subdomain', HERE)
  call test_finish()
end program test_box_mesh
