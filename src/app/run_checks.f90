!> The checks a run makes before its set-up work, run alone by `--check`:
!> the output folder (created as the run creates it, and probed for writing),
!> the ranks against the subdomains (clusters with hybrid TFETI), the coarse
!> groups against the ranks, the size limit of the explicit orthonormal G~;
!> and a memory estimate of the run, logged. Each refusal is an input error
!> (exit 2 on every rank, the group and the variable named).
module run_checks
  use kinds, only: dp, ip, i8
  use logger, only: log_message
  use errors, only: collective_error, exit_input_error
  use params, only: params_t
  use decomposition, only: decomposition_t, build_decomposition
  use clusters, only: is_hybrid, unit_mesh
  use coarse_problem, only: choose_coarse_ranks, estimated_factor_bytes, dense_for, ranks_per_node
  use orthonormal_coarse, only: check_orthonormal_size
  use hdf5_output, only: check_output_directory
  use rigid_hold, only: held_modes
  use mpi_f08, only: MPI_Comm, MPI_Comm_size
  implicit none
  private

  public :: check_run, memory_estimate_bytes

  !> The memory model of memory_estimate_bytes: a fixed part per rank (MPI,
  !> the libraries, the program) and a part per primal dof of the rank (K, its
  !> factors, B, the vectors). Calibrated on inputs/hertz.nml (472,392 dofs
  !> on 2 ranks: 339 MB peak per rank, 26 MB of it after MPI_Init) and rounded
  !> up: an estimate of the order of magnitude, not a bound.
  real(dp), parameter :: bytes_per_rank = 32.0e6_dp, bytes_per_dof = 1500.0_dp

contains

  !> Every check of `p` on `comm` that a run makes before its set-up work;
  !> the memory estimate logged. Collective.
  subroutine check_run(p, comm, dry_run)
    type(params_t), intent(in) :: p
    type(MPI_Comm), intent(in) :: comm
    logical, intent(in), optional :: dry_run   !< `--check`: create and write nothing
    type(decomposition_t) :: dec
    integer :: nranks, ierr, c
    character(len=300) :: msg

    call MPI_Comm_size(comm, nranks, ierr)
    call check_held(p, comm)
    if (p%output%write_hdf5 .or. p%output%write_report) call check_output_directory(comm, p%output%directory, dry_run)
    ! ranks against subdomains (or clusters): build_decomposition refuses more ranks than units
    if (is_hybrid(p%mesh)) then
      call build_decomposition(unit_mesh(p%mesh), comm, dec)
    else
      call build_decomposition(p%mesh, comm, dec)
    end if
    call choose_coarse_ranks(p%solver%coarse%coarse_ranks, p%solver%coarse%coarse_placement, nranks, &
                             dec%nsubdomains, c, msg, node_ranks=ranks_per_node(comm))
    if (len_trim(msg) > 0) call collective_error(msg, comm, exit_input_error)
    if (p%solver%coarse%coarse == 'orthonormal') call check_orthonormal_size(product(p%mesh%nsub), comm)
    call log_memory_estimate(p, nranks, dec%nsubdomains, c)
  end subroutine check_run

  !> Refuse a body that the Dirichlet, symmetry and contact rows together do
  !> not hold against every rigid motion (rigid_hold: its coarse problem
  !> would be singular). Collective; every rank computes the same.
  subroutine check_held(p, comm)
    type(params_t), intent(in) :: p
    type(MPI_Comm), intent(in) :: comm
    integer :: nheld
    integer(ip) :: nodes
    character(len=600) :: msg
    call held_modes(p%mesh, p%boundary, p%obstacle, nheld, nodes)
    if (nheld == 6) return
    write (msg, '(a,i0,a,i0,a,es10.3,a)') 'file '//trim(p%file)//', group &obstacle, variable shape: '// &
      'the body is held only by the contact, and the contact cannot hold it: ', nodes, &
      ' bottom node(s) lie over the obstacle, which with the Dirichlet and symmetry rows leave ', &
      6 - nheld, ' rigid motion(s) free (radius = ', p%obstacle%radius, &
      '): enlarge &obstacle radius, refine &mesh nel, move &obstacle axis under the nodes, or set '// &
      '&boundary top_dirichlet = .true.'
    call collective_error(msg, comm, exit_input_error)
  end subroutine check_held

  !> Log the memory estimate of the run (memory_estimate_bytes).
  subroutine log_memory_estimate(p, nranks, nunits, group_ranks)
    type(params_t), intent(in) :: p
    integer, intent(in) :: nranks, group_ranks
    integer(ip), intent(in) :: nunits
    integer(i8) :: per_rank
    character(len=300) :: line
    per_rank = memory_estimate_bytes(p, nranks, nunits, group_ranks)
    write (line, '(a,i0,a,i0,a)') 'memory estimate: about ', per_rank/1000000_i8, ' MB per rank, ', &
      per_rank*nranks/1000000_i8, ' MB in all (32 MB per rank + 1.5 kB per primal dof + the coarse factor)'
    call log_message(line)
  end subroutine log_memory_estimate

  !> Estimated peak bytes of the most loaded rank of a run of `p` on `nranks`
  !> ranks with `nunits` subdomains (clusters) and coarse groups of
  !> `group_ranks` ranks: bytes_per_rank, bytes_per_dof times the primal dofs
  !> of the rank with the most units (each unit's own copy of its nodes), and
  !> the coarse factor: dense 8 n^2 (n = 6 units) on a one-rank group or with
  !> the explicit G~, else the MUMPS estimate shared by the group's ranks.
  function memory_estimate_bytes(p, nranks, nunits, group_ranks) result(bytes)
    type(params_t), intent(in) :: p
    integer, intent(in) :: nranks, group_ranks
    integer(ip), intent(in) :: nunits
    integer(i8) :: bytes
    real(dp) :: dofs, coarse, n
    ! each subdomain holds its own copy of its interface nodes
    dofs = 3*real(product(p%mesh%nel + 1), dp)*real(product(int(p%mesh%nsub, i8)), dp)
    dofs = dofs*real((nunits + nranks - 1)/nranks, dp)/real(nunits, dp)
    n = 6*real(nunits, dp)
    if (p%solver%coarse%coarse == 'orthonormal' .or. &
        dense_for(p%solver%coarse%coarse_factor, int(6*nunits, ip), group_ranks)) then
      coarse = 8*n*n
    else
      coarse = real(estimated_factor_bytes(nunits), dp)/max(group_ranks, 1)
    end if
    bytes = int(bytes_per_rank + bytes_per_dof*dofs + coarse, i8)
  end function memory_estimate_bytes
end module run_checks
