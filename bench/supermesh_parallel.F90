! P1-P1 coupling matrix B between two distributed tet meshes with libsupermesh's own
! parallel driver, parallel_supermesh (comparison point for bench/transfer.py and
! bench/transfer_mpi.py; built on demand by bench/supermesh_parallel.py against the PyPI
! package `libsupermesh`, whose Fortran modules it ships).
!
! Usage: mpirun -n N supermesh_parallel DIR
! Rank r reads DIR/target_N_r.bin and DIR/source_N_r.bin (stream files: nnodes, nelements
! as int32; coordinates 3 x nnodes float64; connectivity 4 x nelements int32, 1-based;
! global node ids, nnodes int32, 0-based). Mesh a is the target (its elements own the
! calculation), mesh b the source (its elements travel, with their global node ids).
! For every piece of the local supermesh, the products of the two P1 bases are integrated
! exactly (|c|/20 (sum_v f_v g_v + sum_v f_v sum_v g_v)) into triplets, which are summed
! into CSR rows (global target ids) at the end. Rank 0 prints one line:
!   seconds <max over ranks> pairs <intersecting pairs> triplets <n> nnz <n>
! seconds = parallel_supermesh (bounding boxes, communication, search, clipping, the
! integration callback) + the triplet to CSR summation, after a barrier.
program supermesh_parallel

  use iso_c_binding, only : c_int8_t
  use mpi
  use libsupermesh_parallel_supermesh, only : parallel_supermesh
  use libsupermesh_precision, only : real_kind

  implicit none

  integer :: ierr, rank, nprocs, i
  character(len = 4096) :: dir
  character(len = 32) :: tag
  real(kind = real_kind), allocatable :: positions_a(:, :), positions_b(:, :)
  integer, allocatable :: enlist_a(:, :), enlist_b(:, :), gid_a(:), gid_b(:), owner_a(:), owner_b(:)
  integer, allocatable :: recv_gid(:)
  ! triplets
  integer, allocatable :: trow(:), tcol(:)
  real(kind = real_kind), allocatable :: tval(:)
  integer :: ntrip = 0, pairs = 0, nnz, counts(3)
  double precision :: t0, seconds

  call MPI_Init(ierr)
  call MPI_Comm_rank(MPI_COMM_WORLD, rank, ierr)
  call MPI_Comm_size(MPI_COMM_WORLD, nprocs, ierr)
  call get_command_argument(1, dir)
  write(tag, "(i0,a,i0)") nprocs, "_", rank
  call read_part(trim(dir) // "/target_" // trim(tag) // ".bin", positions_a, enlist_a, gid_a)
  call read_part(trim(dir) // "/source_" // trim(tag) // ".bin", positions_b, enlist_b, gid_b)
  allocate(owner_a(size(enlist_a, 2)), owner_b(size(enlist_b, 2)))
  owner_a = rank
  owner_b = rank
  allocate(trow(1024), tcol(1024), tval(1024))

  call MPI_Barrier(MPI_COMM_WORLD, ierr)
  t0 = MPI_Wtime()
  call parallel_supermesh(positions_a, enlist_a, owner_a, positions_b, enlist_b, owner_b, &
                        & pack_data_b, unpack_data_b, intersection_calculation, comm = MPI_COMM_WORLD)
  call to_csr(nnz)
  seconds = MPI_Wtime() - t0

  call MPI_Allreduce(MPI_IN_PLACE, seconds, 1, MPI_DOUBLE_PRECISION, MPI_MAX, MPI_COMM_WORLD, ierr)
  counts = (/pairs, ntrip, nnz/)
  call MPI_Allreduce(MPI_IN_PLACE, counts, 3, MPI_INTEGER, MPI_SUM, MPI_COMM_WORLD, ierr)
  if(rank == 0) then
    write(*, "(a,es24.16,a,i0,a,i0,a,i0)") "seconds ", seconds, " pairs ", counts(1), " triplets ", counts(2), &
      & " nnz ", counts(3)
  end if
  call MPI_Finalize(ierr)

contains

  subroutine read_part(path, positions, enlist, gid)
    character(len = *), intent(in) :: path
    real(kind = real_kind), allocatable, intent(out) :: positions(:, :)
    integer, allocatable, intent(out) :: enlist(:, :), gid(:)
    integer :: unit, nn, ne
    open(newunit = unit, file = path, access = "stream", form = "unformatted", status = "old", action = "read")
    read(unit) nn, ne
    allocate(positions(3, nn), enlist(4, ne), gid(nn))
    read(unit) positions, enlist, gid
    close(unit)
  end subroutine read_part

  ! The global node ids of the source vertices that travel
  subroutine pack_data_b(nodes_b, eles_b, data_b)
    integer, dimension(:), intent(in) :: nodes_b, eles_b
    integer(kind = c_int8_t), dimension(:), allocatable, intent(out) :: data_b
    integer :: position, extent
    call MPI_Type_extent(MPI_INTEGER, extent, ierr)
    allocate(data_b(size(nodes_b) * extent))
    position = 0
    call MPI_Pack(gid_b(nodes_b), size(nodes_b), MPI_INTEGER, data_b, size(data_b), position, MPI_COMM_WORLD, ierr)
    if(size(eles_b) < 0) stop
  end subroutine pack_data_b

  subroutine unpack_data_b(nnodes_b, nelements_b, data_b)
    integer, intent(in) :: nnodes_b, nelements_b
    integer(kind = c_int8_t), dimension(:), intent(in) :: data_b
    integer :: position
    if(allocated(recv_gid)) deallocate(recv_gid)
    allocate(recv_gid(nnodes_b))
    position = 0
    call MPI_Unpack(data_b, size(data_b), position, recv_gid, nnodes_b, MPI_INTEGER, MPI_COMM_WORLD, ierr)
    if(nelements_b < 0) stop
  end subroutine unpack_data_b

  ! Barycentric coordinates of the points x(:, 1:4) in the tet t
  subroutine barycentric(t, x, lam)
    real(kind = real_kind), intent(in) :: t(3, 4), x(3, 4)
    real(kind = real_kind), intent(out) :: lam(4, 4)
    real(kind = real_kind) :: j(3, 3), inv(3, 3), det, r(3)
    integer :: v
    j(:, 1) = t(:, 2) - t(:, 1)
    j(:, 2) = t(:, 3) - t(:, 1)
    j(:, 3) = t(:, 4) - t(:, 1)
    det = j(1, 1) * (j(2, 2) * j(3, 3) - j(2, 3) * j(3, 2)) - j(1, 2) * (j(2, 1) * j(3, 3) - j(2, 3) * j(3, 1)) &
      & + j(1, 3) * (j(2, 1) * j(3, 2) - j(2, 2) * j(3, 1))
    inv(1, 1) = (j(2, 2) * j(3, 3) - j(2, 3) * j(3, 2)) / det
    inv(1, 2) = (j(1, 3) * j(3, 2) - j(1, 2) * j(3, 3)) / det
    inv(1, 3) = (j(1, 2) * j(2, 3) - j(1, 3) * j(2, 2)) / det
    inv(2, 1) = (j(2, 3) * j(3, 1) - j(2, 1) * j(3, 3)) / det
    inv(2, 2) = (j(1, 1) * j(3, 3) - j(1, 3) * j(3, 1)) / det
    inv(2, 3) = (j(1, 3) * j(2, 1) - j(1, 1) * j(2, 3)) / det
    inv(3, 1) = (j(2, 1) * j(3, 2) - j(2, 2) * j(3, 1)) / det
    inv(3, 2) = (j(1, 2) * j(3, 1) - j(1, 1) * j(3, 2)) / det
    inv(3, 3) = (j(1, 1) * j(2, 2) - j(1, 2) * j(2, 1)) / det
    do v = 1, 4
      r = x(:, v) - t(:, 1)
      lam(2:4, v) = matmul(inv, r)
      lam(1, v) = 1.0_real_kind - sum(lam(2:4, v))
    end do
  end subroutine barycentric

  subroutine push(r, c, v)
    integer, intent(in) :: r, c
    real(kind = real_kind), intent(in) :: v
    integer, allocatable :: ti(:)
    real(kind = real_kind), allocatable :: tv(:)
    if(ntrip == size(trow)) then
      allocate(ti(2 * ntrip)); ti(:ntrip) = trow(:ntrip); call move_alloc(ti, trow)
      allocate(ti(2 * ntrip)); ti(:ntrip) = tcol(:ntrip); call move_alloc(ti, tcol)
      allocate(tv(2 * ntrip)); tv(:ntrip) = tval(:ntrip); call move_alloc(tv, tval)
    end if
    ntrip = ntrip + 1
    trow(ntrip) = r
    tcol(ntrip) = c
    tval(ntrip) = v
  end subroutine push

  subroutine intersection_calculation(element_a, element_b, elements_c, nodes_b, ele_a, ele_b, local)
    real(kind = real_kind), dimension(:, :), intent(in) :: element_a, element_b
    real(kind = real_kind), dimension(:, :, :), intent(in) :: elements_c
    integer, dimension(:), intent(in) :: nodes_b
    integer, intent(in) :: ele_a, ele_b
    logical, intent(in) :: local
    real(kind = real_kind) :: la(4, 4), lb(4, 4), sa(4), sb(4), block(4, 4), vol, e(3, 3)
    integer :: c, k, i, cols(4)
    if(size(elements_c, 3) == 0) return
    block = 0.0_real_kind
    do c = 1, size(elements_c, 3)
      e(:, 1) = elements_c(:, 2, c) - elements_c(:, 1, c)
      e(:, 2) = elements_c(:, 3, c) - elements_c(:, 1, c)
      e(:, 3) = elements_c(:, 4, c) - elements_c(:, 1, c)
      vol = abs(e(1, 1) * (e(2, 2) * e(3, 3) - e(2, 3) * e(3, 2)) - e(1, 2) * (e(2, 1) * e(3, 3) - e(2, 3) * e(3, 1)) &
        & + e(1, 3) * (e(2, 1) * e(3, 2) - e(2, 2) * e(3, 1))) / 6.0_real_kind
      if(vol <= 0.0_real_kind) cycle
      call barycentric(element_a, elements_c(:, :, c), la)
      call barycentric(element_b, elements_c(:, :, c), lb)
      sa = sum(la, 2)
      sb = sum(lb, 2)
      do i = 1, 4
        do k = 1, 4
          block(k, i) = block(k, i) + vol / 20.0_real_kind * (sa(k) * sb(i) + dot_product(la(k, :), lb(i, :)))
        end do
      end do
    end do
    pairs = pairs + 1
    if(local) then
      cols = gid_b(nodes_b)
    else
      cols = recv_gid(nodes_b)
    end if
    do k = 1, 4
      do i = 1, 4
        call push(gid_a(enlist_a(k, ele_a)), cols(i), block(k, i))
      end do
    end do
    if(ele_b < 0) stop
  end subroutine intersection_calculation

  ! Sum the triplets into CSR rows (a marker per column: linear in the triplets)
  subroutine to_csr(nnz)
    integer, intent(out) :: nnz
    integer, allocatable :: start(:), order(:), next(:), marker(:), indices(:)
    real(kind = real_kind), allocatable :: values(:)
    integer :: nrows, ncols, r, q, k, row_begin
    nrows = maxval(gid_a) + 1
    ncols = 0
    if(ntrip > 0) ncols = maxval(tcol(:ntrip)) + 1
    allocate(start(nrows + 1), next(nrows), order(ntrip), marker(max(ncols, 1)), indices(ntrip), values(ntrip))
    start = 0
    do k = 1, ntrip
      start(trow(k) + 2) = start(trow(k) + 2) + 1
    end do
    start(1) = 1
    do r = 2, nrows + 1
      start(r) = start(r) + start(r - 1)
    end do
    next = start(:nrows)
    do k = 1, ntrip
      order(next(trow(k) + 1)) = k
      next(trow(k) + 1) = next(trow(k) + 1) + 1
    end do
    marker = 0
    nnz = 0
    do r = 1, nrows
      row_begin = nnz + 1
      do q = start(r), start(r + 1) - 1
        k = order(q)
        if(marker(tcol(k) + 1) >= row_begin) then
          values(marker(tcol(k) + 1)) = values(marker(tcol(k) + 1)) + tval(k)
        else
          nnz = nnz + 1
          marker(tcol(k) + 1) = nnz
          indices(nnz) = tcol(k)
          values(nnz) = tval(k)
        end if
      end do
    end do
  end subroutine to_csr

end program supermesh_parallel
