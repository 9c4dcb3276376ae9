!> Run parameters: the namelist groups, their defaults, reading, checking,
!> broadcasting and echoing.
!>
!> Rank 0 reads the whole file, splits it into groups, reads each group with
!> an internal namelist read, and checks the values. When a group fails to
!> read, its assignments are read again one by one so that the message can
!> name the variable at fault. The outcome (parameters or an error message) is
!> broadcast, and on error every rank exits together with status 2.
!> Every variable is documented in docs/INPUT.md.
module params
  use kinds, only: dp, ip, i8, path_len, name_len
  use errors, only: collective_error, exit_input_error, fatal_error, set_input_file
  use mpi_f08, only: MPI_Comm, MPI_Comm_rank, MPI_Comm_size, MPI_Bcast, MPI_BYTE, MPI_INTEGER, MPI_CHARACTER
  use smalbe, only: smalbe_settings_t
  use mesh_settings, only: mesh_settings_t
  use materials, only: material_settings_t
  use assembly, only: load_settings_t
  use history_settings, only: history_settings_t
  use boundary_settings, only: boundary_settings_t
  use obstacle_settings, only: obstacle_settings_t
  use scaling_settings, only: scaling_settings_t
  use local_settings, only: local_settings_t
  use f_action_settings, only: f_action_settings_t
  use coarse_settings, only: coarse_settings_t
  use preconditioner_settings, only: preconditioner_settings_t
  use feti_settings, only: feti_settings_t
  use dual_settings, only: dual_settings_t
  use reconstruction_settings, only: reconstruction_settings_t
  use output_settings, only: output_settings_t
  implicit none
  private

  public :: read_params, check_params, echo_params, input_warnings, default_params, param_items, group_names
  public :: auto_cluster, resolve_cluster, feti_settings_of

  integer, parameter :: msg_len = 1024
  !> &obstacle gap: the deepest initial penetration accepted, as a fraction of the body's height
  real(dp), parameter, public :: max_penetration = 0.1_dp

  !> &solver: each variable belongs to the component that owns it (its
  !> settings type: defaults, checks, namelist variables); solver_group hands
  !> each assignment to its owner.
  type, public :: solver_params_t
    type(smalbe_settings_t) :: smalbe             !< SMALBE, its inner MPRGP and the polish
    type(dual_settings_t) :: dual                 !< rho_scale, stopping
    type(coarse_settings_t) :: coarse             !< the coarse problem
    type(local_settings_t) :: local               !< the local solver K^+
    type(f_action_settings_t) :: f_action         !< the F action and the ||P F P|| estimate
    type(preconditioner_settings_t) :: preconditioner  !< the dual preconditioner
    type(scaling_settings_t) :: scaling           !< the row scaling of B
  end type solver_params_t

  integer, parameter :: max_values = 3      !< the most values of one variable (arrays of 3)

  !> Variables that were renamed: 'group old new'. The old spelling is
  !> refused with a message that names the new one (never read silently).
  character(len=*), parameter :: renamed_variables(1) = [character(len=48) :: &
    'solver power_iterations lanczos_steps']

  !> One variable of a group as the namelist writes it (param_items).
  type, public :: param_item_t
    character(len=name_len) :: name = ''                !< lower case
    character :: kind = 'i'                             !< 'i' integer, 'r' real, 'l' logical (T/F), 's' string
    integer :: n = 0                                    !< number of values (> 1: an array)
    character(len=path_len), allocatable :: values(:)   !< the values as text (n of them)
  end type param_item_t

  !> All parameters of a run.
  type, public :: params_t
    character(len=path_len) :: file = ''
    type(mesh_settings_t) :: mesh
    type(material_settings_t) :: material
    type(load_settings_t) :: load
    type(boundary_settings_t) :: boundary
    type(obstacle_settings_t) :: obstacle
    type(solver_params_t) :: solver
    type(reconstruction_settings_t) :: reconstruction
    type(output_settings_t) :: output
    type(history_settings_t) :: history
  end type params_t

  !> The namelist groups, in the order of the echo and of report.json.
  character(len=*), parameter :: group_names(9) = [character(len=14) :: 'mesh', 'material', &
    'load', 'boundary', 'obstacle', 'solver', 'reconstruction', 'output', 'history']

contains

  !> The defaults of every variable.
  function default_params() result(p)
    type(params_t) :: p
    p = params_t()
  end function default_params

  !> Read, check and broadcast the parameters of `file`. Collective over
  !> `comm`; on any input error every rank exits with status 2.
  subroutine read_params(file, comm, p)
    character(len=*), intent(in) :: file
    type(MPI_Comm), intent(in) :: comm
    type(params_t), intent(out) :: p
    integer :: rank, nranks, ierr, status
    character(len=msg_len) :: msg

    call MPI_Comm_rank(comm, rank, ierr)
    call MPI_Comm_size(comm, nranks, ierr)
    call set_input_file(file)       ! the refusals at run time name it too
    status = 0
    msg = ''
    p = params_t()
    if (rank == 0) then
      call read_file(file, p, status, msg)
      if (status == 0) call check_params(p, status, msg)
      if (status == 0) then
        call resolve_cluster(p, nranks)
        call check_params(p, status, msg)     ! (the automatic choice meets every check by construction)
      end if
    end if
    call MPI_Bcast(status, 1, MPI_INTEGER, 0, comm, ierr)
    if (status /= 0) then
      call MPI_Bcast(msg, msg_len, MPI_CHARACTER, 0, comm, ierr)
      call collective_error(msg, comm, exit_input_error)
    end if
    call MPI_Bcast(p, storage_size(p)/8, MPI_BYTE, 0, comm, ierr)
  end subroutine read_params

  !> Read every group of `file` into `p` (rank 0 only).
  subroutine read_file(file, p, status, msg)
    character(len=*), intent(in) :: file
    type(params_t), intent(inout) :: p
    integer, intent(out) :: status
    character(len=*), intent(out) :: msg
    character(len=:), allocatable :: text, group_text, name
    integer :: pos, i
    logical :: seen(size(group_names))

    p%file = file
    call load_text(file, text, status, msg)
    if (status /= 0) return
    seen = .false.
    pos = 1
    do
      call next_group(text, pos, name, group_text, status, msg)
      if (status /= 0) then
        msg = 'file '//trim(file)//': '//trim(msg)
        return
      end if
      if (.not. allocated(group_text)) exit
      i = group_index(name)
      if (i == 0) then
        status = 1
        msg = 'file '//trim(file)//': unknown namelist group &'//name// &
              '; allowed groups: &mesh, &material, &load, &boundary, &obstacle, &solver, '// &
              '&reconstruction, &output, &history'
        return
      end if
      if (seen(i)) then
        status = 1
        msg = 'file '//trim(file)//': group &'//name//' appears twice'
        return
      end if
      seen(i) = .true.
      call check_renamed(name, group_text, status, msg)
      if (status == 0) call read_group_checked(name, group_text, p, status, msg)
      if (status == 0) call check_assignments(name, group_text, p, status, msg)
      if (status /= 0) then
        msg = 'file '//trim(file)//', group &'//name//': '//trim(msg)
        return
      end if
    end do
  end subroutine read_file

  !> The whole file as one line: comments removed, line ends made blanks.
  subroutine load_text(file, text, status, msg)
    character(len=*), intent(in) :: file
    character(len=:), allocatable, intent(out) :: text
    integer, intent(out) :: status
    character(len=*), intent(out) :: msg
    integer :: unit, fsize, i
    character(len=:), allocatable :: raw
    character :: quote
    logical :: exists, comment

    msg = ''
    inquire (file=file, exist=exists)
    if (.not. exists) then
      status = 1
      msg = 'input file '//trim(file)//' does not exist'
      return
    end if
    open (newunit=unit, file=file, access='stream', form='unformatted', status='old', &
          action='read', iostat=status, iomsg=msg)
    if (status /= 0) then
      msg = 'cannot open input file '//trim(file)//': '//trim(msg)
      return
    end if
    inquire (unit=unit, size=fsize)
    if (fsize < 0) then
      status = 1
      msg = 'cannot read input file '//trim(file)//' (not a regular file)'
      close (unit)
      return
    end if
    allocate (character(len=fsize) :: raw)
    if (fsize > 0) read (unit, iostat=status, iomsg=msg) raw
    close (unit)
    if (status /= 0) then
      msg = 'cannot read input file '//trim(file)//': '//trim(msg)
      return
    end if
    ! Blank out comments (from ! to the end of the line, outside quotes) and line ends.
    quote = ' '
    comment = .false.
    do i = 1, fsize
      if (raw(i:i) == achar(10) .or. raw(i:i) == achar(13)) then
        comment = .false.
        raw(i:i) = ' '
      else if (comment) then
        raw(i:i) = ' '
      else if (quote /= ' ') then
        if (raw(i:i) == quote) quote = ' '
      else if (raw(i:i) == '"' .or. raw(i:i) == "'") then
        quote = raw(i:i)
      else if (raw(i:i) == '!') then
        comment = .true.
        raw(i:i) = ' '
      else if (raw(i:i) == achar(9)) then
        raw(i:i) = ' '
      end if
    end do
    ! Fold runs of blanks outside quotes into one (gfortran's namelist reading
    ! of some wrong values depends on the number of blanks that follow them).
    text = ''
    quote = ' '
    do i = 1, fsize
      if (quote /= ' ') then
        if (raw(i:i) == quote) quote = ' '
      else if (raw(i:i) == '"' .or. raw(i:i) == "'") then
        quote = raw(i:i)
      else if (raw(i:i) == ' ' .and. i > 1) then
        if (raw(i - 1:i - 1) == ' ') cycle
      end if
      text = text//raw(i:i)
    end do
  end subroutine load_text

  !> Find the next group from `pos`: its lower-case name and its text
  !> ('&name ... /'). `group_text` stays unallocated when there is none.
  subroutine next_group(text, pos, name, group_text, status, msg)
    character(len=*), intent(in) :: text
    integer, intent(inout) :: pos
    character(len=:), allocatable, intent(out) :: name, group_text
    integer, intent(out) :: status
    character(len=*), intent(out) :: msg
    integer :: i, start, name_end
    character :: quote

    status = 0
    msg = ''
    i = pos
    do while (i <= len(text))
      if (text(i:i) /= ' ') exit
      i = i + 1
    end do
    if (i > len(text)) return
    if (text(i:i) /= '&' .and. text(i:i) /= '$') then
      status = 1
      msg = 'text outside a namelist group near "'//snippet(text, i)//'"'
      return
    end if
    start = i
    name_end = i
    do while (name_end < len(text))
      if (.not. is_name_char(text(name_end + 1:name_end + 1))) exit
      name_end = name_end + 1
    end do
    name = lower(text(start + 1:name_end))
    if (len(name) == 0) then
      status = 1
      msg = 'a group has no name near "'//snippet(text, i)//'"'
      return
    end if
    quote = ' '
    do i = name_end + 1, len(text)
      if (quote /= ' ') then
        if (text(i:i) == quote) quote = ' '
      else if (text(i:i) == '"' .or. text(i:i) == "'") then
        quote = text(i:i)
      else if (text(i:i) == '/') then
        group_text = text(start:i)
        pos = i + 1
        return
      else if (text(i:i) == '&' .or. text(i:i) == '$') then
        if (lower(text(i:min(i + 3, len(text)))) == '&end' .or. &
            lower(text(i:min(i + 3, len(text)))) == '$end') then
          group_text = text(start:i - 1)//'/'
          pos = i + 4
          return
        end if
        exit
      end if
    end do
    status = 1
    msg = 'group &'//name//' is not closed with "/"'
  end subroutine next_group

  !> Refuse what a namelist read would accept silently: a variable given twice
  !> in the group, and an array variable given with fewer values than it has
  !> components (an element assignment 'name(i) = v' sets that element only).
  subroutine check_assignments(name, group_text, p, status, msg)
    character(len=*), intent(in) :: name, group_text
    type(params_t), intent(in) :: p
    integer, intent(out) :: status
    character(len=*), intent(out) :: msg
    type(param_item_t), allocatable :: items(:)
    character(len=:), allocatable :: body, piece, lhs
    character(len=name_len), allocatable :: given(:)
    integer, allocatable :: starts(:)
    integer :: k, i, j, nstarts, body_start, nvalues

    status = 0
    msg = ''
    body_start = index(group_text, ' ')
    if (body_start == 0) return
    body = group_text(body_start:len(group_text) - 1)
    if (index(body, '=') == 0) return
    call param_items(p, name, items)
    call assignment_starts(body, starts, nstarts)
    allocate (given(nstarts))
    given = ''
    do k = 1, nstarts
      if (k < nstarts) then
        piece = body(starts(k):starts(k + 1) - 1)
      else
        piece = body(starts(k):)
      end if
      i = index(piece, '=')
      if (i == 0) cycle
      lhs = lower(trim(adjustl(piece(1:i - 1))))
      lhs = lhs(1:len_trim(lhs))
      j = index(lhs, ' ')
      do while (j > 0)          ! 'nsub (1)' and 'nsub(1)' are the same
        lhs = lhs(1:j - 1)//lhs(j + 1:)
        j = index(lhs, ' ')
      end do
      if (any(given(1:k - 1) == lhs)) then
        status = 1
        msg = 'variable '//lhs//': given twice in the group (each variable at most once)'
        return
      end if
      given(k) = lhs
      if (index(lhs, '(') > 0) cycle
      do j = 1, size(items)
        if (items(j)%name /= lhs .or. items(j)%n <= 1) cycle
        nvalues = count_values(piece(i + 1:))
        if (nvalues < items(j)%n) then
          status = 1
          write (msg, '(a,i0,a,i0,a)') 'variable '//lhs//': needs all ', items(j)%n, &
            ' components (got ', nvalues, ' in "'//trim(adjustl(piece))//'")'
          return
        end if
      end do
    end do
  contains
    !> The number of values in a namelist value list ('r*c' counts r).
    integer function count_values(t) result(n)
      character(len=*), intent(in) :: t
      integer :: c, star, r, ios, start
      character :: quote
      n = 0
      quote = ' '
      start = 0
      do c = 1, len(t) + 1
        if (c <= len(t)) then
          if (quote /= ' ') then
            if (t(c:c) == quote) quote = ' '
            cycle
          end if
          if (t(c:c) == '"' .or. t(c:c) == "'") then
            quote = t(c:c)
            if (start == 0) start = c
            cycle
          end if
          if (t(c:c) /= ',' .and. t(c:c) /= ' ') then
            if (start == 0) start = c
            cycle
          end if
        end if
        if (start == 0) cycle
        star = index(t(start:c - 1), '*')
        r = 1
        if (star > 1) then
          read (t(start:start + star - 2), *, iostat=ios) r
          if (ios /= 0) r = 1
        end if
        n = n + r
        start = 0
      end do
    end function count_values
  end subroutine check_assignments

  !> Refuse the old spelling of a renamed variable (renamed_variables) in
  !> group `name`, with a message that names the new one.
  subroutine check_renamed(name, group_text, status, msg)
    character(len=*), intent(in) :: name, group_text
    integer, intent(out) :: status
    character(len=*), intent(out) :: msg
    character(len=48) :: group, old, new, entry
    character(len=:), allocatable :: body, lhs
    integer, allocatable :: starts(:)
    integer :: k, i, r, nstarts, body_start
    status = 0
    msg = ''
    body_start = index(group_text, ' ')
    if (body_start == 0) return
    body = group_text(body_start:len(group_text) - 1)
    call assignment_starts(body, starts, nstarts)
    do k = 1, nstarts
      i = index(body(starts(k):), '=')
      if (i == 0) cycle
      lhs = lower(trim(adjustl(body(starts(k):starts(k) + i - 2))))
      if (index(lhs, '(') > 0) lhs = trim(lhs(1:index(lhs, '(') - 1))
      do r = 1, size(renamed_variables)
        entry = renamed_variables(r)
        read (entry, *) group, old, new
        if (trim(group) /= name .or. trim(old) /= lhs) cycle
        status = 1
        msg = 'variable '//lhs//': renamed '//trim(new)//' (write '//trim(new)//' = ... instead)'
        return
      end do
    end do
  end subroutine check_renamed

  !> Read one group; on failure find the assignment at fault.
  subroutine read_group_checked(name, group_text, p, status, msg)
    character(len=*), intent(in) :: name, group_text
    type(params_t), intent(inout) :: p
    integer, intent(out) :: status
    character(len=*), intent(out) :: msg
    type(params_t) :: scratch
    integer :: body_start, i, k, nstarts, s2
    integer, allocatable :: starts(:)
    character(len=:), allocatable :: body, piece, variable
    character(len=msg_len) :: msg2

    call group_namelist(name, p, status, msg, group_text)
    if (status == 0) return
    ! Locate the assignments 'variable = values' and read them one at a time.
    body_start = index(group_text, ' ')
    if (body_start == 0) body_start = len(group_text)
    body = group_text(body_start:len(group_text) - 1)
    call assignment_starts(body, starts, nstarts)
    scratch = p
    ! gfortran (12) accepts the read that follows a failed logical read: an
    ! empty read of the group first puts its reader back into a clean state.
    call group_namelist(name, scratch, s2, msg2, '&'//name//' /')
    do k = 1, nstarts
      if (k < nstarts) then
        piece = body(starts(k):starts(k + 1) - 1)
      else
        piece = body(starts(k):)
      end if
      call group_namelist(name, scratch, s2, msg2, '&'//name//' '//trim(adjustl(piece))//' /')
      if (s2 /= 0) then
        i = index(piece, '=')
        variable = lower(trim(adjustl(piece(1:i - 1))))
        msg = 'variable '//variable//': '//describe(msg2, variable, is_string(variable))// &
              ' (in "'//trim(adjustl(piece))//'")'
        return
      end if
    end do
    msg = describe(msg, '', .false.)
  contains
    !> `variable` of this group holds a string.
    logical function is_string(variable)
      character(len=*), intent(in) :: variable
      type(param_item_t), allocatable :: items(:)
      integer :: j
      call param_items(p, name, items)
      is_string = .false.
      do j = 1, size(items)
        if (items(j)%name == variable) is_string = items(j)%kind == 's'
      end do
    end function is_string
  end subroutine read_group_checked

  !> Turn a compiler's namelist message about `variable` into one for a user.
  !> `string`: the variable holds a string (an unquoted word then gets the hint on quotes).
  function describe(iomsg, variable, string) result(text)
    character(len=*), intent(in) :: iomsg, variable
    logical, intent(in) :: string
    character(len=:), allocatable :: text, unknown
    integer :: i
    i = index(iomsg, 'Cannot match namelist object name')
    text = 'cannot read the value: '//trim(iomsg)
    if (i == 0) return
    unknown = lower(trim(adjustl(iomsg(i + 33:))))
    unknown = unknown(max(1, verify(unknown, achar(39)//achar(34))):)
    if (index(unknown, variable) == 1 .or. len(variable) == 0) then
      text = 'not a variable of this group (see docs/INPUT.md for the allowed ones)'
    else if (string .and. scan(adjustl(iomsg(i + 33:)), achar(39)//achar(34)) /= 1) then
      ! an unquoted word: gfortran reads it as the name of the next variable
      text = "a string value needs quotes: "//variable//" = '"//trim(unknown)//"'"
    end if
  end function describe

  !> Positions in `body` where an assignment 'name[(...)] =' starts.
  subroutine assignment_starts(body, starts, n)
    character(len=*), intent(in) :: body
    integer, allocatable, intent(out) :: starts(:)
    integer, intent(out) :: n
    integer :: i, j, depth
    character :: quote
    allocate (starts(len(body) + 1))
    n = 0
    quote = ' '
    depth = 0
    do i = 1, len(body)
      if (quote /= ' ') then
        if (body(i:i) == quote) quote = ' '
        cycle
      end if
      select case (body(i:i))
      case ('"', "'")
        quote = body(i:i)
      case ('(')
        depth = depth + 1
      case (')')
        depth = depth - 1
      case ('=')
        if (depth /= 0) cycle
        ! walk back over blanks, an optional (...) and the name
        j = i - 1
        do while (j >= 1)
          if (body(j:j) /= ' ') exit
          j = j - 1
        end do
        if (j >= 1) then
          if (body(j:j) == ')') then
            do while (j >= 1)
              if (body(j:j) == '(') exit
              j = j - 1
            end do
            j = j - 1
          end if
        end if
        do while (j >= 1)
          if (.not. (is_name_char(body(j:j)) .or. body(j:j) == '%')) exit
          j = j - 1
        end do
        n = n + 1
        starts(n) = j + 1
      end select
    end do
    if (n == 0) then
      n = 1
      starts(1) = 1
    end if
  end subroutine assignment_starts

  !> The dispatcher of the groups: each group's owner reads it from
  !> `group_text` into `p` or, without `group_text`, writes it (as the
  !> compiler writes a namelist, strings quoted) into `written`. Adding a
  !> variable: a component with its default in its owner's settings type, in
  !> its owner's namelist and check; the echo and report.json follow.
  subroutine group_namelist(name, p, status, msg, group_text, written)
    character(len=*), intent(in) :: name
    type(params_t), intent(inout) :: p
    integer, intent(out) :: status
    character(len=*), intent(out) :: msg
    character(len=*), intent(in), optional :: group_text
    character(len=*), intent(out), optional :: written(:)
    logical :: reading

    msg = ''
    status = 0
    reading = present(group_text)
    if (present(written)) written = ''
    select case (name)
    case ('mesh')
      if (reading) call p%mesh%read_namelist(group_text, status, msg)
      if (.not. reading) call p%mesh%write_namelist(written, status, msg)
    case ('material')
      if (reading) call p%material%read_namelist(group_text, status, msg)
      if (.not. reading) call p%material%write_namelist(written, status, msg)
    case ('load')
      if (reading) call p%load%read_namelist(group_text, status, msg)
      if (.not. reading) call p%load%write_namelist(written, status, msg)
    case ('history')
      if (reading) call p%history%read_namelist(group_text, status, msg)
      if (.not. reading) call p%history%write_namelist(written, status, msg)
    case ('boundary')
      if (reading) call p%boundary%read_namelist(group_text, status, msg)
      if (.not. reading) call p%boundary%write_namelist(written, status, msg)
    case ('obstacle')
      if (reading) call p%obstacle%read_namelist(group_text, status, msg)
      if (.not. reading) call p%obstacle%write_namelist(written, status, msg)
    case ('solver')
      if (reading) call solver_group(p%solver, group_text, status, msg)
      if (.not. reading) call solver_group(p%solver, status=status, msg=msg, written=written)
    case ('reconstruction')
      if (reading) call p%reconstruction%read_namelist(group_text, status, msg)
      if (.not. reading) call p%reconstruction%write_namelist(written, status, msg)
    case ('output')
      if (reading) call p%output%read_namelist(group_text, status, msg)
      if (.not. reading) call p%output%write_namelist(written, status, msg)
    end select
  end subroutine group_namelist

  !> The dispatcher of &solver: each assignment of `group_text` goes to the
  !> component that owns the variable (SMALBE, its inner MPRGP, the polish,
  !> the dual problem, the coarse problem, the local solver, the F action,
  !> the preconditioner, the row scaling: each reads its own variables with
  !> its own namelist); an assignment no component owns goes to SMALBE, whose
  !> read refuses it. Without `group_text`: the components write their
  !> variables into `written` (from its first line '&SOLVER', without the
  !> closing '/').
  subroutine solver_group(settings, group_text, status, msg, written)
    type(solver_params_t), intent(inout) :: settings
    character(len=*), intent(in), optional :: group_text
    integer, intent(out) :: status
    character(len=*), intent(out) :: msg
    character(len=*), intent(out), optional :: written(:)
    integer, parameter :: n_parts = 9
    character(len=:), allocatable :: body, piece, name, part(:)
    character(len=path_len + 64) :: lines(64)
    type(param_item_t), allocatable :: items(:)
    integer, allocatable :: starts(:)
    integer :: c, k, i, nstarts, body_start, line, owner

    status = 0
    msg = ''
    if (.not. present(group_text)) then
      written = ''
      written(1) = '&SOLVER'
      line = 1
      do c = 1, n_parts
        call write_part(c, lines)
        if (status /= 0) return
        do k = 1, size(lines)
          if (len_trim(lines(k)) == 0) cycle
          if (adjustl(lines(k)) == '/' .or. lines(k)(1:1) == '&') cycle
          line = line + 1
          written(line) = lines(k)
        end do
      end do
      return
    end if
    allocate (character(len=len(group_text)) :: part(n_parts))
    part = ''
    body_start = index(group_text, ' ')
    if (body_start == 0) body_start = len(group_text)
    body = group_text(body_start:len(group_text) - 1)
    call assignment_starts(body, starts, nstarts)
    do k = 1, nstarts
      if (k < nstarts) then
        piece = body(starts(k):starts(k + 1) - 1)
      else
        piece = body(starts(k):)
      end if
      i = index(piece, '=')
      owner = 1
      if (i > 0) then
        name = lower(trim(adjustl(piece(1:i - 1))))
        do c = 1, n_parts
          call write_part(c, lines)
          if (status /= 0) return
          call parse_namelist(join(lines), items)
          if (any(items%name == name)) then
            owner = c
            exit
          end if
        end do
      end if
      part(owner) = trim(part(owner))//' '//piece
    end do
    ! every component reads (an empty group leaves its values as they are)
    do c = 1, n_parts
      call read_part(c, '&solver '//trim(part(c))//' /')
      if (status /= 0) return
    end do
  contains
    subroutine read_part(c, text)
      integer, intent(in) :: c
      character(len=*), intent(in) :: text
      select case (c)
      case (1)
        call settings%smalbe%read_namelist(text, status, msg)
      case (2)
        call settings%smalbe%inner%read_namelist(text, status, msg)
      case (3)
        call settings%smalbe%polish%read_namelist(text, status, msg)
      case (4)
        call settings%dual%read_namelist(text, status, msg)
      case (5)
        call settings%f_action%read_namelist(text, status, msg)
      case (6)
        call settings%coarse%read_namelist(text, status, msg)
      case (7)
        call settings%local%read_namelist(text, status, msg)
      case (8)
        call settings%scaling%read_namelist(text, status, msg)
      case (9)
        call settings%preconditioner%read_namelist(text, status, msg)
      end select
    end subroutine read_part
    subroutine write_part(c, out)
      integer, intent(in) :: c
      character(len=*), intent(out) :: out(:)
      select case (c)
      case (1)
        call settings%smalbe%write_namelist(out, status, msg)
      case (2)
        call settings%smalbe%inner%write_namelist(out, status, msg)
      case (3)
        call settings%smalbe%polish%write_namelist(out, status, msg)
      case (4)
        call settings%dual%write_namelist(out, status, msg)
      case (5)
        call settings%f_action%write_namelist(out, status, msg)
      case (6)
        call settings%coarse%write_namelist(out, status, msg)
      case (7)
        call settings%local%write_namelist(out, status, msg)
      case (8)
        call settings%scaling%write_namelist(out, status, msg)
      case (9)
        call settings%preconditioner%write_namelist(out, status, msg)
      end select
    end subroutine write_part
    function join(out) result(text)
      character(len=*), intent(in) :: out(:)
      character(len=:), allocatable :: text
      integer :: j
      text = ''
      do j = 2, size(out)
        text = text//' '//trim(out(j))
      end do
    end function join
  end subroutine solver_group

  !> Check every value; the first violation gives `status` /= 0 and a message
  !> naming the group, the variable and the allowed values.
  subroutine check_params(p, status, msg)
    type(params_t), intent(in) :: p
    integer, intent(out) :: status
    character(len=*), intent(out) :: msg
    character(len=:), allocatable :: variable, rule, got
    real(dp), allocatable :: step_gaps(:)
    integer(ip) :: k

    status = 0
    msg = ''
    associate (m => p%mesh)
      call m%check(variable, rule, got)
      if (len(variable) > 0) call fail('mesh', variable, rule, got)
      if (any(m%cluster > 1)) then
        if (p%material%variation /= 'none') call fail('mesh', 'cluster', &
          "> 1 (hybrid TFETI) needs &material variation = 'none'", ints(m%cluster))
        if (p%solver%preconditioner%preconditioner == 'dirichlet') call fail('mesh', 'cluster', &
          "> 1 (hybrid TFETI) works with &solver preconditioner = 'none' or 'lumped', not 'dirichlet'", &
          ints(m%cluster))
        if (p%solver%f_action%f_action == 'explicit') call fail('mesh', 'cluster', &
          "> 1 (hybrid TFETI) works with &solver f_action = 'implicit' or 'auto' (which then stays implicit)", &
          ints(m%cluster))
        if (p%solver%local%local_solver == 'dense') call fail('mesh', 'cluster', &
          "> 1 (hybrid TFETI) works with &solver local_solver = 'auto', 'block' or 'subdomain', not 'dense'", &
          ints(m%cluster))
      end if
    end associate
    call p%material%check(variable, rule, got)
    if (len(variable) > 0) call fail('material', variable, rule, got)
    associate (b => p%boundary)
      ! frictionless contact holds u_z only: without the top face, the symmetry planes must hold
      ! the x and y translations and the rotation about z, and an obstacle the z translation
      if (.not. (b%top_dirichlet .or. (b%symmetry_x0 .and. b%symmetry_y0 .and. p%obstacle%shape /= 'none'))) &
        call fail('boundary', 'top_dirichlet', &
                  'the body must be held against every rigid motion: set top_dirichlet, or both '// &
                  'symmetry_x0 and symmetry_y0 together with an &obstacle shape (the frictionless '// &
                  'contact holds only the z direction)', 'F')
    end associate
    if (p%load%top_pressure /= 0 .and. p%boundary%top_dirichlet) &
      call fail('load', 'top_pressure', 'has no effect with &boundary top_dirichlet = .true. (the prescribed '// &
                'displacement holds the top face): set top_dirichlet = .false. or drop top_pressure', &
                reals([p%load%top_pressure])//', top_dirichlet = T')
    call p%obstacle%check(variable, rule, got)
    if (len(variable) > 0) call fail('obstacle', variable, rule, got)
    if (p%obstacle%shape /= 'none' .and. p%obstacle%gap < -max_penetration*p%mesh%lengths(3)) &
      call fail('obstacle', 'gap', 'the obstacle must not start deeper inside the body than 0.1 times '// &
                'its height &mesh lengths(3)', reals([p%obstacle%gap]))
    ! &solver: each component checks its own variables
    associate (s => p%solver)
      call s%smalbe%check(variable, rule, got)
      if (len(variable) > 0) call fail('solver', variable, rule, got)
      call s%dual%check(variable, rule, got)
      if (len(variable) > 0) call fail('solver', variable, rule, got)
      call s%f_action%check(variable, rule, got)
      if (len(variable) > 0) call fail('solver', variable, rule, got)
      call s%coarse%check(variable, rule, got)
      if (len(variable) > 0) call fail('solver', variable, rule, got)
      call s%local%check(variable, rule, got)
      if (len(variable) > 0) call fail('solver', variable, rule, got)
      call s%scaling%check(variable, rule, got)
      if (len(variable) > 0) call fail('solver', variable, rule, got)
      call s%preconditioner%check(variable, rule, got)
      if (len(variable) > 0) call fail('solver', variable, rule, got)
    end associate
    call p%history%check(variable, rule, got)
    if (len(variable) > 0) call fail('history', variable, rule, got)
    if (status == 0) then
      associate (h => p%history)
        step_gaps = [(h%gap(k, p%obstacle%gap), k = 1, h%nsteps)]
        if (any(step_gaps /= p%obstacle%gap) .and. p%obstacle%shape == 'none') &
          call fail('history', 'gaps', "moves the obstacle, but &obstacle shape = 'none'", reals(step_gaps(1:1)))
        if (p%obstacle%shape /= 'none' .and. minval(step_gaps) < -max_penetration*p%mesh%lengths(3)) &
          call fail('history', 'gaps', 'the obstacle must not be deeper inside the body than 0.1 times '// &
                    'its height &mesh lengths(3) at any step', reals([minval(step_gaps)]))
      end associate
    end if
    call p%reconstruction%check(variable, rule, got)
    if (len(variable) > 0) call fail('reconstruction', variable, rule, got)
    call p%output%check(variable, rule, got)
    if (len(variable) > 0) call fail('output', variable, rule, got)

  contains

    subroutine fail(group, variable, rule, got)
      character(len=*), intent(in) :: group, variable, rule, got
      if (status /= 0) return
      status = 1
      msg = 'file '//trim(p%file)//', group &'//group//', variable '//variable//': '//rule// &
            ' (got '//trim(got)//')'
    end subroutine fail
  end subroutine check_params

  !> Settings that are valid but probably not what was meant: each a sentence
  !> naming the group and the variable (the log and report.json's `warnings`).
  function input_warnings(p) result(w)
    type(params_t), intent(in) :: p
    character(len=msg_len), allocatable :: w(:)
    character(len=msg_len) :: line
    allocate (w(0))
    line = p%material%warning()
    if (len_trim(line) > 0) w = [character(len=msg_len) :: w, line]
    associate (o => p%obstacle, b => p%boundary)
      ! the face z = 0 moves down by at most -uz of the prescribed top (the body only shortens)
      if (o%shape /= 'none' .and. b%top_dirichlet .and. o%gap > -b%top_displacement(3)) then
        write (line, '(a,es10.3,a,es10.3,a)') '&obstacle gap = ', o%gap, &
          ' is larger than what &boundary top_displacement(3) = ', b%top_displacement(3), &
          ' can close: the body never touches the obstacle (no contact)'
        w = [character(len=msg_len) :: w, line]
      end if
    end associate
  end function input_warnings

  !> The settings of the FETI operators' components, as the groups gave them.
  function feti_settings_of(p) result(s)
    type(params_t), intent(in) :: p
    type(feti_settings_t) :: s
    s = feti_settings_t(p%mesh, p%material, p%load, p%boundary, p%obstacle, p%solver%scaling, &
                        p%solver%local, p%solver%f_action, p%solver%coarse)
  end function feti_settings_of

  !> `&mesh cluster = 0, 0, 0` (the default): replace it by `auto_cluster`'s
  !> choice for `nranks` ranks, and record that and why (cluster_auto,
  !> cluster_choice). Explicit values are left as they are.
  subroutine resolve_cluster(p, nranks)
    type(params_t), intent(inout) :: p
    integer, intent(in) :: nranks
    character(len=160) :: reason
    if (.not. all(p%mesh%cluster == 0)) return
    p%mesh%cluster = auto_cluster(p, nranks, reason)
    p%mesh%cluster_auto = .true.
    p%mesh%cluster_choice = reason
  end subroutine resolve_cluster

  !> The automatic choice of hybrid TFETI clusters (docs/INPUT.md `cluster`).
  !> Clusters pay where the coarse problem dominates: subdomains of at most
  !> `auto_max_nel` = 2 elements per direction (H/h <= 2), at least
  !> 512 (H/h)^3 of them (H/h the largest entry of nel: 512 subdomains of one
  !> element, 4096 of 2^3; fewer do not pay). Then, per direction, the
  !> largest divisor c of nsub with nel*c <= `auto_cluster_edge` = 4
  !> elements along the cluster's edge, reduced (largest entry first) until
  !> every rank holds at least `auto_clusters_per_rank` = 4 clusters (a
  !> balance guard: a cluster lives on one rank). [1, 1, 1]
  !> (plain TFETI) whenever a requirement of hybrid TFETI fails (box
  !> decomposition, uniform material, no Dirichlet preconditioner, implicit
  !> F) or the rule does not fire; `reason` says which.
  function auto_cluster(p, nranks, reason) result(c)
    type(params_t), intent(in) :: p
    integer, intent(in) :: nranks
    character(len=*), intent(out) :: reason
    integer(ip) :: c(3)
    integer(ip), parameter :: auto_max_nel = 2, auto_min_subdomains = 512, auto_cluster_edge = 4, &
                              auto_clusters_per_rank = 4
    integer(ip) :: d, k, hh
    c = 1
    associate (nsub => p%mesh%nsub, nel => p%mesh%nel)
      if (p%mesh%decomposition /= 'box') then
        reason = "plain TFETI: hybrid TFETI needs decomposition = 'box'"
      else if (p%material%variation /= 'none') then
        reason = "plain TFETI: hybrid TFETI needs &material variation = 'none'"
      else if (p%solver%preconditioner%preconditioner == 'dirichlet') then
        reason = "plain TFETI: hybrid TFETI does not take &solver preconditioner = 'dirichlet'"
      else if (p%solver%f_action%f_action == 'explicit') then
        reason = "plain TFETI: hybrid TFETI does not take &solver f_action = 'explicit'"
      else if (p%solver%local%local_solver == 'dense') then
        reason = "plain TFETI: hybrid TFETI does not take &solver local_solver = 'dense'"
      else if (any(nel > auto_max_nel)) then
        reason = 'plain TFETI: subdomains of more than 2 elements in a direction (clusters pay for H/h <= 2)'
      else if (product(int(nsub, i8)) < int(auto_min_subdomains, i8)*maxval(nel)**3) then
        hh = maxval(nel)
        write (reason, '(a,i0,a,i0,a)') 'plain TFETI: fewer than ', auto_min_subdomains*hh**3, &
          ' subdomains (clusters pay from 512 (H/h)^3 on, H/h = ', hh, ')'
      else
        do d = 1, 3
          do k = max(auto_cluster_edge/nel(d), 1_ip), 1_ip, -1_ip
            if (mod(nsub(d), k) == 0) exit
          end do
          c(d) = k
        end do
        do while (any(c > 1) .and. product(int(nsub/c, i8)) < int(auto_clusters_per_rank, i8)*nranks)
          d = maxloc(c, 1)
          do k = c(d) - 1, 1, -1
            if (mod(nsub(d), k) == 0) exit
          end do
          c(d) = k
        end do
        if (all(c == 1)) then
          reason = 'plain TFETI: no cluster size divides nsub with enough clusters per rank'
        else
          reason = 'hybrid TFETI: small subdomains (H/h <= 2) by the hundred (>= 512 (H/h)^3), '// &
                   'clusters of up to 4 elements per edge'
        end if
      end if
    end associate
  end function auto_cluster

  !> The variables of group `name` as the namelist writes them (see
  !> group_namelist): the one source of the echo and of report.json.
  subroutine param_items(p, name, items)
    type(params_t), intent(in) :: p
    character(len=*), intent(in) :: name
    type(param_item_t), allocatable, intent(out) :: items(:)
    character(len=:), allocatable :: lines(:)
    character(len=:), allocatable :: text
    type(params_t) :: copy
    integer :: status, k
    character(len=msg_len) :: msg
    allocate (character(len=path_len + 64) :: lines(300))
    copy = p
    call group_namelist(name, copy, status, msg, written=lines)
    if (status /= 0) call fatal_error('params: cannot write group &'//name//': '//trim(msg))
    text = ''
    do k = 2, size(lines)             ! lines(1) is '&GROUP'
      text = text//' '//trim(lines(k))
    end do
    call parse_namelist(text, items)
  end subroutine param_items

  !> Split the body of a written namelist group ("NAME= v, r*v, ... /") into
  !> items; values stay text, repeat counts are expanded, quotes removed.
  subroutine parse_namelist(text, items)
    character(len=*), intent(in) :: text
    type(param_item_t), allocatable, intent(out) :: items(:)
    type(param_item_t) :: item
    character(len=:), allocatable :: token
    integer :: i, j, star, repeat, k
    allocate (items(0))
    i = 1
    do
      i = next_nonblank(text, i)
      if (i > len(text)) exit
      if (text(i:i) == '/') exit
      j = index(text(i:), '=') + i - 1
      if (allocated(token)) deallocate (token)
      item = param_item_t(name=lower(trim(adjustl(text(i:j - 1)))))
      i = j + 1
      do                                     ! values up to the next NAME= or '/'
        i = next_nonblank(text, i)
        if (i > len(text)) exit
        if (text(i:i) == '/' .or. starts_name(text, i)) exit
        if (text(i:i) == '"') then
          call quoted(text, i, token)
          item%kind = 's'
          repeat = 1
        else
          j = scan(text(i:), ', /') + i - 1
          if (j < i) j = len(text) + 1
          token = text(i:j - 1)
          i = j
          repeat = 1
          star = index(token, '*')
          if (star > 0) then
            read (token(1:star - 1), *) repeat
            token = token(star + 1:)
          end if
          if (token == 'T' .or. token == 'F') then
            item%kind = 'l'
          else if (scan(token, '.eE') > 0) then
            item%kind = 'r'
          else
            item%kind = 'i'
          end if
        end if
        if (.not. allocated(item%values)) allocate (item%values(0))
        do k = 1, repeat
          item%n = item%n + 1
          item%values = [character(len=path_len) :: item%values, token]
        end do
        i = next_nonblank(text, i)
        if (i <= len(text)) then
          if (text(i:i) == ',') i = i + 1
        end if
      end do
      items = [items, item]
    end do
  contains
    pure integer function next_nonblank(t, from)
      character(len=*), intent(in) :: t
      integer, intent(in) :: from
      next_nonblank = from
      do while (next_nonblank <= len(t))
        if (t(next_nonblank:next_nonblank) /= ' ') exit
        next_nonblank = next_nonblank + 1
      end do
    end function next_nonblank
    !> A variable name followed by '=' starts at t(from:).
    pure logical function starts_name(t, from)
      character(len=*), intent(in) :: t
      integer, intent(in) :: from
      integer :: e
      e = from
      do while (e <= len(t))
        if (.not. is_name_char(t(e:e))) exit
        e = e + 1
      end do
      e = next_nonblank(t, e)
      starts_name = e > from .and. e <= len(t)
      if (starts_name) starts_name = t(e:e) == '='
    end function starts_name
    !> The string quoted by '"' at t(from:), doubled quotes undone; from moves past it.
    subroutine quoted(t, from, value)
      character(len=*), intent(in) :: t
      integer, intent(inout) :: from
      character(len=:), allocatable, intent(out) :: value
      value = ''
      from = from + 1
      do while (from <= len(t))
        if (t(from:from) == '"') then
          if (from < len(t)) then
            if (t(from + 1:from + 1) == '"') then
              value = value//'"'
              from = from + 2
              cycle
            end if
          end if
          from = from + 1
          exit
        end if
        value = value//t(from:from)
        from = from + 1
      end do
      value = trim(value)
    end subroutine quoted
  end subroutine parse_namelist

  !> Print the parameters actually used (rank 0 writes): one line per group,
  !> in the syntax of the input.
  subroutine echo_params(p, unit)
    type(params_t), intent(in) :: p
    integer, intent(in) :: unit
    type(param_item_t), allocatable :: items(:)
    character(len=:), allocatable :: line
    integer :: g, k, v
    write (unit, '(a)') 'input file: '//trim(p%file)
    do g = 1, size(group_names)
      call param_items(p, trim(group_names(g)), items)
      line = '&'//trim(group_names(g))
      do k = 1, size(items)
        line = line//trim(merge(',', ' ', k > 1))//' '//trim(items(k)%name)//' ='
        do v = 1, items(k)%n
          line = line//' '//echo_value(items(k)%kind, items(k)%values(v))
        end do
      end do
      write (unit, '(a)') line//' /'
    end do
  contains
    function echo_value(kind, text) result(s)
      character, intent(in) :: kind
      character(len=*), intent(in) :: text
      character(len=:), allocatable :: s
      character(len=32) :: buf
      real(dp) :: x
      select case (kind)
      case ('s')
        s = "'"//trim(text)//"'"
      case ('r')
        read (text, *) x
        write (buf, '(g0.6)') x
        s = trim(adjustl(buf))
      case default
        s = trim(adjustl(text))
      end select
    end function echo_value
  end subroutine echo_params

  ! ---- small text helpers ----

  !> Position of `name` in group_names, 0 if it is not a group.
  integer function group_index(name)
    character(len=*), intent(in) :: name
    integer :: k
    group_index = 0
    do k = 1, size(group_names)
      if (trim(group_names(k)) == name) group_index = k
    end do
  end function group_index

  pure logical function is_name_char(c)
    character, intent(in) :: c
    is_name_char = (c >= 'a' .and. c <= 'z') .or. (c >= 'A' .and. c <= 'Z') .or. &
                   (c >= '0' .and. c <= '9') .or. c == '_'
  end function is_name_char

  pure function lower(s) result(r)
    character(len=*), intent(in) :: s
    character(len=len(s)) :: r
    integer :: i
    r = s
    do i = 1, len(s)
      if (s(i:i) >= 'A' .and. s(i:i) <= 'Z') r(i:i) = achar(iachar(s(i:i)) + 32)
    end do
  end function lower

  function snippet(text, i) result(s)
    character(len=*), intent(in) :: text
    integer, intent(in) :: i
    character(len=:), allocatable :: s
    s = trim(text(i:min(len(text), i + 30)))
  end function snippet

  !> The values of v separated by blanks (for messages).
  function ints(v) result(s)
    integer(ip), intent(in) :: v(:)
    character(len=:), allocatable :: s
    character(len=256) :: buf
    write (buf, '(*(i0,:," "))') v
    s = trim(buf)
  end function ints

  !> The values of v separated by blanks, 6 significant digits.
  function reals(v) result(s)
    real(dp), intent(in) :: v(:)
    character(len=:), allocatable :: s
    character(len=256) :: buf
    write (buf, '(*(g0.6,:," "))') v
    s = trim(buf)
  end function reals
end module params
