!> Pieces of the run report: the timing table with the memory at the end of
!> each phase (printed, and as JSON) and the peak memory of the ranks.
module report
  use kinds, only: dp, i8, name_len, MPI_INT_I8
  use memory_marks, only: memory_mark_count, memory_mark_get
  use proc_status, only: proc_status_bytes
  use timers, only: timer_stat_t, row_phase, row_tree, row_other, row_memory
  use logger, only: log_is_root, log_unit, log_file_unit, log_to_file
  use json_writer, only: json_writer_t
  use mpi_f08, only: MPI_Comm, MPI_Comm_size, MPI_Allreduce, MPI_MAX, MPI_MIN, MPI_SUM
  implicit none
  private

  public :: print_timing_table, timings_json, memory_json, blas_json

contains

  !> Print the timing table through the logger (rank 0): min, max and mean
  !> seconds over the ranks and the mean's share of the total. With the rows
  !> of timers_reduce: the tree, a phase's parts indented under it and an
  !> `other` row for the rest of it, so the top-level rows add up to the total
  !> (a root timer named 'total', printed last; without one, the sum of the
  !> roots); then the memory marks. Phase rows alone (no tree): one line each,
  !> the total being that of a phase named 'total' if there is one, else the
  !> sum of the means. `total` replaces the total of either.
  subroutine print_timing_table(stats, total)
    type(timer_stat_t), intent(in) :: stats(:)
    real(dp), intent(in), optional :: total
    if (.not. log_is_root()) return
    call print_table(stats, total)
    if (log_file_unit() == -1) return
    call log_to_file(.true.)        ! the same table in the log file
    call print_table(stats, total)
    call log_to_file(.false.)
  end subroutine print_timing_table

  !> print_timing_table on log_unit().
  subroutine print_table(stats, total)
    type(timer_stat_t), intent(in) :: stats(:)
    real(dp), intent(in), optional :: total
    real(dp) :: reference
    if (.not. log_is_root()) return
    if (any(stats%row == row_tree)) then
      reference = tree_total(stats)
      if (present(total)) reference = total
      call print_tree(stats, reference)
    else
      if (present(total)) then
        reference = total
      else
        reference = default_total(stats)
      end if
      call print_phases(stats, reference)
    end if
    if (any(stats%row == row_memory)) call print_memory(stats)
    flush (log_unit())
  end subroutine print_table

  !> One line per phase row, in the order given.
  subroutine print_phases(stats, reference)
    type(timer_stat_t), intent(in) :: stats(:)
    real(dp), intent(in) :: reference
    integer :: i, u, width
    width = 5
    do i = 1, size(stats)
      if (stats(i)%row == row_phase) width = max(width, len_trim(stats(i)%name))
    end do
    u = log_unit()
    write (u, '(a,3a13,a12)') 'phase'//repeat(' ', width - 5), 'min [s]', 'max [s]', 'mean [s]', 'share'
    do i = 1, size(stats)
      if (stats(i)%row /= row_phase) cycle
      write (u, '(a,3f13.6,f12.1,a)') stats(i)%name(1:width), stats(i)%min, stats(i)%max, stats(i)%mean, &
        share(stats(i)%mean, reference), '%'
    end do
  end subroutine print_phases

  !> The tree: a root named 'total' last, below a rule, its sub-rows as the
  !> top level; other roots at the top level; sub-rows indented by two spaces
  !> a level. Nested `other` rows that round to 0.0 % are left out.
  subroutine print_tree(stats, reference)
    type(timer_stat_t), intent(in) :: stats(:)
    real(dp), intent(in) :: reference
    integer :: i, u, width, root
    character(len=:), allocatable :: head
    root = total_root(stats)
    width = 5
    do i = 1, size(stats)
      if (shown(i)) width = max(width, 2*level(i) + len_trim(stats(i)%label))
    end do
    u = log_unit()
    head = 'phase'//repeat(' ', width - 5)
    write (u, '(a,3a12,a8)') head, 'min [s]', 'max [s]', 'mean [s]', 'share'
    do i = 1, size(stats)
      if (shown(i) .and. i /= root) call print_row(i)
    end do
    if (root > 0) then
      write (u, '(a)') repeat('-', width + 44)
      call print_row(root)
    end if
    write (u, '(a)') '(indented rows are parts of the row above them; other: the rest of that row, outside '// &
      'its parts; share: of the total)'
  contains
    logical function shown(i)
      integer, intent(in) :: i
      shown = stats(i)%row == row_tree
      if (stats(i)%row == row_other) shown = level(i) == 0 .or. share(stats(i)%mean, reference) >= 0.05_dp
    end function shown
    integer function level(i)
      integer, intent(in) :: i
      level = stats(i)%depth
      if (root > 0 .and. i /= root .and. under(i, root)) level = level - 1
    end function level
    logical function under(i, r)
      integer, intent(in) :: i, r
      integer :: j
      under = .true.
      j = stats(i)%parent
      do while (j > 0)
        if (j == r) return
        j = stats(j)%parent
      end do
      under = .false.
    end function under
    subroutine print_row(i)
      integer, intent(in) :: i
      character(len=width) :: name
      name = repeat(' ', 2*level(i))//stats(i)%label
      write (u, '(a,3f12.4,f7.1,a)') name, stats(i)%min, stats(i)%max, stats(i)%mean, &
        share(stats(i)%mean, reference), '%'
    end subroutine print_row
  end subroutine print_tree

  !> The memory marks: max over ranks of the peak resident set at the end of
  !> each phase, what the phase added to it, and the resident set then.
  subroutine print_memory(stats)
    type(timer_stat_t), intent(in) :: stats(:)
    integer :: i, u, width
    width = 5
    do i = 1, size(stats)
      if (stats(i)%row == row_memory) width = max(width, len_trim(stats(i)%label))
    end do
    u = log_unit()
    write (u, '(a)') ''
    write (u, '(a)') 'Memory at the end of each phase [MiB], max over ranks: peak resident set (VmHWM), '// &
      'what the phase added to it, resident set (VmRSS)'
    write (u, '(a,3a12)') 'phase'//repeat(' ', width - 5), 'peak', 'added', 'resident'
    do i = 1, size(stats)
      if (stats(i)%row /= row_memory) cycle
      write (u, '(a,3a12)') stats(i)%label(1:width), mib(stats(i)%peak), mib(stats(i)%added), &
        mib(stats(i)%resident)
    end do
  end subroutine print_memory

  !> Bytes as MiB with one decimal, '-' when unknown (negative).
  function mib(bytes) result(text)
    integer(i8), intent(in) :: bytes
    character(len=12) :: text
    if (bytes < 0) then
      text = '-'
    else
      write (text, '(f12.1)') real(bytes, dp)/2.0_dp**20
    end if
    text = adjustr(text)
  end function mib

  real(dp) function share(seconds, reference)
    real(dp), intent(in) :: seconds, reference
    share = 0
    if (reference > 0) share = 100*seconds/reference
  end function share

  !> The root row named 'total', 0 if none.
  integer function total_root(stats)
    type(timer_stat_t), intent(in) :: stats(:)
    integer :: i
    total_root = 0
    do i = 1, size(stats)
      if (stats(i)%row == row_tree .and. stats(i)%parent == 0 .and. stats(i)%label == 'total') then
        total_root = i
        return
      end if
    end do
  end function total_root

  !> The mean of the root named 'total', else the sum of the roots' means.
  real(dp) function tree_total(stats)
    type(timer_stat_t), intent(in) :: stats(:)
    integer :: root
    root = total_root(stats)
    if (root > 0) then
      tree_total = stats(root)%mean
    else
      tree_total = sum(stats%mean, mask=stats%row == row_tree .and. stats%parent == 0)
    end if
  end function tree_total

  real(dp) function default_total(stats)
    type(timer_stat_t), intent(in) :: stats(:)
    integer :: i
    do i = 1, size(stats)
      if (stats(i)%row == row_phase .and. stats(i)%name == 'total') then
        default_total = stats(i)%mean
        return
      end if
    end do
    default_total = sum(stats%mean, mask=stats%row == row_phase)
  end function default_total

  !> The timings as a JSON object, one member per phase row (each name with
  !> all its time, wherever it ran): {"phase": {"min": s, "max": s, "mean": s}}.
  !> The member of a root of the tree also has "children": its parts, each
  !> {"name", "min", "max", "mean", "share" (of the total, 0..1), "children"
  !> when it has parts}, the last one "other" (the rest of the parent).
  function timings_json(stats) result(json)
    type(timer_stat_t), intent(in) :: stats(:)
    character(len=:), allocatable :: json
    type(json_writer_t) :: w
    real(dp) :: reference
    integer :: i, j, root
    reference = tree_total(stats)
    call w%begin_object()
    do i = 1, size(stats)
      if (stats(i)%row /= row_phase) cycle
      call w%begin_object(trim(stats(i)%name))
      call w%add('min', stats(i)%min)
      call w%add('max', stats(i)%max)
      call w%add('mean', stats(i)%mean)
      root = 0
      do j = 1, size(stats)
        if (stats(j)%row == row_tree .and. stats(j)%parent == 0 .and. stats(j)%label == stats(i)%name) then
          root = j
          exit
        end if
      end do
      if (root > 0) call add_children(root)
      call w%end_object()
    end do
    call w%end_object()
    json = w%text()
  contains
    recursive subroutine add_children(p)
      integer, intent(in) :: p
      integer :: k
      if (.not. any((stats%row == row_tree .or. stats%row == row_other) .and. stats%parent == p)) return
      call w%begin_array('children')
      do k = 1, size(stats)
        if (stats(k)%parent /= p .or. (stats(k)%row /= row_tree .and. stats(k)%row /= row_other)) cycle
        call w%begin_object()
        call w%add('name', trim(stats(k)%label))
        call w%add('min', stats(k)%min)
        call w%add('max', stats(k)%max)
        call w%add('mean', stats(k)%mean)
        call w%add('share', share(stats(k)%mean, reference)/100)
        call add_children(k)
        call w%end_object()
      end do
      call w%end_array()
    end subroutine add_children
  end function timings_json

  !> {"peak_rss_bytes": {"max": .., "sum": ..}, "phases": [..]}: the largest
  !> peak of one rank and the sum over the ranks of `comm` (null if some rank
  !> cannot tell); "phases": one object per memory_mark, in the order they
  !> were recorded, {"name", "peak_max", "peak_mean", "rss_max", "rss_mean"}
  !> (VmHWM and VmRSS at that mark, bytes, over the ranks). Collective; every
  !> rank must have recorded the same marks.
  function memory_json(comm) result(json)
    type(MPI_Comm), intent(in) :: comm
    character(len=:), allocatable :: json
    type(json_writer_t) :: w
    integer(i8) :: mine, most, least, total
    integer(i8), allocatable :: local(:, :), hi(:, :), sums(:, :)
    character(len=name_len) :: name
    integer :: ierr, nranks, n, i

    mine = proc_status_bytes('VmHWM')     ! peak resident set size
    call MPI_Allreduce(mine, most, 1, MPI_INT_I8, MPI_MAX, comm, ierr)
    call MPI_Allreduce(mine, least, 1, MPI_INT_I8, MPI_MIN, comm, ierr)
    call MPI_Allreduce(max(mine, 0_i8), total, 1, MPI_INT_I8, MPI_SUM, comm, ierr)
    call MPI_Comm_size(comm, nranks, ierr)
    n = memory_mark_count()
    allocate (local(2, max(n, 1)), hi(2, max(n, 1)), sums(2, max(n, 1)))
    local = 0
    do i = 1, n
      call memory_mark_get(i, name, local(1, i), local(2, i))
    end do
    call MPI_Allreduce(local, hi, 2*max(n, 1), MPI_INT_I8, MPI_MAX, comm, ierr)
    call MPI_Allreduce(local, sums, 2*max(n, 1), MPI_INT_I8, MPI_SUM, comm, ierr)
    call w%begin_object()
    call w%begin_object('peak_rss_bytes')
    if (least < 0) then
      call w%add_null('max')
      call w%add_null('sum')
    else
      call w%add('max', most)
      call w%add('sum', total)
    end if
    call w%end_object()
    call w%begin_array('phases')
    do i = 1, n
      call memory_mark_get(i, name, local(1, i), local(2, i))
      call w%begin_object()
      call w%add('name', trim(name))
      call w%add('peak_max', hi(1, i))
      call w%add('peak_mean', sums(1, i)/nranks)
      call w%add('rss_max', hi(2, i))
      call w%add('rss_mean', sums(2, i)/nranks)
      call w%end_object()
    end do
    call w%end_array()
    call w%end_object()
    json = w%text()
  end function memory_json

  !> {"library", "path", "threads", "source", "multithreaded", "core",
  !> "core_chosen_by_library"}: the BLAS in use, its threads per rank and what
  !> set them, OpenBLAS's kernel table and the one it chose itself before
  !> blas_threads chose again ('' when it did not; see blas_threads).
  function blas_json(library, path, threads, source, multithreaded, core, core_before) result(json)
    character(len=*), intent(in) :: library, path, source, core, core_before
    integer, intent(in) :: threads
    logical, intent(in) :: multithreaded
    character(len=:), allocatable :: json
    type(json_writer_t) :: w
    call w%begin_object()
    call w%add('library', library)
    call w%add('path', path)
    call w%add('threads', threads)
    call w%add('source', source)
    call w%add('multithreaded', multithreaded)
    call w%add('core', core)
    call w%add('core_chosen_by_library', core_before)
    call w%end_object()
    json = w%text()
  end function blas_json
end module report
