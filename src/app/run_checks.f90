!> The checks a run makes before its set-up work, run alone by `--check`:
!> the output folder (created as the run creates it, and probed for writing),
!> the ranks against the subdomains (clusters with hybrid TFETI), the coarse
!> groups against the ranks (the projector's plan_coarse), the size limit of
!> the explicit orthonormal G~; and a memory estimate of the run, logged, and
!> the run refused when the estimate exceeds the memory of a node. Each
!> refusal is an input error (exit 2 on every rank, the group and the
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
  use proc_status, only: meminfo_bytes
  use rigid_hold, only: held_modes
  use mpi_f08, only: MPI_Comm, MPI_Comm_size, MPI_Comm_rank, MPI_Comm_split_type, MPI_Comm_free, &
                     MPI_COMM_TYPE_SHARED, MPI_INFO_NULL, MPI_Allreduce, MPI_Bcast, MPI_MAXLOC, &
                     MPI_2DOUBLE_PRECISION, MPI_DOUBLE_PRECISION
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
  !> `dry_run` (`--check`): create and write nothing. Collective.
  subroutine check_run(p, comm, units, dry_run)
    type(params_t), intent(in) :: p
    type(MPI_Comm), intent(in) :: comm
    type(decomposition_t), intent(out), optional :: units
    logical, intent(in), optional :: dry_run
    type(decomposition_t) :: dec
    type(coarse_plan_t) :: plan
    integer :: nranks, ierr

    call MPI_Comm_size(comm, nranks, ierr)
    call check_held(p, comm)
    if (p%output%write_hdf5 .or. p%output%write_report) call check_output_directory(comm, p%output%directory, dry_run)
    call decompose(p, comm, dec)
    plan = plan_coarse(p%solver%coarse, nranks, dec%nsubdomains, ranks_per_node(comm))
    if (len_trim(plan%refusal) > 0) call collective_error(plan%refusal, comm, exit_input_error)
    if (p%solver%coarse%coarse == 'orthonormal') call check_orthonormal_size(product(p%mesh%nsub), comm)
    call log_memory_estimate(p, nranks, dec%nsubdomains, plan)
    call refuse_above_memory(memory_estimate_bytes(p, nranks, dec%nsubdomains, plan), comm)
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

  !> Refuse (exit 2 on every rank, before any set-up work) a run whose memory
  !> estimate times the ranks sharing a node exceeds that node's memory
  !> (/proc/meminfo MemAvailable, else MemTotal; a node whose memory is not
  !> known is not refused). The message names the worst node's numbers.
  !> Collective.
  subroutine refuse_above_memory(per_rank, comm)
    integer(i8), intent(in) :: per_rank
    type(MPI_Comm), intent(in) :: comm
    type(MPI_Comm) :: node
    integer :: rank, local, ierr
    integer(i8) :: avail
    real(dp) :: mine(2), worst(2), info(3)
    character(len=12) :: field
    character(len=400) :: msg
    call MPI_Comm_rank(comm, rank, ierr)
    call MPI_Comm_split_type(comm, MPI_COMM_TYPE_SHARED, rank, MPI_INFO_NULL, node, ierr)
    call MPI_Comm_size(node, local, ierr)
    call MPI_Comm_free(node, ierr)
    field = 'MemAvailable'
    avail = meminfo_bytes(trim(field))
    if (avail <= 0) then
      field = 'MemTotal'
      avail = meminfo_bytes(trim(field))
    end if
    mine = [0.0_dp, real(rank, dp)]
    if (avail > 0) mine(1) = real(per_rank, dp)*local/real(avail, dp)
    call MPI_Allreduce(mine, worst, 1, MPI_2DOUBLE_PRECISION, MPI_MAXLOC, comm, ierr)
    if (worst(1) <= 1) return
    info = [real(local, dp), real(avail, dp), merge(1.0_dp, 0.0_dp, field == 'MemAvailable')]
    call MPI_Bcast(info, 3, MPI_DOUBLE_PRECISION, nint(worst(2)), comm, ierr)
    field = 'MemTotal'
    if (info(3) > 0) field = 'MemAvailable'
    write (msg, '(a,f0.1,a,f0.1,a,i0,a,f0.1,3a)') 'group &mesh, variable nsub: the run does not fit in memory: about ', &
      real(per_rank, dp)/1e9_dp, ' GB per rank by the memory estimate, ', real(per_rank, dp)*info(1)/1e9_dp, &
      ' GB for the ', nint(info(1)), ' rank(s) of a node, above its ', info(2)/1e9_dp, ' GB (', trim(field), &
      ' in /proc/meminfo); lower nsub or nel, or run on more nodes with fewer ranks on each'
    call collective_error(msg, comm, exit_input_error)
  end subroutine refuse_above_memory

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
  subroutine log_memory_estimate(p, nranks, nunits, plan)
    type(params_t), intent(in) :: p
    integer, intent(in) :: nranks
    integer(ip), intent(in) :: nunits
    type(coarse_plan_t), intent(in) :: plan
    integer(i8) :: per_rank
    character(len=300) :: line
    per_rank = memory_estimate_bytes(p, nranks, nunits, plan)
    write (line, '(a,i0,a,i0,a)') 'memory estimate: about ', per_rank/1000000_i8, ' MB per rank, ', &
      per_rank*nranks/1000000_i8, ' MB in all (32 MB per rank + 1.5 kB per primal dof, less the K that congruent '// &
      'subdomains share, + the coarse factor)'
    call log_message(line)
  end subroutine log_memory_estimate

  !> Estimated peak bytes of the most loaded rank of a run of `p` on `nranks`
  !> ranks with `nunits` subdomains (clusters) and the coarse problem of
  !> `plan`: bytes_per_rank, bytes_per_dof times the primal dofs of the rank
  !> with the most units (each unit's own copy of its nodes), less the
  !> stiffness matrices that congruent units do not keep (shared_stiffness),
  !> and the coarse factor's bytes per rank (plan_coarse).
  function memory_estimate_bytes(p, nranks, nunits, plan) result(bytes)
    type(params_t), intent(in) :: p
    integer, intent(in) :: nranks
    integer(ip), intent(in) :: nunits
    type(coarse_plan_t), intent(in) :: plan
    integer(i8) :: bytes
    real(dp) :: dofs, per_dof
    integer(ip) :: per_rank
    ! each subdomain holds its own copy of its interface nodes
    dofs = 3*real(product(p%mesh%nel + 1), dp)*real(product(int(p%mesh%nsub, i8)), dp)
    per_rank = (nunits + nranks - 1)/nranks
    dofs = dofs*real(per_rank, dp)/real(nunits, dp)
    per_dof = bytes_per_dof
    if (shared_stiffness(p, per_rank)) per_dof = per_dof - stiffness_bytes_per_dof(p)
    bytes = int(bytes_per_rank + per_dof*dofs + plan%factor_bytes, i8)
  end function memory_estimate_bytes

  !> True when the units of a rank are congruent and keep one K per class
  !> (the set-up's rule: `&solver share_subdomains = 'auto'`, box units of an
  !> undistorted mesh, at least 2 units per rank).
  logical function shared_stiffness(p, units_per_rank)
    type(params_t), intent(in) :: p
    integer(ip), intent(in) :: units_per_rank
    shared_stiffness = p%solver%local%share_subdomains == 'auto' .and. p%mesh%decomposition == 'box' .and. &
                       p%mesh%distortion == 0 .and. units_per_rank >= 2
  end function shared_stiffness

  !> Bytes per primal dof of a unit's K (CSR: 12 bytes per entry, 4 per row):
  !> a box of n(1) x n(2) x n(3) Q1 elements has 9 prod(3 n + 1) entries on
  !> 3 prod(n + 1) dofs.
  real(dp) function stiffness_bytes_per_dof(p) result(b)
    type(params_t), intent(in) :: p
    real(dp) :: nel(3)
    nel = real(p%mesh%nel, dp)
    if (is_hybrid(p%mesh)) nel = nel*real(max(p%mesh%cluster, 1_ip), dp)
    b = 12*9*product(3*nel + 1)/(3*product(nel + 1)) + 4
  end function stiffness_bytes_per_dof
end module run_checks
