!> Named wall-clock timers per phase, nested, reported as min / max / mean over ranks.
!>
!> A timer started while others run is kept under them: time accumulates per
!> path (the running timers from the outermost down, then the name), so one
!> name started under two parents gives two rows of the tree. Start/stop pairs
!> of one path add up; a stop must name the innermost running timer. Every
!> rank must call `timers_reduce` together; a path a rank never used counts as
!> 0 s there. Starting and stopping use a fixed table (no allocation).
module timers
  use kinds, only: dp, i8, name_len, MPI_REAL_DP
  use errors, only: fatal_error
  use memory_marks, only: memory_marks_reduce
  use mpi_f08, only: MPI_Comm, MPI_Wtime, MPI_Allreduce, MPI_Bcast, MPI_Comm_size, MPI_Comm_rank, MPI_MIN, &
    MPI_MAX, MPI_SUM, MPI_CHARACTER, MPI_INTEGER
  implicit none
  private

  public :: timer_start, timer_stop, timer_seconds, timers_reduce, stat_path

  integer, parameter :: max_timers = 256       !< distinct paths on one rank
  integer, parameter :: max_depth = 16         !< timers running at once
  character(len=*), parameter :: separator = ' > '
  integer, parameter :: key_len = max_depth*(name_len + len(separator))

  !> Kinds of rows in the array timers_reduce returns.
  integer, parameter, public :: row_phase = 0    !< all the time of one name, wherever it ran
  integer, parameter, public :: row_tree = 1     !< one path of the tree
  integer, parameter, public :: row_other = 2    !< a parent's time outside its timed sub-rows
  integer, parameter, public :: row_memory = 3   !< a memory mark (memory_marks)

  !> Reduced statistics of one row. `name` is set on row_phase rows only (so a
  !> search by name finds the per-name total); tree, other and memory rows carry
  !> `label` (the timer or mark name; 'other'), `depth` (0 for a root) and
  !> `parent` (index of the parent row in the same array, 0 for a root).
  type, public :: timer_stat_t
    character(len=name_len) :: name = ''
    real(dp) :: min = 0, max = 0, mean = 0
    integer :: row = row_phase
    character(len=name_len) :: label = ''
    integer :: depth = 0, parent = 0
    !> memory rows: max over ranks of VmHWM at the mark, of its growth since
    !> the mark before, of VmRSS at the mark (bytes; -1 where unknown)
    integer(i8) :: peak = -1, added = -1, resident = -1
  end type timer_stat_t

  ! the tree of this rank: node 0 is the virtual root
  character(len=name_len) :: names(max_timers) = ''
  integer :: parent_of(max_timers) = 0, next_sibling(max_timers) = 0, first_child(0:max_timers) = 0
  real(dp) :: total(max_timers) = 0, started(max_timers) = -1
  integer :: count = 0
  integer :: stack(max_depth) = 0, depth = 0

contains

  !> The node `name` under `parent` (0: a root), created when missing. Names
  !> longer than name_len are cut to it.
  integer function child(parent, name)
    integer, intent(in) :: parent
    character(len=*), intent(in) :: name
    character(len=name_len) :: cut
    integer :: i, last
    cut = name
    last = 0
    i = first_child(parent)
    do while (i > 0)
      if (names(i) == cut) then
        child = i
        return
      end if
      last = i
      i = next_sibling(i)
    end do
    if (count == max_timers) call fatal_error('timers: more than 256 timer paths')
    count = count + 1
    names(count) = cut
    parent_of(count) = parent
    if (last == 0) then
      first_child(parent) = count
    else
      next_sibling(last) = count
    end if
    child = count
  end function child

  !> Start (or resume) the timer `name` under the innermost running timer.
  subroutine timer_start(name)
    character(len=*), intent(in) :: name
    integer :: i, parent
    parent = 0
    if (depth > 0) parent = stack(depth)
    if (depth == max_depth) call fatal_error('timers: more than 16 timers running at once: '//trim(name))
    i = child(parent, name)
    depth = depth + 1
    stack(depth) = i
    started(i) = MPI_Wtime()
  end subroutine timer_start

  !> Stop the timer `name` (the innermost running one) and add the elapsed time to its path.
  subroutine timer_stop(name)
    character(len=*), intent(in) :: name
    character(len=name_len) :: cut
    integer :: i, k
    if (depth == 0) call fatal_error('timers: stop of a timer not running: '//trim(name))
    i = stack(depth)
    cut = name
    if (names(i) /= cut) then
      do k = depth - 1, 1, -1
        if (names(stack(k)) == cut) call fatal_error('timers: stop of '''//trim(name)//''' while '''// &
                                                      trim(names(i))//''', started inside it, still runs')
      end do
      call fatal_error('timers: stop of a timer not running: '//trim(name))
    end if
    total(i) = total(i) + (MPI_Wtime() - started(i))
    started(i) = -1
    depth = depth - 1
  end subroutine timer_stop

  !> Accumulated seconds of `name` on this rank, over every path it ran under
  !> (0 if never used; the running interval not included).
  real(dp) function timer_seconds(name)
    character(len=*), intent(in) :: name
    character(len=name_len) :: cut
    integer :: i
    cut = name
    timer_seconds = 0
    do i = 1, count
      if (names(i) == cut) then
        if (.not. has_ancestor(i, cut)) timer_seconds = timer_seconds + total(i)
      end if
    end do
  end function timer_seconds

  !> Whether a node above `i` is also named `name` (its time is counted there).
  logical function has_ancestor(i, name)
    integer, intent(in) :: i
    character(len=*), intent(in) :: name
    integer :: j
    has_ancestor = .true.
    j = parent_of(i)
    do while (j > 0)
      if (names(j) == name) return
      j = parent_of(j)
    end do
    has_ancestor = .false.
  end function has_ancestor

  !> The path of node `i`: the names from the root down, joined by ' > '.
  function key_of(i) result(key)
    integer, intent(in) :: i
    character(len=key_len) :: key
    integer :: j
    key = names(i)
    j = parent_of(i)
    do while (j > 0)
      key = trim(names(j))//separator//key
      j = parent_of(j)
    end do
  end function key_of

  !> Row `i` of `stats` as a path: the labels from its root down joined by ' > '
  !> (the name of a phase row).
  function stat_path(stats, i) result(path)
    type(timer_stat_t), intent(in) :: stats(:)
    integer, intent(in) :: i
    character(len=:), allocatable :: path
    integer :: j
    if (stats(i)%row == row_phase) then
      path = trim(stats(i)%name)
      return
    end if
    path = trim(stats(i)%label)
    j = stats(i)%parent
    do while (j > 0)
      path = trim(stats(j)%label)//separator//path
      j = stats(j)%parent
    end do
  end function stat_path

  !> Min / max / mean over the ranks of `comm` (a running timer counts up to
  !> now), collective. The rows: the tree
  !> (row_tree, depth first, sub-rows in the order they were first started,
  !> after the sub-rows of each parent a row_other with the parent's time
  !> outside them, so the sub-rows and `other` add up to the parent), then the
  !> memory marks (row_memory), then one row_phase per name in the order the
  !> names were first started (the per-name totals).
  subroutine timers_reduce(comm, stats)
    type(MPI_Comm), intent(in) :: comm
    type(timer_stat_t), allocatable, intent(out) :: stats(:)
    character(len=key_len), allocatable :: keys(:), local(:)
    character(len=name_len), allocatable :: labels(:), phase_names(:), mark_names(:)
    integer, allocatable :: up(:), order(:), row_of(:), phase_of(:)
    integer(i8), allocatable :: peak(:), added(:), resident(:)
    real(dp), allocatable :: mine(:), lo(:), hi(:), sums(:)
    real(dp) :: now
    integer :: n, nrows, nphases, ntree, i, j, k, ierr, nranks

    allocate (local(count))
    do i = 1, count
      local(i) = key_of(i)
    end do
    call union_of_paths(comm, local, keys)
    n = size(keys)
    allocate (row_of(n), phase_of(n), phase_names(n))
    call path_parents(keys, labels, up)
    ! rows of the tree, depth first; an `other` row (order = -parent) after each parent's sub-rows
    allocate (order(2*n))
    ntree = 0
    do k = 1, n
      if (up(k) == 0) call visit(k)
    end do
    ! one phase per name
    nphases = 0
    do k = 1, n
      if (any(phase_names(1:nphases) == labels(k))) then
        phase_of(k) = findloc(phase_names(1:nphases), labels(k), dim=1)
      else
        nphases = nphases + 1
        phase_names(nphases) = labels(k)
        phase_of(k) = nphases
      end if
    end do

    ! this rank's seconds: tree rows, then phases
    nrows = ntree + nphases
    allocate (mine(nrows), lo(nrows), hi(nrows), sums(nrows))
    mine = 0
    now = MPI_Wtime()
    do i = 1, count
      k = findloc(keys, local(i), dim=1)
      mine(row_of(k)) = total(i)
      if (started(i) >= 0) mine(row_of(k)) = mine(row_of(k)) + (now - started(i))
    end do
    do i = 1, ntree
      if (order(i) < 0) then
        mine(i) = mine(row_of(-order(i)))
        do k = 1, n
          if (up(k) == -order(i)) mine(i) = mine(i) - mine(row_of(k))
        end do
      end if
    end do
    do k = 1, n
      if (.not. under_same_label(up, labels, k)) mine(ntree + phase_of(k)) = mine(ntree + phase_of(k)) + mine(row_of(k))
    end do
    call MPI_Allreduce(mine, lo, nrows, MPI_REAL_DP, MPI_MIN, comm, ierr)
    call MPI_Allreduce(mine, hi, nrows, MPI_REAL_DP, MPI_MAX, comm, ierr)
    call MPI_Allreduce(mine, sums, nrows, MPI_REAL_DP, MPI_SUM, comm, ierr)
    call MPI_Comm_size(comm, nranks, ierr)
    call memory_marks_reduce(comm, mark_names, peak, added, resident)

    allocate (stats(ntree + size(mark_names) + nphases))
    do i = 1, ntree
      k = abs(order(i))
      if (order(i) > 0) then
        stats(i) = timer_stat_t(row=row_tree, label=labels(k), depth=depth_of(up, k), parent=parent_row(up, row_of, k))
      else
        stats(i) = timer_stat_t(row=row_other, label='other', depth=depth_of(up, k) + 1, parent=row_of(k))
      end if
      stats(i)%min = lo(i)
      stats(i)%max = hi(i)
      stats(i)%mean = sums(i)/nranks
    end do
    do i = 1, size(mark_names)
      stats(ntree + i) = timer_stat_t(row=row_memory, label=mark_names(i), peak=peak(i), added=added(i), &
                                      resident=resident(i))
    end do
    do i = 1, nphases
      j = ntree + i
      stats(ntree + size(mark_names) + i) = timer_stat_t(phase_names(i), lo(j), hi(j), sums(j)/nranks)
    end do

  contains

    recursive subroutine visit(k)
      integer, intent(in) :: k
      integer :: c
      logical :: parent
      ntree = ntree + 1
      order(ntree) = k
      row_of(k) = ntree
      parent = .false.
      do c = k + 1, n
        if (up(c) == k) then
          call visit(c)
          parent = .true.
        end if
      end do
      if (parent) then
        ntree = ntree + 1
        order(ntree) = -k
      end if
    end subroutine visit

  end subroutine timers_reduce

  !> The depth of path `k` in the tree of parents `up` (0 at a root).
  pure integer function depth_of(up, k)
    integer, intent(in) :: up(:), k
    integer :: j
    depth_of = 0
    j = up(k)
    do while (j > 0)
      depth_of = depth_of + 1
      j = up(j)
    end do
  end function depth_of

  !> The row of the parent of path `k` (0 at a root).
  pure integer function parent_row(up, row_of, k)
    integer, intent(in) :: up(:), row_of(:), k
    parent_row = 0
    if (up(k) > 0) parent_row = row_of(up(k))
  end function parent_row

  !> Path `k` lies under a path of the same label (its time is counted there).
  pure logical function under_same_label(up, labels, k)
    integer, intent(in) :: up(:), k
    character(len=*), intent(in) :: labels(:)
    integer :: j
    under_same_label = .true.
    j = up(k)
    do while (j > 0)
      if (labels(j) == labels(k)) return
      j = up(j)
    end do
    under_same_label = .false.
  end function under_same_label

  !> Each path's label (its last name) and parent (its position in `keys`,
  !> 0 for a root); parents come before their children in `keys`.
  subroutine path_parents(keys, labels, up)
    character(len=*), intent(in) :: keys(:)
    character(len=name_len), allocatable, intent(out) :: labels(:)
    integer, allocatable, intent(out) :: up(:)
    integer :: i, j, k
    allocate (labels(size(keys)), up(size(keys)))
    up = 0
    do k = 1, size(keys)
      j = index(keys(k), separator, back=.true.)
      if (j == 0) then
        labels(k) = keys(k)(1:name_len)
      else
        labels(k) = keys(k)(j + len(separator):)
        do i = k - 1, 1, -1
          if (keys(i) == keys(k)(1:j - 1)) then
            up(k) = i
            exit
          end if
        end do
      end if
    end do
  end subroutine path_parents

  !> The paths of every rank (`local`: this rank's), the same list on all:
  !> rank 0's in the order it created them, then those only other ranks have
  !> (a rank at a time, the lowest first). A parent comes before its children.
  !> Collective.
  subroutine union_of_paths(comm, local, keys)
    type(MPI_Comm), intent(in) :: comm
    character(len=key_len), intent(in) :: local(:)
    character(len=key_len), allocatable, intent(out) :: keys(:)
    character(len=key_len), allocatable :: extra(:)
    integer :: rank, n, m, i, from, ierr
    logical, allocatable :: known(:)

    call MPI_Comm_rank(comm, rank, ierr)
    allocate (known(size(local)))
    n = size(local)
    call MPI_Bcast(n, 1, MPI_INTEGER, 0, comm, ierr)
    allocate (keys(n))
    if (rank == 0) keys = local
    if (n > 0) call MPI_Bcast(keys, key_len*n, MPI_CHARACTER, 0, comm, ierr)
    do
      do i = 1, size(local)
        known(i) = any(keys == local(i))
      end do
      from = huge(from)
      if (.not. all(known)) from = rank
      call MPI_Allreduce(from, m, 1, MPI_INTEGER, MPI_MIN, comm, ierr)
      if (m == huge(m)) exit
      from = m
      if (rank == from) then
        extra = pack(local, .not. known)
        m = size(extra)
      end if
      call MPI_Bcast(m, 1, MPI_INTEGER, from, comm, ierr)
      if (rank /= from) allocate (extra(m))
      call MPI_Bcast(extra, key_len*m, MPI_CHARACTER, from, comm, ierr)
      keys = [keys, extra]
      deallocate (extra)
    end do
  end subroutine union_of_paths
end module timers
