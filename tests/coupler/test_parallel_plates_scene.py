"""cases/parallel_plates as a scene ([plates], coupler/plates_case.py): ``varcouple check``
prints the study, bad keys stop with one line naming the key, and ``varcouple run`` writes
the resolution study (summary.json, plates.png, VTU) whose errors follow the analysis:
walls on grid faces (offset 0) over-predict Q by exactly the real-wall error 2 (h/w)^2, the
worst error falls as (h/w)^2 (order 2), and the binary mask keeps an O(h/w) error."""

from __future__ import annotations

import json
import shutil

import meshio
import numpy as np
import pytest

from coupler.cli import main
from vc_helpers import CASES, copy_case

CASE = CASES / "parallel_plates"
needs_foam = pytest.mark.skipif(shutil.which("simpleFoam") is None, reason="OpenFOAM (simpleFoam) not installed")


def test_check_prints_the_study(capsys):
    assert main(["check", str(CASE)]) == 0
    out = capsys.readouterr().out
    assert "study         immersed parallel plates against the cubic law" in out
    assert "n = 4, 8, 16, 32 cells across" in out
    assert "2 methods (wall, binary) x 4 offsets (0, 0.25, 0.5, 0.75) x 4 resolutions = 32 simpleFoam solves" in out
    assert "check         worst |Q / Q_cubic - 1| over the offsets < 0.05 at 8 cells across (method wall)" in out


@pytest.mark.parametrize("old, new, message", [
    ("cells_across = [4, 8, 16, 32]", "cells_across = [4, 0]", "[study] cells_across: values must lie in [1, inf)"),
    ("offsets = [0.0, 0.25, 0.5, 0.75]", "offsets = [0.0, 1.0]", "[study] offsets: values must lie in [0.0, 1.0)"),
    ('methods = ["wall", "binary"]', 'methods = ["wall", "mask"]', "[study] methods: unknown value 'mask'"),
    ("aperture = 1.0e-3", "aperture = -1.0", "[plates] aperture: must be positive"),
    ("cells_across = 8\n", "cells_across = 6\n", "[check] cells_across: 6 is not one of [study] cells_across"),
    ("[case]", "[flow]\ninlet_pressure = 1.0\n[case]", "unknown table [flow]"),
    ("tolerance = 1.0e-7", "tolerance = 1.0e-7\nranks = 2", "[solvers.fluid] ranks: unknown key"),
])
def test_bad_keys_are_named(tmp_path, capsys, old, new, message):
    case = copy_case(CASE, tmp_path, {old: new})
    assert main(["check", str(case)]) == 2
    err = capsys.readouterr().err
    assert message in err and "scene.toml" in err, err


@needs_foam
def test_run_writes_the_study(tmp_path, capsys):
    case = copy_case(CASE, tmp_path, {"cells_across = [4, 8, 16, 32]": "cells_across = [4, 8]",
                                      "offsets = [0.0, 0.25, 0.5, 0.75]": "offsets = [0.0, 0.3]"})
    assert main(["run", str(case)]) == 0, capsys.readouterr().err
    out = case / "results"
    s = json.loads((out / "summary.json").read_text())
    assert s["check"]["passed"] and s["Q_cubic"] == pytest.approx(1e-9 * 1e-2 / (12 * 1e-3 * 2e-3))
    rows = {(r["method"], r["n_across"]): r for r in s["table"]}
    assert set(rows) == {("wall", 4), ("wall", 8), ("binary", 4), ("binary", 8)}
    for (method, n), r in rows.items():
        assert r["all_converged"] and r["time_total_mean"] > 0
        if method == "wall":  # offset 0: the walls on grid faces, the real-wall error 2 (h/w)^2
            assert r["errors"]["0"] == pytest.approx(2 / n ** 2, abs=2e-3)
    assert s["order"]["wall"] == pytest.approx(2.0, abs=0.1)
    assert s["order"]["binary"] == pytest.approx(1.0, abs=0.2)  # the mask widens the gap by a cell
    assert abs(rows["wall", 8]["error_worst"]) < 0.05 < abs(rows["binary", 8]["error_worst"])
    assert len(s["runs"]) == 8
    for name in ("plates.png", "plates_wall.pvd", "plates_binary_0008.vtu"):
        assert (out / name).is_file(), name
    vtu = meshio.read(out / "plates_wall_0008.vtu")
    frac = vtu.cell_data["solid_fraction"][0]
    ux = vtu.cell_data["velocity"][0][:, 0]
    assert len(frac) == 4 * 13 and ux[frac == 0].min() > 0 and np.abs(ux[frac == 1]).max() < 1e-3 * ux.max()


@needs_foam
def test_failed_check_exits_1(tmp_path, capsys):
    case = copy_case(CASE, tmp_path, {"cells_across = [4, 8, 16, 32]": "cells_across = [4]",
                                      'methods = ["wall", "binary"]': 'methods = ["wall"]',
                                      "offsets = [0.0, 0.25, 0.5, 0.75]": "offsets = [0.0]",
                                      "cells_across = 8\n": "cells_across = 4\n"})
    assert main(["run", str(case)]) == 1
    out = capsys.readouterr().out
    assert "check: worst error +12.5" in out and "FAIL" in out
