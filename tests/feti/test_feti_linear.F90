#include "assertions.h"
!> The contact-free TFETI solve (PCPG + u = K^+(f - B^T lambda) + R alpha)
!> gives the displacements of an undecomposed solve of the same mesh: the
!> whole box as one subdomain, assembled by the same element code, Dirichlet
!> conditions eliminated, solved by MUMPS (assembled only here, on rank 0).
!> Box and METIS decompositions, plain and distorted meshes.
program test_feti_linear
  use kinds, only: dp, ip
  use assertions, only: assert_true, assert_below, test_finish
  use params, only: params_t
  use decomposition, only: decomposition_t, build_decomposition
  use subdomain, only: subdomain_t, build_subdomain
  use assembly, only: assemble_subdomain
  use mumps_wrapper, only: mumps_t
  use feti_operators, only: feti_t, local_field_t
  use pcpg, only: pcpg_solve
  use feti_test_support, only: small_case
  use mpi_f08, only: MPI_Init, MPI_COMM_WORLD, MPI_COMM_SELF, MPI_Comm_rank, MPI_Bcast, MPI_Allreduce, &
                     MPI_DOUBLE_PRECISION, MPI_MAX, MPI_INTEGER
  implicit none
  integer :: ierr, rank

  call MPI_Init(ierr)
  call MPI_Comm_rank(MPI_COMM_WORLD, rank, ierr)
  call check(small_case('linear', [2, 2, 2], [3, 3, 3], 'box', 0.0_dp), 'box plain')
  call check(small_case('linear', [2, 2, 2], [2, 2, 2], 'metis', 0.3_dp), 'metis distorted')
  call check(small_case('linear', [3, 1, 2], [2, 3, 2], 'box', 0.25_dp), 'box distorted')
  call test_finish()

contains

  subroutine check(p, label)
    type(params_t), intent(in) :: p
    character(len=*), intent(in) :: label
    type(feti_t), target :: op
    type(subdomain_t), pointer :: subs(:)
    real(dp), allocatable :: lambda(:), alpha(:), u_global(:)
    type(local_field_t), allocatable :: u(:)
    integer(ip) :: iterations, ls, a, gid
    logical :: converged
    real(dp) :: err, mine, scale

    call op%setup(p, MPI_COMM_WORLD)
    call pcpg_solve(op, 1.0e-12_dp, 500_ip, lambda, alpha, iterations, converged)
    call assert_true(converged, label//': PCPG converged', HERE)
    allocate (u(op%nlocal()))
    call op%primal(lambda, alpha, u)

    call global_solution(p, u_global)
    scale = maxval(abs(u_global))
    mine = 0
    subs => op%subdomains()
    do ls = 1, op%nlocal()
      do a = 1, subs(ls)%nnodes
        gid = subs(ls)%node_gid(a)
        mine = max(mine, maxval(abs(u(ls)%v(3*a - 2:3*a) - u_global(3*gid - 2:3*gid))))
      end do
    end do
    call MPI_Allreduce(mine, err, 1, MPI_DOUBLE_PRECISION, MPI_MAX, MPI_COMM_WORLD, ierr)
    ! PCPG stops at 1e-12 relative; cond(P F P) of these small cases is < 1e3
    call assert_below(err, 1.0e-8_dp*scale, label//': TFETI u = undecomposed u', HERE)
    call assert_true(scale > 1.0e-4_dp, label//': a non-trivial solution', HERE)
    call op%free()
  end subroutine check

  !> The undecomposed solution by node gid (3 per node), on every rank.
  subroutine global_solution(p, u)
    type(params_t), intent(in) :: p
    real(dp), allocatable, intent(out) :: u(:)
    type(params_t) :: q
    type(decomposition_t) :: dec
    type(subdomain_t) :: whole
    type(mumps_t) :: solver
    integer(ip), allocatable :: irn(:), jcn(:)
    real(dp), allocatable :: a(:), rhs(:), g(:)
    logical, allocatable :: fixed(:)
    integer(ip) :: n, i, k, j, nnz, ijk(3), node
    integer :: nnodes

    q = p
    q%mesh%nel = p%mesh%nsub*p%mesh%nel
    q%mesh%nsub = 1
    q%mesh%decomposition = 'box'
    if (rank == 0) then
      call build_decomposition(q, MPI_COMM_SELF, dec)
      call build_subdomain(dec, 1_ip, whole)
      call assemble_subdomain(q, dec, whole)
      n = whole%ndof
      ! Dirichlet dofs and values, written here independently of the B builder
      allocate (fixed(n), g(n), rhs(n))
      fixed = .false.
      g = 0
      do node = 1, whole%nnodes
        ijk = dec%mesh%node_ijk(whole%node_gid(node))
        if (ijk(1) == 0) fixed(3*node - 2) = .true.
        if (ijk(2) == 0) fixed(3*node - 1) = .true.
        if (ijk(3) == dec%mesh%ng(3)) then
          fixed(3*node - 2:3*node) = .true.
          g(3*node - 2:3*node) = p%boundary%top_displacement
        end if
      end do
      ! eliminate: rhs = f - K g on free dofs, identity rows on fixed dofs
      call whole%K%matvec(g, rhs)
      rhs = whole%f - rhs
      where (fixed) rhs = g
      nnz = 0
      allocate (irn(whole%K%nnz()), jcn(whole%K%nnz()), a(whole%K%nnz()))
      do i = 1, n
        do k = whole%K%rowptr(i), whole%K%rowptr(i + 1) - 1
          j = whole%K%colind(k)
          if (j < i) cycle
          if (fixed(i) .or. fixed(j)) then
            if (i /= j) cycle
            nnz = nnz + 1
            irn(nnz) = i; jcn(nnz) = j; a(nnz) = 1
          else
            nnz = nnz + 1
            irn(nnz) = i; jcn(nnz) = j; a(nnz) = whole%K%values(k)
          end if
        end do
      end do
      call solver%init(MPI_COMM_SELF, .true.)
      call solver%set_centralized(n, irn(1:nnz), jcn(1:nnz), a(1:nnz))
      call solver%set_ordering('auto')
      call solver%factorize()
      call solver%solve(rhs)
      call solver%free()
      nnodes = whole%nnodes
      ! node gids of the whole box are 1..nnodes in order
      call assert_true(all(whole%node_gid == [(i, i = 1, nnodes)]), 'global node numbering', HERE)
      u = rhs
    end if
    call MPI_Bcast(nnodes, 1, MPI_INTEGER, 0, MPI_COMM_WORLD, ierr)
    if (rank /= 0) allocate (u(3*nnodes))
    call MPI_Bcast(u, 3*nnodes, MPI_DOUBLE_PRECISION, 0, MPI_COMM_WORLD, ierr)
  end subroutine global_solution
end program test_feti_linear
