#include "assertions.h"
!> The system of each subdomain on a distorted mesh, box and METIS, on 1 to 4
!> ranks: K symmetric, sparse pattern = node adjacency, K equal to a dense
!> sum of element matrices, exactly 6 zero eigenvalues, K R = 0 to round-off,
!> R orthonormal and spanning the rigid modes; per-subdomain materials;
!> the top pressure sums to -p Lx Ly; tributary areas of the bottom face
!> (summed over copies) equal the exact h-grid shares; von Mises stress of
!> the exact uniaxial solution equals p in every element.
program test_assembly
  use kinds, only: dp, ip, MPI_REAL_DP
  use params, only: params_t, default_params
  use decomposition, only: decomposition_t, build_decomposition
  use subdomain, only: subdomain_t, build_subdomain
  use assembly, only: assemble_subdomain, face_tributary_areas, subdomain_von_mises
  use materials, only: subdomain_material
  use q1_element, only: q1_stiffness
  use mpi_f08, only: MPI_Init, MPI_COMM_WORLD, MPI_Allreduce, MPI_Bcast, MPI_SUM
  use assertions, only: assert_true, assert_close, assert_below, test_finish
  use tolerances, only: reorder_tol
  implicit none
  integer :: ierr

  call MPI_Init(ierr)
  call check_case('box', [2, 2, 1], [2, 2, 3], 'checkerboard')
  call check_case('box', [1, 2, 3], [1, 1, 1], 'random')
  call check_case('metis', [2, 2, 2], [2, 3, 2], 'checkerboard')
  call check_case('metis', [3, 1, 2], [2, 2, 2], 'none')
  call test_finish()

contains

  subroutine check_case(method, nsub, nel, variation)
    character(len=*), intent(in) :: method, variation
    integer, intent(in) :: nsub(3), nel(3)
    real(dp), parameter :: pressure = 7.0_dp, lengths(3) = [1.0_dp, 1.5_dp, 0.8_dp]
    type(params_t) :: p
    type(decomposition_t) :: dec
    type(subdomain_t) :: sub
    character(len=60) :: what
    integer(ip) :: k, a, b, e, i, j, c, n, info, nn, ijk(3), g
    real(dp), allocatable :: kd(:, :), kref(:, :), eig(:), work(:), kr(:, :), raw(:, :), area(:), &
                             node_area(:), total_area(:), vm(:), u(:), young_all(:), young_root(:)
    real(dp) :: ke(24, 24), force(3), gforce(3), young, poisson, expected, d(3), x(3), hx, hy
    logical :: ok, pattern_ok
    logical, allocatable :: share(:, :)

    write (what, '(a,1x,a)') trim(method), trim(variation)
    p = default_params()
    p%mesh%nsub = nsub
    p%mesh%nel = nel
    p%mesh%lengths = lengths
    p%mesh%decomposition = method
    p%mesh%distortion = 0.25_dp
    p%material%variation = variation
    p%material%contrast = 1.0e3_dp
    p%load%top_pressure = pressure
    call build_decomposition(p, MPI_COMM_WORLD, dec)
    nn = dec%mesh%num_nodes()
    allocate (node_area(nn), total_area(nn))
    node_area = 0
    force = 0

    do k = 1, size(dec%local_subdomains)
      call build_subdomain(dec, dec%local_subdomains(k), sub)
      call assemble_subdomain(p, dec, sub)
      n = sub%ndof

      ! materials, derived here from the definitions of &material
      select case (variation)
      case ('checkerboard')
        if (method == 'box') then
          ijk = [mod(sub%id - 1, nsub(1)), mod((sub%id - 1)/nsub(1), nsub(2)), (sub%id - 1)/(nsub(1)*nsub(2))]
          expected = 2.1e5_dp*merge(1.0e3_dp, 1.0_dp, mod(sum(ijk), 2) == 1)
        else
          expected = 2.1e5_dp*merge(1.0e3_dp, 1.0_dp, mod(sub%id, 2) == 0)
        end if
        call assert_close(expected, sub%young, 1e-15_dp, trim(what)//': checkerboard young', HERE)
      case ('random')
        call assert_true(sub%young >= 2.1e5_dp .and. sub%young <= 2.1e8_dp, trim(what)//': random in range', HERE)
      case default
        call assert_close(2.1e5_dp, sub%young, 0.0_dp, trim(what)//': young', HERE)
      end select
      call assert_close(0.3_dp, sub%poisson, 0.0_dp, trim(what)//': poisson', HERE)

      ! pattern: row 3(a-1)+c holds exactly the dofs of nodes sharing an element with a
      pattern_ok = sub%K%nrows == n .and. sub%K%ncols == n
      allocate (kref(n, n), share(sub%nnodes, sub%nnodes))
      kref = 0
      share = .false.
      do e = 1, sub%nelem
        call q1_stiffness(sub%coords(:, sub%elem_nodes(:, e)), sub%young, sub%poisson, ke)
        do i = 1, 8
          do j = 1, 8
            a = sub%elem_nodes(i, e)
            b = sub%elem_nodes(j, e)
            share(a, b) = .true.
            kref(3*a - 2:3*a, 3*b - 2:3*b) = kref(3*a - 2:3*a, 3*b - 2:3*b) + ke(3*i - 2:3*i, 3*j - 2:3*j)
          end do
        end do
      end do
      do i = 1, n
        do j = sub%K%rowptr(i) + 1, sub%K%rowptr(i + 1) - 1
          pattern_ok = pattern_ok .and. sub%K%colind(j - 1) < sub%K%colind(j)
        end do
      end do
      call sub%K%to_dense(kd)
      call assert_true(pattern_ok, trim(what)//': CSR square, columns ascending', HERE)
      call assert_below(maxval(abs(kd - kref)), 1e-12_dp*maxval(abs(kref)), trim(what)//': K = sum of K_e', HERE)
      call assert_below(maxval(abs(kd - transpose(kd))), 1e-14_dp*maxval(abs(kd)), trim(what)//': K symmetric', HERE)
      call assert_true(sub%K%nnz() == 9*count(share), trim(what)//': nnz = 9 x node pairs sharing an element', HERE)
      deallocate (share)

      ! kernel
      allocate (eig(n), work(3*n), kr(n, 6))
      call sub%K%matvec(sub%R(:, 1), kr(:, 1))
      do c = 2, 6
        call sub%K%matvec(sub%R(:, c), kr(:, c))
      end do
      ! K R and R^T R: each entry a sum of at most n products (another order
      ! than exact arithmetic's cancellation): reorder_tol(n) relative
      call assert_below(norm2(kr)/(norm2(kd)*norm2(sub%R)), reorder_tol(int(n)), trim(what)//': |K R|/(|K||R|)', HERE)
      call assert_below(maxval(abs(matmul(transpose(sub%R), sub%R) - identity6())), reorder_tol(int(n)), &
                        trim(what)//': R^T R = I', HERE)
      allocate (raw(n, 6))
      raw = 0
      do a = 1, sub%nnodes
        x = sub%coords(:, a)
        raw(3*a - 2, 1) = 1
        raw(3*a - 1, 2) = 1
        raw(3*a, 3) = 1
        raw(3*a - 2:3*a, 4) = [0.0_dp, -x(3), x(2)]
        raw(3*a - 2:3*a, 5) = [x(3), 0.0_dp, -x(1)]
        raw(3*a - 2:3*a, 6) = [-x(2), x(1), 0.0_dp]
      end do
      call assert_below(norm2(raw - matmul(sub%R, matmul(transpose(sub%R), raw)))/norm2(raw), 1e-13_dp, &
                        trim(what)//': R spans the rigid modes', HERE)
      call dsyev('N', 'U', n, kd, n, eig, work, size(work), info)
      call assert_true(info == 0, 'dsyev', HERE)
      call assert_below(maxval(abs(eig(1:6))), 1e-12_dp*eig(n), trim(what)//': 6 zero eigenvalues', HERE)
      call assert_true(eig(7) > 1e-8_dp*eig(n), trim(what)//': eigenvalue 7 well above round-off', HERE)
      deallocate (kref, kd, eig, work, kr, raw)

      ! load: only on nodes of z = Lz, pointing down
      ok = size(sub%f) == n
      do a = 1, sub%nnodes
        if (sub%coords(3, a) /= lengths(3)) ok = ok .and. all(sub%f(3*a - 2:3*a) == 0)
        ok = ok .and. sub%f(3*a - 2) == 0 .and. sub%f(3*a - 1) == 0 .and. sub%f(3*a) <= 0
        force = force + sub%f(3*a - 2:3*a)
      end do
      call assert_true(ok, trim(what)//': load only on the top face, in -z', HERE)

      ! tributary areas on z = 0, summed over copies below
      allocate (area(sub%nnodes))
      call face_tributary_areas(dec, sub, area)
      do a = 1, sub%nnodes
        node_area(sub%node_gid(a)) = node_area(sub%node_gid(a)) + area(a)
      end do
      deallocate (area)

      ! exact uniaxial solution of the block case: von Mises = p everywhere
      allocate (u(n), vm(sub%nelem))
      do a = 1, sub%nnodes
        x = sub%coords(:, a)
        u(3*a - 2:3*a) = [sub%poisson*x(1), sub%poisson*x(2), -x(3)]*pressure/sub%young
      end do
      call subdomain_von_mises(sub, u, vm)
      call assert_below(maxval(abs(vm - pressure)), 1e-9_dp*pressure, trim(what)//': von Mises = p', HERE)
      deallocate (u, vm)
    end do

    call MPI_Allreduce(force, gforce, 3, MPI_REAL_DP, MPI_SUM, MPI_COMM_WORLD, ierr)
    call assert_close(-pressure*lengths(1)*lengths(2), gforce(3), 1e-13_dp, trim(what)//': total force', HERE)
    call assert_below(maxval(abs(gforce(1:2))), 1e-15_dp, trim(what)//': no horizontal force', HERE)
    call MPI_Allreduce(node_area, total_area, nn, MPI_REAL_DP, MPI_SUM, MPI_COMM_WORLD, ierr)
    call assert_close(lengths(1)*lengths(2), sum(total_area), 1e-13_dp, trim(what)//': bottom area', HERE)
    ok = .true.
    hx = lengths(1)/dec%mesh%ng(1)
    hy = lengths(2)/dec%mesh%ng(2)
    do g = 1, nn
      ijk = dec%mesh%node_ijk(g)
      if (ijk(3) /= 0) then
        ok = ok .and. total_area(g) == 0
        cycle
      end if
      d = 1
      if (ijk(1) == 0 .or. ijk(1) == dec%mesh%ng(1)) d(1) = 0.5_dp
      if (ijk(2) == 0 .or. ijk(2) == dec%mesh%ng(2)) d(2) = 0.5_dp
      ok = ok .and. abs(total_area(g) - d(1)*d(2)*hx*hy) <= 1e-14_dp*hx*hy
    end do
    call assert_true(ok, trim(what)//': tributary area of each bottom node', HERE)

    ! materials depend on the id alone: the same on every rank
    allocate (young_all(dec%nsubdomains))
    do i = 1, dec%nsubdomains
      call subdomain_material(p, dec, i, young, poisson)
      young_all(i) = young
    end do
    young_root = young_all
    call MPI_Bcast(young_root, dec%nsubdomains, MPI_REAL_DP, 0, MPI_COMM_WORLD, ierr)
    call assert_true(all(young_root == young_all), trim(what)//': materials rank-independent', HERE)
    if (variation == 'random' .and. dec%nsubdomains > 1) &
      call assert_true(any(young_all /= young_all(1)), trim(what)//': random materials differ', HERE)
  end subroutine check_case

  pure function identity6() result(eye)
    real(dp) :: eye(6, 6)
    integer :: i
    eye = 0
    do i = 1, 6
      eye(i, i) = 1
    end do
  end function identity6
end program test_assembly
