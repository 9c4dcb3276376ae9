!> The builder of the TFETI operators (submodule of feti_operators): the
!> set-up pipeline from the parameters to feti_t, one timer per phase:
!> 'mesh' (decomposition, subdomain geometry), 'assembly' (K^s, f^s, R^s),
!> 'factorization' (K^+, f_operator), 'B and G' (b_operator), 'coarse setup'
!> (G G^T, projector) and 'dual setup' (d, e, lambda~, ||P F P||).
submodule(feti_operators) feti_builder
  use timers, only: timer_start, timer_stop
  use memory_marks, only: memory_mark
  use kinds, only: MPI_INT_I8, MPI_INT_IP, MPI_REAL_DP
  use decomposition, only: build_decomposition
  use subdomain, only: build_subdomain
  use clusters, only: is_hybrid, merges_corners, unit_mesh, build_cluster
  use face_gluing, only: build_face_gluing
  use assembly, only: assemble_subdomain, assemble_stiffness
  use subdomain_classes, only: subdomain_classes_t, start_classes, add_congruent, add_to_classes, finish_classes
  use materials, only: subdomain_material
  use ritz_values, only: tridiagonal_extremes
  use constraints, only: row_dirichlet
  use lapack_interfaces, only: dsyev
  use mpi_f08, only: MPI_MAX
  implicit none

contains

  module subroutine setup(this, settings, comm, units)
    class(feti_t), intent(inout) :: this
    type(feti_settings_t), intent(in) :: settings
    type(MPI_Comm), intent(in) :: comm
    type(decomposition_t), intent(in), optional :: units
    integer(ip) :: ls, r(2)
    integer :: ierr
    integer(i8) :: mydofs
    type(subdomain_classes_t) :: classes

    call this%free()
    this%communicator = comm
    this%young_rows = settings%scaling%scaling == 'young'

    call timer_start('mesh')
    call build_units(this, settings, comm, units)
    call timer_stop('mesh')
    call memory_mark('mesh')

    call timer_start('assembly')
    call assemble_units(this, settings, classes)
    call timer_stop('assembly')
    call memory_mark('assembly')

    mydofs = sum(this%subs(:)%ndof)
    call timer_start('factorization')
    ! the ordering: `local_ordering = 'auto'` by the largest subdomain of the run (the same on every rank)
    block
      integer(i8) :: largest
      character(len=160) :: line
      largest = 0
      if (this%n_local_subs > 0) largest = maxval(this%subs(:)%ndof)
      call MPI_Allreduce(MPI_IN_PLACE, largest, 1, MPI_INT_I8, MPI_MAX, comm, ierr)
      this%ordering_used = local_ordering_for(settings%local%local_ordering, largest)
      this%solver_used = local_solver_for(settings%local%local_solver, largest, this%hybrid)
      ! the constrained solve of a cluster glued by faces is one kplus_t per cluster (or class)
      if (this%hybrid .and. .not. merges_corners(settings%mesh)) this%solver_used = 'subdomain'
      write (line, '(5a,i0,a)') 'local ordering (', trim(settings%local%local_ordering), '): ', &
        trim(this%ordering_used), ' (largest subdomain ', largest, ' dofs)'
      call log_message(trim(line))
    end block
    ! congruent clusters share K^+ like congruent subdomains (docs/TUNING.md "Clusters")
    call this%f%init(this%subs, this%solver_used, settings%local%regularization, this%ordering_used, &
                     int(mydofs, ip), share=settings%local%share_subdomains(1:4), classes=classes)
    block
      character(len=160) :: line
      write (line, '(a,i0,a,i0,a)') 'local subdomains: ', this%n_local_subs, ' in ', this%f%n_classes(), &
        ' classes of congruent subdomains'
      if (this%f%is_shared()) then
        block
          character(len=40) :: dev
          write (dev, '(es9.2)') this%f%max_class_deviation()
          line = trim(line)//' (K and K^+ shared per class; max |K_s - c_s K_r| / max |K_s| ='//trim(dev)//')'
        end block
      end if
      call log_message(line)
    end block
    call timer_stop('factorization')
    call memory_mark('factorization')

    call timer_start('B and G')
    if (this%hybrid) then
      call this%b%init(settings, this%dec, this%subs, comm, this%sub_dec)
    else
      call this%b%init(settings, this%dec, this%subs, comm)
    end if
    call MPI_Allreduce(mydofs, this%n_primal_dofs, 1, MPI_INT_I8, MPI_SUM, comm, ierr)
    allocate (this%xall(this%b%n_concat()))
    call timer_stop('B and G')
    call memory_mark('B and G')

    ! the dense split K^+ needs the dofs B touches: factorized now
    if (this%f%is_dense()) then
      call timer_start('factorization')
      call this%f%build_dense(this%b, this%subs, settings%local%regularization)
      call timer_stop('factorization')
    end if
    block
      character(len=200) :: line
      if (this%f%is_shared()) then
        write (line, '(3a)') 'local solver (', trim(settings%local%local_solver), '): K^+ shared per class'
      else if (this%f%is_dense()) then
        write (line, '(3a)') 'local solver (', trim(settings%local%local_solver), &
          '): dense, split along the dofs B touches (F through the Schur complements'' Cholesky factors)'
      else
        write (line, '(4a)') 'local solver (', trim(settings%local%local_solver), '): ', trim(this%solver_used)
      end if
      call log_message(trim(line))
    end block

    call timer_start('explicit F')
    call choose_f_action(this, settings)
    call timer_stop('explicit F')
    call memory_mark('explicit F')

    call timer_start('coarse setup')
    call dirichlet_rigid_test(this)
    call this%proj%init(this%dec, this%b, comm, settings%coarse, this%dirichlet_holds)
    call timer_stop('coarse setup')
    call memory_mark('coarse setup')

    call timer_start('dual setup')
    call dual_data(this, comm)
    call estimate_norm_pfp(this, settings%f_action%lanczos_steps, settings%f_action%lanczos_setup_steps)
    call timer_stop('dual setup')
    call memory_mark('dual setup')

  end subroutine setup

  !> K^s, f^s and R^s of every local unit. With `&solver share_subdomains =
  !> 'auto'` the classes of congruent units (K^s = c_s K^r) are found as the
  !> units are assembled: a unit whose geometry repeats a representative's
  !> (subdomain_classes::add_congruent) is not assembled (subdomain_t%k_of =
  !> the representative, k_scale = c_s = K_s(1,1) / K_r(1,1) from one element
  !> matrix); any other is assembled
  !> and compared with the representatives' K (add_to_classes), and keeps no
  !> K when it matches one. The rank holds one K per class, the
  !> representative's, which is what K^+, the explicit F and the
  !> preconditioners per class use. When the classes do not pay
  !> (subdomain_classes_t%shared false) the paths per subdomain run, and the
  !> members' K are assembled.
  subroutine assemble_units(this, settings, classes)
    class(feti_t), intent(inout) :: this
    type(feti_settings_t), intent(in) :: settings
    type(subdomain_classes_t), intent(out) :: classes
    integer(ip) :: ls, r
    logical :: look, found
    look = settings%local%share_subdomains == 'auto'
    call start_classes(classes, this%n_local_subs)
    do ls = 1, this%n_local_subs
      ! E and nu first: the geometric comparison needs them
      call subdomain_material(settings%material, this%dec, this%subs(ls)%id, this%subs(ls)%young, &
                              this%subs(ls)%poisson)
      this%subs(ls)%element = settings%material%element_kind()
      if (this%hybrid .and. .not. merges_corners(settings%mesh) .and. settings%material%variation /= 'none') &
        call element_moduli(this, settings, this%subs(ls))
      ! a cluster whose elements carry their own moduli is compared by its assembled K
      call add_congruent(this%subs, ls, classes, look .and. .not. allocated(this%subs(ls)%elem_young), found)
      call assemble_subdomain(settings%material, settings%load, this%dec, this%subs(ls), stiffness=.not. found)
      if (.not. found) call add_to_classes(this%subs, ls, classes, look)
      r = classes%rep(classes%class_of(ls))
      if (r /= ls) then
        call this%subs(ls)%K%free()
        this%subs(ls)%k_of = r
        this%subs(ls)%k_scale = classes%scale(ls)
      end if
    end do
    call finish_classes(classes)
    if (classes%shared()) return
    do ls = 1, this%n_local_subs
      if (this%subs(ls)%k_of == 0) cycle
      call assemble_stiffness(this%subs(ls))
      this%subs(ls)%k_of = 0
      this%subs(ls)%k_scale = 1
    end do
  end subroutine assemble_units

  !> A cluster glued by faces: the modulus of every element, its subdomain's.
  subroutine element_moduli(this, settings, sub)
    class(feti_t), intent(in) :: this
    type(feti_settings_t), intent(in) :: settings
    type(subdomain_t), intent(inout) :: sub
    integer(ip) :: e
    real(dp) :: nu
    allocate (sub%elem_young(sub%nelem))
    do e = 1, sub%nelem
      call subdomain_material(settings%material, this%sub_dec, this%sub_dec%subdomain_of_element(sub%elem_gid(e)), &
                              sub%elem_young(e), nu)
    end do
  end subroutine element_moduli

  !> The decomposition and the local units (subdomains, or clusters of them
  !> with hybrid TFETI, `&mesh cluster`) with their geometry. `units`: the
  !> decomposition into the units that the checks before the run built
  !> (run_checks), else built here.
  subroutine build_units(this, settings, comm, units)
    class(feti_t), intent(inout) :: this
    type(feti_settings_t), intent(in) :: settings
    type(MPI_Comm), intent(in) :: comm
    type(decomposition_t), intent(in), optional :: units
    integer(ip) :: ls
    this%hybrid = is_hybrid(settings%mesh)
    ! hybrid TFETI: the units are the clusters (src/mesh/clusters.f90), sub_dec the subdomains
    if (this%hybrid) call build_decomposition(settings%mesh, comm, this%sub_dec)
    if (present(units)) then
      this%dec = units
    else if (this%hybrid) then
      call build_decomposition(unit_mesh(settings%mesh), comm, this%dec)
    else
      call build_decomposition(settings%mesh, comm, this%dec)
    end if
    this%n_local_subs = size(this%dec%local_subdomains, kind=ip)
    allocate (this%subs(this%n_local_subs))
    do ls = 1, this%n_local_subs
      if (this%hybrid) then
        call build_cluster(this%sub_dec, this%dec, this%dec%local_subdomains(ls), this%subs(ls), &
                           merge_corners=merges_corners(settings%mesh))
        ! the moments of the jumps on its faces, edges and vertices (docs/THEORY.md)
        if (.not. merges_corners(settings%mesh)) call build_face_gluing(this%sub_dec, this%subs(ls))
      else
        call build_subdomain(this%dec, this%dec%local_subdomains(ls), this%subs(ls))
      end if
    end do
    if (this%hybrid) then
      block
        character(len=200) :: line
        if (merges_corners(settings%mesh)) then
          write (line, '(a,i0,a,i0,a,3(1x,i0),a)') 'hybrid TFETI: ', this%sub_dec%nsubdomains, ' subdomains in ', &
            this%dec%nsubdomains, ' clusters of', settings%mesh%cluster, ' (corners assembled inside a cluster)'
        else
          write (line, '(a,i0,a,i0,a,3(1x,i0),a)') 'hybrid TFETI: ', this%sub_dec%nsubdomains, ' subdomains in ', &
            this%dec%nsubdomains, ' clusters of', settings%mesh%cluster, &
            ' (faces glued by their 6 rigid-body moments inside a cluster)'
        end if
        call log_message(line)
      end block
    end if
  end subroutine build_units

  !> The dual data: d = B K^+ f - c, e = R^T f, lambda~ = G^T (G G^T)^{-1} e
  !> (with a check of the coarse solve's accuracy, logged), the contact rows
  !> and their lower bounds -lambda~. Collective over `comm`.
  subroutine dual_data(this, comm)
    class(feti_t), intent(inout) :: this
    type(MPI_Comm), intent(in) :: comm
    integer(ip) :: ls, r(2)
    integer :: ierr
    associate (n => this%b%n_own())
      allocate (this%d(n), this%lambda_tilde(n), this%lower(n), this%contact(n), this%e(6*this%n_local_subs))
      ! d = B K^+ f - c, e = R^T f
      do ls = 1, this%n_local_subs
        r = this%b%dof_range(ls)
        this%xall(r(1):r(2)) = this%subs(ls)%f
        this%e(6*ls - 5:6*ls) = matmul(this%subs(ls)%f, this%subs(ls)%R)
      end do
      call this%f%local_solve(this%xall)
      call this%b%apply_concat(this%xall, this%d)
      this%d = this%d - this%b%gap_rhs()
      ! lambda~ = G^T (G G^T)^{-1} e
      block
        real(dp) :: z(6*this%n_local_subs), sums(2)
        character(len=120) :: line
        call this%proj%solve(this%e, z)
        call this%b%apply_gt(z, this%lambda_tilde)
        ! the coarse solve's accuracy as the run sees it (inexact with &solver coarse_blr):
        ! G P x = 0 for a keyed random x, relative to G x
        block
          real(dp), allocatable :: x(:), px(:)
          real(dp) :: gx(6*this%n_local_subs)
          allocate (x(this%b%n_own()), px(this%b%n_own()))
          call this%keyed_random(11, x)
          call this%proj%project(this%b, x, px, gx=gx)
          call this%b%apply_g(px, z)
          sums = [sum(z**2), sum(gx**2)]
        end block
        call MPI_Allreduce(MPI_IN_PLACE, sums, 2, MPI_REAL_DP, MPI_SUM, comm, ierr)
        write (line, '(a,es10.3)') 'coarse check: ||G P x|| / ||G x|| =', sqrt(sums(1)/max(sums(2), tiny(1.0_dp)))
        call log_message(line)
      end block
      this%contact = this%b%is_contact()
      this%lower = -huge(1.0_dp)
      where (this%contact) this%lower = -this%lambda_tilde
    end associate
  end subroutine dual_data

  !> `&solver f_action`: build the explicit local operators for 'explicit',
  !> or for 'auto' when the cost model says they pay (the same choice on all
  !> ranks, from global sums). With K^+ shared per class on every rank
  !> (`share_subdomains`), the explicit action is one dgemm per class
  !> (compute bound) against the implicit one's streaming of the factors
  !> (memory bound): explicit when its flops per action are at most
  !> `shared_flops_per_byte` times the implicit bytes. Otherwise (per-subdomain operators:
  !> distorted meshes, METIS subdomains) the build is deferred, rent or buy:
  !> F starts implicit and the explicit operators are built once the run has
  !> made about as many F actions as pay the build back, N = ratio actions,
  !> ratio = sum n_d^3 / (I - E) (the build's flops over the bytes one
  !> explicit action saves; I, E the implicit and explicit bytes per action),
  !> and only where E < I. A run that stops before N actions never pays the
  !> build; one that goes on pays it once the implicit actions have cost
  !> about as much, so it spends at most about twice what the better of the
  !> two up-front choices would have (feti_t%apply_f makes the switch).
  subroutine choose_f_action(this, settings)
    class(feti_t), intent(inout) :: this
    type(feti_settings_t), intent(in) :: settings
    !> F actions before the deferred explicit build per unit of the ratio
    !> build flops / bytes saved per action (the break-even count is about the ratio)
    real(dp), parameter :: deferred_actions_per_ratio = 1
    real(dp), parameter :: shared_flops_per_byte = 8
    integer(i8) :: mine(3), all(3)
    integer(ip), allocatable :: nd(:)
    integer :: ierr, sharing
    logical :: use_explicit
    real(dp) :: ratio, fl(3)
    character(len=240) :: line
    sharing = merge(1, 0, this%f%is_shared())
    call MPI_Allreduce(MPI_IN_PLACE, sharing, 1, MPI_INTEGER, MPI_MIN, this%communicator, ierr)
    ! hybrid TFETI: explicit operators only shared per class of congruent clusters
    if (this%hybrid .and. settings%f_action%f_action == 'auto' .and. sharing == 0) then
      call log_message('F action: implicit (K^+ solves; hybrid TFETI without congruent clusters)')
      return
    end if
    select case (settings%f_action%f_action)
    case ('explicit')
      use_explicit = .true.
    case ('implicit')
      use_explicit = .false.
    case default
     if (sharing == 1) then
      ! shared per class on every rank: the explicit action is one dgemm per
      ! class (compute bound), the implicit one memory bound
      fl(1:2) = this%f%shared_explicit_flops(this%b)
      fl(3) = real(this%f%implicit_bytes(this%b), dp)
      call MPI_Allreduce(MPI_IN_PLACE, fl, 3, MPI_REAL_DP, MPI_SUM, this%communicator, ierr)
      ratio = fl(1)/max(1.0_dp, fl(3))
      use_explicit = ratio <= shared_flops_per_byte
      write (line, '(a,es10.3,a,es10.3,a,f0.3,a)') 'F action (auto, shared): implicit ', fl(3), &
        ' bytes, explicit ', fl(1), ' flops per action on all ranks; ', ratio, ' flop per byte'
      call log_message(line)
     else
      nd = this%f%touched_dofs(this%b)
      mine = [this%f%implicit_bytes(this%b), this%f%explicit_bytes(this%b, settings%f_action%f_storage, nd), &
              sum(int(nd, i8)**3)]
      call MPI_Allreduce(mine, all, 3, MPI_INT_I8, MPI_SUM, this%communicator, ierr)
      ratio = real(all(3), dp)/max(1.0_dp, real(all(1) - all(2), dp))
      write (line, '(a,es10.3,a,es10.3,a,f0.1,a)') 'F action (auto): implicit ', real(all(1), dp), &
        ' bytes, explicit ', real(all(2), dp), ' bytes per action on all ranks; build/saving ', ratio, &
        ' flop per byte'
      call log_message(line)
      ! deferred build (rent or buy): implicit at first, explicit once the
      ! implicit actions have cost about what the build costs (apply_f)
      use_explicit = .false.
      if (all(2) < all(1)) then
        this%f_build_at = max(1_i8, nint(min(deferred_actions_per_ratio*ratio, 1.0e15_dp), i8))
        this%f_regularization = settings%local%regularization
        this%f_storage = settings%f_action%f_storage
      end if
     end if
    end select
    if (use_explicit) then
      call this%f%build_explicit(this%b, this%subs, settings%local%regularization, settings%f_action%f_storage)
      if (this%f%is_shared()) then
        call log_message('F action: explicit local operators shared per class (dgemm)')
      else
        call log_message('F action: explicit local operators ('//trim(settings%f_action%f_storage)//')')
      end if
    else if (this%f_build_at > 0) then
      write (line, '(a,i0,a)') "F action: implicit (K^+ solves), the explicit local operators ("// &
        trim(this%f_storage)//") from F action ", this%f_build_at + 1, &
        " on ('auto': the implicit actions have then cost about their build)"
      call log_message(trim(line))
    else
      call log_message('F action: implicit (K^+ solves)')
    end if
  end subroutine choose_f_action

  !> ||P F P|| = lambda_max(P F P) by the Lanczos process on Im P, from a
  !> keyed random start: the largest eigenvalue theta of the tridiagonal
  !> matrix T_k of k steps (a lower bound of lambda_max that grows towards it
  !> with k, Golub and Van Loan, "Matrix Computations", 4th ed., Sec. 10.1),
  !> found by ritz_values::tridiagonal_extremes. It stops when theta changes by
  !> less than lanczos_change (1e-2) relative or after `max_iterations` steps
  !> (each one F action and one coarse solve); a low estimate is safe because
  !> MPRGP raises its ||A|| to any larger Rayleigh quotient of its search
  !> directions (mprgp). The Krylov space of k steps contains the k-th power
  !> method iterate, and theta >= its Rayleigh quotient, so Lanczos reaches a
  !> given accuracy in fewer steps than the power method. Plain three-term recurrence (no stored basis): loss of
  !> orthogonality only repeats converged Ritz values, it does not move them
  !> above lambda_max. The estimate scales the dual problem and sets the MPRGP
  !> step 1.9/||A||, which tolerates an underestimate of 5%.
  !> Deferred: set-up makes `steps` (&solver lanczos_setup_steps)
  !> of them, whose theta (a lower bound) scales the dual problem; the process
  !> is kept and continued to the stopping rule by refine_norm_pfp when MPRGP
  !> first needs its step length (dual_problem%refined_norm).
  subroutine estimate_norm_pfp(this, max_iterations, steps)
    class(feti_t), intent(inout) :: this
    integer(ip), intent(in) :: max_iterations
    !> steps to make now (at most; fewer when the stopping rule holds)
    integer(ip), intent(in) :: steps
    real(dp), allocatable :: z(:)
    real(dp) :: nrm
    allocate (z(this%b%n_own()))
    if (allocated(this%lz_v)) deallocate (this%lz_v, this%lz_vold, this%lz_alpha, this%lz_beta)
    allocate (this%lz_v(this%b%n_own()), this%lz_vold(this%b%n_own()))
    allocate (this%lz_alpha(max_iterations), this%lz_beta(max_iterations))
    this%lz_max = max_iterations
    this%lz_steps = 0
    this%lz_done = .true.
    this%pfp_norm = 0
    call this%keyed_random(7, z)
    call this%project(z, this%lz_v)
    nrm = this%norm(this%lz_v)
    if (nrm == 0) return
    this%lz_v = this%lz_v/nrm
    this%lz_vold = 0
    this%lz_beta = 0
    this%lz_previous = 0
    this%lz_done = .false.
    call lanczos_steps(this, steps)
  end subroutine estimate_norm_pfp

  module subroutine refine_norm_pfp(this)
    class(feti_t), intent(inout) :: this
    if (this%lz_done) return
    call lanczos_steps(this, this%lz_max, '         ')   ! within the solver's monitor: indented as its notes
  end subroutine refine_norm_pfp

  !> Up to `steps` more steps of the Lanczos process of estimate_norm_pfp
  !> (state in feti_t%lz_*), fewer when it stops (lz_done); pfp_norm = the
  !> largest Ritz value so far; its log line starts with `indent` (optional). Collective.
  subroutine lanczos_steps(this, steps, indent)
    class(feti_t), intent(inout) :: this
    integer(ip), intent(in) :: steps
    character(len=*), intent(in), optional :: indent
    !> the relative change of theta at which the Lanczos process stops
    real(dp), parameter :: lanczos_change = 1.0e-2_dp
    real(dp), allocatable :: w(:), z(:)
    real(dp) :: nrm, lo, hi, c
    integer(ip) :: it, last
    character(len=120) :: line
    allocate (w(this%b%n_own()), z(this%b%n_own()))
    last = min(this%lz_max, this%lz_steps + steps)
    do while (.not. this%lz_done .and. this%lz_steps < last)
      it = this%lz_steps + 1
      this%lz_steps = it
      associate (v => this%lz_v, vold => this%lz_vold, alpha => this%lz_alpha, beta => this%lz_beta)
        call this%apply_f(v, z)
        call this%project(z, w)            ! w = P F P v, since P v = v
        alpha(it) = this%dot(v, w)
        w = w - alpha(it)*v
        if (it > 1) w = w - beta(it - 1)*vold
        c = this%dot(v, w)                 ! one local reorthogonalization against v
        w = w - c*v
        alpha(it) = alpha(it) + c
        call tridiagonal_extremes(alpha(1:it), beta(1:it - 1), lo, hi)
        this%pfp_norm = max(hi, this%pfp_norm)
        if (it > 1 .and. abs(hi - this%lz_previous) <= lanczos_change*hi) then
          this%lz_done = .true.
        else
          this%lz_previous = hi
          nrm = this%norm(w)
          if (nrm <= 1.0e-14_dp*hi) then  ! an invariant subspace: theta is exact
            this%lz_done = .true.
          else
            beta(it) = nrm
            vold = v
            v = w/nrm
          end if
        end if
      end associate
      if (this%lz_steps >= this%lz_max) this%lz_done = .true.
    end do
    if (this%lz_done) then
      write (line, '(a,es12.5,a,i0,a)') '||P F P|| ~ ', this%pfp_norm, ' (Lanczos, ', this%lz_steps, ' iterations)'
      deallocate (this%lz_v, this%lz_vold, this%lz_alpha, this%lz_beta)
    else
      write (line, '(a,es12.5,a,i0,a)') '||P F P|| >= ', this%pfp_norm, ' (Lanczos, ', this%lz_steps, &
        ' iterations; continued when MPRGP first needs its step length)'
    end if
    if (present(indent)) then
      call log_message(indent//trim(line))
    else
      call log_message(line)
    end if
  end subroutine lanczos_steps

  !> this%dirichlet_holds: the Dirichlet rows alone fix every rigid body
  !> motion of the body. With r_i the values of the 6 rigid body motions at
  !> Dirichlet row i (its node and component; coordinates relative to the
  !> centre of the Dirichlet nodes' bounding box, divided by its size), the
  !> Gram matrix sum_i r_i r_i^T has full rank: lambda_min > sqrt(eps)
  !> lambda_max (a rank test; a motion the rows leave free gives 0 up to
  !> rounding). The body is glued into one piece by the gluing rows, so then
  !> no coarse vector has G^T y = 0 on the equality rows: G_E G_E^T and every
  !> G_F G_F^T over more rows are regular. Collective.
  subroutine dirichlet_rigid_test(this)
    class(feti_t), intent(inout) :: this
    integer(ip), allocatable :: kinds(:)
    integer(i8), allocatable :: keys(:)
    real(dp), allocatable :: x(:, :)
    real(dp) :: gram(6, 6), r(6), box(6), centre(3), size3, d(3), w(6), work(64)
    integer(ip) :: i, comp, nrows
    integer :: ierr, info
    this%dirichlet_holds = .false.
    kinds = this%b%row_kind()
    keys = this%b%row_keys()
    x = this%b%row_coordinates(this%subs)
    nrows = count(kinds == row_dirichlet, kind=ip)
    call MPI_Allreduce(MPI_IN_PLACE, nrows, 1, MPI_INT_IP, MPI_SUM, this%communicator, ierr)
    if (nrows < 6) return
    box(1:3) = -huge(1.0_dp)       ! max of -x, then max of x
    box(4:6) = -huge(1.0_dp)
    do i = 1, size(kinds, kind=ip)
      if (kinds(i) /= row_dirichlet) cycle
      box(1:3) = max(box(1:3), -x(:, i))
      box(4:6) = max(box(4:6), x(:, i))
    end do
    call MPI_Allreduce(MPI_IN_PLACE, box, 6, MPI_REAL_DP, MPI_MAX, this%communicator, ierr)
    centre = 0.5_dp*(box(4:6) - box(1:3))
    size3 = max(maxval(box(4:6) + box(1:3)), tiny(1.0_dp))
    gram = 0
    do i = 1, size(kinds, kind=ip)
      if (kinds(i) /= row_dirichlet) cycle
      comp = int(mod(keys(i)/32, 3_i8), ip) + 1        ! constraints::row_key
      d = (x(:, i) - centre)/size3
      r = 0
      r(comp) = 1
      select case (comp)          ! rotations about x, y, z: (0, -z, y), (z, 0, -x), (-y, x, 0)
      case (1)
        r(5) = d(3)
        r(6) = -d(2)
      case (2)
        r(4) = -d(3)
        r(6) = d(1)
      case default
        r(4) = d(2)
        r(5) = -d(1)
      end select
      gram = gram + spread(r, 2, 6)*spread(r, 1, 6)
    end do
    call MPI_Allreduce(MPI_IN_PLACE, gram, 36, MPI_REAL_DP, MPI_SUM, this%communicator, ierr)
    call dsyev('N', 'U', 6, gram, 6, w, work, size(work), info)
    if (info == 0) this%dirichlet_holds = w(6) > 0 .and. w(1) > sqrt(epsilon(1.0_dp))*w(6)
  end subroutine dirichlet_rigid_test
end submodule feti_builder
