!> The input's part of report.json: the settings of every group as a JSON
!> object (the "case") and the solver variant, both from the same table as
!> the echo (params' param_items), and the warnings about the input; handed
!> to run_report as a run_case_t.
module input_report
  use kinds, only: dp, i8
  use build_info, only: fc_version, fc_commit
  use json_writer, only: json_writer_t
  use params, only: params_t, param_item_t, param_items, group_names, default_params, input_warnings
  use run_report, only: run_case_t
  implicit none
  private

  public :: params_json, solver_variant, run_case_of

contains

  !> The input's part of report.json for the run of `p`.
  function run_case_of(p) result(c)
    type(params_t), intent(in) :: p
    type(run_case_t) :: c
    c%case_json = params_json(p)
    c%warnings = input_warnings(p)
    c%variant = solver_variant(p)
  end function run_case_of

  !> The parameters as a JSON object (the "case" of report.json): "file" and
  !> one object per namelist group, from the same table as the echo.
  function params_json(p) result(json)
    type(params_t), intent(in) :: p
    character(len=:), allocatable :: json
    type(json_writer_t) :: w
    type(param_item_t), allocatable :: items(:)
    integer :: g, k
    call w%begin_object()
    call w%add('version', fc_version)
    call w%add('commit', fc_commit)
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

  !> The solver variant of the run: the &solver settings that differ from their
  !> defaults, as 'name=value' separated by ', ' (values as the namelist
  !> writes them; `monitor` left out: it changes no iterate), or 'default'.
  function solver_variant(p) result(text)
    type(params_t), intent(in) :: p
    character(len=:), allocatable :: text
    type(param_item_t), allocatable :: items(:), defaults(:)
    integer :: k, j, i
    call param_items(p, 'solver', items)
    call param_items(default_params(), 'solver', defaults)
    text = ''
    do k = 1, size(items)
      if (items(k)%name == 'monitor') cycle
      j = 0
      do i = 1, size(defaults)
        if (defaults(i)%name == items(k)%name) j = i
      end do
      if (j > 0) then
        if (all(items(k)%values == defaults(j)%values)) cycle
      end if
      if (len(text) > 0) text = text//', '
      text = text//trim(items(k)%name)//'='//short(items(k)%values(1), items(k)%kind)
      do j = 2, items(k)%n
        text = text//','//short(items(k)%values(j), items(k)%kind)
      end do
    end do
    if (len(text) == 0) text = 'default'
  contains
    !> A real without the trailing zeros of its mantissa (2.0000 -> 2.0, 1.5000E-08 -> 1.5E-08).
    function short(value, kind) result(v)
      character(len=*), intent(in) :: value
      character, intent(in) :: kind
      character(len=:), allocatable :: v, mantissa
      integer :: e
      v = trim(adjustl(value))
      if (kind /= 'r' .or. index(v, '.') == 0) return
      e = scan(v, 'EeDd')
      if (e == 0) e = len(v) + 1
      mantissa = v(1:e - 1)
      do while (len(mantissa) > 1)
        if (mantissa(len(mantissa):len(mantissa)) /= '0' .or. &
            mantissa(len(mantissa) - 1:len(mantissa) - 1) == '.') exit
        mantissa = mantissa(1:len(mantissa) - 1)
      end do
      v = mantissa//v(e:)
    end function short
  end function solver_variant
end module input_report
