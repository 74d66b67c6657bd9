"""Mortar contact on several MPI ranks (solid_fenicsx.contact_mpi, nonsmooth.distributed):
the Hertz case on 2 ranks and two rough blocks on 2 and 3 ranks equal the serial solution
(displacement, contact pressure, gap, force, active set, active-set iterations) to 1e-9;
a warm start on the ranks needs fewer iterations for the same answer; `varcouple run` of a
closure scene with [solvers.solid] ranks = 2 gives the 1-rank figures; what cannot run on
several ranks says so."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
from mpi4py import MPI

from vc_helpers import ROOT, copy_case, run_mpi

pytestmark = [pytest.mark.skipif(shutil.which("mpirun") is None, reason="mpirun not found"),
              pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="already running under MPI")]

SCRIPT = ROOT / "tests" / "solid_fenicsx" / "mpi_contact_cases.py"
EQUAL = 1e-9


@pytest.fixture(scope="module")
def solved(tmp_path_factory):
    """(case, ranks) -> (figures, arrays), each run once."""
    directory, runs = tmp_path_factory.mktemp("contact_mpi"), {}

    def run(case: str, ranks: int):
        if (case, ranks) not in runs:
            out = directory / f"{case}_{ranks}.npz"
            figures = run_mpi(SCRIPT, ranks, case, out)
            assert figures["ranks"] == ranks and figures["converged"] and figures["warm_converged"]
            runs[case, ranks] = figures, dict(np.load(out))
        return runs[case, ranks]

    return run


def assert_same(serial, parallel):
    (fs, s), (fp, p) = serial, parallel
    assert np.abs(p["u"] - s["u"]).max() <= EQUAL * np.abs(s["u"]).max()
    assert np.abs(p["pressure"] - s["pressure"]).max() <= EQUAL * s["pressure"].max()
    assert np.array_equal(np.isnan(p["gap"]), np.isnan(s["gap"]))
    assert np.nanmax(np.abs(p["gap"] - s["gap"])) <= EQUAL * np.nanmax(np.abs(s["gap"]))
    assert np.abs(p["force"] - s["force"]).max() <= EQUAL * np.linalg.norm(s["force"])
    assert np.array_equal(p["active"], s["active"]) and s["active"].sum() > 10 and (~s["active"]).sum() > 10
    assert fp["iterations"] == fs["iterations"] and fp["dofs"] == fs["dofs"]
    assert fp["area_fraction"] == pytest.approx(fs["area_fraction"], rel=EQUAL)
    # the warm start (the same contact solved again at a 2 % larger push) on the ranks
    assert fp["warm_iterations"] == fs["warm_iterations"] < fs["iterations"]
    assert np.abs(p["warm_u"] - s["warm_u"]).max() <= EQUAL * np.abs(s["warm_u"]).max()
    assert np.array_equal(p["warm_active"], s["warm_active"])


def test_hertz_on_two_ranks_equals_one_rank(solved):
    serial = solved("hertz", 1)
    assert serial[0]["dofs"] > 6000 and serial[0]["iterations"] >= 4
    assert_same(serial, solved("hertz", 2))


@pytest.mark.parametrize("ranks", [2, 3])
def test_two_rough_blocks_on_several_ranks_equal_one_rank(solved, ranks):
    assert_same(solved("blocks", 1), solved("blocks", ranks))


def closure_scene(tmp_path, ranks: int, method: str = "search"):
    """cases/fracture_closure, coarser (lattice 8 x 8 x 3) and two stresses, on `ranks` ranks, the
    platen's `method`."""
    return copy_case(ROOT / "cases" / "fracture_closure", tmp_path / f"ranks_{ranks}", {
        "lattice = [16, 16, 5] ": "lattice = [8, 8, 3] ",
        "stress = [1.0e6, 2.0e6, 4.0e6, 6.0e6, 10.0e6, 15.0e6, 20.0e6]": "stress = [1.0e6, 4.0e6]",
        'type = "platen"': f'type = "platen"\nmethod = "{method}"',
        "[contact]": f"[solvers.solid]\nranks = {ranks}\n\n[output]\npictures = false\n\n[contact]"})


@pytest.mark.parametrize("method", ["search", "constraint"])
def test_varcouple_runs_a_contact_scene_on_two_ranks(tmp_path, capsys, method):
    """The platen's search of contact solves, or its displacement as one more unknown of one
    contact solve per stress, on 2 ranks: every figure of every step as on 1 rank (but the Krylov
    iterations, timings and the round-off size of a closed gap)."""
    from cli_helpers import run_cli

    summaries = []
    for ranks in (1, 2):
        case = closure_scene(tmp_path, ranks, method)
        code, _, err = run_cli(capsys, "run", case)
        assert code == 0, err
        summaries.append(json.loads((case / "results" / "summary.json").read_text()))
        assert summaries[-1]["participants_announced"]["solid"]["ranks"] == ranks
    for one, two in zip(summaries[0]["steps"], summaries[1]["steps"]):
        assert one["converged"] and two["converged"]
        a, b = one["figures"]["solid"], two["figures"]["solid"]
        assert a.keys() == b.keys() and a["active_nodes"] > 0
        assert (a["contact_solves"] == 1) == (method == "constraint")
        scale = {"force": abs(a["force_z"]), "gap": 1e-9, "fluid": 1.0}
        for key in {k for k in a if not k.startswith("seconds") and "krylov_iterations" not in k} - {"min_gap"}:
            atol = next((v for k, v in scale.items() if k in key), 0.0) * EQUAL
            assert b[key] == pytest.approx(a[key], rel=EQUAL, abs=atol), key


def test_what_does_not_run_on_several_ranks_says_so(tmp_path):
    from coupler.errors import SceneError
    from coupler.scene import load

    case = copy_case(ROOT / "cases" / "fracture_closure", tmp_path, {
        'solver = "active_set"': 'solver = "snes_vi"', "[contact]": "[solvers.solid]\nranks = 2\n\n[contact]"})
    with pytest.raises(SceneError, match=r"scene.toml: \[solvers.solid\] ranks: 2 ranks need \[contact\] solver = "
                                         r"'active_set' .*'snes_vi' runs on one rank"):
        load(case)
