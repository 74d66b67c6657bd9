"""The solid's mesh on N ranks without the whole mesh on one rank (solid_fenicsx.mesh: from_blocks,
lattice_mesh; tests/solid_fenicsx/mpi_mesh_cases.py under mpirun): every rank gives dolfinx one
block of cells and of points, a generator's lattices make on each rank only its block (and the
vertices of its cells), the mesh is the old path's (rank 0 giving dolfinx everything) in input
numbering, and bad input raises the same error, naming file, key and reason, on every rank."""

from __future__ import annotations

import shutil

import pytest

pytest.importorskip("dolfinx")

from vc_helpers import ROOT, run_mpi  # noqa: E402

SCRIPT = ROOT / "tests" / "solid_fenicsx" / "mpi_mesh_cases.py"


@pytest.mark.skipif(shutil.which("mpirun") is None, reason="mpirun not installed")
@pytest.mark.parametrize("ranks", [1, 2, 3])
def test_each_rank_gives_its_block_and_the_mesh_is_the_old_one(ranks, tmp_path):
    found = run_mpi(SCRIPT, ranks, tmp_path)
    assert found["ranks"] == ranks
    for name, same in found["same"].items():
        assert same == dict.fromkeys(("points", "cells", "tags", "boundaries", "counts"), True), name
    for name, (num_cells, num_points) in found["sizes"].items():
        given = found["given"][name]  # (cells, points) each rank gave create_mesh
        assert [c for c, _ in given] == [-(-num_cells // ranks) if r < num_cells % ranks or not num_cells % ranks
                                         else num_cells // ranks for r in range(ranks)], name
        assert sum(p for _, p in given) == num_points and max(p for _, p in given) <= -(-num_points // ranks), name
        made = found["made"][name]  # the largest block one rank made from the lattices
        if name == "msh file":  # read on rank 0 and scattered: no lattices
            assert made == [{"cells": 0, "points": 0}] * ranks
            continue
        for m in made:
            assert m["cells"] == -(-num_cells // ranks) or m["cells"] == num_cells // ranks, name
            assert ranks == 1 or m["points"] < num_points, name  # its own points or its cells' vertices
    errors = found["errors"]
    assert all(e == errors[0] for e in errors)  # every rank raised, the same message
    assert errors[0]["msh file"].endswith("empty.msh: meshio cannot read it (not a mesh in the format its suffix "
                                          "names)")
    assert errors[0]["generator parameter"] == "generator 'rough_fracture': seed: must lie in [0, inf), got -1"
    first = 120 * (ranks - 1) // ranks  # the top layer's degenerate cells (of 120): the last rank's block
    assert errors[0]["a rank's cells"].startswith(f"[geometry.solid] box: cells {first} to 119: cell ")
    assert "is degenerate" in errors[0]["a rank's cells"]
