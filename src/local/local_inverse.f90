!> The generalized inverse K^+ of all the subdomains of one rank, as the FETI
!> operators see it: one in-place solve on the concatenated vector of the
!> rank's subdomains (in the order of their offsets). Extended by
!> kplus_block_t (one block-diagonal factorization, the default) and
!> kplus_set_t (one factorization per subdomain); `&solver local_solver`
!> chooses (see f_operator%init).
module local_inverse
  use kinds, only: dp, i8
  use subdomain, only: subdomain_t
  implicit none
  private

  type, abstract, public :: local_inverse_t
  contains
    procedure(init_iface), deferred :: init
    procedure(solve_iface), deferred :: solve
    procedure(bytes_iface), deferred :: factor_bytes
    procedure(flops_iface), deferred :: factor_flops
    procedure(free_iface), deferred :: free
  end type local_inverse_t

  abstract interface
    !> Factorize K_reg of every subdomain in `subs` (which hold K and R);
    !> `regularization` is rho_f relative to the mean diagonal of K,
    !> `ordering` 'amd' or 'metis'.
    subroutine init_iface(this, subs, regularization, ordering)
      import :: local_inverse_t, subdomain_t, dp
      class(local_inverse_t), intent(inout) :: this
      type(subdomain_t), intent(in) :: subs(:)
      real(dp), intent(in) :: regularization
      character(len=*), intent(in) :: ordering
    end subroutine init_iface

    !> x <- K^+ x for the concatenated vector of all the subdomains.
    subroutine solve_iface(this, x)
      import :: local_inverse_t, dp
      class(local_inverse_t), intent(inout) :: this
      real(dp), intent(inout) :: x(:)
    end subroutine solve_iface

    !> Bytes of the factors.
    integer(i8) function bytes_iface(this)
      import :: local_inverse_t, i8
      class(local_inverse_t), intent(in) :: this
    end function bytes_iface

    !> Floating-point operations of the factorizations (MUMPS's count).
    real(dp) function flops_iface(this)
      import :: local_inverse_t, dp
      class(local_inverse_t), intent(in) :: this
    end function flops_iface

    !> Release the factorizations; safe on a never initialized object.
    subroutine free_iface(this)
      import :: local_inverse_t
      class(local_inverse_t), intent(inout) :: this
    end subroutine free_iface
  end interface
end module local_inverse
