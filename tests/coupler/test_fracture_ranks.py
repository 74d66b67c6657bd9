"""The fracture monitor's figures on P coupler ranks (coupler/fsi/apertures.py, flow_rate.py,
open_gap.py with ``comm``/``rows``): mpi_fracture_cases.py under mpirun on 2 ranks, rows and grid
slabs split over them, equals the serial functions on the whole arrays to 1e-10; percolation
through open cells that connect only across the slab cut (once, or down and up again: two
components of one slab joined through the other), and not when the cut is blocked or the cells
meet across it diagonally."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from vc_helpers import run_mpi

HERE = Path(__file__).resolve().parent
pytestmark = pytest.mark.skipif(shutil.which("mpirun") is None, reason="mpirun not installed")


@pytest.fixture(scope="module")
def result():
    found = run_mpi(HERE / "mpi_fracture_cases.py", 2)
    assert found["ranks"] == 2
    return found


@pytest.mark.parametrize("case, connected", [("across the cut", True), ("blocked at the cut", False),
                                             ("down and up again", True), ("diagonal at the cut", False),
                                             ("along x across the cut", True), ("along x blocked", False)])
def test_percolation_joins_the_labels_across_the_slab_cut(result, case, connected):
    serial, ranks, lower, upper = result["percolation"][case]
    assert serial is connected and ranks is connected
    assert lower == [0, 0, 0] and upper in ([6, 4, 4], [4, 4, 3])  # rank 0 holds half the grid


def test_sums_over_the_ranks_are_the_serial_figures(result):
    assert result["flow_rates"] < 1e-10
    assert result["open_lengths"].keys() == {"across the cut", "along the cut"}
    assert all(v < 1e-14 for v in result["open_lengths"].values()), result["open_lengths"]
    assert result["apertures"].keys() == {"mechanical_aperture", "mean_open_aperture", "contact_area_fraction"}
    assert all(v < 1e-10 for v in result["apertures"].values()), result["apertures"]


def test_the_contact_share_on_ranks_is_the_serial_one(result):
    """Triangles dealt out over the ranks, or each face whole on one rank: every vertex's share
    equals the serial one to 1e-10, the coarse face's shares strictly between 0 and 1."""
    shares = result["contact_share"]
    assert shares["other face touches"]
    assert shares["dealt out"] < 1e-10 and shares["a face per rank"] < 1e-10
