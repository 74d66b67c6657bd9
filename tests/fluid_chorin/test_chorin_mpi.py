"""The Chorin fluid on 2 and 3 MPI ranks by grid slabs (fluid_chorin/slabs.py) gives the serial
fields: the flows of mpi_chorin_cases.py under mpirun against the same flows in this process, and
small_fracture coupled with ``ranks = 2`` against ``ranks = 1``.

The bound, EQUAL = 1e-10 of the field's largest value: every owned value is computed by the
serial formula from the same neighbours (the ghost layers hold the neighbours' values), so
the ranks differ from the serial run only by round-off: the order of the sums reduced over
the ranks (norms, means) and, with the direct Poisson solver, MUMPS's Cholesky against PETSc's
own (both to about 1e-15 per solve). Measured: 1e-16 to 5e-16 for every case here, gamg
included (the steady state and each converged implicit time step do not depend on the Poisson
solves' error, only the iterations on the way do)."""

from __future__ import annotations

import json
import shutil

import meshio
import numpy as np
import pytest
from mpi4py import MPI

from coupler.cli import main
from mpi_chorin_cases import solve
from vc_helpers import CASES, ROOT, copy_case, run_mpi

pytestmark = [pytest.mark.skipif(shutil.which("mpirun") is None, reason="mpirun not found"),
              pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="already running under MPI")]

SCRIPT = ROOT / "tests" / "fluid_chorin" / "mpi_chorin_cases.py"
EQUAL = 1e-10
CHORIN = {'participant = "openfoam"': 'participant = "chorin"', "max_iterations = 3000\n": ""}


def assert_equal(a, b) -> None:
    assert np.abs(a - b).max() <= EQUAL * np.abs(b).max(), np.abs(a - b).max() / np.abs(b).max()


def input_planes(bounds: list[int], layers: int | None) -> list[list[int]]:
    """Each rank's input planes: its slab and ``layers`` more each side within the grid (None: all)."""
    n = bounds[-1]
    return [[0, n] if layers is None else [max(0, lo - layers), min(n, hi + layers)]
            for lo, hi in zip(bounds[:-1], bounds[1:])]


@pytest.mark.parametrize("case,poisson,slab_axis,ranks,direction,layers", [
    ("cavity", "direct", "longest", 2, 0, 2),  # closed: a singular Poisson matrix, one cell pinned
    ("cavity", "gamg", "y", 3, 1, 2),
    ("plates", "direct", "longest", 2, 1, 2),  # wall penalization (drag from the neighbours' fractions), open faces
    ("plates", "direct", "x", 2, 0, 2),        # the slabs cut the pressure inlet and outlet apart
    ("plates", "direct", "y", 4, 1, 2),        # ranks 1, 2: a fluid ghost cell's wall drag from a solid cell beyond it
    ("plates_power", "direct", "longest", 3, 1, 1),  # a cell's drag from its own fraction: the ghost layer alone
    ("box", "direct", "longest", 2, 2, 2),     # 3D, transient, a moving and turning block, the inlet cut in slabs
    ("box", "gamg", "x", 3, 0, 2),
    ("bodies", "direct", "x", 2, 0, 2),  # a rigid body across the slab cut, labelled on the ranks
    ("bodies", "gamg", "y", 3, 1, 2),    # across both cuts
    ("rough_gap", "direct", "x", 2, 0, 2),  # lubrication drag: the in-plane faces' from both columns
])
def test_slabs_on_several_ranks_give_the_serial_fields(tmp_path, case, poisson, slab_axis, ranks, direction, layers):
    """Each rank is given the rows of its input cells only (the ghost layer and the wall drag's
    reach beyond its slab): still the serial fields. The steady cavity also logs a progress line
    at every pseudo-time step: they come from rank 0 alone, not once per rank."""
    serial, run = solve(case, poisson, slab_axis)
    out = tmp_path / "fields.npz"
    progress = case == "cavity" and poisson == "direct"
    figures = run_mpi(SCRIPT, ranks, case, poisson, slab_axis, out, *(["progress"] if progress else []))
    if progress:
        assert figures["progress_lines"][0] >= figures["iterations"] - 1 > 10
        assert figures["progress_lines"][1:] == [0] * (ranks - 1)
    assert figures["ranks"] == ranks and figures["direction"] == direction
    assert len(figures["slabs"]) == ranks + 1 and min(np.diff(figures["slabs"])) >= 2
    assert figures["input_planes"] == input_planes(figures["slabs"], layers)
    assert figures["same_solid"] == [True] * ranks  # drag and solid velocity bit for bit
    assert figures["converged"] and figures["poisson_converged"] and run.converged
    assert figures["iterations"] == run.report.iterations
    assert figures["poisson"] == {"direct": "Cholesky (MUMPS)", "gamg": "CG + GAMG"}[poisson]
    parallel = np.load(out)
    assert_equal(parallel["pressure"], serial.cell_pressure())
    assert_equal(parallel["velocity"], serial.cell_velocity())


@pytest.mark.parametrize("slab_axis, ranks, fine, coarse", [("longest", 2, [0, 6, 13], [0, 3, 7]),
                                                           pytest.param("y", 3, [0, 4, 8, 13], [0, 2, 4, 7],
                                                                        marks=pytest.mark.slow)])
def test_the_flow_on_the_coarsened_grid_on_ranks_is_the_serial_one(tmp_path, slab_axis, ranks, fine, coarse):
    """The plates' flow rate on the grid coarsened across y (fluid_chorin/coarsened.py: the error
    estimate's) on 2 and 3 ranks equals the serial one to EQUAL, the slabs cut across the gap
    itself, the coarse grid's cuts at other planes than the fine one's (the pairs joined over the
    ranks)."""
    from mpi_chorin_cases import coarse_rate

    serial, _ = solve("plates", "direct", slab_axis)
    rate, _ = coarse_rate(serial, "plates")
    figures = run_mpi(SCRIPT, ranks, "plates", "direct", slab_axis, tmp_path / "fields.npz", "coarsened")
    assert figures["slabs"] == fine and figures["coarse_slabs"] == coarse
    assert abs(figures["coarse_rate"] - rate) <= EQUAL * abs(rate) and rate > 0


@pytest.mark.parametrize("slab_axis", ["longest", "z"])
def test_small_fracture_with_two_chorin_ranks_gives_the_one_rank_run(tmp_path, slab_axis):
    """varcouple run with [solvers.fluid] ranks = 2 (mpirun -n 2, slabs along x, the longest, or
    across the fracture along z, each rank given its input cells only): the same coupling
    iterations, displacements and fluid fields as one rank, to EQUAL."""
    runs = {}
    for ranks in (1, 2):
        case = copy_case(CASES / "small_fracture", tmp_path / f"case{ranks}",
                         {**CHORIN, 'penalization = "wall"': f'penalization = "wall"\nranks = {ranks}\n'
                                                            f'slab_axis = "{slab_axis}"'})
        out = tmp_path / f"out{ranks}"
        assert main(["run", str(case), "--output", str(out)]) == 0
        runs[ranks] = out, json.loads((out / "summary.json").read_text())
    (one, s1), (two, s2) = runs[1], runs[2]
    assert [p["ranks"] for p in s2["participants"] if p["name"] == "fluid"] == [2]
    assert s2["iterations"] == s1["iterations"] == [5, 1]
    assert "fluid: chorin on 2 MPI ranks" in " ".join(s2["tasks"])
    assert s2["steps"][0]["solves"]["fluid"][1]["solver"] == "pressure Poisson (Cholesky (MUMPS))"
    for step in (0, 1):
        assert s2["steps"][step]["max_displacement"] == pytest.approx(s1["steps"][step]["max_displacement"],
                                                                       rel=EQUAL)
    for name, fields in (("fluid_0001.vtu", ("pressure", "velocity")), ("solid_0001.vtu", ("displacement",))):
        a, b = meshio.read(two / name), meshio.read(one / name)
        for field in fields:
            data = (a.cell_data[field][0], b.cell_data[field][0]) if field in a.cell_data else \
                (a.point_data[field], b.point_data[field])
            assert_equal(*data)


def test_the_ranks_benchmark_times_the_cavity_on_one_and_two_ranks():
    """bench/fluids.py --ranks runs ``--cavity`` under mpirun: one JSON line from rank 0."""
    rows = [run_mpi(ROOT / "bench" / "fluids.py", r, "--cavity", 8, 8, 1, 3, "direct") for r in (1, 2)]
    assert [row["ranks"] for row in rows] == [1, 2] and [row["cells"] for row in rows] == [64, 64]
    assert [row["poisson"] for row in rows] == ["Cholesky", "Cholesky (MUMPS)"]
    assert all(row["seconds_per_step"] > 0 and 0 < row["poisson_share"] < 1 for row in rows)
