"""The OpenFOAM fluid on 2 MPI ranks behind the coupler's client (docs/protocol.md, "Parts"): rank r
handles processor<r> of the decomposed case only. Each rank's part holds its processor's cells
(cellProcAddressing) and declares as input_ids those and the cells their wall drag reads; it receives
exactly those rows; the coupler's join equals, bitwise, the whole arrays one process gave from the same
decomposed case (the participant before it ran per processor). A processor directory missing or
malformed, a result file malformed and a rank that dies are one-line errors naming the participant,
the rank and the file or key."""

from __future__ import annotations

import re
import shutil

import numpy as np
import pytest

from coupler.plan.plan import make_plan
from coupler.protocol.errors import ParticipantDied, ParticipantError
from coupler.scene import load
from fluid_openfoam.case import CaseSpec
from fluid_openfoam.fields import read_label_list
from fluid_openfoam.solver import OpenFOAMSolver
from transfer.labels import cell_box
from transfer.penalization import reach
from vc_helpers import CASES

pytestmark = pytest.mark.skipif(shutil.which("simpleFoam") is None or shutil.which("mpirun") is None
                                or shutil.which("decomposePar") is None,
                                reason="OpenFOAM (simpleFoam, decomposePar) or mpirun not installed")

RECORDING = '''
import os, shutil, signal
import numpy as np
from coupler.protocol.participant import main
from fluid_openfoam import parallel, solver
from fluid_openfoam.participant import FluidParticipant

class Recording(FluidParticipant):
    """The OpenFOAM fluid saving, per rank, the ids it declared and the input rows it received; its
    argument breaks processor1 ("malformed", "missing": after decomposePar; "result": its U after the
    solve), gives every rank a NaN in its result ("nan") or kills rank 1 in advance ("die")."""
    def geometry(self):
        header, fields = super().geometry()
        self.declared = fields
        return header, fields

    def advance(self, window, iteration, t, dt, inputs):
        if self.rank == 1 and self.extra_args == ["die"]:
            os.kill(os.getpid(), signal.SIGKILL)
        np.savez(os.path.join(os.environ["RECORD_DIR"], f"rank{self.rank}.npz"), **self.declared,
                 **{name: f.data for name, f in inputs.items()})
        return super().advance(window, iteration, t, dt, inputs)

decompose, ended = parallel.Decomposition.decompose, solver.OpenFOAMSolver._ended

def broken_decompose(self, run):
    decompose(self, run)
    mesh = self.case / "processor1" / "constant" / "polyMesh"
    if os.environ["FAULT"] == "malformed":
        (mesh / "cellProcAddressing").write_text("not a label list")
    if os.environ["FAULT"] == "missing":
        shutil.rmtree(self.case / "processor1")

def broken_result(self, t0, wall):
    end, run = ended(self, t0, wall)
    (self.case / "processor1" / end / "U").write_bytes(b"FoamFile { format binary; }\\ninternalField nonsense;")
    return end, run

read_cells = solver.OpenFOAMSolver.read_cells

def diverged(self, time, name):
    values = read_cells(self, time, name).copy()
    values[2] = np.nan
    return values

parallel.Decomposition.decompose = broken_decompose
if os.environ["FAULT"] == "result":
    solver.OpenFOAMSolver._ended = broken_result
if os.environ["FAULT"] == "nan":
    solver.OpenFOAMSolver.read_cells = diverged
main(Recording)
'''


def config(case_dir) -> dict:
    """A 3D duct (16 x 8 x 4 cells of 1 mm) with a velocity inlet, split in x by decomposePar."""
    return {"grid": {"origin": [0, 0, 0], "spacing": [1e-3] * 3, "shape": [16, 8, 4]}, "location": "cells",
            "inlet": {"velocity": [0.01, 0, 0]}, "mu": 1e-3, "rho": 1000.0, "tolerance": 1e-8,
            "max_iterations": 400, "case_dir": str(case_dir)}


def step_fraction() -> np.ndarray:
    """Solid below y = 2.3 mm (a sub-cell wall) and a block from x = 6 to 9 mm: wall drag on both processors
    and next to their boundary, inlet masking on processor 0."""
    spec = CaseSpec.from_config(config(""))
    c, h = spec.grid.cell_centres(), spec.grid.spacing[1]
    frac = np.clip((2.3e-3 - (c[:, 1] - h / 2)) / h, 0.0, 1.0)
    frac[(c[:, 0] > 6e-3) & (c[:, 0] < 9e-3) & (c[:, 1] < 5e-3)] = 1.0
    return frac


@pytest.fixture
def fluid(tmp_path, launch_script):
    return lambda fault="": launch_script("fluid", "recording_openfoam", RECORDING, [fault] if fault else [],
                                          {"RECORD_DIR": str(tmp_path), "FAULT": fault}, timeout=120)


def test_each_rank_publishes_its_processor_and_the_join_is_the_whole_arrays(fluid, tmp_path):
    client = fluid()
    client.configure(config(tmp_path / "case"))
    header, _ = client.geometry()
    assert header["grid"]["shape"] == [16, 8, 4] and client.parts == 2
    fraction = step_fraction()
    out = client.advance(0, 0, 0.0, 1.0, {"solid_fraction": fraction})
    for rank in (0, 1):
        mine = read_label_list(tmp_path / "case" / f"processor{rank}" / "constant" / "polyMesh" / "cellProcAddressing")
        got = np.load(tmp_path / f"rank{rank}.npz")
        assert np.array_equal(got["cell_ids"], mine) and len(mine) == 256  # its processor's cells, no other
        assert np.array_equal(got["input_ids"], reach(mine, (16, 8, 4), "wall"))
        assert len(got["input_ids"]) == 256 + 32  # and the plane of cells across the processor boundary
        assert np.array_equal(got["solid_fraction"], fraction[got["input_ids"]])
    # the whole arrays of one process handling both processors of the same decomposition
    whole = OpenFOAMSolver(tmp_path / "whole", CaseSpec.from_config(config(""), ranks=2))
    whole.setup()
    U, p = whole.solve(fraction)
    assert whole.last_run["converged"], whole.last_run  # equal arrays of converged solves, not of two stalled ones
    assert np.array_equal(out["velocity"].data, U) and np.array_equal(out["pressure"].data, p * 1000.0)
    assert np.abs(U).max() > 1e-3 and np.ptp(p) > 0
    # rigid bodies are labelled across the processors by a transient fluid's ranks: a steady one refuses them
    with pytest.raises(ParticipantError, match=r"rank 0: input 'solid_velocity': solid_velocity 'bodies' on several "
                                               r"ranks needs a transient fluid.*; rank 1: varcouple/.*/fluid/advance/1"):
        client.advance(0, 1, 0.0, 1.0, {"solid_fraction": fraction, "solid_velocity": np.zeros((fraction.size, 3))})


def test_rigid_bodies_are_labelled_across_the_processors(fluid, tmp_path):
    """Transient with a moving body (solid_velocity "bodies") on both processors: each rank asks for
    its cells and their face neighbours only (the wall drag's reach: 288 of the 512 cells, the whole
    grid before) and the ranks label the body together; rank 0 writes the velocity source into
    fvOptions, each rank its processor's cellSet: the files equal those of one process handling both
    processors from the whole grid, the join its arrays. The body spans z and moves in z: those
    faces are open."""
    cfg = {**config(tmp_path / "case"), "transient": True, "dt": 0.01,
           "boundaries": {"zmin": {"pressure": 0.0}, "zmax": {"pressure": 0.0}}}
    client = fluid()
    client.configure(cfg)
    client.geometry()
    fraction = step_fraction()
    velocity = np.where(fraction[:, None] > 0.5, [0.0, 0.0, 2e-3], 0.0)
    out = client.advance(0, 0, 0.0, 0.01, {"solid_fraction": fraction, "solid_velocity": velocity})
    for rank in (0, 1):
        mine = read_label_list(tmp_path / "case" / f"processor{rank}" / "constant" / "polyMesh" / "cellProcAddressing")
        got = np.load(tmp_path / f"rank{rank}.npz")
        assert np.array_equal(got["input_ids"], reach(mine, (16, 8, 4), "wall", at_least=1))
        assert len(got["input_ids"]) == 288 and np.array_equal(got["solid_velocity"], velocity[got["input_ids"]])
    whole = OpenFOAMSolver(tmp_path / "whole", CaseSpec.from_config(cfg, ranks=2))
    whole.setup()
    U, p = whole.solve(fraction, velocity, 0.0, 0.01)
    assert whole.last_run["converged"], whole.last_run
    assert len(whole.sources) == 1 and np.mean(U[fraction > 0.99, 2]) > 1e-3  # the body moves the fluid
    for name in ["constant/fvOptions"] + [f"processor{r}/constant/polyMesh/sets/solidBody0" for r in (0, 1)]:
        assert (tmp_path / "case" / name).read_text() == (tmp_path / "whole" / name).read_text(), name
    assert np.array_equal(out["velocity"].data, U) and np.array_equal(out["pressure"].data, p * 1000.0)


@pytest.mark.parametrize("fault, text", [
    ("malformed", "{case}/processor1/constant/polyMesh/cellProcAddressing: no FoamFile header"),
    ("missing", "{case}/processor1/constant/polyMesh/cellProcAddressing: missing (decomposePar did not write "
                "processor1)")])
def test_a_broken_processor_directory_names_the_rank_and_the_file(fluid, tmp_path, fault, text):
    client = fluid(fault)
    error = "FieldFormatError" if fault == "malformed" else "OpenFOAMError"
    with pytest.raises(ParticipantError) as info:
        client.configure(config(tmp_path / "case"))
    assert str(info.value) == (f"participant 'fluid' failed: RanksError: rank 1: {error}: "
                               + text.format(case=tmp_path / "case"))


def test_a_malformed_result_names_the_rank_and_the_file(fluid, tmp_path):
    client = fluid("result")
    client.configure(config(tmp_path / "case"))
    client.geometry()
    with pytest.raises(ParticipantError, match=r"^participant 'fluid' failed: RanksError: rank 1: FieldFormatError: "
                                               + f"{tmp_path}/case/processor1/" + r"\d+/U: "):
        client.advance(0, 0, 0.0, 1.0, {"solid_fraction": step_fraction()})


def test_a_result_with_nan_on_every_rank_quotes_the_shared_log_once(fluid, tmp_path):
    """Both ranks find a NaN in their processor's result: each is named with its processor's time
    directory; the log both share is quoted by rank 0 and only named by rank 1."""
    client = fluid("nan")
    client.configure(config(tmp_path / "case"))
    client.geometry()
    with pytest.raises(ParticipantError) as info:
        client.advance(0, 0, 0.0, 1.0, {"solid_fraction": step_fraction()})
    text, case = str(info.value), tmp_path / "case"
    for rank in (0, 1):
        assert re.search(rf"rank {rank}: OpenFOAMError: simpleFoam produced non-finite U \(first at cell \d+\) in "
                         rf"{case}/processor{rank}/\d+; ", text), text
    assert text.count("log tail:") == 1 and f"rank 1: " in text.split("log tail:")[1]
    assert text.endswith(f"log {case}/log.simpleFoam"), text


def test_a_rank_that_dies_is_named_with_its_key(fluid, tmp_path):
    client = fluid("die")
    client.configure(config(tmp_path / "case"))
    client.geometry()
    with pytest.raises(ParticipantDied) as info:
        client.advance(0, 0, 0.0, 1.0, {"solid_fraction": step_fraction()})
    assert f"participant 'fluid' died: rank 1 gave no reply on varcouple/{client.run_id}/fluid/advance/1" in str(info.value)


def test_processors_that_are_not_boxes_take_the_whole_grid(launch_script, tmp_path):
    """16 cells along x in 3 processors (simple: 171, 171 and 170 cells, not whole planes): every
    rank asks for the whole grid's inputs and labels the bodies from them (logged once), and the
    join equals one process's arrays."""
    cfg = {**config(tmp_path / "case"), "transient": True, "dt": 0.01,
           "boundaries": {"zmin": {"pressure": 0.0}, "zmax": {"pressure": 0.0}}}
    client = launch_script("fluid", "recording_openfoam", RECORDING, [], {"RECORD_DIR": str(tmp_path), "FAULT": ""},
                           ranks=3, timeout=120)
    client.configure(cfg)
    client.geometry()
    fraction = step_fraction()
    velocity = np.where(fraction[:, None] > 0.5, [0.0, 0.0, 2e-3], 0.0)
    out = client.advance(0, 0, 0.0, 0.01, {"solid_fraction": fraction, "solid_velocity": velocity})
    for rank in range(3):
        assert np.array_equal(np.load(tmp_path / f"rank{rank}.npz")["input_ids"], np.arange(fraction.size))
    log = (tmp_path / "logs" / "fluid.log").read_text()
    assert log.count("processor0, processor1, processor2 of the simple decomposition not an index box of the grid "
                     "(16, 8, 4): every rank receives the whole grid's inputs for the rigid bodies") == 1, log
    whole = OpenFOAMSolver(tmp_path / "whole", CaseSpec.from_config(cfg, ranks=3))
    whole.setup()
    U, p = whole.solve(fraction, velocity, 0.0, 0.01)
    assert whole.last_run["converged"] and len(whole.sources) == 1
    assert np.array_equal(out["velocity"].data, U) and np.array_equal(out["pressure"].data, p * 1000.0)


@pytest.mark.parametrize("ranks, boxes", [(2, True), (3, False), (4, True), (5, True), (6, False)])
def test_the_shipped_rigid_body_scenes_processors_are_boxes_when_the_cells_divide(tmp_path, ranks, boxes):
    """cases/added_mass_heavy and added_mass_light (the shipped scenes with rigid bodies in the
    OpenFOAM fluid, 20 x 4 x 6 cells) with [solvers.fluid] ranks = 2 to 6: decomposePar's simple
    blocks cut x only, into index boxes where 20 planes divide evenly (2, 4, 5 ranks); on 3 and 6
    ranks they are not boxes, and the ranks take the whole grid's inputs
    (test_processors_that_are_not_boxes_take_the_whole_grid)."""
    config = make_plan(load(CASES / "added_mass_heavy")).participant("fluid").config
    assert config["transient"] and config["solid_velocity"] == "bodies" and config["grid"]["shape"] == [20, 4, 6]
    solver = OpenFOAMSolver(tmp_path / "case", CaseSpec.from_config(config, ranks=ranks))
    solver.setup()  # one process handling every processor: decomposePar's cellProcAddressing
    found = [cell_box(cells, (20, 4, 6)) for cells in solver.parallel.cells]
    assert [b is not None for b in found] == [boxes] * ranks
    if boxes:
        assert [b[0].tolist() for b in found] == [[20 * r // ranks, 0, 0] for r in range(ranks)]
