!> Run parameters: the namelist groups, their defaults, reading, checking
!> and echoing.
!>
!> Every component's settings type (settings_base::settings_t) declares its
!> group, its variables and its namelist; `components` is the one list of
!> them, and reading, writing and checking loop over it. Rank 0 reads the
!> file and broadcasts its text; every rank splits it into groups, hands each
!> group to its owners (an internal namelist read each) and checks the
!> values. When a group fails to read, its assignments are read again one by
!> one so that the message can name the variable at fault. On an error every
!> rank exits together with status 2 (rank 0 says why). Every variable is
!> documented in docs/INPUT.md.
module params
  use kinds, only: dp, ip, i8, path_len, name_len
  use errors, only: collective_error, exit_input_error, fatal_error, set_input_file
  use mpi_f08, only: MPI_Comm, MPI_Comm_rank, MPI_Comm_size, MPI_Bcast, MPI_Allreduce, MPI_MAX, MPI_INTEGER, &
                     MPI_CHARACTER
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
  use settings_base, only: settings_t
  implicit none
  private

  public :: read_params, check_params, echo_params, input_warnings, default_params, param_items, group_names
  public :: auto_cluster, resolve_cluster, feti_settings_of, components

  integer, parameter :: msg_len = 1024
  !> &obstacle gap: the deepest initial penetration accepted, as a fraction of the body's height
  real(dp), parameter, public :: max_penetration = 0.1_dp

  !> &solver: each variable belongs to the component that owns it (its
  !> settings type: defaults, checks, namelist variables); read_group hands
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

  !> A settings type of a run: a component of params_t (see components).
  type, public :: component_t
    class(settings_t), pointer :: s => null()
  end type component_t

  !> The namelist groups, in the order of the echo and of report.json.
  character(len=*), parameter :: group_names(9) = [character(len=14) :: 'mesh', 'material', &
    'load', 'boundary', 'obstacle', 'solver', 'reconstruction', 'output', 'history']

contains

  !> The defaults of every variable.
  function default_params() result(p)
    type(params_t) :: p
    p = params_t()
  end function default_params

  !> Read and check the parameters of `file`. Collective over `comm`: rank
  !> 0 reads the file and broadcasts its text, every rank reads the groups
  !> from it and checks them (the same text gives the same values and the
  !> same verdict everywhere); on any input error every rank exits with
  !> status 2 and rank 0 says why.
  subroutine read_params(file, comm, p)
    character(len=*), intent(in) :: file
    type(MPI_Comm), intent(in) :: comm
    type(params_t), intent(out) :: p
    integer :: rank, nranks, ierr, status, worst, length
    character(len=msg_len) :: msg
    character(len=:), allocatable :: text

    call MPI_Comm_rank(comm, rank, ierr)
    call MPI_Comm_size(comm, nranks, ierr)
    call set_input_file(file)       ! the refusals at run time name it too
    status = 0
    msg = ''
    length = 0
    if (rank == 0) then
      call load_text(file, text, status, msg)
      if (status == 0) length = len(text)
    end if
    call MPI_Bcast(status, 1, MPI_INTEGER, 0, comm, ierr)
    if (status /= 0) then
      call MPI_Bcast(msg, msg_len, MPI_CHARACTER, 0, comm, ierr)
      call collective_error(msg, comm, exit_input_error)
    end if
    call MPI_Bcast(length, 1, MPI_INTEGER, 0, comm, ierr)
    if (rank /= 0) allocate (character(len=length) :: text)
    if (length > 0) call MPI_Bcast(text, length, MPI_CHARACTER, 0, comm, ierr)
    p = params_t()
    call read_text(file, text, p, status, msg)
    if (status == 0) call check_params(p, status, msg)
    if (status == 0) p%obstacle%axis = p%obstacle%centre_of(p%mesh%lengths)   ! echoed resolved
    if (status == 0) then
      call resolve_cluster(p, nranks)
      call check_params(p, status, msg)     ! (the automatic choice meets every check by construction)
    end if
    call MPI_Allreduce(status, worst, 1, MPI_INTEGER, MPI_MAX, comm, ierr)
    if (worst /= 0) then
      call MPI_Bcast(msg, msg_len, MPI_CHARACTER, 0, comm, ierr)
      call collective_error(msg, comm, exit_input_error)
    end if
  end subroutine read_params

  !> Read every group of the input's text `text` (load_text of `file`) into `p`.
  subroutine read_text(file, text, p, status, msg)
    character(len=*), intent(in) :: file, text
    type(params_t), intent(inout) :: p
    integer, intent(out) :: status
    character(len=*), intent(out) :: msg
    character(len=:), allocatable :: group_text, name
    integer :: pos, i
    logical :: seen(size(group_names))

    p%file = file
    status = 0
    msg = ''
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
  end subroutine read_text

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
              did_you_mean(p, name, variable, msg2)//' (in "'//trim(adjustl(piece))//'")'
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

  !> For a variable that is not one of group `name` (the namelist message
  !> `iomsg` says so): '; did you mean <v>?' with the group's variable
  !> nearest in spelling (at most 2 edits, or one starts with the other),
  !> else ''.
  function did_you_mean(p, name, variable, iomsg) result(text)
    type(params_t), intent(in) :: p
    character(len=*), intent(in) :: name, variable, iomsg
    character(len=:), allocatable :: text, given
    type(param_item_t), allocatable :: items(:)
    integer :: j, d, best
    text = ''
    if (index(iomsg, 'Cannot match namelist object name') == 0) return
    given = variable
    if (index(given, '(') > 0) given = given(1:index(given, '(') - 1)
    call param_items(p, name, items)
    best = 3
    do j = 1, size(items)
      d = edit_distance(given, trim(items(j)%name))
      if (len(given) >= 3 .and. (index(trim(items(j)%name), given) == 1 .or. &
                                  index(given, trim(items(j)%name)) == 1)) d = min(d, 2)
      if (d < best) then
        best = d
        text = '; did you mean '//trim(items(j)%name)//'?'
      end if
    end do
  contains
    !> Levenshtein distance of a and b.
    pure integer function edit_distance(a, b) result(dist)
      character(len=*), intent(in) :: a, b
      integer :: row(0:len(b)), prev(0:len(b)), i, k
      prev = [(k, k = 0, len(b))]
      do i = 1, len(a)
        row(0) = i
        do k = 1, len(b)
          row(k) = min(prev(k) + 1, row(k - 1) + 1, prev(k - 1) + merge(0, 1, a(i:i) == b(k:k)))
        end do
        prev = row
      end do
      dist = prev(len(b))
    end function edit_distance
  end function did_you_mean

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

  !> Every settings type of a run (pointers into `p`), in the order of
  !> group_names and, within a group, of the echo. The one list of the
  !> components: reading, writing and checking loop over it. A new component:
  !> its field in params_t (solver_params_t for &solver) and its entry here.
  subroutine components(p, c)
    type(params_t), intent(in), target :: p
    type(component_t), allocatable, intent(out) :: c(:)
    allocate (c(17))
    c(1)%s => p%mesh
    c(2)%s => p%material
    c(3)%s => p%load
    c(4)%s => p%boundary
    c(5)%s => p%obstacle
    c(6)%s => p%solver%smalbe
    c(7)%s => p%solver%smalbe%inner
    c(8)%s => p%solver%smalbe%polish
    c(9)%s => p%solver%dual
    c(10)%s => p%solver%f_action
    c(11)%s => p%solver%coarse
    c(12)%s => p%solver%local
    c(13)%s => p%solver%scaling
    c(14)%s => p%solver%preconditioner
    c(15)%s => p%reconstruction
    c(16)%s => p%output
    c(17)%s => p%history
  end subroutine components

  !> The components that own the variables of group `name`.
  subroutine group_owners(p, name, owners)
    type(params_t), intent(in), target :: p
    character(len=*), intent(in) :: name
    type(component_t), allocatable, intent(out) :: owners(:)
    type(component_t), allocatable :: c(:)
    integer :: k
    call components(p, c)
    allocate (owners(0))
    do k = 1, size(c)
      if (c(k)%s%group() == name) owners = [owners, c(k)]
    end do
  end subroutine group_owners

  !> Group `name` of `p`: its owners read it from `group_text` or, without
  !> `group_text`, write it into `written` (from its first line '&name',
  !> without the closing '/'; strings quoted).
  subroutine group_namelist(name, p, status, msg, group_text, written)
    character(len=*), intent(in) :: name
    type(params_t), intent(inout), target :: p
    integer, intent(out) :: status
    character(len=*), intent(out) :: msg
    character(len=*), intent(in), optional :: group_text
    character(len=*), intent(out), optional :: written(:)
    type(component_t), allocatable :: owners(:)

    msg = ''
    status = 0
    call group_owners(p, name, owners)
    if (present(group_text)) then
      call read_group(owners, name, group_text, status, msg)
    else
      call write_group(owners, name, written, status, msg)
    end if
  end subroutine group_namelist

  !> Each owner writes its variables; `written` gets them one after the other.
  subroutine write_group(owners, name, written, status, msg)
    type(component_t), intent(in) :: owners(:)
    character(len=*), intent(in) :: name
    character(len=*), intent(out) :: written(:)
    integer, intent(out) :: status
    character(len=*), intent(out) :: msg
    character(len=:), allocatable :: lines(:)
    integer :: o, k, line
    allocate (character(len=len(written)) :: lines(size(written)))
    written = ''
    written(1) = '&'//name
    line = 1
    do o = 1, size(owners)
      call owners(o)%s%write_namelist(lines, status, msg)
      if (status /= 0) return
      do k = 1, size(lines)
        if (len_trim(lines(k)) == 0) cycle
        if (adjustl(lines(k)) == '/' .or. lines(k)(1:1) == '&') cycle
        line = line + 1
        written(line) = lines(k)
      end do
    end do
  end subroutine write_group

  !> The owners read the group text '&name ... /'. A group of one owner goes
  !> to it whole; in a group of several (&solver), each assignment goes to
  !> the owner that declares the variable (an assignment no owner declares to
  !> the first, whose read refuses it), and every owner reads its part (an
  !> empty part leaves its values as they are).
  subroutine read_group(owners, name, group_text, status, msg)
    type(component_t), intent(in) :: owners(:)
    character(len=*), intent(in) :: name, group_text
    integer, intent(out) :: status
    character(len=*), intent(out) :: msg
    character(len=:), allocatable :: body, piece, lhs, part(:)
    character(len=name_len), allocatable :: names(:)
    integer, allocatable :: starts(:)
    integer :: o, k, i, nstarts, body_start, owner

    status = 0
    msg = ''
    if (size(owners) == 1) then
      call owners(1)%s%read_namelist(group_text, status, msg)
      return
    end if
    allocate (character(len=len(group_text)) :: part(size(owners)))
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
        lhs = lower(trim(adjustl(piece(1:i - 1))))
        do o = 1, size(owners)
          call owners(o)%s%variables(names)
          if (any(names == lhs)) then
            owner = o
            exit
          end if
        end do
      end if
      part(owner) = trim(part(owner))//' '//piece
    end do
    do o = 1, size(owners)
      call owners(o)%s%read_namelist('&'//name//' '//trim(part(o))//' /', status, msg)
      if (status /= 0) return
    end do
  end subroutine read_group

  !> Check every value; the first violation gives `status` /= 0 and a message
  !> naming the group, the variable and the allowed values: each component's
  !> own check (in the order of components), then the checks across groups.
  subroutine check_params(p, status, msg)
    type(params_t), intent(in), target :: p
    integer, intent(out) :: status
    character(len=*), intent(out) :: msg
    character(len=:), allocatable :: variable, rule, got
    type(component_t), allocatable :: c(:)
    integer :: k

    status = 0
    msg = ''
    call components(p, c)
    do k = 1, size(c)
      call c(k)%s%check(variable, rule, got)
      if (len(variable) > 0) then
        status = 1
        msg = refusal(p, c(k)%s%group(), variable, rule, got)
        return
      end if
    end do
    call check_across_groups(p, status, msg)
  end subroutine check_params

  !> The message of a refused value (the tests of tests/input expect this form).
  function refusal(p, group, variable, rule, got) result(msg)
    type(params_t), intent(in) :: p
    character(len=*), intent(in) :: group, variable, rule, got
    character(len=:), allocatable :: msg
    msg = 'file '//trim(p%file)//', group &'//group//', variable '//variable//': '//rule//' (got '//trim(got)//')'
  end function refusal

  !> The checks of values against other groups' values.
  subroutine check_across_groups(p, status, msg)
    type(params_t), intent(in) :: p
    integer, intent(out) :: status
    character(len=*), intent(out) :: msg
    real(dp), allocatable :: step_gaps(:)
    integer(ip) :: k

    status = 0
    msg = ''
    associate (m => p%mesh)
      if (any(m%cluster > 1) .and. m%cluster_gluing == 'corners') then
        if (p%material%variation /= 'none') call fail('mesh', 'cluster_gluing', &
          "= 'corners' needs &material variation = 'none' (merged corners have one modulus)", m%cluster_gluing)
        if (p%solver%preconditioner%preconditioner == 'dirichlet') call fail('mesh', 'cluster_gluing', &
          "= 'corners' works with &solver preconditioner = 'none' or 'lumped', not 'dirichlet'", m%cluster_gluing)
      end if
      if (any(m%cluster > 1)) then
        if (p%solver%f_action%f_action == 'explicit') call fail('mesh', 'cluster', &
          "> 1 (hybrid TFETI) works with &solver f_action = 'implicit' or 'auto' (explicit only for classes "// &
          "of congruent clusters)", ints(m%cluster))
        if (p%solver%local%local_solver == 'dense') call fail('mesh', 'cluster', &
          "> 1 (hybrid TFETI) works with &solver local_solver = 'auto', 'block' or 'subdomain', not 'dense'", &
          ints(m%cluster))
      end if
    end associate
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
    if (p%obstacle%shape /= 'none' .and. p%obstacle%gap < -max_penetration*p%mesh%lengths(3)) &
      call fail('obstacle', 'gap', 'the obstacle must not start deeper inside the body than 0.1 times '// &
                'its height &mesh lengths(3)', reals([p%obstacle%gap]))
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
    if (status == 0) call check_obstacle_axis(p, status, msg)

  contains

    subroutine fail(group, variable, rule, got)
      character(len=*), intent(in) :: group, variable, rule, got
      if (status /= 0) return
      status = 1
      msg = refusal(p, group, variable, rule, got)
    end subroutine fail
  end subroutine check_across_groups

  !> A symmetry plane must contain the sphere's axis (&obstacle axis): a plane
  !> off the axis models the mirror image of the obstacle on its other side,
  !> which only &obstacle mirror_images = .true. accepts.
  subroutine check_obstacle_axis(p, status, msg)
    type(params_t), intent(in) :: p
    integer, intent(inout) :: status
    character(len=*), intent(inout) :: msg
    real(dp) :: c(2)
    integer :: d
    character(len=*), parameter :: plane(2) = ['symmetry_x0', 'symmetry_y0'], xy(2) = ['x', 'y']
    logical :: on(2)
    if (p%obstacle%shape /= 'sphere' .or. p%obstacle%mirror_images) return
    c = p%obstacle%centre_of(p%mesh%lengths)
    on = [p%boundary%symmetry_x0, p%boundary%symmetry_y0]
    do d = 1, 2
      if (.not. on(d) .or. c(d) == 0) cycle
      status = 1
      write (msg, '(a,i0,a,es10.3,a)') 'file '//trim(p%file)//', group &boundary, variable '//plane(d)// &
        ': the symmetry plane '//xy(d)//' = 0 does not contain the obstacle''s axis (&obstacle axis(', d, &
        ') = ', c(d), '; the default is the face centre): put the sphere on the plane (&obstacle axis('// &
        achar(48 + d)//') = 0.0) or, if mirror images of the obstacle are meant, set &obstacle '// &
        'mirror_images = .true.'
      return
    end do
  end subroutine check_obstacle_axis

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
      if (o%shape /= 'none' .and. b%top_dirichlet .and. b%top_displacement(3) > 0) then
        write (line, '(a,sp,es10.3,a)') '&boundary top_displacement(3) = ', b%top_displacement(3), &
          ' moves the top face upward, away from the obstacle: a sign error? (pressing the body onto '// &
          'the obstacle needs a negative value, e.g. -0.005)'
        w = [character(len=msg_len) :: w, line]
      else if (o%shape /= 'none' .and. b%top_dirichlet .and. o%gap > -b%top_displacement(3)) then
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
    character(len=240) :: reason
    if (.not. all(p%mesh%cluster == 0)) return
    p%mesh%cluster = auto_cluster(p, nranks, reason)
    p%mesh%cluster_auto = .true.
    p%mesh%cluster_choice = reason
  end subroutine resolve_cluster

  !> The automatic choice of hybrid TFETI clusters (docs/INPUT.md `cluster`,
  !> docs/THEORY.md "Automatic choice of clusters"): plain TFETI or clusters
  !> glued by faces, whichever a cost model of the run finds cheaper. N
  !> subdomains of n dofs in N_u units (subdomains or clusters) of n_u dofs,
  !> H/h = the elements along a unit's longest edge:
  !>   k = c_k (H/h)^e                                    (Hessian products)
  !>   T = N n k (v + a n_u^(1/3)) + k b (6 N_u)^(4/3) + cf (6 N_u)^2
  !> (per product: vector work on every dof, a sparse solve per unit, a
  !> coarse solve with the polish's face solves; once, G G^T's factorization;
  !> the constants fitted by tools/cluster_model_fit.py on 2 ranks).
  !> Candidates: clusters of k subdomains per direction (1 where k does not
  !> divide nsub_d), k = 2 .. 4, with at least `clusters_per_rank` clusters
  !> per rank; clusters are chosen when the cheapest candidate costs at most
  !> `margin` times plain TFETI and there are at least `min_subdomains`
  !> subdomains (below, the coarse problem costs too little to pay for
  !> anything). [1, 1, 1] whenever a requirement fails; `reason` gives the
  !> model's inputs and verdict.
  function auto_cluster(p, nranks, reason) result(c)
    type(params_t), intent(in) :: p
    integer, intent(in) :: nranks
    character(len=*), intent(out) :: reason
    integer(ip) :: c(3)
    integer(ip), parameter :: min_subdomains = 512, clusters_per_rank = 4, max_edge = 4
    !> the chosen clusters' cost at most this fraction of plain TFETI's (the model's error)
    real(dp), parameter :: margin = 0.9_dp
    integer(ip) :: k, t(3)
    real(dp) :: plain, best, cost
    c = 1
    associate (nsub => p%mesh%nsub, nel => p%mesh%nel)
      plain = run_cost(int(product(int(nsub, i8)), i8), [1_ip, 1_ip, 1_ip])
      best = huge(1.0_dp)
      do k = 2, max_edge
        t = merge(k, 1_ip, mod(nsub, k) == 0)
        if (all(t == 1)) cycle
        if (product(int(nsub/t, i8)) < int(clusters_per_rank, i8)*nranks) cycle
        cost = run_cost(product(int(nsub/t, i8)), t)
        if (cost < best) then
          best = cost
          c = t
        end if
      end do
      if (p%mesh%decomposition /= 'box') then
        c = 1
        reason = "plain TFETI: clusters need decomposition = 'box'"
      else if (p%solver%f_action%f_action == 'explicit') then
        c = 1
        reason = "plain TFETI: clusters do not take &solver f_action = 'explicit'"
      else if (p%solver%local%local_solver == 'dense') then
        c = 1
        reason = "plain TFETI: clusters do not take &solver local_solver = 'dense'"
      else if (all(c == 1)) then
        reason = 'plain TFETI: no cluster size divides nsub with enough clusters per rank'
      else if (product(int(nsub, i8)) < min_subdomains .or. best > margin*plain) then
        reason = 'plain TFETI: cost model '//trim(adjustl(model_line(plain, best, c)))
        c = 1
      else
        reason = 'clusters glued by faces: cost model '//trim(adjustl(model_line(plain, best, c)))
      end if
    end associate
  contains
    !> The model's cost [s] of `nunits` units of t(1) x t(2) x t(3) subdomains.
    real(dp) function run_cost(nunits, t)
      integer(i8), intent(in) :: nunits
      integer(ip), intent(in) :: t(3)
      real(dp), parameter :: c_k = 5.65_dp, e = 0.653_dp
      real(dp), parameter :: v = 7.9e-8_dp, a = 2.0e-9_dp, b = 2.08e-7_dp, cf = 1.53e-9_dp
      real(dp) :: dofs, unit_dofs, hh, products, coarse_rows
      dofs = 3*product(real(p%mesh%nel + 1, dp))*product(real(p%mesh%nsub, dp))
      unit_dofs = 3*real(product(t), dp)*product(real(p%mesh%nel + 1, dp))
      hh = real(maxval(p%mesh%nel*t), dp)
      products = c_k*hh**e
      coarse_rows = 6.0_dp*real(nunits, dp)
      run_cost = dofs*products*(v + a*unit_dofs**(1.0_dp/3)) + products*b*coarse_rows**(4.0_dp/3) &
                 + cf*coarse_rows**2
    end function run_cost

    !> The model's verdict in one line.
    function model_line(plain, best, t) result(line)
      real(dp), intent(in) :: plain, best
      integer(ip), intent(in) :: t(3)
      character(len=200) :: line
      write (line, '(a,es8.2,a,3(i0,a),es8.2,a,i0,a,i0,a,f4.2,a,i0,a)') 'plain ', plain, ' s, clusters ', t(1), 'x', &
        t(2), 'x', t(3), ' ', best, ' s (', product(int(p%mesh%nsub, i8)), ' subdomains, H/h = ', &
        maxval(p%mesh%nel), ', clusters if <= ', margin, ' x plain, >= ', min_subdomains, ' subdomains)'
    end function model_line
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
