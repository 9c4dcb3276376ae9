!> The face solver of a QP with an equality constraint (qp_problem), an
!> optional part of the problem (`qp_problem_t%face`) that SMALBE's polish
!> uses: C restricted to the free rows F of an active set.
!> - `init(free, reused)` prepares C_F C_F^T (free: the local mask of F;
!>   `reused`: the last face's matrices were those and are kept), `release()`
!>   lets it go;
!> - `coefficient(y, c)` gives the multiplier-form coefficients c (length
!>   eq%size(), the form eq%apply_t takes) of the least squares fit
!>   (C_F C_F^T)^{-1} C y, so that the face projector onto
!>   {y : y_A = 0, C y = 0} reads P_F y = y_F - (eq%apply_t(c))_F for c of
!>   y_F (face_solve);
!> - `apply(p, q)`: q = A p for p on the face (C p = 0, p_A = 0) (the
!>   Hessian, or what a problem saves there);
!> - `precondition(prec, r, z)`: used only as P_F z, an SPD preconditioner on
!>   the face (default: the problem's preconditioner `prec`);
!> - `regular()`: the equality rows alone give a regular C_E C_E^T (then
!>   every C_F C_F^T is regular, and the polish may start from the face with
!>   every bounded row at its bound); false by default;
!> - a lazy face operator: a face whose `lazy()` is true gives by
!>   `apply_lazy(p, q)` A p plus some vector C^T c of the range of C^T
!>   (cheaper: the FETI dual skips its projector), and by
!>   `range_coefficient(y, c)` the coefficients of the orthogonal projection
!>   of y onto that range, (C C^T)^{-1} C y in the form eq%apply_t takes; the
!>   face solve then carries the extra terms in its gradient (P_F removes
!>   them) and takes them out every few steps and at the end (face_solve's
!>   fold).
!> Every procedure is collective unless stated otherwise.
module qp_face
  use kinds, only: dp
  use errors, only: fatal_error
  use qp_preconditioner, only: qp_preconditioner_t
  implicit none
  private

  type, abstract, public :: qp_face_t
  contains
    procedure(init_iface), deferred :: init
    procedure(vector_iface), deferred :: coefficient
    procedure(vector_iface), deferred :: apply
    procedure :: release => default_release
    procedure :: precondition => default_precondition
    procedure :: regular => default_regular
    procedure :: lazy => default_lazy
    procedure :: apply_lazy => default_apply_lazy
    procedure :: range_coefficient => default_range_coefficient
  end type qp_face_t

  abstract interface
    !> Prepare C_F C_F^T for the free rows `free` (local mask).
    subroutine init_iface(self, free, reused)
      import :: qp_face_t
      class(qp_face_t), intent(inout) :: self
      logical, intent(in) :: free(:)
      logical, intent(out), optional :: reused
    end subroutine init_iface

    !> A vector of the face's (coefficient: c = (C_F C_F^T)^{-1} C y;
    !> apply: q = A p on the face).
    subroutine vector_iface(self, x, y)
      import :: qp_face_t, dp
      class(qp_face_t), intent(inout) :: self
      real(dp), intent(in) :: x(:)
      real(dp), intent(out) :: y(:)
    end subroutine vector_iface
  end interface

contains

  !> Release what init prepared (nothing by default).
  subroutine default_release(self)
    class(qp_face_t), intent(inout) :: self
  end subroutine default_release

  !> The face's preconditioner before P_F: the problem's by default.
  subroutine default_precondition(self, prec, r, z)
    class(qp_face_t), intent(inout) :: self
    class(qp_preconditioner_t), intent(inout) :: prec
    real(dp), intent(in) :: r(:)
    real(dp), intent(out) :: z(:)
    call prec%apply(r, z)
  end subroutine default_precondition

  !> False: C_F C_F^T may be singular when every bounded row is at its bound. Local.
  logical function default_regular(self)
    class(qp_face_t), intent(in) :: self
    default_regular = .false.
  end function default_regular

  !> apply_lazy leaves a term in the range of C^T: not by default. Local.
  logical function default_lazy(self)
    class(qp_face_t), intent(in) :: self
    default_lazy = .false.
  end function default_lazy

  !> q = A p (+ a term C^T c) for p on the face: apply by default.
  subroutine default_apply_lazy(self, p, q)
    class(qp_face_t), intent(inout) :: self
    real(dp), intent(in) :: p(:)
    real(dp), intent(out) :: q(:)
    call self%apply(p, q)
  end subroutine default_apply_lazy

  !> c = (C C^T)^{-1} C y: needed only by a face whose lazy() is true.
  subroutine default_range_coefficient(self, y, c)
    class(qp_face_t), intent(inout) :: self
    real(dp), intent(in) :: y(:)
    real(dp), intent(out) :: c(:)
    c = 0
    call fatal_error('qp_face: range_coefficient not provided by this face (lazy() is false)')
  end subroutine default_range_coefficient
end module qp_face
