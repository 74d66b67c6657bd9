"""A tet mesh with its facet and cell tags as XDMF + HDF5, read and written by dolfinx in parallel.

The layout is the one dolfinx's ``XDMFFile`` writes: a ``Grid`` named ``mesh`` (linear
tetrahedra), the facet tags as a ``Grid`` of triangles (``facet_tags``), the cell tags as one of
tetrahedra (``cell_tags``), and the tags' names as two ``Information`` elements holding JSON
objects name -> tag (``boundaries``, ``regions``; gmsh's physical names). Reading, every rank
reads only its own rows of the HDF5 datasets (dolfinx's ``read_mesh``; no rank holds the whole
mesh): the input numbering of the solid (:mod:`solid_fenicsx.mesh`) is the row order of the
file's geometry and topology, the same on any number of ranks.

:func:`layout` checks the XML on one rank before any rank opens the HDF5 file collectively (a
bad file then fails on every rank alike, none waits in a collective read); its errors are
``ValueError`` with the reason, which :func:`solid_fenicsx.mesh.read_mesh` names the file in.
"""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import dolfinx
import dolfinx.io
import dolfinx.mesh

#: the grids' names (dolfinx's defaults and gmshio's) and the Information elements of the names
MESH, FACETS, CELLS = "mesh", "facet_tags", "cell_tags"
BOUNDARIES, REGIONS = "boundaries", "regions"
HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"


@dataclass
class Layout:
    """What an XDMF file holds: the grids to read and the tags' names."""

    facets: str | None = None
    cells: str | None = None
    boundaries: dict[str, int] = field(default_factory=dict)
    regions: dict[str, int] = field(default_factory=dict)


def layout(path: Path, facets: str | None = None) -> Layout | None:
    """Check the XML of `path` and the HDF5 files it names; the grids of the mesh, of its facet
    tags (the grid `facets`, default ``facet_tags`` if there is one) and of its cell tags; None
    for an XDMF file without a grid named ``mesh`` (another writer's layout, e.g. meshio's).
    Raises ``ValueError`` naming the reason."""
    if not path.is_file():
        raise ValueError("no such file")
    try:
        domain = ET.parse(path).getroot().find("Domain")
    except ET.ParseError as exc:
        raise ValueError(f"not an XDMF file ({exc})") from None
    if domain is None:
        raise ValueError("not an XDMF file (no Domain)")
    grids = {g.get("Name"): g for g in domain.findall("Grid")}
    if MESH not in grids:
        return None
    _topology(grids[MESH], MESH, "Tetrahedron", "cells are {}, not linear tetrahedra")
    if facets is not None and facets not in grids:
        raise ValueError(f"no facet tags {facets!r} (grids: {sorted(grids)})")
    out = Layout(facets=facets or (FACETS if FACETS in grids else None), cells=CELLS if CELLS in grids else None)
    if out.facets:
        _topology(grids[out.facets], out.facets, "Triangle", "facet tags {!r} are on {}, not triangles")
    if out.cells:
        _topology(grids[out.cells], out.cells, "Tetrahedron", "cell tags {!r} are on {}, not tetrahedra")
    for item in domain.iter("DataItem"):
        if item.get("Format") == "HDF":
            _check_hdf5(path.parent / (item.text or "").strip().split(":")[0])
    for info in domain.findall("Information"):
        if info.get("Name") in (BOUNDARIES, REGIONS):
            try:
                names = {str(k): int(v) for k, v in json.loads(info.get("Value", "")).items()}
            except (ValueError, TypeError, AttributeError):
                raise ValueError(f"Information {info.get('Name')!r} is not a JSON object name -> tag") from None
            setattr(out, info.get("Name"), names)
    return out


def _topology(grid, name: str, expected: str, message: str) -> None:
    found = grid.find("Topology")
    kind = None if found is None else found.get("TopologyType")
    if kind != expected:
        raise ValueError(message.format(*((kind,) if name == MESH else (name, kind))))


def _check_hdf5(path: Path) -> None:
    """An HDF5 file: its superblock's signature at offset 0, 512, 1024, ... (the HDF5 format)."""
    if not path.is_file():
        raise ValueError(f"its HDF5 file {path.name} does not exist")
    size, offset = path.stat().st_size, 0
    with open(path, "rb") as f:
        while offset + len(HDF5_SIGNATURE) <= size:
            f.seek(offset)
            if f.read(len(HDF5_SIGNATURE)) == HDF5_SIGNATURE:
                return
            offset = 512 if offset == 0 else 2 * offset
    raise ValueError(f"{path.name} is not an HDF5 file")


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
