!> Pieces of the run report: the timing table (printed and as JSON) and the
!> peak memory of the ranks.
module report
  use kinds, only: dp, i8, name_len, MPI_INT_I8
  use memory_marks, only: memory_mark_count, memory_mark_get
  use proc_status, only: proc_status_bytes
  use timers, only: timer_stat_t
  use logger, only: log_is_root, log_unit
  use json_writer, only: json_writer_t
  use params, only: params_t, param_item_t, param_items, group_names
  use mpi_f08, only: MPI_Comm, MPI_Comm_size, MPI_Allreduce, MPI_MAX, MPI_MIN, MPI_SUM
  implicit none
  private

  public :: print_timing_table, timings_json, memory_json, blas_json, params_json

contains

  !> Print one line per phase: min, max and mean seconds over the ranks and
  !> the share of the mean in `total`. Without `total`, the total is the
  !> mean of a phase named 'total' if there is one, else the sum of the
  !> means (right when the phases do not nest). Through the logger (rank 0).
  subroutine print_timing_table(stats, total)
    type(timer_stat_t), intent(in) :: stats(:)
    real(dp), intent(in), optional :: total
    real(dp) :: reference, share
    integer :: i, u, width

    if (.not. log_is_root()) return
    if (present(total)) then
      reference = total
    else
      reference = default_total(stats)
    end if
    width = 5
    do i = 1, size(stats)
      width = max(width, len_trim(stats(i)%name))
    end do
    u = log_unit()
    write (u, '(a,3a13,a12)') 'phase'//repeat(' ', width - 5), 'min [s]', 'max [s]', 'mean [s]', 'share'
    do i = 1, size(stats)
      share = 0
      if (reference > 0) share = 100*stats(i)%mean/reference
      write (u, '(a,3f13.6,f12.1,a)') stats(i)%name(1:width), stats(i)%min, stats(i)%max, &
        stats(i)%mean, share, '%'
    end do
    flush (u)
  end subroutine print_timing_table

  real(dp) function default_total(stats)
    type(timer_stat_t), intent(in) :: stats(:)
    integer :: i
    do i = 1, size(stats)
      if (stats(i)%name == 'total') then
        default_total = stats(i)%mean
        return
      end if
    end do
    default_total = sum(stats%mean)
  end function default_total

  !> The timings as a JSON object {"phase": {"min": s, "max": s, "mean": s}, ...}.
  function timings_json(stats) result(json)
    type(timer_stat_t), intent(in) :: stats(:)
    character(len=:), allocatable :: json
    type(json_writer_t) :: w
    integer :: i
    call w%begin_object()
    do i = 1, size(stats)
      call w%begin_object(trim(stats(i)%name))
      call w%add('min', stats(i)%min)
      call w%add('max', stats(i)%max)
      call w%add('mean', stats(i)%mean)
      call w%end_object()
    end do
    call w%end_object()
    json = w%text()
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

  !> The parameters as a JSON object (the "case" of report.json): "file" and
  !> one object per namelist group, from the same table as the echo.
  function params_json(p) result(json)
    type(params_t), intent(in) :: p
    character(len=:), allocatable :: json
    type(json_writer_t) :: w
    type(param_item_t), allocatable :: items(:)
    integer :: g, k
    call w%begin_object()
    call w%add('file', trim(p%file))
    do g = 1, size(group_names)
      call param_items(p, trim(group_names(g)), items)
      call w%begin_object(trim(group_names(g)))
      do k = 1, size(items)
        call add_item(items(k))
      end do
      if (group_names(g) == 'mesh') then      ! the automatic cluster choice (not namelist variables)
        call w%add('cluster_auto', p%mesh%cluster_auto)
        call w%add('cluster_choice', trim(p%mesh%cluster_choice))
      end if
      call w%end_object()
    end do
    call w%end_object()
    json = w%text()
  contains
    subroutine add_item(item)
      type(param_item_t), intent(in) :: item
      integer :: v
      if (item%n > 1) call w%begin_array(trim(item%name))
      do v = 1, item%n
        call add_value(item%n > 1, trim(item%name), item%kind, trim(item%values(v)))
      end do
      if (item%n > 1) call w%end_array()
    end subroutine add_item
    !> One value: appended to the open array, or the member `key`.
    subroutine add_value(in_array, key, kind, text)
      logical, intent(in) :: in_array
      character(len=*), intent(in) :: key, text
      character, intent(in) :: kind
      real(dp) :: x
      integer(i8) :: n
      select case (kind)
      case ('s')
        if (in_array) call w%append(text)
        if (.not. in_array) call w%add(key, text)
      case ('l')
        if (in_array) call w%append(text == 'T')
        if (.not. in_array) call w%add(key, text == 'T')
      case ('r')
        read (text, *) x
        if (in_array) call w%append(x)
        if (.not. in_array) call w%add(key, x)
      case default
        read (text, *) n
        if (in_array) call w%append(n)
        if (.not. in_array) call w%add(key, n)
      end select
    end subroutine add_value
  end function params_json
end module report
