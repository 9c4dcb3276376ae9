!> Neighbour exchange of dual (multiplier) values.
!>
!> Every multiplier has one owning rank. A rank keeps a "local" dual vector:
!> its owned multipliers first (1..n_own), then the ghosts it needs from
!> other ranks (multipliers owned elsewhere that touch its subdomains).
!> `gather` fills the ghosts from their owners; `scatter_add` adds the ghost
!> contributions back into the owners' entries. Both talk to neighbour ranks
!> only, through one MPI_Neighbor_alltoallv on a distributed graph
!> communicator. Buffers are allocated once, at `init`.
module dual_exchange
  use kinds, only: dp, ip, MPI_REAL_DP
  use errors, only: fatal_error
  use mpi_f08, only: MPI_Comm, MPI_Dist_graph_create_adjacent, MPI_Neighbor_alltoallv, MPI_UNWEIGHTED, &
    MPI_INFO_NULL, MPI_Comm_free, MPI_COMM_NULL, operator(/=)
  implicit none
  private

  !> The exchange pattern of one rank.
  type, public :: dual_exchange_t
    type(MPI_Comm) :: graph_comm = MPI_COMM_NULL
    integer(ip) :: n_own = 0, n_local = 0
    integer :: nneighbours = 0
    integer, allocatable :: neighbours(:)
    !> Owned entries sent to each neighbour in `gather` (received back in
    !> `scatter_add`), concatenated by neighbour: send_index(send_displs(q)+1 : ...).
    integer, allocatable :: send_counts(:), send_displs(:)
    integer(ip), allocatable :: send_index(:)
    !> Local ghost entries received from each neighbour.
    integer, allocatable :: recv_counts(:), recv_displs(:)
    integer(ip), allocatable :: recv_index(:)
    real(dp), allocatable :: send_buffer(:), recv_buffer(:)
  contains
    procedure :: init
    procedure :: gather
    procedure :: scatter_add
    procedure :: scatter_add_multi
    procedure :: ghosts_to_owners
    procedure :: free
  end type dual_exchange_t

contains

  !> Set up the pattern. `neighbours` are sorted ranks; for neighbour q,
  !> send_index(send_displs(q)+1 : send_displs(q)+send_counts(q)) are the owned
  !> entries that rank q holds as ghosts, in the order in which q lists them in
  !> its recv_index for this rank.
  subroutine init(this, comm, n_own, n_local, neighbours, send_counts, send_index, &
                  recv_counts, recv_index)
    class(dual_exchange_t), intent(inout) :: this
    type(MPI_Comm), intent(in) :: comm
    integer(ip), intent(in) :: n_own, n_local
    integer, intent(in) :: neighbours(:), send_counts(:), recv_counts(:)
    integer(ip), intent(in) :: send_index(:), recv_index(:)
    integer :: ierr, q

    call this%free()
    this%n_own = n_own
    this%n_local = n_local
    this%nneighbours = size(neighbours)
    this%neighbours = neighbours
    this%send_counts = send_counts
    this%recv_counts = recv_counts
    allocate (this%send_displs(this%nneighbours), this%recv_displs(this%nneighbours))
    if (this%nneighbours > 0) then
      this%send_displs(1) = 0
      this%recv_displs(1) = 0
      do q = 2, this%nneighbours
        this%send_displs(q) = this%send_displs(q - 1) + send_counts(q - 1)
        this%recv_displs(q) = this%recv_displs(q - 1) + recv_counts(q - 1)
      end do
    end if
    this%send_index = send_index
    this%recv_index = recv_index
    if (sum(send_counts) /= size(send_index) .or. sum(recv_counts) /= size(recv_index)) &
      call fatal_error('dual_exchange: counts do not match the index lists')
    allocate (this%send_buffer(max(1, size(send_index))), this%recv_buffer(max(1, size(recv_index))))
    call MPI_Dist_graph_create_adjacent(comm, this%nneighbours, this%neighbours, MPI_UNWEIGHTED, &
                                        this%nneighbours, this%neighbours, MPI_UNWEIGHTED, &
                                        MPI_INFO_NULL, .false., this%graph_comm, ierr)
    if (ierr /= 0) call fatal_error('dual_exchange: MPI_Dist_graph_create_adjacent failed')
  end subroutine init

  !> local(1:n_own) = own; local ghosts = the owners' values.
  subroutine gather(this, own, local)
    class(dual_exchange_t), intent(inout) :: this
    real(dp), intent(in) :: own(:)
    real(dp), intent(inout) :: local(:)
    integer :: i, ierr

    local(1:this%n_own) = own(1:this%n_own)
    do i = 1, size(this%send_index)
      this%send_buffer(i) = own(this%send_index(i))
    end do
    call MPI_Neighbor_alltoallv(this%send_buffer, this%send_counts, this%send_displs, MPI_REAL_DP, &
                                this%recv_buffer, this%recv_counts, this%recv_displs, MPI_REAL_DP, &
                                this%graph_comm, ierr)
    do i = 1, size(this%recv_index)
      local(this%recv_index(i)) = this%recv_buffer(i)
    end do
  end subroutine gather

  !> own = local(1:n_own) + the ghost values other ranks hold for these entries.
  subroutine scatter_add(this, local, own)
    class(dual_exchange_t), intent(inout) :: this
    real(dp), intent(in) :: local(:)
    real(dp), intent(inout) :: own(:)
    integer :: i, ierr

    do i = 1, size(this%recv_index)
      this%recv_buffer(i) = local(this%recv_index(i))
    end do
    call MPI_Neighbor_alltoallv(this%recv_buffer, this%recv_counts, this%recv_displs, MPI_REAL_DP, &
                                this%send_buffer, this%send_counts, this%send_displs, MPI_REAL_DP, &
                                this%graph_comm, ierr)
    own(1:this%n_own) = local(1:this%n_own)
    do i = 1, size(this%send_index)
      own(this%send_index(i)) = own(this%send_index(i)) + this%send_buffer(i)
    end do
  end subroutine scatter_add

  !> The ncomp values every ghost entry holds here (`ghost(:, i)` for local
  !> entry n_own + i) to the entry's owner, unsummed: received(:, k) is a
  !> neighbour's value for owned entry send_index(k) (an entry that several
  !> neighbours hold comes once from each). For set-up only.
  subroutine ghosts_to_owners(this, ncomp, ghost, received)
    class(dual_exchange_t), intent(inout) :: this
    integer, intent(in) :: ncomp
    real(dp), intent(in) :: ghost(:, :)
    real(dp), allocatable, intent(out) :: received(:, :)
    real(dp), allocatable :: sbuf(:, :)
    integer :: i, ierr

    allocate (sbuf(ncomp, max(1, size(this%recv_index))), received(ncomp, size(this%send_index)))
    do i = 1, size(this%recv_index)
      sbuf(:, i) = ghost(:, this%recv_index(i) - this%n_own)
    end do
    call MPI_Neighbor_alltoallv(sbuf, ncomp*this%recv_counts, ncomp*this%recv_displs, MPI_REAL_DP, &
                                received, ncomp*this%send_counts, ncomp*this%send_displs, MPI_REAL_DP, &
                                this%graph_comm, ierr)
  end subroutine ghosts_to_owners

  !> `scatter_add` of ncomp values per entry. For set-up only.
  subroutine scatter_add_multi(this, ncomp, local, own)
    class(dual_exchange_t), intent(inout) :: this
    integer, intent(in) :: ncomp
    real(dp), intent(in) :: local(:, :)
    real(dp), intent(inout) :: own(:, :)
    real(dp), allocatable :: sbuf(:, :), rbuf(:, :)
    integer :: i, ierr

    allocate (sbuf(ncomp, max(1, size(this%send_index))), rbuf(ncomp, max(1, size(this%recv_index))))
    do i = 1, size(this%recv_index)
      rbuf(:, i) = local(:, this%recv_index(i))
    end do
    call MPI_Neighbor_alltoallv(rbuf, ncomp*this%recv_counts, ncomp*this%recv_displs, MPI_REAL_DP, &
                                sbuf, ncomp*this%send_counts, ncomp*this%send_displs, MPI_REAL_DP, &
                                this%graph_comm, ierr)
    own(:, 1:this%n_own) = local(:, 1:this%n_own)
    do i = 1, size(this%send_index)
      own(:, this%send_index(i)) = own(:, this%send_index(i)) + sbuf(:, i)
    end do
  end subroutine scatter_add_multi

  !> Release the graph communicator and the buffers.
  subroutine free(this)
    class(dual_exchange_t), intent(inout) :: this
    integer :: ierr
    if (this%graph_comm /= MPI_COMM_NULL) call MPI_Comm_free(this%graph_comm, ierr)
    if (allocated(this%neighbours)) deallocate (this%neighbours)
    if (allocated(this%send_counts)) deallocate (this%send_counts)
    if (allocated(this%send_displs)) deallocate (this%send_displs)
    if (allocated(this%send_index)) deallocate (this%send_index)
    if (allocated(this%recv_counts)) deallocate (this%recv_counts)
    if (allocated(this%recv_displs)) deallocate (this%recv_displs)
    if (allocated(this%recv_index)) deallocate (this%recv_index)
    if (allocated(this%send_buffer)) deallocate (this%send_buffer)
    if (allocated(this%recv_buffer)) deallocate (this%recv_buffer)
    this%nneighbours = 0
    this%n_own = 0
    this%n_local = 0
  end subroutine free
end module dual_exchange
