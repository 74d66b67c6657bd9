"""The traction with the viscous part (``[coupling] traction = "full"``) on P coupler ranks
(coupler/fsi/ranks.py: the deeper sampling surfaces as distributed pseudo-L2 traces from the grid
slabs, the samples, the wall shear and the traction at each rank's rows of the interface, the
figures reduced over the ranks): mpi_traction_cases.py under mpirun on 2 and 3 ranks against the
serial code on the whole arrays. Plane Poiseuille flow between the plates (test_viscous_traction.py)
with the slab cuts across the gap (between a wall and its samples, or between the samples) and
along the flow (through every sampling surface); the block under a thin channel whose deepest
surface leaves the grid on every rank (None, as serially), tilted so that it leaves the grid at
some vertices only (NaN there), and deformed (rebuilt on the ranks), its cells dealt out
round-robin or placed on the slabs (each rank the cells whose centroid lies over its slab, with the
wetted triangles they bound). The grid-stress method is refused on ranks."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from vc_helpers import run_mpi

HERE = Path(__file__).resolve().parent
pytestmark = pytest.mark.skipif(shutil.which("mpirun") is None, reason="mpirun not installed")
CASES = ("plates, cuts across the gap", "plates, cuts along the flow", "thin channel", "tilted thin channel",
         "deformed tilted channel", "deformed tilted channel on slabs")


@pytest.fixture(scope="module", params=[2, 3])
def result(request):
    found = run_mpi(HERE / "mpi_traction_cases.py", request.param)
    assert found["ranks"] == request.param and sorted(found["cases"]) == sorted(CASES)
    return found["cases"]


@pytest.mark.parametrize("case", CASES)
def test_the_traction_at_every_interface_row_is_the_serial_one(result, case):
    """Both parts at every row to 1e-12 of their largest value (measured up to 4.8e-15), every row
    held by one rank, the same fits, the figures to 1e-12 (the forces of the largest force
    component); the slab cuts pass through the sampled region."""
    found = result[case]
    assert found["pressure"] < 1e-12 and found["viscous"] < 1e-12, found
    assert found["rows"] == found["vertices"]
    serial, ranks = found["fits"]
    assert serial == ranks and sum(serial.values()) == found["vertices"]
    serial, ranks = found["figures"]
    assert ranks["shear_to_pressure"] == pytest.approx(serial["shear_to_pressure"], rel=1e-12)
    forces = ("pressure_force", "viscous_force")
    scale = max(abs(f) for key in forces for f in serial[key])  # the plates' pressure forces cancel: round-off
    for key in forces:
        assert all(abs(a - b) <= 1e-12 * scale for a, b in zip(serial[key], ranks[key])), (key, serial, ranks)
    assert found["cuts"] and all(found["sampled"][0] < cut < found["sampled"][-1] for cut in found["cuts"])


def test_the_plates_resolve_every_vertex_with_three_samples(result):
    for case in CASES[:2]:
        assert result[case]["fits"][1]["three samples"] == result[case]["vertices"] == 20


def test_a_surface_beyond_the_grid_is_none_and_one_partly_beyond_reads_nan(result):
    """The thin channel's deepest surface leaves the grid on every rank: None on the ranks as
    serially (every vertex through the wall and two samples); tilted, it leaves it at some vertices
    only: those fall back, on the ranks as serially."""
    thin = result["thin channel"]
    assert thin["deeper_none"] == [[False, True], [False, True]]
    assert thin["fits"][1]["wall and two samples"] == thin["vertices"]
    for case in CASES[3:]:
        tilted = result[case]
        assert tilted["deeper_none"] == [[False, False], [False, False]]
        assert 0 < tilted["outside"][1] < tilted["vertices"]
        assert tilted["fits"][1]["three samples"] < tilted["vertices"]


def test_the_grid_stress_method_is_refused_on_ranks(result):
    """The 'stress' method (reachable from code only) differentiates the velocity on the whole grid."""
    for case in CASES:
        assert result[case]["stress"] == ("viscous traction: method 'stress' differentiates the velocity on the "
                                          "whole grid: not on several coupler ranks; use 'wall'")


def test_the_cells_placed_on_the_slabs(result):
    """Every cell on one rank, each over that rank's slab (the block reaching x = 0 and 1, the
    grid's ends); every rank has some. A part whose wetted triangles are no faces of its cells
    cannot be placed: one line, on every rank."""
    found = result["deformed tilted channel on slabs"]
    assert found["off_slab"] == 0 and sum(found["cells"]) == found["solid_cells"] and all(found["cells"])
    assert found["misplaced"] == ("participant 'solid': a wetted triangle of its parts is a face of none of their "
                                  "cells: the coupler's ranks cannot place it with its cell")
