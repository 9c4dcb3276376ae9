!> F = B K^+ B^T, the dual operator of TFETI, with K^+ of the rank's
!> subdomains behind local_inverse_t (`&solver local_solver`: 'block', one
!> block-diagonal factorization, or 'subdomain', one per subdomain). B is
!> passed in: F owns only K^+ and its work vector. Timer 'F action'.
module f_operator
  use kinds, only: dp, ip, i8
  use errors, only: fatal_error
  use timers, only: timer_start, timer_stop
  use subdomain, only: subdomain_t
  use local_inverse, only: local_inverse_t
  use kplus_block, only: kplus_block_t
  use kplus_set, only: kplus_set_t
  use b_operator, only: b_operator_t
  implicit none
  private

  type, public :: f_operator_t
    private
    class(local_inverse_t), allocatable :: kinv   !< K^+ of all local subdomains
    real(dp), allocatable :: xall(:)              !< work: concatenated primal vector
    integer(i8) :: applications = 0
  contains
    procedure :: init
    procedure :: apply
    procedure :: local_solve
    procedure :: bytes_per_action
    procedure :: n_applications
    procedure :: free
  end type f_operator_t

contains

  !> Factorize K_reg of the local subdomains `subs` (K and R assembled) with
  !> `local_solver` 'block' or 'subdomain'; `n_concat`: length of their
  !> concatenated vector.
  subroutine init(this, subs, local_solver, regularization, ordering, n_concat)
    class(f_operator_t), intent(inout) :: this
    type(subdomain_t), intent(in) :: subs(:)
    character(len=*), intent(in) :: local_solver, ordering
    real(dp), intent(in) :: regularization
    integer(ip), intent(in) :: n_concat
    call this%free()
    if (local_solver == 'block') then
      allocate (kplus_block_t :: this%kinv)
    else
      allocate (kplus_set_t :: this%kinv)
    end if
    call this%kinv%init(subs, regularization, ordering)
    allocate (this%xall(n_concat))
  end subroutine init

  !> y = F x = B K^+ B^T x (dual vectors, owned rows).
  subroutine apply(this, b, x, y)
    class(f_operator_t), intent(inout) :: this
    type(b_operator_t), intent(inout) :: b
    real(dp), intent(in) :: x(:)
    real(dp), intent(inout) :: y(:)
    call timer_start('F action')
    this%xall = 0
    call b%add_transpose(x, 1.0_dp, this%xall)
    call this%kinv%solve(this%xall)
    call b%apply_concat(this%xall, y)
    this%applications = this%applications + 1
    call timer_stop('F action')
  end subroutine apply

  !> x <- K^+ x for the concatenated vector of all local subdomains.
  subroutine local_solve(this, x)
    class(f_operator_t), intent(inout) :: this
    real(dp), intent(inout) :: x(:)
    if (size(x) /= size(this%xall)) call fatal_error('f_operator%local_solve: x must have the length of '// &
                                                     'the concatenated local vectors')
    call this%kinv%solve(x)
  end subroutine local_solve

  !> Bytes one F action must read on this rank: the factors of K_reg twice
  !> (forward and backward substitution) and the entries of B twice (B^T,
  !> then B; 16 bytes each: value, row, dof). Vectors are not counted.
  integer(i8) function bytes_per_action(this, b)
    class(f_operator_t), intent(in) :: this
    type(b_operator_t), intent(in) :: b
    bytes_per_action = 2*this%kinv%factor_bytes() + 2*16*b%n_entries()
  end function bytes_per_action

  integer(i8) function n_applications(this)
    class(f_operator_t), intent(in) :: this
    n_applications = this%applications
  end function n_applications

  subroutine free(this)
    class(f_operator_t), intent(inout) :: this
    if (allocated(this%kinv)) then
      call this%kinv%free()
      deallocate (this%kinv)
    end if
    if (allocated(this%xall)) deallocate (this%xall)
    this%applications = 0
  end subroutine free
end module f_operator
