"""An XDMF + HDF5 mesh read in parts (transfer/pieces.py): each rank reads one slab of topology
rows, N / P, and the geometry rows they use by hyperslabs, then holds the cells the coordinate
bisection of the whole mesh gives it (the partition ``mpirun -n P varcouple transfer`` cuts a
single file into), whatever order the file's rows are in."""

from __future__ import annotations

import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest

from transfer.generate import box_tetrahedra
from transfer.pieces import hyperslabs, read_rows
from vc_helpers import run_mpi, write_xdmf

HERE = Path(__file__).resolve().parent


def test_rows_are_read_by_hyperslabs_through_short_gaps(tmp_path):
    """Rows 3-5, 10 and 40-41 of a 60-row dataset with gaps of 4 and 29: with a gap of 4 rows read
    through, two hyperslabs (3-10 and 40-41), the rows given back in their order."""
    with h5py.File(tmp_path / "d.h5", "w") as f:
        f["x"] = np.arange(180.0).reshape(60, 3)
        rows = np.array([3, 4, 5, 10, 40, 41])
        starts, stops = hyperslabs(rows, gap=4)
        assert starts.tolist() == [3, 40] and stops.tolist() == [11, 42]
        values, read = read_rows(f["x"], rows)
        np.testing.assert_array_equal(values, f["x"][:][rows])
        assert read == (11 - 3) + (42 - 40)
        assert read_rows(f["x"], np.zeros(0, np.int64))[0].shape == (0, 3)
    assert hyperslabs(rows, gap=3)[0].tolist() == [3, 10, 40]


@pytest.mark.skipif(shutil.which("mpirun") is None, reason="mpirun not installed")
@pytest.mark.parametrize("ranks", [2, 3])
def test_each_rank_holds_the_bisections_cells_having_read_its_rows(tmp_path, ranks):
    """A 3,000-tet box written with its cells and points shuffled (a run of rows spans the whole
    box, as in dolfinx's files): each rank read N / P topology rows and at most its rows' 4 vertices
    each, and holds exactly the cells (ids, vertices, coordinates) that the bisection of the whole
    mesh gives it; rank 0 joins the file's mesh back, rows in the file's order."""
    mesh = box_tetrahedra((10, 10, 5), jitter=0.2, seed=3)
    rng = np.random.default_rng(0)
    cells, points = rng.permutation(mesh.num_cells), rng.permutation(mesh.num_points)
    renumber = np.argsort(points)
    write_xdmf(tmp_path / "m.xdmf", mesh.points[points], renumber[mesh.cells[cells]])
    found = run_mpi(HERE / "mpi_pieces_cases.py", ranks, tmp_path / "m.xdmf")
    n = found["num_cells"]
    assert found["ranks"] == ranks and n == mesh.num_cells and found["whole"]
    for r, rank in enumerate(found["per_rank"]):
        rows = (r + 1) * n // ranks - r * n // ranks
        assert rank["cells_read"] == rows, (r, rank)
        assert rank["points_read"] <= found["num_points"], (r, rank)  # no geometry row twice
        assert rank["cell_ids"] and rank["cells_equal"] and rank["points_equal"], (r, rank)
    assert sum(rank["cells"] for rank in found["per_rank"]) == n
