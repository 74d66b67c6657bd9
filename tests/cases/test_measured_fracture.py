"""cases/measured_fracture: a closure test whose fracture faces are height maps. The scene's
map files are found relative to the case directory, a bad map is one line naming the scene
file, the parameter and the reason, a scan as scanners deliver it (2^n nodes, periodic, in
first contact) loads with the plan saying what was done to it, and the XYZ form of the shipped
map runs a contact step whose platen force is the contact force."""

from __future__ import annotations

import json
import os
import re

import numpy as np
import pytest

from cli_helpers import assert_clean_error, run_cli
from coupler.run import preflight
from transfer.generators.height_maps import read_npz, write_npz, write_xyz
from transfer.generators.surfaces import fracture_pair
from vc_helpers import CASES, copy_case


def test_check_finds_the_map_beside_the_scene(capsys, monkeypatch, tmp_path):
    monkeypatch.chdir(tmp_path)  # not the case directory
    code, out, _ = run_cli(capsys, "check", "--quick", CASES / "measured_fracture")
    assert code == 0
    assert "contact of 'fracture_lower' (slave) on 'fracture_upper' (master)" in out and "3 load steps" in out


@pytest.mark.parametrize("broken, words", [
    (lambda case: np.savez(case / "surfaces.npz", **{k: v for k, v in np.load(CASES / "measured_fracture" /
                                                                               "surfaces.npz").items() if k != "upper"}),
     ["[geometry.solid.parameters] surfaces:", "surfaces.npz has no array 'upper' (it holds: lower, spacing)"]),
    (lambda case: (case / "surfaces.npz").unlink(), ["[geometry.solid.parameters] surfaces: no file", "surfaces.npz"]),
])
def test_a_bad_map_is_one_line_naming_the_scene_and_key(capsys, tmp_path, broken, words):
    case = copy_case(CASES / "measured_fracture", tmp_path)
    broken(case)
    code, _, err = run_cli(capsys, "check", "--quick", case)
    assert_clean_error(code, err, str(case / "scene.toml"), *words)


def test_a_scan_as_delivered_loads_and_the_plan_says_what_was_done(capsys, tmp_path):
    """32 x 32 nodes of one period, the faces in first contact (touching nodes a round-off apart),
    in the shipped scene without min_aperture: check accepts it at coarsen 8 and ratio 2 without
    extra keys, and its notes name the periodic closure and the lattice; without periodic the
    31 cells take a remainder cell, also noted."""
    lower, upper = fracture_pair((32, 32), (0.016, 0.016), aperture=1e-4, rms=2e-4, mismatch_length=4e-3, seed=7,
                                 min_aperture=0.0, periodic=True)
    lower, upper = lower[:-1, :-1].T + 1e-3, upper[:-1, :-1].T + 1e-3  # one period, offset as a scanner's
    upper = np.where(upper <= lower, np.nextafter(lower, -np.inf), upper)
    assert (upper < lower).any()
    for periodic, words in ((True, "map of 32 x 32 nodes, periodic, closed by its first row and column: 32 x 32 "
                                   "cells, 0.016 x 0.016 m; lattice 4 x 4, map cells per lattice cell 8 (x), 8 (y)"),
                            (False, "map of 32 x 32 nodes; lattice 4 x 4, map cells per lattice cell 8, the last 7 "
                                    "(x), 8, the last 7 (y)")):
        case = copy_case(CASES / "measured_fracture", tmp_path / str(periodic), {
            "coarsen = 2 ": f"coarsen = 8\nperiodic = {str(periodic).lower()} ",
            "min_aperture = 1.0e-6 ": "# no min_aperture "})
        write_npz(case / "surfaces.npz", lower, upper, (0.5e-3, 0.5e-3))
        code, out, err = run_cli(capsys, "check", "--quick", case)
        assert code == 0, err
        assert f"note          measured_fracture: {words}" in out


def test_check_warns_when_the_first_step_may_outlast_the_messaging_timeout(capsys, monkeypatch, tmp_path):
    """A timeout of 1 s: check estimates the first load step from the solid's size, warns naming
    [messaging] timeout and a value; with that value set the warning is gone. The shipped scene
    (timeout 300 s by default) is not warned about. The estimate grows with the machine's load
    per core (here fixed: 2 cores, load 1, then 8)."""
    monkeypatch.setattr(preflight, "cores", lambda: 2)
    monkeypatch.setattr(os, "getloadavg", lambda: (1.0, 1.0, 1.0))
    code, out, _ = run_cli(capsys, "check", "--quick", CASES / "measured_fracture")
    assert code == 0 and "time          the solid's first load step with contact about" in out
    assert "warning" not in out
    case = copy_case(CASES / "measured_fracture", tmp_path, {"[contact]": "[messaging]\ntimeout = 1.0\n\n[contact]"})
    code, out, _ = run_cli(capsys, "check", "--quick", case)
    assert code == 0
    (warning,) = [line for line in out.splitlines() if line.startswith("warning")]
    assert "9,600 cells" in warning and "more than [messaging] timeout = 1 s" in warning
    value = int(re.search(r"set \[messaging\] timeout = (\d+) in the scene$", warning).group(1))
    assert value >= 100
    scene = (case / "scene.toml").read_text().replace("timeout = 1.0", f"timeout = {value}")
    (case / "scene.toml").write_text(scene)
    code, out, _ = run_cli(capsys, "check", "--quick", case)
    assert code == 0 and "warning" not in out and f"[messaging] timeout {value} s" in out
    idle = float(re.search(r"about ([\d,.]+) s \(9,600 cells", out).group(1).replace(",", ""))
    monkeypatch.setattr(os, "getloadavg", lambda: (8.0, 8.0, 8.0))  # 4 runnable processes per core
    code, out, _ = run_cli(capsys, "check", "--quick", case)
    loaded = float(re.search(r"about ([\d,.]+) s \(9,600 cells", out).group(1).replace(",", ""))
    assert loaded == pytest.approx(4 * idle, rel=0.05) and "load 8.0 on 2 cores" in out


def test_the_xyz_map_closes_under_the_platen(capsys, tmp_path):
    case = copy_case(CASES / "measured_fracture", tmp_path, {
        'surfaces = "surfaces.npz"': 'lower = "faces/lower.xyz"\nupper = "faces/upper.xyz"',
        "stress = [1.0e6, 5.0e6, 20.0e6]": "stress = [5.0e6]"})
    (lower, upper), spacing = read_npz(case / "surfaces.npz")
    (case / "faces").mkdir()
    write_xyz(case / "faces" / "lower.xyz", lower, spacing)
    write_xyz(case / "faces" / "upper.xyz", upper, spacing)
    (case / "surfaces.npz").unlink()
    code, _, err = run_cli(capsys, "run", case, "-o", tmp_path / "out")
    assert code == 0, err
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    (step,) = summary["steps"]
    figures = step["figures"]["solid"]
    assert abs(figures["stress"] / 5e6 - 1) <= 5e-3 and 0 < figures["area_fraction"] < 1
    assert figures["platen_force"] == pytest.approx(-figures["force_z"], rel=1e-9)  # the contact carries the load
    assert figures["platen_force"] == pytest.approx(figures["stress"] * 0.01, rel=1e-12)
    assert figures["min_gap"] >= -1e-15 and 0 < figures["closure"] < 2e-4 + 1e-4
    keys = list(figures)  # what a user compares, side by side: the faces' closure and the platen's displacement
    assert keys[keys.index("mean_gap"):keys.index("mean_gap") + 3] == ["mean_gap", "closure", "platen_displacement"]
    # the platen's displacement is the closure plus the blocks' compression, about stress x 2 height / E
    bulk = (figures["platen_displacement"] - figures["closure"]) / (figures["stress"] * 2 * 0.04 / 1e10)
    assert 0.7 < bulk < 1.1, bulk
