"""cases/parallel_plates, an ordinary scene: a fixed immersed solid (the plates generator), one
simpleFoam solve, the [check] cubic_law. Its single runs give the numbers the resolution
study recorded before it became a scene (tests/data/parallel_plates_study.json: per method,
cells across and offset), to round-off; the study itself is `varcouple study` (README.md)."""

from __future__ import annotations

import json
import shutil

import meshio
import numpy as np
import pytest

from coupler.cli import main
from vc_helpers import CASES, ROOT, copy_case

CASE = CASES / "parallel_plates"
STUDY = json.loads((ROOT / "tests" / "data" / "parallel_plates_study.json").read_text())
#: the study's methods as scene keys: (penalization, solid_fraction)
METHODS = {"wall": ("wall", "exact"), "binary": ("linear", "cell_centre")}
needs_foam = pytest.mark.skipif(shutil.which("simpleFoam") is None, reason="OpenFOAM (simpleFoam) not installed")


def run(tmp_path, n: int, offset: float, method: str = "wall", capsys=None) -> tuple[int, dict]:
    """``varcouple run`` of the scene at n cells across, the plates at `offset`, with `method`:
    (exit code, summary)."""
    penalization, fraction = METHODS[method]
    case = copy_case(CASE, tmp_path / f"{method}-{n}-{offset}",
                     {"cells_across = 8 ": f"cells_across = {n} ", "offset = 0.25 ": f"offset = {offset} ",
                      'penalization = "wall"': f'penalization = "{penalization}"',
                      'solid_fraction = "exact"': f'solid_fraction = "{fraction}"'})
    code = main(["run", str(case)])
    return code, json.loads((case / "results" / "summary.json").read_text())


def recorded(method: str, n: int, offset: float) -> dict:
    return next(r for r in STUDY["runs"] if (r["method"], r["cells_across"], r["offset"]) == (method, n, offset))


@needs_foam
def test_the_scene_passes_its_check_with_the_study_s_number(tmp_path):
    code, s = run(tmp_path, 8, 0.25)
    assert code == 0 and s["status"] == "completed" and s["check"]["passed"]
    old = recorded("wall", 8, 0.25)
    assert s["check"]["relative_difference"] == pytest.approx(old["error"], rel=1e-9, abs=1e-12)
    assert s["check"]["Q"] == pytest.approx(old["Q"], rel=1e-12)
    assert s["steps"][0]["solves"]["fluid"][0]["iterations"] <= old["iterations"]  # (317 against 451 since the
    # pressure solve stops at its attainable tolerance: fluid_openfoam.case.fv_solution)
    assert s["steps"][0]["solves"]["solid"] == [] and s["participants"][0]["in_process"]
    vtu = meshio.read(tmp_path / "wall-8-0.25" / "case" / "results" / "fluid_0000.vtu")
    frac, ux = vtu.cell_data["solid_fraction"][0], vtu.cell_data["velocity"][0][:, 0]
    assert len(frac) == 4 * 13 and ux[frac == 0].min() > 0 and np.abs(ux[frac == 1]).max() < 1e-3 * ux.max()


@needs_foam
@pytest.mark.parametrize("method", ["wall", "binary"])
def test_single_runs_give_the_study_s_numbers(tmp_path, method):
    """4 cells across with the walls on grid faces (offset 0: the real-wall error 2 (h/w)^2 for
    'wall', a gap one cell wider for the centre mask) and through cell centres (0.5)."""
    for offset in (0.0, 0.5):
        code, s = run(tmp_path, 4, offset, method)
        assert code == (0 if abs(s["check"]["relative_difference"]) < 0.05 else 1)
        assert s["check"]["relative_difference"] == pytest.approx(recorded(method, 4, offset)["error"], rel=1e-9)
    assert recorded("wall", 4, 0.0)["error"] == pytest.approx(2 / 4 ** 2, abs=2e-3)


@needs_foam
def test_a_fixed_solid_is_pictured_in_the_flow_only(tmp_path):
    case = copy_case(CASE, tmp_path, {'solid_fraction = "exact"': 'solid_fraction = "exact"\n[output]\npictures = true'})
    assert main(["run", str(case)]) == 0
    s = json.loads((case / "results" / "summary.json").read_text())
    assert s["pictures"] == ["flow_speed.png"] and "pictures_error" not in s  # no deformed solid


@needs_foam
def test_a_failed_check_exits_1(tmp_path, capsys):
    code, s = run(tmp_path, 4, 0.0)
    assert code == 1 and s["status"] == "completed" and not s["check"]["passed"]
    assert "+12.521% (tolerance 0.05): FAIL" in capsys.readouterr().out


@needs_foam
@pytest.mark.slow
def test_the_refinement_study_as_single_runs(tmp_path):
    """All 32 runs of the old study (4 to 32 cells across, offsets 0 to 0.75, both methods): the
    worst error over the offsets per cells across and method is the recorded one, the exact
    fractions converge at second order and the mask at first."""
    worst = {}
    for row in STUDY["runs"]:
        _, s = run(tmp_path, row["cells_across"], row["offset"], row["method"])
        key = row["method"], row["cells_across"]
        worst[key] = max(worst.get(key, 0.0), s["check"]["relative_difference"], key=abs)
    for row in STUDY["worst"]:
        assert worst[row["method"], row["cells_across"]] == pytest.approx(row["error_worst"], rel=1e-9)
    for method, order in (("wall", 2.0), ("binary", 1.0)):
        n = [4, 8, 16, 32]
        slope = -np.polyfit(np.log(n), np.log([abs(worst[method, k]) for k in n]), 1)[0]
        assert slope == pytest.approx(order, abs=0.1)
