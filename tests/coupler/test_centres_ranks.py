"""The binary solid fraction (``[flow] solid_fraction = "cell_centre"``) on P coupler ranks
(coupler.fsi.ranks.slab_centres): mpi_centres_cases.py under mpirun on 2 and 3 ranks, each rank
holding the tetrahedra over another rank's grid slab, gives the serial mask of the whole mesh at
every cell; the rank's own tetrahedra alone (no OR over the ranks) miss every cell inside; a solid
that holds no centre gives an empty mask."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from vc_helpers import run_mpi

HERE = Path(__file__).resolve().parent
pytestmark = pytest.mark.skipif(shutil.which("mpirun") is None, reason="mpirun not installed")


@pytest.mark.parametrize("ranks", [2, 3])
def test_the_slab_owner_gets_the_or_over_the_ranks(ranks):
    found = run_mpi(HERE / "mpi_centres_cases.py", ranks)
    assert found["ranks"] == ranks
    box = found["jittered box"]
    assert box["differ"] == 0 and all(box["tetrahedra"])
    assert box["inside"] > 0 and box["differ_alone"] == box["inside"]  # found by other ranks only
    empty = found["between the centres"]
    assert empty == {"differ": 0, "differ_alone": 0, "inside": 0, "tetrahedra": [0] * (ranks - 1) + [6]}
