"""Distributed transfer (issue: parallel information transfer): B, D, T and the transferred
field assembled on 1 to 4 MPI ranks, with source and target partitioned independently and
not aligned, equal the serial ones to 1e-12 (mpi_transfer_cases.py under mpirun, 3 and 4
ranks oversubscribed); the serial path loads no MPI; parts and partitions."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from transfer import FunctionSpace, StructuredGrid, Transfer, TransferError
from transfer.generate import box_tetrahedra
from vc_helpers import ROOT

HERE = Path(__file__).resolve().parent
EQUAL = 1e-12
needs_mpirun = pytest.mark.skipif(shutil.which("mpirun") is None, reason="no mpirun")


def mpi_env() -> dict:
    return dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1", OMP_NUM_THREADS="1",
                PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))


@pytest.fixture(scope="module", params=[1, 2, 3, 4])
def distributed(request):
    ranks = request.param
    cmd = ["mpirun", "-n", str(ranks), "--oversubscribe", sys.executable, str(HERE / "mpi_transfer_cases.py")]
    proc = subprocess.run(cmd, capture_output=True, text=True, env=mpi_env(), timeout=300, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr[-3000:]
    result = json.loads(proc.stdout.strip().splitlines()[-1])
    assert result["ranks"] == ranks
    return result["cases"]


CASES = ["tets P1 -> tets P1", "tets P0 -> tets P0", "hexes Q1 -> tets P1", "grid Q1 -> tets P1",
         "tets P1 -> grid Q0 (partial)", "tets P1 -> triangles P1 (trace)", "triangles P1 -> quads Q1 (mortar)",
         "tets P1 -> tets P1 (empty ranks)"]


@needs_mpirun
@pytest.mark.parametrize("case", CASES)
@pytest.mark.parametrize("method", ["l2", "pseudo_l2"])
def test_distributed_equals_serial(distributed, case, method):
    r = distributed[case][method]
    assert r["B"] <= EQUAL and r["D"] <= EQUAL and r["T"] <= EQUAL
    assert r["v"] <= EQUAL
    assert r["nan_same"] and r["covered_same"]
    assert r["pairs"][0] == r["pairs"][1]  # every intersecting pair found once, by its target's rank
    assert r["conservation"] < 1e-13


@needs_mpirun
def test_partial_overlap_leaves_the_same_dofs_uncovered(distributed):
    r = distributed["tets P1 -> grid Q0 (partial)"]["l2"]
    assert 0.1 < r["covered_fraction"] < 0.5 and r["nan_same"]


def test_serial_path_loads_no_mpi():
    code = ("import sys, numpy as np\n"
            "from transfer import FunctionSpace, Transfer\n"
            "from transfer.generate import box_tetrahedra\n"
            "S = FunctionSpace(box_tetrahedra((2, 2, 2)), 'P1')\n"
            "T = Transfer.assemble(S, S, 'l2'); T(np.ones(S.num_dofs))\n"
            "print(sorted(m for m in ('mpi4py', 'petsc4py') if m in sys.modules))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=60)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"


def test_with_comm_the_spaces_must_be_parts():
    from mpi4py import MPI

    S = FunctionSpace(box_tetrahedra((2, 2, 2)), "P1")
    with pytest.raises(TransferError, match="transfer.distributed.Part"):
        Transfer.assemble(S, S, "l2", comm=MPI.COMM_SELF)


def test_a_part_needs_one_global_id_per_dof():
    from transfer.distributed import Part

    mesh = box_tetrahedra((2, 2, 2), name="box")
    with pytest.raises(TransferError, match="box: 3 global dof ids for 27 local P1 dofs"):
        Part(mesh, "P1", [0, 1, 2])


def test_grid_blocks_number_dofs_as_the_whole_grid():
    from transfer.distributed import Part

    grid = StructuredGrid.from_bounds((0, 0, 0), (1, 2, 3), (4, 5, 6))
    for family, whole in (("Q1", grid.points), ("Q0", grid.cell_centers())):
        part = Part.grid_block(grid, (1, 2, 3), (3, 5, 4), family)
        assert part.mesh.shape == (2, 3, 1)
        local = part.mesh.points if family == "Q1" else part.mesh.cell_centers()
        np.testing.assert_allclose(local, whole[part.global_dofs], rtol=0, atol=1e-14)
    assert Part.grid_block(grid, (0, 0, 4), (4, 5, 4), "Q1").num_cells == 0


def test_partitions_balance_the_cells():
    from transfer.distributed import Part
    from transfer.partition import bisection, slabs

    mesh = box_tetrahedra((5, 4, 3), jitter=0.2, seed=1)
    for owner in (slabs(mesh, 3, axis=0), bisection(mesh, 3)):
        counts = np.bincount(owner, minlength=3)
        assert counts.sum() == mesh.num_cells and counts.max() - counts.min() <= 1
    centres = mesh.points[mesh.cells].mean(axis=1)
    owner = slabs(mesh, 3, axis=2)
    assert centres[owner == 0, 2].max() <= centres[owner == 1, 2].min()
    part = Part.of_cells(mesh, np.flatnonzero(owner == 1), "P1")
    np.testing.assert_array_equal(part.mesh.points, mesh.points[part.global_dofs])


def test_box_search_finds_every_overlap_touching_ones_too():
    """Step 2's selection of the source cells a neighbour needs (a sorted sweep in x) equals
    the brute-force test of every box against every cluster, boxes that only touch included."""
    from transfer.distributed import _meets

    rng = np.random.default_rng(4)
    lower = np.round(rng.uniform(-5, 5, (2000, 3)), 1)  # on a 0.1 lattice: many exact touches
    size = np.round(rng.uniform(0, 1.5, (2000, 3)), 1)
    size[:, 0] = 1.5  # all as wide as the widest: the sweep's bound is met exactly
    boxes = np.stack([lower, lower + size], axis=1) + 1e6
    lo = np.round(rng.uniform(-5, 5, (40, 3)), 1)
    others = np.stack([lo, lo + np.round(rng.uniform(0, 2, (40, 3)), 1)], axis=1) + 1e6
    brute = np.zeros(len(boxes), bool)
    for a, b in others:
        brute |= np.all(boxes[:, 0] <= b, axis=1) & np.all(boxes[:, 1] >= a, axis=1)
    touching = np.any(np.isin(boxes[:, 1, 0], others[:, 0, 0]))
    assert touching and 0 < brute.sum() < len(boxes)
    np.testing.assert_array_equal(_meets(boxes, others), brute)
    assert not _meets(boxes, others[:0]).any() and len(_meets(boxes[:0], others)) == 0


def status_mb(key: str) -> float:
    """A figure of /proc/self/status (VmRSS, VmHWM, RssAnon) in MB."""
    return int(next(line for line in Path("/proc/self/status").read_text().splitlines()
                    if line.startswith(key)).split()[1]) / 1024


@pytest.fixture(params=[False, True], ids=["serial", "distributed"])
def box_to_grid(request):
    """Assembles pseudo-L2 from a 24^3 box of P1 tets (82,944) to a 30^3 Q0 grid, serial or on
    COMM_WORLD (a process of its own: one rank)."""
    from mpi4py import MPI

    from transfer.distributed import Part, assemble

    S = box_tetrahedra((24, 24, 24), (0, 0, 0), (1, 1, 1))
    G = StructuredGrid((0, 0, 0), (1 / 30,) * 3, (30, 30, 30))
    if request.param:
        source, target = Part.of_cells(S, np.arange(S.num_cells), "P1"), Part.grid_block(G, (0, 0, 0), G.shape, "Q0")
        return lambda: assemble(source, target, "pseudo_l2", MPI.COMM_WORLD)
    return lambda: Transfer.assemble(FunctionSpace(S, "P1"), FunctionSpace(G, "Q0"), "pseudo_l2")


@pytest.mark.parametrize("world", [False, True], ids=["COMM_SELF", "COMM_WORLD"])
def test_a_rebuilt_transfer_frees_its_predecessor(world):
    """petsc4py queues the objects Python drops until a cleanup of their communicator: assemble
    cleans its own and PETSc's COMM_SELF (the sequential scatters of every transfer), so
    rebuilding a transfer (the coupler does, each time the solid deforms) keeps one set of
    matrices and scatters, not all of them (before: 7.6 MB more for each of these rebuilds;
    on COMM_WORLD, where only the scatters stayed, 0.5 MB each)."""
    import ctypes

    from mpi4py import MPI

    from transfer.distributed import Part, assemble

    libc = ctypes.CDLL("libc.so.6")

    def private_mb() -> float:  # the heap given back first: freed memory is not counted
        libc.malloc_trim(0)
        return status_mb("RssAnon")

    S = box_tetrahedra((24, 24, 24), (0, 0, 0), (1, 1, 1))
    G = StructuredGrid((0, 0, 0), (1 / 30,) * 3, (30, 30, 30))
    source, target = Part.of_cells(S, np.arange(S.num_cells), "P1"), Part.grid_block(G, (0, 0, 0), (30, 30, 30), "Q0")
    comm = MPI.COMM_WORLD if world else MPI.COMM_SELF
    T = assemble(source, target, "pseudo_l2", comm)
    first = private_mb()
    for _ in range(6):
        T = None
        T = assemble(source, target, "pseudo_l2", comm)
    assert T.num_covered == 30**3
    assert private_mb() - first < 1.0


def test_matrices_are_made_from_the_kernels_rows_without_copies_of_them():
    """transfer.petsc.aij puts the kernel's CSR rows straight into PETSc's preallocated block: its
    peak resident memory is PETSc's matrix (12 B per entry) and a few bytes per entry more, not the
    triplets, their sorted copies and scipy's CSR (85 B per entry before), and it sums rows given
    twice (ADD) as the serial CSR does."""
    import ctypes

    import scipy.sparse as sp
    from mpi4py import MPI

    from transfer.petsc import aij, destroy_dropped, gather_matrix, ownership

    m, n, k = 100_000, 50_000, 10
    rng = np.random.default_rng(0)
    indptr, indices, data = np.arange(m + 1) * k, rng.integers(0, n, m * k).astype(np.int32), rng.random(m * k)
    rows = rng.permutation(m)
    rows[-1] = rows[0]  # a row given twice: summed
    comm = MPI.COMM_WORLD
    ctypes.CDLL("libc.so.6").malloc_trim(0)
    Path("/proc/self/clear_refs").write_text("5")  # the peak resident memory starts again from now
    before = status_mb("VmRSS")
    A = aij(comm, (indptr, indices, data), rows, np.arange(n), (m, n), ownership(m, 1), ownership(n, 1))
    per_entry = (status_mb("VmHWM") - before) * 2**20 / (m * k)
    placed = sp.csr_matrix((np.ones(m), (rows, np.arange(m))), shape=(m, m))  # row i to rows[i]
    expected = placed @ sp.csr_matrix((data, indices, indptr), shape=(m, n))
    assert abs(gather_matrix(A, comm) - expected).max() < 1e-15
    assert per_entry < 35.0, per_entry
    A = None
    destroy_dropped(comm)


def test_the_kernels_peak_is_its_search_and_its_rows():
    """The kernel's peak resident memory while it assembles (P1 tets -> Q0 grid, 82,944 tets) is
    its search structures (each tet's packed vertices, 96 B, and its filed box, 56 B) and its
    rows: the search goes before the rows are merged, the row pieces before the CSR is made, and
    no tet box is kept twice (before: 442 B per tet, now about 265). Measured in a fresh process
    with malloc tuned as a coupler's (coupler.protocol.transport.tune_malloc): the figure depends on
    what the heap held before."""
    code = """
import ctypes, sys
from pathlib import Path
from coupler.protocol.transport import tune_malloc
from transfer import FunctionSpace, StructuredGrid
from transfer.assembly import assemble_rows, integration_rule
from transfer.generate import box_tetrahedra

def rss(key):
    status = Path("/proc/self/status").read_text().splitlines()
    return int(next(line for line in status if line.startswith(key)).split()[1]) * 1024

tune_malloc()
S = box_tetrahedra((24, 24, 24), (0, 0, 0), (1, 1, 1))
source, target = FunctionSpace(S, "P1"), FunctionSpace(StructuredGrid((0, 0, 0), (1 / 30,) * 3, (30, 30, 30)), "Q0")
rule = integration_rule(source, target, None)
raw = None
for _ in range(2):  # the first run's pages (first use) out of the figure
    raw = None
    ctypes.CDLL("libc.so.6").malloc_trim(0)
    Path("/proc/self/clear_refs").write_text("5")
    before = rss("VmRSS")
    raw = assemble_rows(source, target, "pseudo_l2", rule, search_distance=0.0, max_normal_angle=90.0, nthreads=1)
    peak = rss("VmHWM") - before
print(raw["pairs_intersected"], peak / S.num_cells)
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert out.returncode == 0, out.stderr
    pairs, per_tet = out.stdout.split()
    assert int(pairs) == 430272
    assert float(per_tet) < 320.0, per_tet


def test_an_assembly_leaves_no_freed_heap_resident(box_to_grid):
    """An assembly frees several times what it keeps (the kernel's row pieces, the matrices'
    intermediates); assemble gives those pages back (transfer.heap.give_back), so a rebuilt transfer
    does not leave the process at the peak of its assembly: the private memory right after it is
    what stays after glibc trims its heap (before: 33 MB more here, serial and distributed alike)."""
    import ctypes

    T = box_to_grid()
    T = None
    T = box_to_grid()
    after = status_mb("RssAnon")
    ctypes.CDLL("libc.so.6").malloc_trim(0)
    assert T.covered.all()
    assert after - status_mb("RssAnon") < 1.0


def test_an_assembly_runs_in_the_heap_its_caller_freed(box_to_grid):
    """What the caller freed before an assembly (here 64 MB of small arrays, one in eight kept, so
    the heap cannot shrink from its top) is given back before the kernel runs, so the assembly's
    large arrays take those pages again instead of adding to them: the peak above the memory
    resident when it starts, freed heap included, is a fraction of the peak without that heap."""
    import ctypes

    from mpi4py import MPI

    from transfer.petsc import destroy_dropped

    def peak(garbage: bool) -> float:
        """The peak resident memory of an assembly above the memory resident when it starts."""
        destroy_dropped(MPI.COMM_WORLD)
        ctypes.CDLL("libc.so.6").malloc_trim(0)
        kept = []
        if garbage:
            arrays = [np.ones(2048) for _ in range(4096)]  # 16 kB each: on the heap, not mapped
            kept = arrays[::8]
            del arrays
        Path("/proc/self/clear_refs").write_text("5")  # the peak starts again from now
        before = status_mb("VmRSS")
        T = box_to_grid()
        assert T.covered.all() and len(kept) in (0, 512)
        return status_mb("VmHWM") - before

    peak(False)
    clean = peak(False)
    assert clean > 20.0 and peak(True) < 0.25 * clean, clean
