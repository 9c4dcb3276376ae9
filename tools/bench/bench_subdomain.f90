!> Cost of one subdomain's local solver, for the tables of docs/RESULTS.md.
!>
!>   bench_subdomain [repetitions] [nel ...]      defaults: 5, 4 8 12 16
!>
!> For each nel: one floating cube subdomain of nel^3 Q1 elements (side 1,
!> distortion 0.2, E = 2.1e5, nu = 0.3), both orderings of K^+ (METIS nested
!> dissection on the node graph via PERM_IN, MUMPS's AMD). Times are medians
!> over the repetitions, all measured in this one run: assembly (geometry, K,
!> f, R), factorization (kplus%init: fixing nodes, K_reg, ordering, MUMPS
!> analysis + factorization), one solve, ten solves one at a time, ten
!> right-hand sides in one solve_many; the size of the factors (MUMPS
!> INFOG(9), INFOG(10)). Then the MUMPS cost per call on the smallest system
!> (one element, 24 dofs) and the resident memory per live kplus_t instance.
!> Prints Markdown. Run on one rank (the others idle).
program bench_subdomain
  use, intrinsic :: iso_fortran_env, only: output_unit
  use kinds, only: dp, ip, i8
  use params, only: params_t, default_params
  use decomposition, only: decomposition_t, build_decomposition
  use subdomain, only: subdomain_t, build_subdomain
  use assembly, only: assemble_subdomain
  use kplus, only: kplus_t
  use proc_status, only: proc_status_bytes
  use mpi_f08, only: MPI_Init, MPI_Finalize, MPI_Wtime, MPI_COMM_SELF, MPI_COMM_WORLD, MPI_Comm_rank
  implicit none
  character(len=8), parameter :: orderings(2) = [character(len=8) :: 'metis', 'amd']
  integer, parameter :: nphases = 6   ! assembly, factorization, 1 solve, 10 solves, 10 batched, bytes
  integer :: ierr, rank, reps, nsizes, i, status
  integer, allocatable :: nels(:)
  character(len=32) :: arg
  character(len=200) :: memory_line

  call MPI_Init(ierr)
  call MPI_Comm_rank(MPI_COMM_WORLD, rank, ierr)
  reps = 5
  call get_command_argument(1, arg, status=status)
  if (status == 0 .and. len_trim(arg) > 0) read (arg, *) reps
  nsizes = max(command_argument_count() - 1, 0)
  if (nsizes == 0) then
    nels = [4, 8, 12, 16]
  else
    allocate (nels(nsizes))
    do i = 1, nsizes
      call get_command_argument(i + 1, arg)
      read (arg, *) nels(i)
    end do
  end if
  if (rank == 0) then
    ! memory first, on a heap that earlier phases have not left holes in
    call memory_per_instance(4, 200, memory_line)
    call size_table(nels, reps)
    call call_overhead(reps)
    write (output_unit, '(a)') trim(memory_line)
  end if
  call MPI_Finalize(ierr)

contains

  !> One floating cube subdomain of nel^3 elements, assembled.
  subroutine cube(nel, p, dec, sub)
    integer, intent(in) :: nel
    type(params_t), intent(out) :: p
    type(decomposition_t), intent(out) :: dec
    type(subdomain_t), intent(out) :: sub
    p = default_params()
    p%mesh%nsub = [1, 1, 1]
    p%mesh%nel = [nel, nel, nel]
    p%mesh%distortion = 0.2_dp
    call build_decomposition(p%mesh, MPI_COMM_SELF, dec)
    call build_subdomain(dec, 1_ip, sub)
    call assemble_subdomain(p%material, p%load, dec, sub)
  end subroutine cube

  subroutine size_table(nels, reps)
    integer, intent(in) :: nels(:), reps
    real(dp), allocatable :: t(:, :, :)      ! (phase, ordering, repetition)
    type(params_t) :: p
    type(decomposition_t) :: dec
    type(subdomain_t) :: sub
    type(kplus_t) :: kp
    real(dp), allocatable :: x(:, :), x1(:)
    real(dp) :: t0
    integer :: s, r, o, k, n

    write (output_unit, '(a)') '| nel | dofs | ordering | assembly [ms] | factorization [ms] | 1 solve [ms] | '// &
      '10 solves [ms] | 10 RHS batched [ms] | factors [MB] |'
    write (output_unit, '(a)') '|---:|---:|---|---:|---:|---:|---:|---:|---:|'
    do s = 1, size(nels)
      allocate (t(nphases, size(orderings), reps))
      do r = 1, reps
        t0 = MPI_Wtime()
        call cube(nels(s), p, dec, sub)
        t(1, :, r) = MPI_Wtime() - t0
        n = sub%ndof
        allocate (x(n, 10), x1(n))
        do o = 1, size(orderings)
          t0 = MPI_Wtime()
          call kp%init(sub, 1.0_dp, orderings(o))
          t(2, o, r) = MPI_Wtime() - t0
          call right_hand_sides(x)
          x1 = x(:, 1)
          t0 = MPI_Wtime()
          call kp%solve(x1)
          t(3, o, r) = MPI_Wtime() - t0
          t0 = MPI_Wtime()
          do k = 1, 10
            x1 = x(:, k)
            call kp%solve(x1)
          end do
          t(4, o, r) = MPI_Wtime() - t0
          t0 = MPI_Wtime()
          call kp%solve_many(x)
          t(5, o, r) = MPI_Wtime() - t0
          t(6, o, r) = real(kp%factor_bytes(), dp)
          call kp%free()
        end do
        deallocate (x, x1)
      end do
      do o = 1, size(orderings)
        write (output_unit, '(a,i0,a,i0,20a)') '| ', nels(s), '^3 | ', n, ' | ', trim(orderings(o)), &
          ' | ', num(1.0e3_dp*median(t(1, o, :)), 3), ' | ', num(1.0e3_dp*median(t(2, o, :)), 2), &
          ' | ', num(1.0e3_dp*median(t(3, o, :)), 3), ' | ', num(1.0e3_dp*median(t(4, o, :)), 3), &
          ' | ', num(1.0e3_dp*median(t(5, o, :)), 3), ' | ', num(median(t(6, o, :))/1.0e6_dp, 2), ' |'
      end do
      deallocate (t)
    end do
    write (output_unit, '(a,i0,a)') '(medians of ', reps, ' repetitions)'
  end subroutine size_table

  !> MUMPS's fixed cost per call: one solve on a one-element subdomain
  !> (24 dofs), where the arithmetic is negligible.
  subroutine call_overhead(reps)
    integer, intent(in) :: reps
    integer, parameter :: calls = 2000
    type(params_t) :: p
    type(decomposition_t) :: dec
    type(subdomain_t) :: sub
    type(kplus_t) :: kp
    real(dp) :: x(24), t0, tsolve(reps), tinit(reps)
    integer :: r, k

    call cube(1, p, dec, sub)
    do r = 1, reps
      t0 = MPI_Wtime()
      do k = 1, 100
        call kp%init(sub, 1.0_dp, 'amd')
      end do
      tinit(r) = (MPI_Wtime() - t0)/100
      x = 1
      t0 = MPI_Wtime()
      do k = 1, calls
        call kp%solve(x)
      end do
      tsolve(r) = (MPI_Wtime() - t0)/calls
      call kp%free()
    end do
    write (output_unit, '(/,5a)') 'One element (24 dofs): kplus%init ', num(1.0e6_dp*median(tinit), 1), &
      ' us, one solve ', num(1.0e6_dp*median(tsolve), 1), ' us (MUMPS''s fixed cost per call).'
  end subroutine call_overhead

  !> Resident memory per live kplus_t: `count` instances of a nel^3 subdomain
  !> alive at once, as a line of text.
  subroutine memory_per_instance(nel, count, line)
    integer, intent(in) :: nel, count
    character(len=*), intent(out) :: line
    type(params_t) :: p
    type(decomposition_t) :: dec
    type(subdomain_t) :: sub
    type(kplus_t), allocatable :: kps(:)
    integer(i8) :: rss0, rss1
    integer :: k

    call cube(nel, p, dec, sub)
    allocate (kps(count))
    rss0 = max(proc_status_bytes('VmRSS'), 0_i8)/1024
    do k = 1, count
      call kps(k)%init(sub, 1.0_dp, 'metis')
    end do
    rss1 = max(proc_status_bytes('VmRSS'), 0_i8)/1024
    write (line, '(a,i0,a,i0,a,i0,5a)') 'Memory: ', count, ' live instances of ', nel, &
      '^3 (', sub%ndof, ' dofs, METIS): ', num(real(rss1 - rss0, dp)/count, 1), ' KiB resident each, factors ', &
      num(real(kps(1)%factor_bytes(), dp)/1024, 1), ' KiB of it.'
    do k = 1, count
      call kps(k)%free()
    end do
  end subroutine memory_per_instance

  subroutine right_hand_sides(x)
    real(dp), intent(out) :: x(:, :)
    integer :: i, j
    do j = 1, size(x, 2)
      do i = 1, size(x, 1)
        x(i, j) = sin(0.1_dp*i + j)
      end do
    end do
  end subroutine right_hand_sides

  !> `x` with `digits` decimals and its leading zero.
  function num(x, digits) result(text)
    real(dp), intent(in) :: x
    integer, intent(in) :: digits
    character(len=:), allocatable :: text
    character(len=32) :: buf, fmt
    write (fmt, '(a,i0,a)') '(f24.', digits, ')'
    write (buf, fmt) x
    text = trim(adjustl(buf))
  end function num

  real(dp) function median(v)
    real(dp), intent(in) :: v(:)
    real(dp) :: w(size(v)), tmp
    integer :: i, j, n
    n = size(v)
    w = v
    do i = 2, n
      tmp = w(i)
      j = i - 1
      do while (j >= 1)
        if (w(j) <= tmp) exit
        w(j + 1) = w(j)
        j = j - 1
      end do
      w(j + 1) = tmp
    end do
    if (mod(n, 2) == 1) then
      median = w((n + 1)/2)
    else
      median = 0.5_dp*(w(n/2) + w(n/2 + 1))
    end if
  end function median

end program bench_subdomain
