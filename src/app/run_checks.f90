!> The checks a run makes before its set-up work, run alone by `--check`:
!> the output folder (created as the run creates it, and probed for writing),
!> the ranks against the subdomains (clusters with hybrid TFETI), the coarse
!> groups against the ranks (the projector's plan_coarse), the size limit of
!> the explicit orthonormal G~; and a memory estimate of the run, logged.
!> Each refusal is an input error (exit 2 on every rank, the group and the
!> variable named). The decomposition the checks build is the run's: the
!> set-up takes it over (`units`).
module run_checks
  use kinds, only: dp, ip, i8
  use logger, only: log_message
  use errors, only: collective_error, exit_input_error
  use params, only: params_t
  use decomposition, only: decomposition_t, build_decomposition
  use clusters, only: is_hybrid, unit_mesh
  use coarse_problem, only: ranks_per_node
  use projector, only: coarse_plan_t, plan_coarse
  use orthonormal_coarse, only: check_orthonormal_size
  use hdf5_output, only: check_output_directory
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
  !> the memory estimate logged. `units`: the decomposition into the FETI
  !> units (subdomains, or clusters with hybrid TFETI), for the set-up.
  !> Collective.
  subroutine check_run(p, comm, units)
    type(params_t), intent(in) :: p
    type(MPI_Comm), intent(in) :: comm
    type(decomposition_t), intent(out), optional :: units
    type(decomposition_t) :: dec
    type(coarse_plan_t) :: plan
    integer :: nranks, ierr

    call MPI_Comm_size(comm, nranks, ierr)
    if (p%output%write_hdf5 .or. p%output%write_report) call check_output_directory(comm, p%output%directory)
    call decompose(p, comm, dec)
    plan = plan_coarse(p%solver%coarse, nranks, dec%nsubdomains, ranks_per_node(comm))
    if (len_trim(plan%refusal) > 0) call collective_error(plan%refusal, comm, exit_input_error)
    if (p%solver%coarse%coarse == 'orthonormal') call check_orthonormal_size(product(p%mesh%nsub), comm)
    call log_memory_estimate(p, nranks, dec%nsubdomains, plan)
    if (present(units)) units = dec
  end subroutine check_run

  !> The decomposition into the FETI units: build_decomposition refuses more
  !> ranks than units.
  subroutine decompose(p, comm, dec)
    type(params_t), intent(in) :: p
    type(MPI_Comm), intent(in) :: comm
    type(decomposition_t), intent(out) :: dec
    if (is_hybrid(p%mesh)) then
      call build_decomposition(unit_mesh(p%mesh), comm, dec)
    else
      call build_decomposition(p%mesh, comm, dec)
    end if
  end subroutine decompose

  !> Log the memory estimate of the run (memory_estimate_bytes).
  subroutine log_memory_estimate(p, nranks, nunits, plan)
    type(params_t), intent(in) :: p
    integer, intent(in) :: nranks
    integer(ip), intent(in) :: nunits
    type(coarse_plan_t), intent(in) :: plan
    integer(i8) :: per_rank
    character(len=300) :: line
    per_rank = memory_estimate_bytes(p, nranks, nunits, plan)
    write (line, '(a,i0,a,i0,a)') 'memory estimate: about ', per_rank/1000000_i8, ' MB per rank, ', &
      per_rank*nranks/1000000_i8, ' MB in all (32 MB per rank + 1.5 kB per primal dof + the coarse factor)'
    call log_message(line)
  end subroutine log_memory_estimate

  !> Estimated peak bytes of the most loaded rank of a run of `p` on `nranks`
  !> ranks with `nunits` subdomains (clusters) and the coarse problem of
  !> `plan`: bytes_per_rank, bytes_per_dof times the primal dofs of the rank
  !> with the most units (each unit's own copy of its nodes), and the coarse
  !> factor's bytes per rank (plan_coarse).
  function memory_estimate_bytes(p, nranks, nunits, plan) result(bytes)
    type(params_t), intent(in) :: p
    integer, intent(in) :: nranks
    integer(ip), intent(in) :: nunits
    type(coarse_plan_t), intent(in) :: plan
    integer(i8) :: bytes
    real(dp) :: dofs
    ! each subdomain holds its own copy of its interface nodes
    dofs = 3*real(product(p%mesh%nel + 1), dp)*real(product(int(p%mesh%nsub, i8)), dp)
    dofs = dofs*real((nunits + nranks - 1)/nranks, dp)/real(nunits, dp)
    bytes = int(bytes_per_rank + bytes_per_dof*dofs + plan%factor_bytes, i8)
  end function memory_estimate_bytes
end module run_checks
