!> The solvers' monitor (`&solver monitor`), in the style of PETSc's
!> -ksp_monitor and PERMON's -qps_view_convergence: one line per step of the
!> loop that does the work, each with the Hessian multiplications so far, the
!> loop, the step, the measure its stopping test compares and that test's
!> target. Columns (docs/INPUT.md "The monitor"):
!>
!>     products  loop   step        measure    target  details
!>
!> - `outer`: one SMALBE outer iteration; measure and target those of the
!>   outer test's optimality part, details its feasibility part, rho and the
!>   dual rows at their bound;
!> - `mprgp`: a run of consecutive MPRGP steps of one kind (`cg(5)`: five CG
!>   steps, `expansion(1)`, `proportioning(1)`); measure ||g^P|| after the
!>   run, target the inner test's bound min(M ||C x||, eta) at its last
!>   evaluation of ||C x|| (eta before the first);
!> - `face`: one CG step of a polish face solve (step `p.r.k`: polish p,
!>   round r, step k; polish 0 is the polish first); measure the residual of
!>   the face problem, target the face solve's;
!> - `round`: one face solve of a polish (an active-set round, step `p.r`):
!>   its residual, and the rows it would change (projected, wrong sign) and
!>   what the polish does with them.
!> Lines are written on rank 0 only (module logger); the callers pass values
!> that are the same on every rank.
module solver_monitor
  use kinds, only: dp, ip
  use logger, only: log_message
  use text, only: str
  implicit none
  private

  !> MPRGP step kinds (the argument `kind` of inner_step; 0: none yet)
  integer, parameter, public :: step_none = 0, step_cg = 1, step_expansion = 2, step_proportioning = 3

  !> The monitor of one solve: on or off, the products before the current
  !> inner loop (its lines count from there), and the current run of MPRGP
  !> steps of one kind (flushed as one line when the kind changes).
  type, public :: solver_monitor_t
    logical :: on = .false.
    integer(ip) :: base = 0                  !< Hessian products before the current inner loop
    integer(ip) :: outer = 0                 !< the outer iteration whose inner loop runs
    integer(ip) :: polish = 0                !< the polish whose face solve runs (face lines)
    integer(ip) :: round = 0                 !< its round
    integer, private :: run_kind = step_none
    integer(ip), private :: run_count = 0
    integer(ip), private :: run_products = 0
    real(dp), private :: run_measure = 0, run_target = 0
  contains
    procedure :: legend
    procedure :: inner_step
    procedure :: inner_flush
    procedure :: outer_line
    procedure :: face_step
    procedure :: round_line
    procedure :: note
  end type solver_monitor_t

  !> products, loop, step (both left-aligned in character(len=6) and (len=18) variables), measure,
  !> target, details
  character(len=*), parameter :: line_format = '(i9,2x,a,1x,a,2es11.3,2x,a)'

contains

  !> The column heads, after the lines saying what measure and target are.
  subroutine legend(self, optimality, feasibility)
    class(solver_monitor_t), intent(in) :: self
    character(len=*), intent(in) :: optimality, feasibility
    character(len=200) :: buf
    if (.not. self%on) return
    call log_message('monitor: products = Hessian multiplications so far; measure/target: outer '// &
                     optimality//' (feasibility: '//feasibility//'),')
    call log_message('         mprgp ||g^P|| (inner bound min(M ||C x||, eta)), face/round the face residual')
    write (buf, '(a9,2x,a,1x,a,2a11,2x,a)') 'products', loop_name('loop'), step_name('step'), 'measure', 'target', &
      'details'
    call log_message(trim(buf))
  end subroutine legend

  !> After an MPRGP step of `kind` (step_cg, ...): `products` inner products so
  !> far, ||g^P|| = measure, the inner bound `target`. A run of one kind is
  !> written as one line when the next kind differs (or at inner_flush).
  subroutine inner_step(self, kind, products, measure, target)
    class(solver_monitor_t), intent(inout) :: self
    integer, intent(in) :: kind
    integer(ip), intent(in) :: products
    real(dp), intent(in) :: measure, target
    if (.not. self%on .or. kind == step_none) return
    if (kind /= self%run_kind) call self%inner_flush()
    self%run_kind = kind
    self%run_count = self%run_count + 1
    self%run_products = products
    self%run_measure = measure
    self%run_target = target
  end subroutine inner_step

  !> Write the current run of MPRGP steps (if any) as one line.
  subroutine inner_flush(self)
    class(solver_monitor_t), intent(inout) :: self
    character(len=200) :: buf
    character(len=:), allocatable :: step
    if (.not. self%on .or. self%run_count == 0) return
    select case (self%run_kind)
    case (step_cg)
      step = 'cg('//str(self%run_count)//')'
    case (step_expansion)
      step = 'expansion('//str(self%run_count)//')'
    case default
      step = 'proportioning('//str(self%run_count)//')'
    end select
    write (buf, line_format) self%base + self%run_products, loop_name('mprgp'), step_name(step), self%run_measure, &
      self%run_target, 'outer '//str(self%outer)
    call log_message(trim(buf))
    self%run_kind = step_none
    self%run_count = 0
  end subroutine inner_flush

  !> The line of outer iteration `outer`.
  subroutine outer_line(self, outer, products, measure, target, feasibility, feasibility_target, rho, at_bound)
    class(solver_monitor_t), intent(inout) :: self
    integer(ip), intent(in) :: outer, products, at_bound
    real(dp), intent(in) :: measure, target, feasibility, feasibility_target, rho
    character(len=200) :: buf, details
    if (.not. self%on) return
    call self%inner_flush()
    write (details, '(a,es10.3,a,es10.3,a,es10.3,a,i0)') 'feasibility ', feasibility, ' (target ', &
      feasibility_target, '), rho ', rho, ', at bound ', at_bound
    write (buf, line_format) products, loop_name('outer'), step_name(str(outer)), measure, target, trim(details)
    call log_message(trim(buf))
  end subroutine outer_line

  !> CG step `step` of the face solve of round self%round of polish self%polish
  !> (products: of this face solve so far).
  subroutine face_step(self, step, products, measure, target)
    class(solver_monitor_t), intent(in) :: self
    integer(ip), intent(in) :: step, products
    real(dp), intent(in) :: measure, target
    character(len=200) :: buf
    if (.not. self%on) return
    write (buf, line_format) self%base + products, loop_name('face'), &
      step_name(str(self%polish)//'.'//str(self%round)//'.'//str(step)), measure, target, ''
    call log_message(trim(buf))
  end subroutine face_step

  !> The end of round `round` of polish `polish`: its residual, and `details`.
  subroutine round_line(self, polish, round, products, measure, target, details)
    class(solver_monitor_t), intent(in) :: self
    integer(ip), intent(in) :: polish, round, products
    real(dp), intent(in) :: measure, target
    character(len=*), intent(in) :: details
    character(len=400) :: buf
    if (.not. self%on) return
    write (buf, line_format) products, loop_name('round'), step_name(str(polish)//'.'//str(round)), measure, target, &
      details
    call log_message(trim(buf))
  end subroutine round_line

  !> A remark between the lines (indented, no columns).
  subroutine note(self, text)
    class(solver_monitor_t), intent(in) :: self
    character(len=*), intent(in) :: text
    if (.not. self%on) return
    call log_message('         '//text)
  end subroutine note

  !> The loop's name in its column (left-aligned).
  pure function loop_name(name) result(column)
    character(len=*), intent(in) :: name
    character(len=6) :: column
    column = name
  end function loop_name

  !> A step's label in its column (left-aligned; a longer one widens its line).
  pure function step_name(name) result(column)
    character(len=*), intent(in) :: name
    character(len=max(18, len(name))) :: column
    column = name
  end function step_name

end module solver_monitor
