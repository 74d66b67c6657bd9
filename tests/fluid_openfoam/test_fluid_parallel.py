"""The decomposed (MPI-parallel) OpenFOAM fluid (fluid_openfoam/parallel.py): decomposePar
once, inputs written and outputs read per processor through cellProcAddressing, never
reconstructPar. A 2-rank solve gives the serial fields to the solver's tolerance; a coupled
case runs with ``[solvers.fluid] ranks = 2`` and gives the serial coupled result."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from coupler.cli import main
from fluid_openfoam.case import CaseSpec
from fluid_openfoam.parallel import simple_split
from fluid_openfoam.solver import OpenFOAMSolver, time_dirs
from vc_helpers import ROOT, copy_case

needs_mpi_foam = pytest.mark.skipif(shutil.which("simpleFoam") is None or shutil.which("mpirun") is None
                                    or shutil.which("decomposePar") is None,
                                    reason="OpenFOAM (simpleFoam, decomposePar) or mpirun not installed")


def test_simple_split_cuts_fewest_faces():
    assert simple_split(2, (16, 8, 4)) == (2, 1, 1)  # cut across the longest axis
    assert simple_split(2, (4, 16, 8)) == (1, 2, 1)
    assert simple_split(4, (8, 8, 1)) == (2, 2, 1)  # 8 + 8 faces, against 24 for (4, 1, 1)
    assert simple_split(3, (2, 9, 1)) == (1, 3, 1)
    assert simple_split(1, (3, 3, 3)) == (1, 1, 1)
    with pytest.raises(ValueError, match="cannot split"):
        simple_split(5, (2, 2, 1))


def test_a_bad_method_is_rejected():
    grid = {"origin": [0, 0, 0], "spacing": [1, 1, 1], "shape": [4, 2, 2]}
    with pytest.raises(ValueError, match="decomposition: unknown value 'scotch'; use one of 'simple'"):
        CaseSpec.from_config({"grid": grid, "decomposition": "scotch"}, ranks=2)


def channel(ranks: int, **extra) -> CaseSpec:
    """A 3D duct (16 x 8 x 4 cells of 1 mm) with a velocity inlet and an immersed step (a
    solid layer with a sub-cell wall): inlet masking, penalization and the pressure solve
    all cross the processor boundary."""
    return CaseSpec.from_config({"grid": {"origin": [0, 0, 0], "spacing": [1e-3] * 3, "shape": [16, 8, 4]},
                                 "inlet": {"velocity": [0.01, 0, 0]}, "mu": 1e-3, "rho": 1000.0,
                                 "tolerance": 1e-10, "max_iterations": 3000, **extra}, ranks=ranks)


def step_fraction(spec: CaseSpec, height: float) -> np.ndarray:
    """Solid below y = height (exact fractions of an axis-aligned layer) and a block from x = 6 mm."""
    c = spec.grid.cell_centres()
    h = spec.grid.spacing[1]
    frac = np.clip((height - (c[:, 1] - h / 2)) / h, 0.0, 1.0)
    frac[(c[:, 0] > 6e-3) & (c[:, 0] < 9e-3) & (c[:, 1] < 5e-3)] = 1.0
    return frac


@needs_mpi_foam
def test_two_ranks_give_the_serial_fields(tmp_path):
    serial = OpenFOAMSolver(tmp_path / "serial", channel(1))
    parallel = OpenFOAMSolver(tmp_path / "parallel", channel(2))
    serial.setup()
    parallel.setup()
    assert parallel.parallel is not None and len(parallel.parallel.processors) == 2
    sizes = [len(c) for c in parallel.parallel.cells]
    assert sum(sizes) == serial.n and min(sizes) >= serial.n // 2 - 16
    for height in (2.3e-3, 2.6e-3):  # two advances: the second from the first's (processor) time directory
        frac = step_fraction(serial.spec, height)
        Us, ps = serial.solve(frac)
        Up, pp = parallel.solve(frac)
        assert serial.last_run["converged"] and parallel.last_run["converged"], (serial.last_run, parallel.last_run)
        # simpleFoam stops at the residual tolerance (1e-10): the fields agree to far better than 1e-6
        assert np.max(np.abs(Up - Us)) < 1e-6 * np.max(np.abs(Us)), np.max(np.abs(Up - Us))
        assert np.max(np.abs(pp - ps)) < 1e-6 * np.max(np.abs(ps)), np.max(np.abs(pp - ps))
        assert abs(parallel.last_run["iterations"] - serial.last_run["iterations"]) <= 0.1 * serial.last_run["iterations"]
    assert "nProcs : 2" in (tmp_path / "parallel" / "log.simpleFoam").read_text()
    # no reconstruction: the case root holds only the initial time, the processors the results
    assert list(time_dirs(tmp_path / "parallel").values()) == ["0"]
    assert parallel.start in time_dirs(tmp_path / "parallel" / "processor1").values()
    # a repeated window (restore_state): from time 0 again, the stale processor results are replaced
    parallel.start = "0"
    Up2, _ = parallel.solve(frac)
    assert np.max(np.abs(Up2 - Up)) < 1e-6 * np.max(np.abs(Us))


SMALL = ROOT / "cases" / "small_fracture"


@needs_mpi_foam
def test_coupled_small_fracture_with_two_fluid_ranks(tmp_path, capsys):
    """small_fracture, one step, fluid on 2 ranks: the plan says so, the run converges and
    gives the serial run's displacement and iteration count."""
    results = {}
    for ranks in (1, 2):
        extra = f"\nranks = {ranks}\ndecomposition = \"simple\"" if ranks > 1 else ""
        case = copy_case(SMALL, tmp_path / f"r{ranks}",
                         {"steps = 2": "steps = 1", 'participant = "openfoam"': f'participant = "openfoam"{extra}'})
        if ranks > 1:
            assert main(["check", str(case)]) == 0
            printed = capsys.readouterr().out
            assert "fluid: openfoam on 2 MPI ranks (simple decomposition" in printed
            assert "participant   fluid: openfoam (python -m fluid_openfoam, 2 ranks)" in printed
        out = tmp_path / f"out{ranks}"
        assert main(["run", str(case), "--output", str(out)]) == 0, capsys.readouterr().err
        results[ranks] = json.loads((out / "summary.json").read_text())
    s1, s2 = results[1]["steps"][0], results[2]["steps"][0]
    assert s2["converged"] and s2["iterations"] == s1["iterations"], (s1, s2)
    assert abs(s2["max_displacement"] / s1["max_displacement"] - 1) < 1e-4, (s1, s2)
    log = (tmp_path / "out2" / "logs" / "fluid.log").read_text()
    assert "Traceback" not in log


@needs_mpi_foam
def test_two_ranks_with_a_moving_body(tmp_path):
    """A solid body moving at a uniform velocity (one velocity source on its cellSet,
    fluid_openfoam/zones.py): each processor gets its part of the set; the fields match. The body
    spans z from face to face and moves in z, so those faces are open (fixed pressure): through
    closed ones the participant drops the normal velocity (incompressibility)."""
    open_z = {"boundaries": {"zmin": {"pressure": 0.0}, "zmax": {"pressure": 0.0}}}
    serial = OpenFOAMSolver(tmp_path / "serial", channel(1, **open_z))
    parallel = OpenFOAMSolver(tmp_path / "parallel", channel(2, **open_z))
    serial.setup()
    parallel.setup()
    frac = step_fraction(serial.spec, 2.3e-3)
    velocity = np.where(frac[:, None] > 0.5, [0.0, 0.0, 2e-3], 0.0)
    Us, ps = serial.solve(frac, velocity)
    Up, pp = parallel.solve(frac, velocity)
    assert serial.sources and len(parallel.sources) == len(serial.sources)
    assert serial.last_run["converged"] and parallel.last_run["converged"]
    assert np.max(np.abs(Up - Us)) < 1e-6 * np.max(np.abs(Us))
    assert np.max(np.abs(pp - ps)) < 1e-6 * np.max(np.abs(ps))
    assert np.mean(Up[frac > 0.99, 2]) > 1e-3  # the source acts on both processors' cells of the body
