"""The XML of a tet mesh as XDMF + HDF5 in dolfinx's layout (read by the solid in parallel:
:mod:`solid_fenicsx.xdmf_mesh`): a ``Grid`` named ``mesh`` (linear tetrahedra), the facet tags as a
``Grid`` of triangles (``facet_tags``), the cell tags as one of tetrahedra (``cell_tags``), and
the tags' names as two ``Information`` elements holding JSON objects name -> tag
(``boundaries``, ``regions``). Read on one process without the HDF5 data: what the file holds,
its cell count, and whether it can be read at all.
"""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

#: the grids' names (dolfinx's defaults and gmshio's) and the Information elements of the names
MESH, FACETS, CELLS = "mesh", "facet_tags", "cell_tags"
BOUNDARIES, REGIONS = "boundaries", "regions"
HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"


@dataclass
class Layout:
    """What an XDMF file holds: the grids to read and the tags' names."""

    num_cells: int
    facets: str | None = None
    cells: str | None = None
    boundaries: dict[str, int] = field(default_factory=dict)
    regions: dict[str, int] = field(default_factory=dict)


def layout(path: Path, facets: str | None = None) -> Layout | None:
    """Check the XML of `path` and its HDF5 file (dolfinx reads the ``.h5`` of the same name,
    whatever file the XML names): the mesh's cell count, the grids of its facet tags (the grid
    `facets`, default ``facet_tags`` if there is one) and of its cell tags, their names; None
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
    topology = _topology(grids[MESH], MESH, "Tetrahedron", "cells are {}, not linear tetrahedra")
    if facets is not None and facets not in grids:
        raise ValueError(f"no facet tags {facets!r} (grids: {sorted(grids)})")
    try:
        num_cells = int(topology.get("NumberOfElements", ""))
    except ValueError:
        raise ValueError(f"grid {MESH!r}: no NumberOfElements") from None
    out = Layout(num_cells, facets or (FACETS if FACETS in grids else None), CELLS if CELLS in grids else None)
    if out.facets:
        _topology(grids[out.facets], out.facets, "Triangle", "facet tags {!r} are on {}, not triangles")
    if out.cells:
        _topology(grids[out.cells], out.cells, "Tetrahedron", "cell tags {!r} are on {}, not tetrahedra")
    _check_hdf5(path.with_suffix(".h5"))
    for info in domain.findall("Information"):
        if info.get("Name") in (BOUNDARIES, REGIONS):
            try:
                names = {str(k): int(v) for k, v in json.loads(info.get("Value", "")).items()}
            except (ValueError, TypeError, AttributeError):
                raise ValueError(f"Information {info.get('Name')!r} is not a JSON object name -> tag") from None
            setattr(out, info.get("Name"), names)
    return out


def _topology(grid, name: str, expected: str, message: str):
    """The grid's Topology element, of type `expected`."""
    found = grid.find("Topology")
    kind = None if found is None else found.get("TopologyType")
    if kind != expected:
        raise ValueError(message.format(*((kind,) if name == MESH else (name, kind))))
    return found


def _check_hdf5(path: Path) -> None:
    """An HDF5 file: its superblock's signature at offset 0, 512, 1024, ... (the HDF5 format)."""
    if not path.is_file():
        raise ValueError(f"its HDF5 file {path.name} does not exist (dolfinx reads the .h5 of the same name)")
    size, offset = path.stat().st_size, 0
    with open(path, "rb") as f:
        while offset + len(HDF5_SIGNATURE) <= size:
            f.seek(offset)
            if f.read(len(HDF5_SIGNATURE)) == HDF5_SIGNATURE:
                return
            offset = 512 if offset == 0 else 2 * offset
    raise ValueError(f"{path.name} is not an HDF5 file")
