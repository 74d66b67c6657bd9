"""The solid's meshes on the ranks of MPI.COMM_WORLD without a whole mesh on one rank
(tests/solid_fenicsx/test_solid_mesh_blocks.py): ``mpirun -n N python
tests/solid_fenicsx/mpi_mesh_cases.py DIR`` builds a box, two generators' meshes and a tagged mesh
file each the new way (every rank gives dolfinx its block) and the old way (rank 0 gives dolfinx
the whole mesh, :func:`old_path`), and prints as JSON from rank 0: the blocks each rank gave
``create_mesh``, the largest block of cells or points a rank made from a generator's lattices,
whether the two meshes are the same in input numbering (points, cells, tagged facets, boundary
names, counts), and the error every rank raised for bad input."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
from mpi4py import MPI

import dolfinx
from solid_fenicsx import mesh as solid_mesh
from solid_fenicsx.mesh import SolidMeshError, from_blocks, generated_mesh, lattice_mesh, read_mesh
from transfer.generators import generate
from transfer.generators.lattices import Lattices, box_lattices

COMM = MPI.COMM_WORLD
ROUGH = {"shape": [6, 4, 3], "size": [0.05, 0.025], "height": 0.005, "aperture": 0.001, "min_aperture": 0.0005,
         "rms": 0.00015, "mismatch_length": 0.0125, "seed": 4, "grading": 1.2}
SPECIMEN = {"lattice": [8, 8, 2], "ratio": 2}
#: the blocks (cells, points) each rank gave create_mesh in the latest call
GIVEN: list = []
#: the most cells or points one call of a Lattices made on this rank
MADE = {"cells": 0, "points": 0}


def record() -> None:
    create, cells, points = dolfinx.mesh.create_mesh, Lattices.cells, Lattices.points

    def create_mesh(comm, c, x, domain):
        GIVEN[:] = [len(c), len(x)]
        return create(comm, c, x, domain)

    def made_cells(self, start=0, stop=None):
        out = cells(self, start, stop)
        MADE["cells"] = max(MADE["cells"], len(out[0]))
        return out

    def made_points(self, ids):
        MADE["points"] = max(MADE["points"], len(ids))
        return points(self, ids)

    def refuse(self):
        raise AssertionError("a rank made the whole mesh")

    solid_mesh.dolfinx.mesh.create_mesh = create_mesh
    Lattices.cells, Lattices.points, Lattices.arrays = made_cells, made_points, refuse


def old_path(points, cells, triangles=None, tags=None, tag_names=None, boundaries=None):
    """Before: rank 0 handed dolfinx the whole mesh (the others nothing)."""
    if COMM.rank:
        points, cells = np.empty((0, 3)), np.empty((0, 4), np.int64)
        triangles, tags = (None, None) if triangles is None else (np.empty((0, 3), np.int64), np.empty(0, np.int32))
    return from_blocks(points, cells, triangles, tags, tag_names, boundaries, COMM)


def joined(solid) -> dict:
    """The mesh in input numbering on every rank of its communicator: points and cells by input
    id, the tagged facets as sorted input vertex ids with their tag, the boundary names and the
    counts."""
    m = solid.mesh
    tdim = m.topology.dim
    ids = np.asarray(m.geometry.input_global_indices, np.int64)
    owned = m.geometry.index_map().size_local
    n_cells = m.topology.index_map(tdim).size_local
    geo = m.geometry.dofmap.array.reshape(-1, 4)
    cells = (np.asarray(m.topology.original_cell_index[:n_cells], np.int64), ids[geo[:n_cells]])
    f2v = m.topology.connectivity(tdim - 1, 0)
    c2v = m.topology.connectivity(tdim, 0)
    node = np.empty(len(ids), np.int64)  # topology vertex -> geometry node, through the cells
    node[c2v.array.reshape(-1, 4)] = geo
    facets = solid.facet_tags.indices
    keep = facets < m.topology.index_map(tdim - 1).size_local
    tris = [np.sort(ids[node[f2v.links(f)]]).tolist() + [int(t)]
            for f, t in zip(facets[keep], solid.facet_tags.values[keep])]
    parts = m.comm.allgather((ids[:owned], m.geometry.x[:owned], cells, tris))
    points = np.empty((solid.num_points, 3))
    tets = np.empty((solid.num_cells, 4), np.int64)
    for i, x, (c, v), _ in parts:
        points[i], tets[c] = x, v
    return {"points": points, "cells": tets, "tags": sorted(t for *_, part in parts for t in part),
            "boundaries": solid.boundaries, "counts": (solid.num_points, solid.num_cells)}


def same(a: dict, b: dict) -> dict:
    return {k: bool(np.array_equal(a[k], b[k])) if isinstance(a[k], np.ndarray) else a[k] == b[k] for k in a}


def block_arrays(block):
    triangles, tags = block.tagged_triangles()
    return block.points, block.cells, triangles, tags, block.face_tags


def error_of(build) -> str:
    try:
        build()
    except SolidMeshError as exc:
        return str(exc)
    return ""


def main(directory: Path) -> None:
    faces = {"xmin": lambda x: np.isclose(x[0], 0.0), "top": lambda x: np.isclose(x[2], 1.0)}
    path = directory / "rough.msh"
    if COMM.rank == 0:
        generate("rough_fracture", ROUGH).write(path)
        (directory / "empty.msh").write_text("not a mesh\n")
    COMM.barrier()
    cases = {
        "box": (lambda: lattice_mesh(box_lattices((3, 4, 5), (0, 0, 0), (1, 1, 1)), "box", faces, COMM),
                lambda: old_path(*box_lattices((3, 4, 5), (0, 0, 0), (1, 1, 1)).arrays()[:2], boundaries=faces)),
        "rough_fracture": (lambda: generated_mesh("rough_fracture", ROUGH, comm=COMM),
                           lambda: old_path(*block_arrays(generate("rough_fracture", ROUGH)))),
        "cylinder specimen": (lambda: generated_mesh("fracture_specimen", SPECIMEN, comm=COMM),
                              lambda: old_path(*block_arrays(generate("fracture_specimen", SPECIMEN)))),
        "msh file": (lambda: read_mesh(path, comm=COMM),
                     lambda: old_path(*block_arrays(generate("rough_fracture", ROUGH)))),
    }
    out = {"ranks": COMM.size, "same": {}, "given": {}, "made": {}, "sizes": {}}
    for name, (new, old) in cases.items():
        reference = joined(old())  # first: the old path's arrays come from the unpatched Lattices
        record()
        MADE.update(cells=0, points=0)
        solid = new()
        out["given"][name] = COMM.gather(list(GIVEN))
        out["made"][name] = COMM.gather(dict(MADE))
        out["sizes"][name] = [solid.num_cells, solid.num_points]
        out["same"][name] = same(joined(solid), reference)
        Lattices.cells, Lattices.points, Lattices.arrays = CELLS, POINTS, ARRAYS
        solid_mesh.dolfinx.mesh.create_mesh = CREATE

    def flat_top(points):  # the top layer's cells (the last rank's) degenerate
        points[:, 2] = np.minimum(points[:, 2], 0.8)
        return points

    flattened = Lattices(box_lattices((2, 2, 5), (0, 0, 0), (1, 1, 1)).pieces, {}, transform=flat_top)
    errors = {"msh file": error_of(lambda: read_mesh(directory / "empty.msh", comm=COMM)),
              "generator parameter": error_of(lambda: generated_mesh("rough_fracture", {**ROUGH, "seed": -1},
                                                                     comm=COMM)),
              "a rank's cells": error_of(lambda: lattice_mesh(flattened, "[geometry.solid] box", comm=COMM))}
    out["errors"] = COMM.gather(errors)
    if COMM.rank == 0:
        print(json.dumps(out))


CELLS, POINTS, ARRAYS, CREATE = Lattices.cells, Lattices.points, Lattices.arrays, dolfinx.mesh.create_mesh

if __name__ == "__main__":
    main(Path(sys.argv[1]))
