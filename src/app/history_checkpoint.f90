!> The checkpoint of a load history: after a step, each rank writes the
!> state the next step starts from (lambda of its owned rows, the SMALBE
!> multiplier of its coarse blocks, whether 'auto' switched to 'dirichlet',
!> the face CG directions kept for the next face solves),
!> the number of the step done and the records of the steps so far, with a
!> fingerprint of the input and the mesh, to <base>.<rank> (unformatted
!> stream). Reading refuses a file that is missing, not a checkpoint, of
!> another input or mesh, of another number of ranks, or of another step
!> than the other ranks' files; the caller agrees on the answer over ranks.
module history_checkpoint
  use kinds, only: dp, ip, i8
  use text, only: str
  use face_recycle, only: face_recycle_t
  implicit none
  private

  public :: write_checkpoint, read_checkpoint, text_hash

  character(len=8), parameter :: magic = 'FCHIST03'

  !> What a step reports (the log line, report.json's `history`).
  type, public :: step_record_t
    integer(ip) :: step = 0
    real(dp) :: factor = 0, gap = 0
    real(dp) :: total_force = 0, max_pressure = 0, contact_radius = 0
    integer(ip) :: active_nodes = 0, outer = 0, hessian = 0
    !> the start of the solve: 0 cold (zero), 1 the previous step's solution, 2 that scaled by the
    !> ratio of the load factors, 3 extrapolated linearly in the load factor from the two previous steps
    integer(ip) :: warm = 0
    !> face solves of the step on the face before (its matrices reused), kept CG directions its
    !> face solves started from (Galerkin starts)
    integer(ip) :: faces_reused = 0, recycled = 0
    !> seconds (max over ranks): right-hand sides, solve, rec new, rec standard, primal, KKT, the whole step
    real(dp) :: seconds(7) = 0
    real(dp) :: kkt_worst = 0
    real(dp) :: alpha_difference = -1
    integer(ip) :: converged = 0, kkt_passed = 0
  end type step_record_t

  !> The solutions of the last two steps (column 1 the last) that the next
  !> step starts from (load_history's warm start).
  type, public :: warm_state_t
    integer(ip) :: n = 0                          !< steps held (0, 1, 2)
    real(dp) :: factor(2) = 0, gap(2) = 0
    real(dp), allocatable :: lambda(:, :), muhat(:, :)
  end type warm_state_t

  type, public :: checkpoint_t
    integer(i8) :: fingerprint(2) = 0
    integer(ip) :: step = 0                       !< the last step done
    integer(ip) :: switched = 0                   !< 1: 'auto' preconditioner switched to 'dirichlet'
    type(warm_state_t) :: warm
    type(step_record_t), allocatable :: records(:)
  end type checkpoint_t

contains

  !> Write `ck` and `recycle` of this rank (`rank` of `nranks`) to <base>.<rank>.
  !> `status` /= 0 with `msg` on an I/O error.
  subroutine write_checkpoint(base, rank, nranks, ck, recycle, status, msg)
    character(len=*), intent(in) :: base
    integer, intent(in) :: rank, nranks
    type(checkpoint_t), intent(in) :: ck
    type(face_recycle_t), intent(in) :: recycle     !< the face CG directions kept (warm starts)
    integer, intent(out) :: status
    character(len=*), intent(out) :: msg
    integer :: u
    msg = ''
    open (newunit=u, file=rank_file(base, rank), access='stream', form='unformatted', status='replace', &
          action='write', iostat=status, iomsg=msg)
    if (status /= 0) return
    write (u, iostat=status, iomsg=msg) magic, ck%fingerprint, int(nranks, ip), int(rank, ip), ck%step, &
      ck%switched, size(ck%warm%lambda, 1, kind=ip), size(ck%warm%muhat, 1, kind=ip), size(ck%records, kind=ip), &
      ck%warm%n, ck%warm%factor, ck%warm%gap, ck%warm%lambda, ck%warm%muhat, ck%records
    if (status /= 0) return
    call recycle%write_state(u, status, msg)
    if (status /= 0) return
    close (u, iostat=status, iomsg=msg)
  end subroutine write_checkpoint

  !> Read <base>.<rank> into `ck` and check it against `fingerprint`,
  !> `nranks` and the sizes `n_lambda`, `n_mu` of this run. `status` /= 0
  !> with a message naming the file and the reason otherwise.
  subroutine read_checkpoint(base, rank, nranks, fingerprint, n_lambda, n_mu, ck, recycle, status, msg)
    character(len=*), intent(in) :: base
    integer, intent(in) :: rank, nranks
    integer(i8), intent(in) :: fingerprint(2)
    integer(ip), intent(in) :: n_lambda, n_mu
    type(checkpoint_t), intent(out) :: ck
    type(face_recycle_t), intent(inout) :: recycle
    integer, intent(out) :: status
    character(len=*), intent(out) :: msg
    character(len=8) :: tag
    character(len=:), allocatable :: file
    integer(ip) :: file_ranks, file_rank, nl, nm, nr
    integer :: u, ios
    logical :: exists
    file = rank_file(base, rank)
    msg = ''
    inquire (file=file, exist=exists)
    if (.not. exists) then
      status = 1
      msg = 'checkpoint '//file//' does not exist (run the history without restart first)'
      return
    end if
    open (newunit=u, file=file, access='stream', form='unformatted', status='old', action='read', &
          iostat=status, iomsg=msg)
    if (status /= 0) then
      msg = 'cannot open checkpoint '//file//': '//trim(msg)
      return
    end if
    tag = ''
    read (u, iostat=ios) tag
    if (ios /= 0 .or. tag /= magic) then
      status = 1
      msg = 'checkpoint '//file//' is not a feticontact history checkpoint (unreadable or of another version)'
      close (u)
      return
    end if
    read (u, iostat=ios) ck%fingerprint, file_ranks, file_rank, ck%step, ck%switched, nl, nm, nr
    status = 1
    if (ios /= 0) then
      msg = 'checkpoint '//file//' is truncated (unreadable header)'
    else if (any(ck%fingerprint /= fingerprint)) then
      msg = 'checkpoint '//file//' belongs to another input or mesh (its fingerprint differs from this run''s)'
    else if (file_ranks /= nranks .or. file_rank /= rank) then
      msg = 'checkpoint '//file//' was written by rank '//str(file_rank)//' of '//str(file_ranks)// &
            ' ranks; restart on the same number of ranks'
    else if (nl /= n_lambda .or. nm /= n_mu .or. nr < 1 .or. ck%step < 1 .or. nr /= ck%step) then
      msg = 'checkpoint '//file//' has sizes that do not fit this run'
    else
      allocate (ck%warm%lambda(nl, 2), ck%warm%muhat(nm, 2), ck%records(nr))
      read (u, iostat=ios) ck%warm%n, ck%warm%factor, ck%warm%gap, ck%warm%lambda, ck%warm%muhat, ck%records
      if (ios == 0) call recycle%read_state(u, nl, ios)
      if (ios /= 0) then
        msg = 'checkpoint '//file//' is truncated (unreadable data)'
      else
        status = 0
      end if
    end if
    close (u)
  end subroutine read_checkpoint

  !> Two independent 31-bit polynomial hashes of `text` (a fingerprint; no
  !> integer overflow).
  pure function text_hash(text) result(h)
    character(len=*), intent(in) :: text
    integer(i8) :: h(2)
    integer(i8), parameter :: prime = 2147483647_i8
    integer :: i
    h = [7_i8, 11_i8]
    do i = 1, len(text)
      h(1) = mod(h(1)*131_i8 + iachar(text(i:i)), prime)
      h(2) = mod(h(2)*257_i8 + iachar(text(i:i)) + 1, prime)
    end do
  end function text_hash

  function rank_file(base, rank) result(file)
    character(len=*), intent(in) :: base
    integer, intent(in) :: rank
    character(len=:), allocatable :: file
    file = trim(base)//'.'//str(int(rank, ip))
  end function rank_file
end module history_checkpoint
