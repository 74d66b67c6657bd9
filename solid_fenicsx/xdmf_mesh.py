"""A tet mesh with its facet and cell tags as XDMF + HDF5 in dolfinx's layout
(:mod:`transfer.xdmf`: the grids ``mesh``, ``facet_tags``, ``cell_tags`` and the tags' names),
read and written by dolfinx in parallel. Reading, every rank reads only its own rows of the HDF5
datasets (dolfinx's ``read_mesh``; no rank holds the whole mesh): the input numbering of the
solid (:mod:`solid_fenicsx.mesh`) is the row order of the file's geometry and topology, the
same on any number of ranks. :func:`solid_fenicsx.mesh.read_xdmf` checks the file with
:func:`transfer.xdmf.layout` on one rank before the ranks open it together.
"""

from __future__ import annotations

import json
from pathlib import Path

import dolfinx
import dolfinx.io
import dolfinx.mesh
from transfer.xdmf import BOUNDARIES, CELLS, FACETS, MESH, REGIONS, Layout


def read(path: Path, found: Layout, comm):
    """The dolfinx mesh of `path`, its facet and cell MeshTags (None where `found` has none);
    collective, each rank reading its own rows."""
    with dolfinx.io.XDMFFile(comm, str(path), "r") as f:
        mesh = f.read_mesh(name=MESH)
        tdim = mesh.topology.dim
        mesh.topology.create_connectivity(tdim - 1, tdim)
        mesh.topology.create_connectivity(tdim - 1, 0)
        facet_tags = f.read_meshtags(mesh, found.facets) if found.facets else None
        cell_tags = f.read_meshtags(mesh, found.cells) if found.cells else None
    return mesh, facet_tags, cell_tags


def write(path: Path, solid) -> None:
    """Write a :class:`solid_fenicsx.mesh.SolidMesh` (its mesh, facet tags, cell tags and their
    names) to `path` (and the HDF5 file beside it); collective, each rank writing its own part."""
    mesh = solid.mesh
    tdim = mesh.topology.dim
    mesh.name = MESH
    with dolfinx.io.XDMFFile(mesh.comm, str(path), "w") as f:
        f.write_mesh(mesh)
        for name, dim, tags, names in ((FACETS, tdim - 1, solid.facet_tags, solid.boundaries),
                                       (CELLS, tdim, solid.cell_tags, solid.regions)):
            if tags is not None and names:
                copy = dolfinx.mesh.meshtags(mesh, dim, tags.indices, tags.values)
                copy.name = name
                f.write_meshtags(copy)
        f.write_information(BOUNDARIES, json.dumps(solid.boundaries))
        f.write_information(REGIONS, json.dumps(solid.regions))
