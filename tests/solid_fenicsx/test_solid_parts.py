"""The solid participant on several ranks gathers nothing (docs/protocol.md, "Parts"): each rank answers
geometry and advance with its owned vertices and own cells only, and the coupler's join of the parts is
exactly what the old gathers gave (tests/solid_fenicsx/mpi_part_cases.py under mpirun)."""

from __future__ import annotations

import shutil

import pytest

pytest.importorskip("dolfinx")

from vc_helpers import ROOT, run_mpi  # noqa: E402

SCRIPT = ROOT / "tests" / "solid_fenicsx" / "mpi_part_cases.py"


@pytest.mark.skipif(shutil.which("mpirun") is None, reason="mpirun not installed")
@pytest.mark.parametrize("ranks", [1, 2, 3])
def test_each_rank_answers_its_own_part_and_the_join_is_the_old_gather(ranks):
    found = run_mpi(SCRIPT, ranks)
    assert found["ranks"] == ranks
    sizes = found["sizes"]
    total = sizes[0]["all_points"]
    for rank in sizes:  # owned sizes only: no rank holds the whole mesh or a whole field
        assert rank["points"] == rank["owned_points"] and rank["cells"] == rank["owned_cells"]
        assert rank["outputs"] == dict.fromkeys(("displacement", "velocity", "von_mises"), rank["owned_points"])
        assert ranks == 1 or rank["points"] < total
    assert sum(rank["points"] for rank in sizes) == total == 125
    assert found["same"] == dict.fromkeys(("points", "cells", "interface_triangles", "displacement", "velocity",
                                           "von_mises", "inputs"), True)
    assert found["max_displacement"] > 0
