"""cases/hm_fracture_map: the Reynolds fluid on the 256 x 256 aperture map of a rough fracture
closed by a platen (contact + flow). By default a small grid of it (the solid on an 8 x 8
lattice, 16 x 16 columns): it runs and reports what the README states; the case as shipped is
slow-marked (minutes: the solid's contact on a 32 x 32 face and the coupler's solid fractions of
1.6 million fluid cells per coupling iteration, README.md)."""

from __future__ import annotations

import json
import re

import pytest

from coupler.cli import main
from vc_helpers import CASES, copy_case

CASE = CASES / "hm_fracture_map"
SMALL = {"lattice = [32, 32, 2]": "lattice = [8, 8, 2]", "shape = [256, 256, 24]": "shape = [16, 16, 24]"}


def run(case, out) -> dict:
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("VARCOUPLE_PICTURES", "0")
        assert main(["run", str(case), "-o", str(out)]) == 0
    return json.loads((out / "summary.json").read_text())


def check(summary: dict, columns: int) -> None:
    """Completed, each Reynolds solve converged on the plane grid of one cell per column, the
    fracture's figures falling with stress and the local cubic law's e_h above e_m."""
    assert summary["status"] == "completed" and len(summary["steps"]) == 3
    rows = []
    for step in summary["steps"]:
        (reynolds,) = step["solves"]["fluid"]
        assert reynolds["converged"] and reynolds["solver"] == "Reynolds (SuperLU)"
        assert re.fullmatch(rf"\d+ of {columns} plane cells open and connected", reynolds["detail"])
        rows.append(step["fracture"])
    for row in rows:
        assert row["percolating"] and row["hydraulic_aperture"] > row["mechanical_aperture"] > 0
    for before, after in zip(rows, rows[1:]):
        assert after["mechanical_aperture"] < before["mechanical_aperture"]
        assert after["flow_rate"] < before["flow_rate"]


def test_a_small_grid_of_the_map_case_runs(tmp_path):
    check(run(copy_case(CASE, tmp_path, SMALL), tmp_path / "out"), 16 * 16)


@pytest.mark.slow
def test_the_full_map_case(tmp_path):
    """As shipped: 256 x 256 columns (about 16 minutes at a load average of 13, README.md)."""
    check(run(CASE, tmp_path / "out"), 256 * 256)
