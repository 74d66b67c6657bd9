"""The coupler on P MPI ranks (docs/scaling.md, step 3; coupler/run/ranks.py): small_fracture with
the Chorin fluid gives the one-rank coupler's fields and summary to 1e-10 with the coupler on 2
ranks, each coupler rank holding a slab of the grid and the solid parts of its solid ranks (never
the whole solid); what still needs a whole field on one process refuses P > 1 with one line naming
the scene file, the key and the reason."""

from __future__ import annotations

import json
import shutil
from types import SimpleNamespace

import pytest

from coupler import scene as scenes
from coupler.errors import SceneError
from coupler.plan.plan import make_plan
from coupler.run.execute import coupler_ranks
from coupler.run.ranks import RanksRun
from test_rank_independence import assert_same, run
from vc_helpers import CASES, copy_case

needs_mpi = pytest.mark.skipif(shutil.which("mpirun") is None, reason="mpirun not installed")


def coupled(tmp_path, coupler: int, solid: int, fluid: int):
    """small_fracture's first step, Chorin fluid, with the coupler on `coupler` ranks (the key
    ``[coupling] ranks``: varcouple run starts itself under mpirun)."""
    out = run(tmp_path / f"p{coupler}", solid, fluid, steps=1, fluid="chorin", fluid_tolerance="1e-7",
              coupling=f"ranks = {coupler}" if coupler > 1 else "")
    return out


def holdings(out) -> list[dict]:
    return json.loads((out / "summary.json").read_text())["coupler_ranks"]


@needs_mpi
def test_two_coupler_ranks_give_the_serial_run(tmp_path):
    """Solid and fluid on 2 ranks each: coupler ranks 0 and 1 each talk to one rank of each; the
    fields of every VTU file (joined from each rank's piece) and every summary figure equal the
    one-rank coupler's to 1e-10, with the same iterations; each rank holds half the grid, its
    solid rank's cells and a part of the interface vector only, and writes its pieces."""
    serial, ranks = coupled(tmp_path, 1, 2, 2), coupled(tmp_path, 2, 2, 2)
    assert_same(serial, ranks, "coupler on 2 ranks")
    assert sorted(f.name for f in ranks.glob("*_0000*")) == [
        "fluid_0000.pvtu", "fluid_0000_p0.vtu", "fluid_0000_p1.vtu",
        "solid_0000.pvtu", "solid_0000_p0.vtu", "solid_0000_p1.vtu"]
    held = holdings(ranks)
    interface = json.loads((serial / "summary.json").read_text())["interface"]["vertices"]
    assert sum(h["interface_rows"] for h in held) == interface == 462
    assert all(0 < h["interface_rows"] < interface for h in held)
    assert len(held) == 2
    assert sum(h["grid_cells"] for h in held) == 21 * 11 * 11 and all(h["grid_cells"] < 21 * 11 * 11 for h in held)
    assert sum(h["solid_cells"] for h in held) == 4800 and all(0 < h["solid_cells"] < 4800 for h in held)
    solid_rows = json.loads((serial / "summary.json").read_text())["sizes"]["solid"]["vertices"]
    assert sum(h["solid_rows"] for h in held) == solid_rows and all(h["solid_rows"] < solid_rows for h in held)
    assert sum(h["interface_triangles"] for h in held) == 800


@pytest.mark.slow
@needs_mpi
def test_a_coupler_rank_without_participant_ranks(tmp_path):
    """Solid and fluid on one rank each: coupler rank 1 talks to none (it holds no rows of either)
    and still works its slab of the grid: the serial run to 1e-10."""
    serial, ranks = coupled(tmp_path, 1, 1, 1), coupled(tmp_path, 2, 1, 1)
    assert_same(serial, ranks, "coupler on 2 ranks, participants on 1")
    held = holdings(ranks)
    assert [h["solid_rows"] > 0 for h in held] == [True, False]
    assert [h["fluid_rows"] > 0 for h in held] == [True, False]
    assert all(h["grid_cells"] > 0 for h in held)


@pytest.mark.slow
@needs_mpi
@pytest.mark.skipif(shutil.which("simpleFoam") is None, reason="OpenFOAM not installed")
def test_the_openfoam_fluid_on_two_coupler_ranks(tmp_path):
    """The OpenFOAM fluid (one participant process per processor of its decomposed case) and the
    solid on 2 ranks each: coupler ranks 0 and 1 each talk to one processor's process; the fields
    and the summary equal the one-rank coupler's to 1e-10, with the same iterations."""
    serial, ranks = (run(tmp_path / f"p{p}", 2, 2, steps=1, fluid="openfoam", fluid_tolerance="1e-7",
                         coupling=f"ranks = {p}" if p > 1 else "") for p in (1, 2))
    assert_same(serial, ranks, "OpenFOAM fluid, coupler on 2 ranks")
    held = holdings(ranks)
    assert all(0 < h["fluid_rows"] < 21 * 11 * 11 for h in held)


# -- refusals: what needs a whole field on one process ------------------------------------
def refusal(tmp_path, case: str, replace: dict | None = None, append: str = "") -> str:
    scene_dir = copy_case(CASES / case, tmp_path / case, replace)
    if append:
        with open(scene_dir / "scene.toml", "a") as f:
            f.write(append)
    scene = scenes.load(scene_dir)
    with pytest.raises(SceneError) as err:
        RanksRun.admit(scene, make_plan(scene), SimpleNamespace(size=2))
    text = str(err.value)
    assert text.startswith(f"{scene.path}: ") and "\n" not in text and "2 coupler ranks" in text
    return text


def test_pictures_are_refused(tmp_path):
    assert "[output] pictures: the pictures are rendered from whole fields" in refusal(tmp_path, "small_fracture",
                                                                                append="\n[output]\npictures = true\n")


def test_a_check_is_refused(tmp_path):
    assert "[check] kind: 'cubic_law' compares whole fields" in refusal(tmp_path, "parallel_plates",
                                                                         append="\n[output]\npictures = false\n")


def test_in_process_participants_are_refused(tmp_path):
    scene = (CASES / "transfer_demo" / "scene.toml").read_text()
    text = refusal(tmp_path, "transfer_demo", {scene[scene.index("[check]"):scene.index("[output]")]: ""},
                   append="pictures = false\n")
    assert "[solvers.source]: 'mesh_file' is served whole in the coupler's process" in text


def test_an_operator_without_ranks_is_refused(tmp_path):
    text = refusal(tmp_path, "small_fracture", {'acceleration = "iqn-ils"': 'acceleration = "iqn-ils"\ntraction = "full"'},
                   append="\n[output]\npictures = false\n")
    assert "the operator 'viscous_traction', which needs whole fields on one process" in text


def test_cell_centre_fractions_are_refused(tmp_path):
    text = refusal(tmp_path, "small_fracture", {'walls = "slip" ': 'solid_fraction = "cell_centre"\nwalls = "slip" '},
                   append="\n[output]\npictures = false\n")
    assert "[flow] solid_fraction: 'cell_centre' samples the whole solid mesh" in text


def test_the_key_and_the_job_must_agree(tmp_path, monkeypatch):
    case = copy_case(CASES / "small_fracture", tmp_path, {'acceleration = "iqn-ils"': 'acceleration = "iqn-ils"\nranks = 3'})
    scene = scenes.load(case)
    assert coupler_ranks(scene) == 3
    monkeypatch.setenv("OMPI_COMM_WORLD_SIZE", "2")
    with pytest.raises(SceneError, match=r"scene.toml: \[coupling\] ranks: 3, but this coupler runs on 2 MPI ranks"):
        coupler_ranks(scene)
