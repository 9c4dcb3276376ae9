!> The threads of the BLAS: one per MPI rank unless the user asks otherwise.
!>
!> Several ranks share the cores of a node, and a threaded BLAS (Debian's
!> libopenblas0-pthread, which becomes the libblas.so.3 alternative when it is
!> installed) would start one thread per core in every rank: MUMPS then runs
!> ranks x cores threads on the cores. `blas_threads_setup`, called once right
!> after MPI_Init, finds out at run time which BLAS the loader gave the
!> process (through blas_threads_c.c: dlsym of each library's own thread
!> controls, dladdr of dgemm_; no link-time dependency on any of them) and
!> sets its thread count by this policy:
!>   1. the environment variable FETICONTACT_BLAS_THREADS (a positive integer),
!>      else
!>   2. the library's own variable (OPENBLAS_NUM_THREADS, GOTO_NUM_THREADS,
!>      BLIS_NUM_THREADS, MKL_NUM_THREADS) or OMP_NUM_THREADS when the user set
!>      one: the library already read it, it is left alone, else
!>   3. one thread per rank.
!> The count reported is the one the library answers after that (a sequential
!> build answers 1 whatever is asked).
!>
!> Before that, and before any BLAS call, an OpenBLAS that fell back to its
!> generic kernels ("Prescott": the CPU model is newer than the library, as
!> Debian 12's 0.3.21 on Intel's Emerald Rapids) on a CPU with AVX2 and FMA
!> chooses its kernels again, SkylakeX or Haswell by what the CPU has
!> (fc_openblas_core in blas_threads_c.c); the user's OPENBLAS_CORETYPE is
!> never overridden. The log line and report.json say which kernels run.
module blas_threads
  use, intrinsic :: iso_c_binding, only: c_int, c_char, c_null_char
  use kinds, only: path_len
  use errors, only: collective_error, exit_input_error
  use mpi_f08, only: MPI_Comm, MPI_Allreduce, MPI_IN_PLACE, MPI_INTEGER, MPI_LOGICAL, MPI_LAND, MPI_MAX, &
                     MPI_MIN
  implicit none
  private

  public :: blas_threads_setup, blas_in_use, blas_log_line

  character(len=*), parameter, public :: blas_threads_variable = 'FETICONTACT_BLAS_THREADS'
  integer, parameter :: max_threads = 4096    !< a larger request is a typing error

  !> What `blas_threads_setup` found and did.
  type, public :: blas_info_t
    character(len=512) :: library = 'not set up'   !< e.g. 'OpenBLAS 0.3.21 (pthread)'
    character(len=path_len) :: path = 'unknown'   !< the file that provides dgemm_
    character(len=32) :: source = 'none'           !< 'default', 'FETICONTACT_BLAS_THREADS', 'OPENBLAS_NUM_THREADS', ...
    integer :: threads = 1         !< threads per rank the library will use (max over the ranks)
    integer :: requested = 1       !< threads per rank asked by the source
    logical :: settable = .false.  !< the library can run more than one thread
    logical :: uniform = .true.    !< every rank has the same thread count
    character(len=32) :: core = ''          !< OpenBLAS's kernel table ('' for another BLAS), e.g. 'SkylakeX'
    character(len=32) :: core_before = ''   !< the table OpenBLAS chose itself, when it was chosen again
  end type blas_info_t

  ! the kinds of BLAS of blas_threads_c.c (0: reference or unknown)
  integer(c_int), parameter :: kind_openblas = 1, kind_blis = 2, kind_mkl = 3

  interface
    integer(c_int) function fc_blas_owner_kind() bind(C, name='fc_blas_owner_kind')
      import :: c_int
    end function fc_blas_owner_kind
    integer(c_int) function fc_blas_kinds() bind(C, name='fc_blas_kinds')
      import :: c_int
    end function fc_blas_kinds
    subroutine fc_blas_describe(kind, name, name_len, threaded) bind(C, name='fc_blas_describe')
      import :: c_int, c_char
      integer(c_int), value :: kind
      character(kind=c_char), intent(out) :: name(*)
      integer(c_int), value :: name_len
      integer(c_int), intent(out) :: threaded
    end subroutine fc_blas_describe
    subroutine fc_blas_path(path, path_len) bind(C, name='fc_blas_path')
      import :: c_int, c_char
      character(kind=c_char), intent(out) :: path(*)
      integer(c_int), value :: path_len
    end subroutine fc_blas_path
    integer(c_int) function fc_blas_get_threads(kind) bind(C, name='fc_blas_get_threads')
      import :: c_int
      integer(c_int), value :: kind
    end function fc_blas_get_threads
    integer(c_int) function fc_openblas_core(before, before_len, after, after_len) bind(C, name='fc_openblas_core')
      import :: c_int, c_char
      character(kind=c_char), intent(out) :: before(*), after(*)
      integer(c_int), value :: before_len, after_len
    end function fc_openblas_core
    subroutine fc_blas_set_threads(kind, n) bind(C, name='fc_blas_set_threads')
      import :: c_int
      integer(c_int), value :: kind, n
    end subroutine fc_blas_set_threads
  end interface

  type(blas_info_t), save :: info

contains

  !> Find the BLAS and set its threads (see the module). Collective on `comm`:
  !> an invalid FETICONTACT_BLAS_THREADS on any rank ends every rank with
  !> exit status 2 and a message naming the variable.
  subroutine blas_threads_setup(comm)
    type(MPI_Comm), intent(in) :: comm
    character(len=64) :: value
    character(len=:), allocatable :: text, user_variable, library
    character(kind=c_char, len=32) :: core_before, core_after
    integer(c_int) :: owner, mask, k, threaded, switched
    integer :: requested, counts(2), ierr
    logical :: valid, given

    ! 1. FETICONTACT_BLAS_THREADS, checked on every rank before anything else
    call read_request(value, given, valid, requested)
    call MPI_Allreduce(MPI_IN_PLACE, valid, 1, MPI_LOGICAL, MPI_LAND, comm, ierr)
    if (.not. valid) then
      if (given .and. requested < 0) then
        text = "environment variable "//blas_threads_variable//"='"//trim(value)//"'"
      else
        text = 'environment variable '//blas_threads_variable//' (on another rank)'
      end if
      call collective_error(text//' is not a positive integer <= 4096: give the number of BLAS threads '// &
                            'per MPI rank (for example 1), or unset it for 1 thread per rank', comm, exit_input_error)
    end if

    ! 2. the library that provides dgemm_, and every thread control in the process
    owner = fc_blas_owner_kind()
    mask = fc_blas_kinds()
    info%core = ''
    info%core_before = ''
    if (btest(mask, kind_openblas)) then          ! before any BLAS call: the kernels OpenBLAS runs
      core_before = c_null_char
      core_after = c_null_char
      switched = fc_openblas_core(core_before, int(len(core_before), c_int), core_after, int(len(core_after), c_int))
      info%core = c_text(core_after)
      if (switched /= 0) info%core_before = c_text(core_before)
    end if
    library = c_text(describe(owner, threaded))
    info%settable = threaded /= 0
    do k = kind_openblas, kind_mkl
      if (k == owner .or. .not. btest(mask, k)) cycle
      library = library//' (also in the process: '//c_text(describe(k, threaded))//')'
      info%settable = info%settable .or. threaded /= 0
    end do
    info%library = library
    info%path = c_text(library_path())
    if (given) then
      info%source = blas_threads_variable
      info%requested = requested
      call set_threads(mask, requested)
    else
      user_variable = user_thread_variable(mask)
      if (len(user_variable) > 0) then
        info%source = user_variable
        info%requested = -1                          ! the library's own reading of it
      else
        info%source = 'default'
        info%requested = 1
        call set_threads(mask, 1)
      end if
    end if
    counts = 1
    do k = kind_openblas, kind_mkl
      if (btest(mask, k)) counts(1) = max(counts(1), int(fc_blas_get_threads(k)))
    end do
    counts(2) = -counts(1)
    call MPI_Allreduce(MPI_IN_PLACE, counts, 2, MPI_INTEGER, MPI_MAX, comm, ierr)
    info%threads = counts(1)
    info%uniform = counts(1) == -counts(2)
    if (info%requested < 0) info%requested = info%threads
    call MPI_Allreduce(MPI_IN_PLACE, info%requested, 1, MPI_INTEGER, MPI_MIN, comm, ierr)
  end subroutine blas_threads_setup

  !> What the last `blas_threads_setup` found (library 'not set up' before it).
  function blas_in_use() result(b)
    type(blas_info_t) :: b
    b = info
  end function blas_in_use

  !> One line for the log, e.g. 'BLAS: OpenBLAS 0.3.21 (pthread) /usr/lib/x86_64-linux-gnu/openblas-pthread/
  !> libblas.so.3, 1 thread per rank (default; FETICONTACT_BLAS_THREADS overrides)'.
  function blas_log_line() result(line)
    character(len=:), allocatable :: line
    type(blas_info_t) :: b
    character(len=16) :: n
    b = blas_in_use()
    write (n, '(i0)') b%threads
    line = 'BLAS: '//trim(b%library)//' '//trim(b%path)//', '//trim(n)//' thread'
    if (b%threads /= 1) line = line//'s'
    if (.not. b%uniform) line = line//' (the most of any rank)'
    line = line//' per rank ('
    select case (trim(b%source))
    case ('default')
      line = line//'default'
    case (blas_threads_variable)
      line = line//'from '//blas_threads_variable
    case default
      line = line//'from '//trim(b%source)//' in the environment'
    end select
    if (b%requested /= b%threads) then
      write (n, '(i0)') b%requested
      if (b%settable) then
        line = line//', '//trim(n)//' asked: the library allows fewer'
      else
        line = line//', '//trim(n)//' asked: this BLAS is single-threaded'
      end if
    end if
    if (b%source /= blas_threads_variable) line = line//'; '//blas_threads_variable//' overrides'
    line = line//')'
    if (len_trim(b%core) > 0) then
      line = line//', kernels '//trim(b%core)
      if (len_trim(b%core_before) > 0) line = line//' (OpenBLAS chose its generic '//trim(b%core_before)// &
                                          ' kernels for this CPU, which it does not know; chosen again by the '// &
                                          "CPU's instruction sets; OPENBLAS_CORETYPE overrides)"
    end if
  end function blas_log_line

  ! ---- helpers ----

  !> FETICONTACT_BLAS_THREADS: `given` when set and not empty; `valid` when
  !> not given or a positive integer <= max_threads (then `requested`; -1 if
  !> given and invalid).
  subroutine read_request(value, given, valid, requested)
    character(len=*), intent(out) :: value
    logical, intent(out) :: given, valid
    integer, intent(out) :: requested
    integer :: length, status, iostat

    value = ''
    requested = -1
    call get_environment_variable(blas_threads_variable, value, length, status)
    given = status /= 1 .and. length > 0
    valid = .not. given
    if (.not. given) return
    if (status /= 0) then                              ! longer than value: not a thread count
      value = value(1:len(value) - 3)//'...'
      return
    end if
    value = adjustl(value)
    ! digits only, at most 9 of them (no sign, no blanks inside, no overflow)
    if (verify(trim(value), '0123456789') /= 0 .or. len_trim(value) > 9) return
    read (value, *, iostat=iostat) requested
    if (iostat /= 0 .or. requested < 1 .or. requested > max_threads) then
      requested = -1
    else
      valid = .true.
    end if
  end subroutine read_request

  !> Set `n` threads in each library of `mask` (bit k: a library of kind k).
  subroutine set_threads(mask, n)
    integer(c_int), intent(in) :: mask
    integer, intent(in) :: n
    integer(c_int) :: k
    do k = kind_openblas, kind_mkl
      if (btest(mask, k)) call fc_blas_set_threads(k, int(n, c_int))
    end do
  end subroutine set_threads

  !> The first thread variable read by a library of `mask` (its own, then
  !> OMP_NUM_THREADS) that is set and not empty, or ''.
  function user_thread_variable(mask) result(name)
    integer(c_int), intent(in) :: mask
    character(len=:), allocatable :: name
    character(len=24), parameter :: names(5) = [character(len=24) :: 'OPENBLAS_NUM_THREADS', 'GOTO_NUM_THREADS', &
                                                'BLIS_NUM_THREADS', 'MKL_NUM_THREADS', 'OMP_NUM_THREADS']
    integer(c_int), parameter :: read_by(5) = [kind_openblas, kind_openblas, kind_blis, kind_mkl, -1_c_int]
    integer :: i, length, status

    name = ''
    do i = 1, size(names)
      if (read_by(i) >= 0) then
        if (.not. btest(mask, read_by(i))) cycle
      else if (mask == 0) then
        cycle
      end if
      call get_environment_variable(trim(names(i)), length=length, status=status)
      if (status /= 1 .and. length > 0) then
        name = trim(names(i))
        return
      end if
    end do
  end function user_thread_variable

  !> Name of the BLAS of `kind` as C text; `threaded` from fc_blas_describe.
  function describe(kind, threaded) result(buffer)
    integer(c_int), intent(in) :: kind
    integer(c_int), intent(out) :: threaded
    character(kind=c_char, len=512) :: buffer
    buffer = c_null_char
    call fc_blas_describe(kind, buffer, int(len(buffer), c_int), threaded)
  end function describe

  !> The file of the BLAS as C text.
  function library_path() result(buffer)
    character(kind=c_char, len=path_len) :: buffer
    buffer = c_null_char
    call fc_blas_path(buffer, int(len(buffer), c_int))
  end function library_path

  !> The text of a NUL-terminated C string in `buffer`, trimmed.
  function c_text(buffer) result(text)
    character(kind=c_char, len=*), intent(in) :: buffer
    character(len=:), allocatable :: text
    integer :: n
    n = index(buffer, c_null_char) - 1
    if (n < 0) n = len(buffer)
    text = trim(buffer(1:n))
  end function c_text
end module blas_threads
