"""Connected components and rigid bodies on a grid tiled by the ranks' index boxes
(transfer/labels.py, transfer/bodies.py): mpi_labels_cases.py under mpirun on 2, 3 and 4 ranks,
slabs along each axis, decomposePar's blocks (2x2x1, 1x2x2, 2x1x2), a box whose face meets two
boxes and an empty box. The joined labels equal scipy's on the whole grid exactly (the same
numbering); the bodies equal the serial ones: the same cells, velocities to 1e-14, the same
dropped components, on every rank the same."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from vc_helpers import run_mpi

HERE = Path(__file__).resolve().parent
pytestmark = pytest.mark.skipif(shutil.which("mpirun") is None, reason="mpirun not installed")


@pytest.fixture(scope="module", params=[2, 3, 4])
def result(request):
    found = run_mpi(HERE / "mpi_labels_cases.py", request.param)
    assert found["ranks"] == request.param
    return found


def test_the_joined_labels_are_scipys_on_the_whole_grid(result):
    """Every mask (none, all, a checkerboard of single cells, random at densities 0.3 to 0.7, the
    designed bodies below) on every tiling."""
    for tiling, cases in result["labels"].items():
        assert len(cases) == 16
        for mask, case in cases.items():
            assert case["equal"] and case["ranks"] == case["serial"], (tiling, mask, case)


def test_bodies_crossing_cuts_are_joined_and_diagonal_contacts_stay_apart(result):
    for tiling, cases in result["labels"].items():
        counts = {mask: case["ranks"] for mask, case in cases.items()}
        assert counts["none"] == 0 and counts["all"] == 1 and counts["checkerboard"] == 120
        assert counts["one cut"] == counts["several cuts"] == 1
        assert counts["U leaving and re-entering"] == 2  # the U and a bar apart from it
        assert counts["diagonal only"] == 6  # edges and a corner shared across cuts: no face, no join
        assert sum(cases["several cuts"]["own"]) >= 2, tiling  # its pieces in several boxes
    if result["ranks"] == 2:  # the U's two arms in the box x < 4, joined through the other box
        assert result["labels"]["slabs along x"]["U leaving and re-entering"]["own"] == [3, 1]
    if result["ranks"] == 4:  # blocks 2x2x1: the bars cross the cuts x = 4 and y = 3
        assert result["labels"]["blocks 2x2x1"]["several cuts"]["own"] == [1, 1, 0, 1]


def test_boxes_that_do_not_tile_the_grid_fail_on_every_rank(result):
    assert result["wrong tilings"] == {
        "overlap": ["the boxes of ranks 0 and 1 overlap"] * result["ranks"],
        "gap": ["the boxes of the ranks do not cover the grid of [8, 6, 5] cells"] * result["ranks"]}


def test_rigid_bodies_on_ranks_are_the_serial_bodies(result):
    """Four solid fractions and velocities (closed faces: all six, two, none, three), each rank
    given its box and the face neighbours (the OpenFOAM fluid's inputs): the serial bodies, some
    held by several ranks, some velocity components dropped at closed faces."""
    for tiling, fields in result["bodies"].items():
        for seed, b in fields.items():
            assert b["bodies"][0] == b["bodies"][1] > 0, (tiling, seed, b)
            assert b["cells"] and b["in the box"] and b["drops"] and b["same on every rank"], (tiling, seed, b)
            assert b["velocity"] < 1e-14, (tiling, seed, b)
            assert b["across boxes"] >= 1, (tiling, seed)
        assert sum(b["dropped"] for b in fields.values()) > 0


def test_rows_without_the_face_neighbours_fail_on_every_rank(result):
    assert result["missing"] == [f"rigid bodies: the rows given lack cells of the box or of their face neighbours "
                                 f"(rank 1 misses {30 if result['ranks'] == 2 else 60})"] * result["ranks"]
