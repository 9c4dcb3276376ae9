!> The constraint matrix B = [B_E; B_I] and its right-hand side c, built from
!> node sharing, distributed by rows (multipliers).
!>
!> Rows, per physical node and displacement component:
!> - Dirichlet (top face, symmetry planes): one row per subdomain copy,
!>   B = e_dof, c = prescribed value. Every copy gets its own row, so such a
!>   component needs no gluing, and all these rows are orthonormal.
!> - gluing, for a component that is not Dirichlet and a node with m > 1
!>   copies (sorted subdomain ids s_1 < ... < s_m): the m-1 non-redundant,
!>   orthonormal Helmert rows, row k = (1,...,1,-k,0,...)/sqrt(k(k+1)) on the
!>   copies 1..k+1. Non-redundant so that B has full row rank; orthonormal so
!>   that B_E B_E^T = I also where 4 or 8 subdomains meet.
!> - contact, component z of a node of the face z = 0 under the obstacle's
!>   footprint: one row spread over all m copies of the node with the gluing
!>   weights w_c (below; all 1 without scaling), S = w_1 + ... + w_m:
!>   B = -(w_1 e_z,1 + ... + w_m e_z,m)/sqrt(S), c = sqrt(S) g, g = z - psi(x, y)
!>   (-(weighted mean of u_z) <= g, multiplier >= 0); owned like the gluing
!>   rows (rank of s_1). With the gluing rows it is the same constraint as
!>   -u_z <= g on any one copy, and (w_1, ..., w_m) is orthogonal to every
!>   weighted Helmert row in the diag(1/w) inner product with unit weighted
!>   norm, so B diag(1/w) B^T = I holds on contact nodes too. The copies
!>   together carry the force: sum_c (B^T lambda~)_z,c = -sqrt(S) lambda~, so
!>   scale = unit = sqrt(S).
!> Scaling (&solver scaling = 'young', the default): with w_c = E(s_c)/young the
!> relative Young's modulus of the subdomain of copy c, the gluing row k becomes
!> alpha_k (w_1, ..., w_k, -S_k, 0, ...), S_k = w_1 + ... + w_k,
!> alpha_k = 1/sqrt(S_k (1 + S_k/w_(k+1))), Dirichlet rows are multiplied by
!> sqrt(w) of their copy (c too), and contact rows take the weights as above.
!> The rows span the same space as unweighted ones (same constraints, same
!> primal solution) and are orthonormal in the inner product weighted by
!> diag(1/w): B diag(1/w) B^T = I per node, which makes the lumped
!> approximation B diag(1/E) B^T of F scale-free across material jumps
!> ("reorthogonalized rho-scaling"). A multiplier of a scaled row is
!> lambda~ = lambda/s with s = `scale` of the row: the force is scale*lambda~.
!> With equal moduli (variation 'none') every w_c = 1 and the rows are the
!> unweighted ones bit for bit.
!> Top Dirichlet takes precedence over symmetry on shared edges.
!>
!> Hybrid TFETI (`&mesh cluster`, src/mesh/clusters.f90): the local units
!> `subs` are clusters and `dec` is the cluster-level decomposition;
!> `sub_dec` (the subdomains) gives a node's copies. The copies of a corner
!> node inside one cluster are one dof (merged by partial assembly), so the
!> rows above are built over the node's copies after merging (clusters::
!> node_copies: one representative per cluster, weight w = the number of
!> merged subdomains, w = 1 for every other copy), with the same formulas;
!> B diag(1/w) B^T = I per node holds with these weights. Rows are owned by
!> the rank of the first copy's cluster. Without clusters the merged list
!> is the plain one and the rows are today's bit for bit. Clusters glued by
!> faces (`&mesh cluster_gluing = 'faces'`) merge nothing: the rows are
!> plain TFETI's (copies and weights w_c = E(s_c)/young of the subdomains),
!> applied to the clusters' dofs.
!>
!> Every row has a canonical 64-bit key (node, component, kind, index) that
!> does not depend on the number of ranks, and one owner: the rank of the
!> subdomain the row is attached to (s_1 for gluing and contact rows). Owned
!> rows are stored in key order; ghost rows (owned elsewhere, touching this
!> rank's subdomains) follow, grouped by owner and in key order, which is the
!> order in which owner and user exchange them (see dual_exchange).
module constraints
  use kinds, only: dp, ip, i8, MPI_INT_IP
  use errors, only: fatal_error
  use feti_settings, only: feti_settings_t
  use decomposition, only: decomposition_t
  use subdomain, only: subdomain_t
  use sorting, only: sort_permutation, sort_unique
  use dual_exchange, only: dual_exchange_t
  use mpi_f08, only: MPI_Comm, MPI_Comm_rank, MPI_Allreduce, MPI_Exscan, MPI_SUM
  use materials, only: subdomain_material
  use clusters, only: node_copies, merges_corners
  implicit none
  private

  public :: build_constraints, row_key

  integer(ip), parameter, public :: row_gluing = 0, row_dirichlet = 1, row_contact = 2

  !> B^s of one local subdomain as a list of entries; `g(:, e)` holds the
  !> matching entries of G^T = B R: val * R^s(dof, :).
  type, public :: subdomain_rows_t
    integer(ip) :: nentries = 0
    integer(ip), allocatable :: row(:)     !< local row index (1..n_local)
    integer(ip), allocatable :: dof(:)     !< subdomain dof
    integer(ip), allocatable :: slot(:)    !< position of this subdomain in the node's copy list
    real(dp), allocatable :: val(:)
    real(dp), allocatable :: g(:, :)       !< (6, nentries) entries of G^T = B R
  end type subdomain_rows_t

  type, public :: constraints_t
    type(MPI_Comm) :: comm
    integer(ip) :: n_own = 0, n_ghost = 0, n_local = 0
    integer(ip) :: n_global = 0, offset = 0            !< global id of owned row i: offset + i
    integer(ip) :: n_contact = 0, n_contact_global = 0 !< contact rows owned / in all
    integer(ip) :: n_dirichlet_global = 0, n_gluing_global = 0
    integer(i8), allocatable :: key(:)        !< (n_local) canonical keys
    integer(ip), allocatable :: kind(:)       !< (n_own) row_gluing | row_dirichlet | row_contact
    real(dp), allocatable :: c(:)             !< (n_own) right-hand side
    real(dp), allocatable :: scale(:)         !< (n_own) force = scale * multiplier (1 unless &solver scaling)
    !> (n_own) a row's value is unit x a displacement: (B u - c)_i / unit_i is
    !> the violation in displacement units (Dirichlet: sqrt(w), contact:
    !> sqrt(S), as scale; gluing: the weighted Helmert row k is unit x (the w-weighted mean
    !> of copies 1..k minus copy k+1), unit = alpha_k S_k, sqrt(k/(k+1)) unweighted)
    real(dp), allocatable :: unit(:)
    integer(ip), allocatable :: node(:)       !< (n_own) node gid
    integer(ip), allocatable :: row_sub(:)    !< (n_own) local subdomain index of the row's copy (s_1)
    integer(ip), allocatable :: row_node(:)   !< (n_own) local node number in that subdomain
    type(subdomain_rows_t), allocatable :: b(:)  !< (number of local subdomains)
    type(dual_exchange_t) :: exchange
    !> The nonzero 6-blocks of G^T of every owned row, gathered at the owner:
    !> blocks g_row_first(i) .. g_row_first(i+1)-1 of row i, g_row_block(:, k)
    !> of subdomain g_row_sub(k) on copy g_row_slot(k) (the position of the
    !> subdomain in the node's copy list; blocks in slot order). Filled once by
    !> coarse_problem::ensure_row_blocks (G does not change during a run) and
    !> read by every coarse assembly.
    logical :: g_rows_ready = .false.
    integer(ip), allocatable :: g_row_first(:)    !< (n_own + 1)
    integer(ip), allocatable :: g_row_slot(:)     !< (blocks) 1..8
    integer(ip), allocatable :: g_row_sub(:)      !< (blocks) subdomain id
    real(dp), allocatable :: g_row_block(:, :)    !< (6, blocks)
  end type constraints_t

  !> One entry of B found while visiting the subdomains' nodes.
  type :: record_t
    integer(i8) :: key
    integer :: owner
    integer(ip) :: sub, dof, node, gid, kind, slot
    integer(ip) :: cslot   !< position of the unit in the node's unit list (the G^T block, coarse_problem)
    real(dp) :: val, c, scale, unit
  end type record_t

contains

  !> Canonical key of a row: node gid, component 1..3, kind, index 1..8.
  pure integer(i8) function row_key(gid, comp, kind, index)
    integer(ip), intent(in) :: gid, comp, kind, index
    row_key = ((int(gid, i8)*3 + (comp - 1))*4 + kind)*8 + (index - 1)
  end function row_key

  !> Build B, c, the entries of G^T = B R and the exchange pattern for the
  !> local subdomains `subs` (geometry and R^s are needed). Collective over `comm`.
  subroutine build_constraints(settings, dec, subs, comm, con, sub_dec)
    type(feti_settings_t), intent(in) :: settings
    type(decomposition_t), intent(in) :: dec
    type(decomposition_t), intent(in), optional :: sub_dec   !< hybrid TFETI: the subdomains
    type(subdomain_t), intent(in) :: subs(:)
    type(MPI_Comm), intent(in) :: comm
    type(constraints_t), intent(out) :: con
    type(record_t), allocatable :: rec(:)
    integer(ip) :: nrec, me
    integer(ip), allocatable :: row_of_rec(:), local_index(:), urow_first(:), ghost_owner(:)
    integer :: ierr, rank
    logical :: filling
    integer(ip) :: cslot   ! visit -> emit: the unit's position in the node's unit list
    real(dp), allocatable :: sub_weight(:)   ! w of every subdomain (subdomain_weights)

    con%comm = comm
    call MPI_Comm_rank(comm, rank, ierr)
    me = rank

    ! 1. Records of every B entry of the local subdomains (count, then fill).
    if (present(sub_dec)) then       ! hybrid TFETI: the subdomains' weights, not the clusters'
      call subdomain_weights(settings, sub_dec, sub_weight)
    else
      call subdomain_weights(settings, dec, sub_weight)
    end if
    nrec = 0
    call visit(.false.)
    allocate (rec(nrec))
    nrec = 0
    call visit(.true.)
    ! 2. Unique rows, owned ones first (key order), then ghosts by (owner, key).
    call order_rows(rec, me, con, row_of_rec, urow_first, local_index, ghost_owner)
    ! 3. The rows' data and the B^s entries per local subdomain.
    call fill_rows(rec, urow_first, row_of_rec, local_index, subs, con)
    ! 4. Sizes.
    call count_rows(comm, rank, con)
    ! 5. Exchange pattern.
    call build_exchange(dec, con, ghost_owner, me, merges_corners(settings%mesh), sub_dec)

  contains

    !> Visit every node of every local subdomain and emit its B entries
    !> (count them when `fill` is false).
    subroutine visit(fill)
      logical, intent(in) :: fill
      integer(ip) :: copies(8), reps(8), merged(8), member(8), units(8), nunits
      integer(ip) :: ls, a, gid, comp, m, j, k, ijk(3), s_id
      integer :: owner
      logical :: dirichlet(3), contact
      real(dp) :: value(3), x(3), gap, w(8), sk, alpha
      filling = fill
      do ls = 1, size(subs, kind=ip)
        s_id = subs(ls)%id
        do a = 1, subs(ls)%nnodes
          gid = subs(ls)%node_gid(a)
          ijk = dec%mesh%node_ijk(gid)
          x = subs(ls)%coords(:, a)
          call node_conditions(settings, dec, ijk, x, dirichlet, value, contact, gap)
          if (present(sub_dec)) then
            call node_copies(sub_dec, dec, gid, reps, copies, merged, member, m, merges_corners(settings%mesh))
            if (m == 1 .and. .not. (any(dirichlet) .or. contact)) cycle
            if (subs(ls)%node_copy(a) == 0) then
              j = findloc(copies(1:m), s_id, 1)
            else
              j = findloc(reps(1:m), subs(ls)%node_copy(a), 1)
            end if
            owner = dec%subdomain_rank(copies(1))
            w(1:m) = real(merged(1:m), dp)     ! corners (uniform material, checked): w = merged subdomains
            if (.not. merges_corners(settings%mesh)) w(1:m) = sub_weight(reps(1:m))   ! faces: plain TFETI's
            call dec%node_subdomain_list(gid, units, nunits)
            cslot = findloc(units(1:nunits), s_id, 1)
          else
            call dec%node_subdomain_list(gid, copies, m)
            if (m == 1 .and. .not. (any(dirichlet) .or. contact)) cycle
            j = findloc(copies(1:m), s_id, 1)
            owner = dec%subdomain_rank(copies(1))
            w(1:m) = sub_weight(copies(1:m))   ! E(s)/young with &solver scaling = 'young', else 1
            cslot = j
          end if
          do comp = 1, 3
            if (dirichlet(comp)) then
              call emit(row_key(gid, comp, row_dirichlet, j), int(me), ls, 3*(a - 1) + comp, a, gid, &
                        row_dirichlet, j, sqrt(w(j)), sqrt(w(j))*value(comp), sqrt(w(j)), sqrt(w(j)))
            else if (all(w(1:m) == 1)) then
              do k = max(1, j - 1), m - 1
                call emit(row_key(gid, comp, row_gluing, k), owner, ls, 3*(a - 1) + comp, a, gid, row_gluing, j, &
                          merge(1.0_dp, -real(k, dp), j <= k)/sqrt(real(k*(k + 1), dp)), 0.0_dp, 1.0_dp, &
                          sqrt(k/real(k + 1, dp)))
              end do
            else
              ! weighted Helmert rows (see the module header)
              do k = max(1, j - 1), m - 1
                sk = sum(w(1:k))
                alpha = 1/sqrt(sk*(1 + sk/w(k + 1)))
                call emit(row_key(gid, comp, row_gluing, k), owner, ls, 3*(a - 1) + comp, a, gid, row_gluing, j, &
                          merge(alpha*w(j), -alpha*sk, j <= k), 0.0_dp, 1.0_dp, alpha*sk)
              end do
            end if
          end do
          if (contact) then
            ! spread over all copies with the gluing weights (see the module header)
            sk = sum(w(1:m))
            call emit(row_key(gid, 3_ip, row_contact, 1_ip), owner, ls, 3*(a - 1) + 3, a, gid, &
                      row_contact, j, -w(j)/sqrt(sk), sqrt(sk)*gap, sqrt(sk), sqrt(sk))
          end if
        end do
      end do
    end subroutine visit

    subroutine emit(key, owner, ls, dof, node, gid, kind, slot, val, c, scale, unit)
      integer(i8), intent(in) :: key
      integer, intent(in) :: owner
      integer(ip), intent(in) :: ls, dof, node, gid, kind, slot
      real(dp), intent(in) :: val, c, scale, unit
      nrec = nrec + 1
      if (filling) rec(nrec) = record_t(key, owner, ls, dof, node, gid, kind, slot, cslot, val, c, scale, unit)
    end subroutine emit
  end subroutine build_constraints

  !> w(s) = E(s)/young for every subdomain s of `dec` with &solver scaling =
  !> 'young', else 1. From the parameters alone: the same on every rank.
  subroutine subdomain_weights(settings, dec, w)
    type(feti_settings_t), intent(in) :: settings
    type(decomposition_t), intent(in) :: dec
    real(dp), allocatable, intent(out) :: w(:)
    integer(ip) :: s
    real(dp) :: young, nu
    allocate (w(dec%nsubdomains))
    w = 1
    if (settings%scaling%scaling /= 'young') return
    do s = 1, dec%nsubdomains
      call subdomain_material(settings%material, dec, s, young, nu)
      w(s) = young/settings%material%young
    end do
  end subroutine subdomain_weights

  !> The unique rows of the records `rec` in key order: `row_of_rec` the
  !> row of each record, `urow_first` the first record of each row (sorted
  !> order); `local_index` each row's place, owned rows first (key order),
  !> then the ghosts by (owner, key) with their owners in `ghost_owner`.
  !> Sets con%n_own, n_ghost, n_local.
  subroutine order_rows(rec, me, con, row_of_rec, urow_first, local_index, ghost_owner)
    type(record_t), intent(in) :: rec(:)
    integer(ip), intent(in) :: me
    type(constraints_t), intent(inout) :: con
    integer(ip), allocatable, intent(out) :: row_of_rec(:), urow_first(:), local_index(:), ghost_owner(:)
    integer(ip), allocatable :: perm(:), ghost_perm(:), ghost_rows(:), owners(:)
    integer(i8), allocatable :: keys(:)
    integer(i8) :: last
    integer(ip) :: nrec, nrows, n_ghost, i, j, r

    nrec = size(rec, kind=ip)
    allocate (keys(nrec))
    keys = rec(:)%key
    call sort_permutation(keys, perm)
    allocate (row_of_rec(nrec), urow_first(nrec))
    nrows = 0
    last = -1
    do i = 1, nrec
      r = perm(i)
      if (rec(r)%key /= last) then
        nrows = nrows + 1
        urow_first(nrows) = r
        last = rec(r)%key
      end if
      row_of_rec(r) = nrows
    end do
    allocate (local_index(nrows))
    con%n_own = count(rec(urow_first(1:nrows))%owner == me)
    n_ghost = nrows - con%n_own
    allocate (owners(n_ghost), ghost_rows(n_ghost))
    j = 0
    i = 0
    do r = 1, nrows
      if (rec(urow_first(r))%owner == me) then
        j = j + 1
        local_index(r) = j
      else
        i = i + 1
        owners(i) = rec(urow_first(r))%owner
        ghost_rows(i) = r
      end if
    end do
    call sort_permutation(owners, ghost_perm)    ! stable: key order kept within an owner
    do i = 1, n_ghost
      local_index(ghost_rows(ghost_perm(i))) = con%n_own + i
    end do
    ghost_owner = owners(ghost_perm)
    con%n_ghost = n_ghost
    con%n_local = con%n_own + n_ghost
  end subroutine order_rows

  !> The rows' keys, kinds, right-hand sides, scales and nodes, the owner's
  !> copy of each owned row, and the B^s entries (with G^T = B R) of the
  !> local subdomains `subs`, from the records (order_rows's maps).
  subroutine fill_rows(rec, urow_first, row_of_rec, local_index, subs, con)
    type(record_t), intent(in) :: rec(:)
    integer(ip), intent(in) :: urow_first(:), row_of_rec(:), local_index(:)
    type(subdomain_t), intent(in) :: subs(:)
    type(constraints_t), intent(inout) :: con
    integer(ip) :: i, j, r, ls

    allocate (con%key(con%n_local), con%kind(con%n_own), con%c(con%n_own), con%node(con%n_own), &
              con%row_sub(con%n_own), con%row_node(con%n_own), con%scale(con%n_own), con%unit(con%n_own))
    do r = 1, size(local_index, kind=ip)
      associate (first => rec(urow_first(r)))
        con%key(local_index(r)) = first%key
        if (local_index(r) <= con%n_own) then
          con%kind(local_index(r)) = first%kind
          con%c(local_index(r)) = first%c
          con%scale(local_index(r)) = first%scale
          con%unit(local_index(r)) = first%unit
          con%node(local_index(r)) = first%gid
        end if
      end associate
    end do
    ! the owner's copy of each owned row (s_1, or the Dirichlet copy): for contact output
    do i = 1, size(rec, kind=ip)
      j = local_index(row_of_rec(i))
      if (j > con%n_own) cycle
      if (rec(i)%kind == row_dirichlet .or. rec(i)%slot == 1) then
        con%row_sub(j) = rec(i)%sub
        con%row_node(j) = rec(i)%node
      end if
    end do
    ! B^s entries per local subdomain
    allocate (con%b(size(subs)))
    do i = 1, size(rec, kind=ip)
      con%b(rec(i)%sub)%nentries = con%b(rec(i)%sub)%nentries + 1
    end do
    do ls = 1, size(subs, kind=ip)
      allocate (con%b(ls)%row(con%b(ls)%nentries), con%b(ls)%dof(con%b(ls)%nentries), &
                con%b(ls)%val(con%b(ls)%nentries), con%b(ls)%g(6, con%b(ls)%nentries), &
                con%b(ls)%slot(con%b(ls)%nentries))
      con%b(ls)%nentries = 0
    end do
    do i = 1, size(rec, kind=ip)
      associate (bs => con%b(rec(i)%sub))
        bs%nentries = bs%nentries + 1
        bs%row(bs%nentries) = local_index(row_of_rec(i))
        bs%dof(bs%nentries) = rec(i)%dof
        bs%val(bs%nentries) = rec(i)%val
        bs%slot(bs%nentries) = rec(i)%cslot
        bs%g(:, bs%nentries) = rec(i)%val*subs(rec(i)%sub)%R(rec(i)%dof, :)   ! G^T = B R
      end associate
    end do
  end subroutine fill_rows

  !> The global offset of this rank's owned rows and the global row counts
  !> (all, contact, Dirichlet, gluing). Collective over `comm`.
  subroutine count_rows(comm, rank, con)
    type(MPI_Comm), intent(in) :: comm
    integer, intent(in) :: rank
    type(constraints_t), intent(inout) :: con
    integer(ip) :: counts(4), totals(4)
    integer :: ierr
    call MPI_Exscan(con%n_own, con%offset, 1, MPI_INT_IP, MPI_SUM, comm, ierr)
    if (rank == 0) con%offset = 0
    con%n_contact = count(con%kind == row_contact)
    counts = [con%n_own, con%n_contact, count(con%kind == row_dirichlet, kind=ip), &
              count(con%kind == row_gluing, kind=ip)]
    call MPI_Allreduce(counts, totals, 4, MPI_INT_IP, MPI_SUM, comm, ierr)
    con%n_global = totals(1)
    con%n_contact_global = totals(2)
    con%n_dirichlet_global = totals(3)
    con%n_gluing_global = totals(4)
  end subroutine count_rows

  !> Dirichlet components with values, and the contact condition, of a node.
  subroutine node_conditions(settings, dec, ijk, x, dirichlet, value, contact, gap)
    type(feti_settings_t), intent(in) :: settings
    type(decomposition_t), intent(in) :: dec
    integer(ip), intent(in) :: ijk(3)
    real(dp), intent(in) :: x(3)
    logical, intent(out) :: dirichlet(3), contact
    real(dp), intent(out) :: value(3), gap
    real(dp) :: r2, psi, c(2)

    dirichlet = .false.
    value = 0
    if (settings%boundary%symmetry_x0 .and. ijk(1) == 0) dirichlet(1) = .true.
    if (settings%boundary%symmetry_y0 .and. ijk(2) == 0) dirichlet(2) = .true.
    if (settings%boundary%top_dirichlet .and. ijk(3) == dec%mesh%ng(3)) then
      dirichlet = .true.
      value = settings%boundary%top_displacement
    end if
    contact = .false.
    gap = 0
    if (ijk(3) /= 0 .or. dirichlet(3)) return
    c = settings%obstacle%centre_of(dec%mesh%lengths)
    select case (settings%obstacle%shape)
    case ('plane')
      contact = .true.
      psi = -settings%obstacle%gap
    case ('sphere')
      r2 = (x(1) - c(1))**2 + (x(2) - c(2))**2
      if (r2 > settings%obstacle%radius**2) return
      contact = .true.
      psi = -settings%obstacle%radius - settings%obstacle%gap + sqrt(settings%obstacle%radius**2 - r2)
    case default
      return
    end select
    gap = x(3) - psi
  end subroutine node_conditions

  !> The neighbour exchange: ghosts are received from their owners in the
  !> order of `ghost_owner`; owned gluing and contact rows are sent to every
  !> other rank holding one of their copies, in key order.
  subroutine build_exchange(dec, con, ghost_owner, me, merge_corners, sub_dec)
    type(decomposition_t), intent(in) :: dec
    logical, intent(in) :: merge_corners     !< hybrid TFETI: the clusters merge their corners
    type(decomposition_t), intent(in), optional :: sub_dec
    type(constraints_t), intent(inout) :: con
    integer(ip), intent(in) :: ghost_owner(:)   ! owner of ghost i (local row n_own+i)
    integer(ip), intent(in) :: me
    integer(ip) :: copies(8), ncopies, reps(8), merged(8), member(8)
    integer(ip), allocatable :: dest_rank(:), dest_row(:), perm(:), send_index(:), recv_index(:)
    integer(ip), allocatable :: nbrs(:)
    integer, allocatable :: send_counts(:), recv_counts(:), ranks_here(:)
    integer(ip) :: i, k, n, index, q
    integer(ip) :: nr
    integer :: t

    ! (destination rank, owned row) pairs, in row (= key) order
    allocate (dest_rank(16*con%n_own + 1), dest_row(16*con%n_own + 1))
    n = 0
    do i = 1, con%n_own
      if (con%kind(i) == row_dirichlet) cycle
      if (present(sub_dec)) then
        call node_copies(sub_dec, dec, con%node(i), reps, copies, merged, member, ncopies, merge_corners)   ! clusters
      else
        call dec%node_subdomain_list(con%node(i), copies, ncopies)
      end if
      if (con%kind(i) == row_gluing) then
        index = int(mod(con%key(i), 8_i8), ip) + 1   ! Helmert row k touches copies 1..k+1
        ranks_here = [(dec%subdomain_rank(copies(k)), k = 1, index + 1)]
      else
        ranks_here = [(dec%subdomain_rank(copies(k)), k = 1, ncopies)]   ! contact: every copy
      end if
      do k = 1, size(ranks_here)
        if (ranks_here(k) == me) cycle
        if (any(ranks_here(1:k - 1) == ranks_here(k))) cycle
        if (n == size(dest_rank)) then
          dest_rank = [dest_rank, dest_rank]
          dest_row = [dest_row, dest_row]
        end if
        n = n + 1
        dest_rank(n) = ranks_here(k)
        dest_row(n) = i
      end do
    end do
    call sort_permutation(dest_rank(1:n), perm)     ! stable: row order kept per rank
    send_index = dest_row(perm)

    ! neighbours: union of destination ranks and ghost owners
    nbrs = [dest_rank(1:n), ghost_owner]
    call sort_unique(nbrs, nr)
    allocate (send_counts(nr), recv_counts(nr))
    do t = 1, nr
      q = nbrs(t)
      send_counts(t) = count(dest_rank(1:n) == q)
      recv_counts(t) = count(ghost_owner == q)
    end do
    recv_index = [(con%n_own + i, i = 1, size(ghost_owner, kind=ip))]
    ! ghosts are grouped by owner in ascending owner order, as nbrs is
    if (sum(recv_counts) /= size(ghost_owner)) call fatal_error('constraints: ghost rows without a neighbour')
    call con%exchange%init(con%comm, con%n_own, con%n_local, int(nbrs(1:nr)), send_counts, send_index, &
                           recv_counts, recv_index)
  end subroutine build_exchange

end module constraints
