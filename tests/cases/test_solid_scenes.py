"""The solid's studies as ordinary scenes through ``varcouple check|run``: the fracture closure
(a generated specimen, stress-controlled platen load steps, mortar contact) and the obstacle
problems (contact with a rigid plane, the nonsmooth multigrid), with the numbers the obstacle
study recorded before it became a scene: its level sweep (paper figure 14) is the scene with
other lattices and levels, each run reproducing the old run's iterations, asymptotic rate,
contact nodes, contact force and displacement."""

from __future__ import annotations

import json

import meshio
import numpy as np
import pytest

from coupler.cli import main
from vc_helpers import CASES, copy_case

#: the obstacle study's runs (tests/data/case_figures.json before the study became these scenes):
#: case, lattice, levels -> iterations, asymptotic rate, contact nodes, contact force z [N],
#: displacement (min, max, l2 over all components), nodal contact force (max, l2)
OBSTACLE_STUDY = {
    ("cube_obstacle", 6, 2): (11, 0.15107660237068288, 49, 30840.739402825002,
                              [-0.0003, 4.14734843298804e-05, 0.0034206995788774283], [874.2339998329793, 4727.41310170483]),
    ("cube_obstacle", 13, 3): (13, 0.20706804567248355, 196, 30696.037489388895,
                               [-0.0003, 3.974960400369704e-05, 0.009480197247531021],
                               [184.7237170730429, 2272.5833596369503]),
    ("cube_obstacle", 25, 4): (12, 0.1781422644339145, 676, 30648.30486090336,
                               [-0.0003, 3.922376939965367e-05, 0.023795935715766568],
                               [49.80717089184236, 1201.9203619248333]),
    ("rock_obstacle", 48, 4): (16, 0.2605576855100872, 26, 49083.10922524527,
                               [-0.0005043164029268934, 3.555061445305255e-05, 0.09983883918945922],
                               [5512.026225083805, 12831.222429908667]),
}


def run(case, out) -> dict:
    assert main(["run", str(case), "-o", str(out)]) == 0
    return json.loads((out / "summary.json").read_text())


@pytest.mark.parametrize("key", [pytest.param(k, marks=pytest.mark.slow) if k[1] > 13 else k for k in OBSTACLE_STUDY])
def test_the_obstacle_study_runs_are_the_scene_at_other_levels(tmp_path, key):
    name, cells, levels = key
    iterations, rate, nodes, force, u_stats, force_stats = OBSTACLE_STUDY[key]
    replace = {"levels = 4": f"levels = {levels}"}
    if name == "cube_obstacle":
        replace["shape = [25, 25, 25]"] = f"shape = [{cells}, {cells}, {cells}]"
    summary = run(copy_case(CASES / name, tmp_path, replace), tmp_path / "out")
    (step,) = summary["steps"]
    figures = step["figures"]["solid"]
    (report,) = step["solves"]["solid"]
    assert report["solver"] == "contact multilevel" and report["converged"] and report["residual"] < 1e-12
    assert figures["iterations"] == iterations and figures["active_nodes"] == nodes
    assert figures["asymptotic_rate"] == pytest.approx(rate, rel=1e-5)  # the iterates agree to round-off
    assert figures["force_z"] == pytest.approx(force, rel=1e-9)
    solid = meshio.read(tmp_path / "out" / "solid_0000.vtu")
    u = solid.point_data["displacement"]
    assert [u.min(), u.max(), np.linalg.norm(u)] == pytest.approx(u_stats, rel=1e-9, abs=1e-15)
    nodal = solid.point_data["contact_pressure"] * solid.point_data["mortar_weight"]
    assert [nodal.max(), np.linalg.norm(nodal)] == pytest.approx(force_stats, rel=1e-9)
    assert figures["min_gap"] >= -1e-15  # no penetration


def test_check_prints_the_plans(capsys):
    assert main(["check", "--quick", str(CASES / "fracture_closure")]) == 0
    out = capsys.readouterr().out
    assert "platen on 'top': rigid, mean normal stress 1e+06, 2e+06, 4e+06, 6e+06, 1e+07, 1.5e+07, 2e+07 per step" in out
    assert "7 load steps" in out and "'fracture_lower' (slave) on 'fracture_upper'" in out
    assert main(["check", "--quick", str(CASES / "rock_obstacle")]) == 0
    out = capsys.readouterr().out
    assert "rigid obstacle the plane of normal [0.0, 0.0, 1.0] 0 m beyond it" in out and "multilevel on 4 levels" in out


def test_a_coarse_closure_test(tmp_path):
    """The closure scene on an 8 x 8 x 3 lattice to 1, 5 and 20 MPa: one load step per stress,
    the platen's search an inner solve, closure and contact area growing, the curve stiffening,
    the slave face a disc, figures.png of the figures per step."""
    case = copy_case(CASES / "fracture_closure", tmp_path, {
        "lattice = [16, 16, 5]": "lattice = [8, 8, 3]",
        "stress = [1.0e6, 2.0e6, 4.0e6, 6.0e6, 10.0e6, 15.0e6, 20.0e6]": "stress = [1.0e6, 5.0e6, 20.0e6]"})
    summary = run(case, tmp_path / "out")
    figures = [s["figures"]["solid"] for s in summary["steps"]]
    for s, target in zip(summary["steps"], (1e6, 5e6, 20e6)):
        platen = next(r for r in s["solves"]["solid"] if r["solver"] == "platen")
        assert platen["converged"] and platen["residual"] <= 5e-3 and platen["tolerance"] == 5e-3
        assert abs(s["figures"]["solid"]["stress"] / target - 1) <= 5e-3
    stress, closure, area = (np.array([f[k] for f in figures]) for k in ("stress", "closure", "area_fraction"))
    assert np.all(np.diff(closure) > 0) and np.all(np.diff(area) > 0)
    stiffness = np.diff(stress) / np.diff(closure)
    assert stiffness[1] > stiffness[0] and closure[-1] < figures[0]["closure"] + figures[0]["mean_gap"]
    assert [f["platen_force"] for f in figures] == pytest.approx(stress * np.pi * 0.061 ** 2, rel=1e-12)
    face = meshio.read(tmp_path / "out" / "solid_0001.vtu")
    slave = face.point_data["slave"] == 1
    radius = np.hypot(face.points[slave, 0] - 0.061, face.points[slave, 1] - 0.061)
    assert radius.max() == pytest.approx(0.061, rel=1e-9)  # the lower face is a disc
    assert (tmp_path / "out" / "figures.png").stat().st_size > 0
