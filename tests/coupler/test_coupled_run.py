"""End to end: `varcouple run` on coupled scenes with stand-in participants, as
real processes talking zenoh (paper 2.3, Steps 1-6)."""

import json
import os
import signal
import threading
import time

import meshio
import numpy as np
import pytest

from coupler.cli import main
from coupler.errors import CouplerError
from vc_helpers import CASES, copy_case

CASE = CASES / "standin_flow"


def summary(out):
    return json.loads((out / "summary.json").read_text())


def test_implicit_loop_converges_with_iqn_ils(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["run", str(CASE), "--output", str(out)]) == 0, capsys.readouterr().err
    s = summary(out)
    assert s["status"] == "completed"
    assert [p["name"] for p in s["participants"]] == ["solid", "fluid"]
    assert {"participants", "effects", "exchanges", "phases_seconds", "steps"} <= set(s)
    # spring_solid has no boundary triangles: the fallback volume projection onto all vertices
    assert s["interface"]["method"] == "volume projection"
    # the fixed point has gain 3 (plain iteration diverges); IQN-ILS needs a few iterations
    assert all(s["converged"]) and max(s["iterations"]) <= 4
    for step in s["steps"]:
        assert step["residuals"][-1] <= 1e-8
    # the stand-ins: p = p0 - c v with v = (p - p_previous) / (k dt) (spring opening
    # p / k), so p_n = (p0 + g p_{n-1}) / (1 + g) with the gain g = c / (k dt) = 3
    g, p = 3e4 / (1e6 * 0.01), 0.0
    for n in range(4):
        p = (1e5 + g * p) / (1 + g)
        step = meshio.read(out / f"solid_{n:04d}.vtu")
        np.testing.assert_allclose(step.point_data["pressure"], p, rtol=1e-7)
        np.testing.assert_allclose(step.point_data["displacement"][:, 2], p / 1e6, rtol=1e-7)
    for phase in ("solid", "fluid", "transfer", "messaging"):
        assert s["phases_seconds"][phase] > 0
    assert (out / "solid.pvd").is_file() and (out / "fluid.pvd").is_file() and (out / "residuals.png").is_file()


def test_constant_relaxation_diverges_with_a_clear_error(tmp_path, capsys):
    case = copy_case(CASE, tmp_path, {'acceleration = "iqn-ils"': 'acceleration = "constant"\nrelaxation = 1.0'})
    out = tmp_path / "out"
    assert main(["run", str(case), "--output", str(out)]) == 3
    err = capsys.readouterr().err
    assert err.startswith("varcouple: error: ") and "time step 0" in err and "Traceback" not in err
    # the advice fits the scene: constant relaxation is told about IQN-ILS, not told to use constant
    assert "acceleration = 'iqn-ils'" in err
    s = summary(out)
    assert s["status"] == "not_converged" and "CouplingDiverged" in s["error"]


def test_aitken_converges_too(tmp_path, capsys):
    case = copy_case(CASE, tmp_path, {'acceleration = "iqn-ils"': 'acceleration = "aitken"'})
    out = tmp_path / "out"
    assert main(["run", str(case), "--output", str(out)]) == 0, capsys.readouterr().err
    s = summary(out)
    assert all(s["converged"])


def test_killed_participant_ends_the_run_cleanly(tmp_path, capsys):
    case = copy_case(CASE, tmp_path, {"steps = 4": "steps = 100000"})
    out = tmp_path / "out"

    def kill_fluid():
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            try:
                s = summary(out)
            except (OSError, ValueError):
                s = {}
            if s.get("steps"):
                os.kill(s["participants_announced"]["fluid"]["pid"], signal.SIGKILL)
                return
            time.sleep(0.05)

    killer = threading.Thread(target=kill_fluid)
    killer.start()
    start = time.monotonic()
    code = main(["run", str(case), "--output", str(out)])
    killer.join()
    assert code == 4
    err = capsys.readouterr().err
    assert "fluid" in err and "Traceback" not in err
    assert time.monotonic() - start < 60
    s = summary(out)
    assert s["status"] == "failed" and len(s["steps"]) >= 1  # what was done is kept
    pids = [p["pid"] for p in s["participants_announced"].values()]
    time.sleep(0.5)
    for pid in pids:  # every process has ended
        with pytest.raises(ProcessLookupError):
            os.kill(pid, 0)


def test_swapping_the_solid_is_one_line(tmp_path, capsys):
    """The same coupled scene with dolfinx instead of the spring stand-in."""
    case = copy_case(CASE, tmp_path, {'participant = "spring_solid"': 'participant = "solid_fenicsx"',
                                      '"dynamics", ': ""})  # a static dolfinx solid: no velocity feedback
    out = tmp_path / "out"
    assert main(["run", str(case), "--output", str(out)]) == 0, capsys.readouterr().err
    s = summary(out)
    assert s["participants_announced"]["solid"]["kind"] == "solid_fenicsx" and all(s["converged"])
    last = meshio.read(out / "solid_0003.vtu")
    # the pressure pushes the top face down (static solve: no velocity, so the stand-in
    # fluid's pressure is the prescribed one); dolfinx gives its wetted boundary's
    # triangles, so the pressure is sampled on that surface (half a cell into the fluid)
    # and the other vertices get none
    assert s["interface"]["method"] == "surface trace" and s["interface"]["vertices"] == 25
    top = np.isclose(last.points[:, 2], 0.6)
    np.testing.assert_allclose(last.point_data["pressure"][top], 1e5, rtol=1e-9)
    np.testing.assert_array_equal(last.point_data["pressure"][~top], 0.0)
    assert last.point_data["displacement"][:, 2].min() < 0


def test_the_vtu_series_takes_mesh_fields_and_leaves_single_values_to_the_figures():
    """A participant's fields of one value per point or cell go to its VTU series, a single
    value (the inlet pressure of a flow-rate control) does not, any other length is an error."""
    from coupler.run.runner import mesh_fields
    from transfer import StructuredGrid

    grid = StructuredGrid.from_bounds((0, 0, 0), (1, 1, 1), (2, 2, 2))  # 27 points, 8 cells
    fields = {"pressure": np.zeros(8), "phi": np.zeros(27), "inlet_pressure": np.ones(1)}
    assert set(mesh_fields(fields, grid, "fluid")) == {"pressure", "phi"}
    with pytest.raises(CouplerError, match=r"participant 'fluid': field\(s\) velocity \(5\) match neither its 27 "
                                           r"points nor its 8 cells"):
        mesh_fields({**fields, "velocity": np.zeros((5, 3))}, grid, "fluid")
