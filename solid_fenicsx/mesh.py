"""Distributed tetrahedral meshes with named boundaries for the solid participant.

The solid of paper section 2.2 (eq. 7) is split into boundary parts (Dirichlet
``Gamma_D``, Neumann ``Gamma_N``, and, for fluid coupling, the wetted surface).
This module turns a tetrahedral mesh, given as arrays or read from a file with
meshio, into a dolfinx mesh distributed over an MPI communicator plus one facet
:class:`MeshTags` and a ``name -> tag`` dictionary, so that loads can be given
per named boundary.

Boundary facets get their tags from two sources, in this order:

1. triangle blocks of the input with integer cell data (``gmsh:physical`` or a
   named cell-data array); gmsh physical names (``field_data``) name the tags,
   tags without a name are named by their value (``"3"``);
2. geometric predicates given by the caller, evaluated on the midpoints of the
   exterior facets, e.g. ``{"top": lambda x: np.isclose(x[2], 1.0)}`` (``x``
   has shape ``(3, n)``, dolfinx's convention). A predicate overrides earlier
   tags on the facets it selects (a facet carries one tag).

Vertex numbering: the vertices of the input, compacted to those used by a cell,
in input order, are the "input numbering" that :mod:`solid_fenicsx.vertex_io`
gathers fields in. Cell tags (gmsh's physical volumes) are kept beside the facet tags.

No rank hands the whole mesh to dolfinx: every rank gives ``create_mesh`` one block
of cells and one block of points (:func:`from_blocks`). A box, or a generator that
describes its mesh by index (:class:`transfer.generators.lattices.Lattices`), is made
block by block, each rank only its own (:func:`lattice_mesh`); a file, or any other
generator, is read or made on the root rank, which scatters the blocks (:func:`from_arrays`);
an XDMF file (:mod:`solid_fenicsx.xdmf_mesh`, written by ``python -m solid_fenicsx.convert``) is
read by every rank, each its own rows (:func:`read_mesh`).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Mapping, Sequence

import numpy as np
import ufl
from mpi4py import MPI

import dolfinx
import dolfinx.cpp
from coupler.protocol.errors import InputError
from transfer.generators.lattices import Lattices, axes_lattice
from transfer.grid import BOX_FACES
from transfer.mesh import Mesh
from transfer.xdmf import layout

from . import xdmf_mesh

Predicate = Callable[[np.ndarray], np.ndarray]

#: cells validated at once (:func:`lattice_mesh`, :func:`from_arrays`)
VALIDATE_CELLS = 1 << 15


class SolidMeshError(InputError):
    """A mesh that cannot be used by the solid (no tetrahedra, bad tags, a boundary selecting
    nothing, a generator's parameters it cannot mesh): bad input (exit 2)."""


@dataclass
class SolidMesh:
    """A distributed dolfinx tet mesh with its boundary tags.

    Attributes
    ----------
    mesh : dolfinx.mesh.Mesh, P1 geometry, distributed over ``mesh.comm``
    facet_tags : facet MeshTags (local facets, one integer tag each)
    boundaries : name -> integer tag (the same on every rank)
    num_points, num_cells : global counts of input vertices and tetrahedra
    cell_tags : cell MeshTags (local cells) or None without cell tags
    regions : name -> integer tag of the cell tags (the same on every rank)
    """

    mesh: dolfinx.mesh.Mesh
    facet_tags: object
    boundaries: dict[str, int]
    num_points: int
    num_cells: int
    cell_tags: object = None
    regions: dict[str, int] = field(default_factory=dict)

    @property
    def comm(self) -> MPI.Comm:
        return self.mesh.comm

    def tags_of(self, boundary: str | int | Sequence[str | int]) -> tuple[int, ...]:
        """Integer tags of a boundary given by name, tag, or a list of them."""
        items = [boundary] if isinstance(boundary, (str, int, np.integer)) else list(boundary)
        tags = []
        for item in items:
            if isinstance(item, str):
                if item not in self.boundaries:
                    raise SolidMeshError(f"unknown boundary {item!r}; known: {sorted(self.boundaries)}")
                tags.append(self.boundaries[item])
            else:
                tags.append(int(item))
        return tuple(tags)

    def require_tags(self, tags: Mapping[str, int], source: str) -> None:
        """Raise :class:`SolidMeshError` naming `source` (the mesh's file) if a boundary of `tags`
        (name -> tag, e.g. a scene's ``boundaries``) has a tag the mesh does not have."""
        for name, tag in tags.items():
            if tag not in self.boundaries.values():
                raise SolidMeshError(f"{source}: boundary {name!r}: no facet tag {tag} "
                                     f"(tags: {sorted(self.boundaries.values())})")

    def facets(self, boundary) -> np.ndarray:
        """Local indices of the facets of a boundary (name, tag or list of them)."""
        tags = self.tags_of(boundary)
        mask = np.isin(self.facet_tags.values, tags)
        return np.asarray(self.facet_tags.indices[mask], dtype=np.int32)


# -- construction from arrays -------------------------------------------------
def _tet_domain() -> ufl.Mesh:
    return ufl.Mesh(ufl.VectorElement("Lagrange", ufl.tetrahedron, 1))


def _compact(points: np.ndarray, tets: np.ndarray, triangles: np.ndarray | None):
    """Drop points no tetrahedron uses; renumber cells and triangles."""
    used = np.zeros(len(points), bool)
    used[tets.ravel()] = True
    point_map = np.flatnonzero(used)
    new_index = np.full(len(points), -1, np.int64)
    new_index[point_map] = np.arange(len(point_map))
    tris = None
    if triangles is not None and len(triangles):
        tris = new_index[triangles]
        if (tris < 0).any():
            raise SolidMeshError("boundary triangles use points that belong to no tetrahedron")
    elif triangles is not None:
        tris = np.empty((0, 3), np.int64)
    return points[point_map], new_index[tets], tris


def _check_arrays(points, tets):
    if points.ndim != 2 or points.shape[1] != 3:
        raise SolidMeshError(f"points must have shape (n, 3), got {points.shape}")
    if tets.ndim != 2 or tets.shape[1] != 4:
        raise SolidMeshError(f"cells must be tetrahedra, shape (m, 4), got {tets.shape}")
    if len(tets) == 0:
        raise SolidMeshError("the mesh has no tetrahedra")
    if tets.min() < 0 or tets.max() >= len(points):
        raise SolidMeshError("cell vertex index out of range")
    if not np.isfinite(points).all():
        raise SolidMeshError("points contain NaN or infinite coordinates")
    degenerate = 0
    for first in range(0, len(tets), VALIDATE_CELLS):  # a bounded batch: the checks' temporaries stay small
        p = points[tets[first:first + VALIDATE_CELLS]]
        vol = np.einsum("ij,ij->i", p[:, 1] - p[:, 0], np.cross(p[:, 2] - p[:, 0], p[:, 3] - p[:, 0])) / 6.0
        scale = np.max(np.linalg.norm(p - p[:, :1], axis=2), axis=1) ** 3
        degenerate += int((np.abs(vol) <= 1e-14 * scale).sum())
    if degenerate:
        raise SolidMeshError(f"{degenerate} degenerate tetrahedra")


def _prepare(points, cells, triangles, triangle_tags):
    """Validate and compact the root's arrays."""
    points = np.ascontiguousarray(np.asarray(points, dtype=np.float64))
    if points.ndim == 2 and points.shape[1] == 2:
        points = np.hstack([points, np.zeros((len(points), 1))])
    tets = np.asarray(cells, dtype=np.int64)
    _check_arrays(points, tets)
    tris = None if triangles is None else np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    vals = None
    if tris is not None:
        vals = np.asarray(triangle_tags, dtype=np.int32).ravel()
        if len(vals) != len(tris):
            raise SolidMeshError(f"{len(tris)} triangles but {len(vals)} triangle tags")
    points, tets, tris = _compact(points, tets, tris)
    return points, tets, tris, vals


def block_rows(n: int, size: int, rank: int) -> tuple[int, int]:
    """The rows ``[start, stop)`` of ``rank`` when ``n`` rows are split in ``size`` consecutive
    near-equal blocks (the first ``n % size`` ranks one row more)."""
    q, r = divmod(int(n), size)
    start = rank * q + min(rank, r)
    return start, start + q + (rank < r)


def agree(comm: MPI.Comm, error: str | None) -> None:
    """Raise :class:`SolidMeshError` on every rank with the first rank's `error` if any rank
    has one (collective: a rank's bad block stops every rank, none waits for it)."""
    errors = [e for e in comm.allgather(error) if e]
    if errors:
        raise SolidMeshError(errors[0])


def from_blocks(points, cells, triangles=None, triangle_tags=None, tag_names: Mapping[str, int] | None = None,
                boundaries: Mapping[str, Predicate] | None = None, comm: MPI.Comm = MPI.COMM_WORLD,
                cell_tags=None, region_names: Mapping[str, int] | None = None) -> SolidMesh:
    """Distribute a tet mesh of which every rank gives one block (dolfinx's ``create_mesh``).

    Parameters (each rank's own, collective)
    ----------
    points : (n_r, 3) this rank's block of the input points: row ``i`` is input vertex
        ``offset_r + i``, ``offset_r`` the points of the ranks before it (every point used by a cell)
    cells : (m_r, 4) this rank's block of tetrahedra in input vertex ids; input cell ``c_r + i``
    triangles, triangle_tags : tagged boundary triangles (input vertex ids) held by this rank, or
        None on every rank; only exterior facets keep their tag
    tag_names : name -> tag of the triangle tags (the same on every rank)
    boundaries : name -> predicate on facet midpoints, as in :func:`from_arrays`
    cell_tags : (m_r,) integer tag of each of this rank's cells, or None on every rank
    region_names : name -> tag of the cell tags (the same on every rank)
    """
    points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    cells = np.ascontiguousarray(cells, dtype=np.int64).reshape(-1, 4)
    num_points, num_cells = (int(n) for n in comm.allreduce(np.array([len(points), len(cells)], np.int64)))
    mesh = dolfinx.mesh.create_mesh(comm, cells, points, _tet_domain())
    tdim = mesh.topology.dim
    mesh.topology.create_connectivity(tdim - 1, tdim)
    mesh.topology.create_connectivity(tdim - 1, 0)

    indices, values, names = np.empty(0, np.int32), np.empty(0, np.int32), {}
    if triangles is not None:
        vals = np.ascontiguousarray(triangle_tags, dtype=np.int32).ravel()
        indices, values = _exterior(mesh, _entity_tags(mesh, tdim - 1, triangles, vals))
        names = _named(vals, tag_names, comm)
    tagged_cells, regions = None, {}
    if cell_tags is not None:
        vals = np.ascontiguousarray(cell_tags, dtype=np.int32).ravel()
        tagged_cells, regions = _entity_tags(mesh, tdim, cells, vals), _named(vals, region_names, comm)
    return _finish(mesh, indices, values, names, boundaries, num_points, num_cells, tagged_cells, regions)


def _entity_tags(mesh, dim: int, entities, values):
    """The MeshTags of dimension `dim` of `entities` (this rank's, rows of input vertex ids)
    tagged `values`, sent to the ranks that hold them (collective)."""
    entities = np.ascontiguousarray(entities, dtype=np.int64).reshape(-1, dim + 1)
    local_entities, local_values = dolfinx.cpp.io.distribute_entity_data(mesh._mesh, dim, entities, values)
    adj = dolfinx.cpp.graph.AdjacencyList_int32(np.asarray(local_entities, dtype=np.int32))
    return dolfinx.cpp.mesh.create_meshtags(mesh._mesh, dim, adj, np.asarray(local_values, np.int32))


def _exterior(mesh, facet_tags) -> tuple[np.ndarray, np.ndarray]:
    """The (indices, values) of the exterior facets among `facet_tags`."""
    keep = np.isin(facet_tags.indices, dolfinx.mesh.exterior_facet_indices(mesh.topology))
    return np.asarray(facet_tags.indices[keep], np.int32), np.asarray(facet_tags.values[keep], np.int32)


def _named(values, tag_names: Mapping[str, int] | None, comm: MPI.Comm) -> dict[str, int]:
    """name -> tag of every tag of `values` on any rank, named by `tag_names` or ``str(tag)``."""
    by_tag = {int(v): k for k, v in (tag_names or {}).items()}
    return {by_tag.get(int(t), str(int(t))): int(t)
            for t in sorted(set().union(*comm.allgather(set(np.unique(values).tolist()))))}


def from_arrays(points=None, cells=None, triangles=None, triangle_tags=None,
                tag_names: Mapping[str, int] | None = None,
                boundaries: Mapping[str, Predicate] | None = None,
                comm: MPI.Comm = MPI.COMM_WORLD, root: int = 0, cell_tags=None,
                region_names: Mapping[str, int] | None = None) -> SolidMesh:
    """Distribute a tet mesh given as arrays on the ``root`` rank: ``root`` validates and
    compacts them, then scatters consecutive blocks of points, cells and triangles
    (:func:`block_rows`) to :func:`from_blocks`, so dolfinx never takes the whole mesh on one rank.

    Parameters
    ----------
    points : (n, 3) float array, cells : (m, 4) int array (VTK/dolfinx vertex order);
        read on ``root`` only (other ranks may pass None)
    triangles, triangle_tags : optional tagged boundary triangles (k, 3) and (k,)
        (vertex indices into ``points``); only exterior facets keep their tag
    tag_names : name -> tag for the triangle tags (others are named ``str(tag)``); read on ``root``
    boundaries : name -> predicate on facet midpoints, ``x`` of shape (3, n)
    cell_tags : optional (m,) integer tag of each cell, region_names : name -> tag of them; on ``root``
    """
    arrays, payload, error = (None,) * 5, None, None
    if comm.rank == root:
        try:
            points, tets, tris, vals = _prepare(points, cells, triangles, triangle_tags)
            regions = None if cell_tags is None else np.asarray(cell_tags, np.int32).ravel()
            if regions is not None and len(regions) != len(tets):
                raise SolidMeshError(f"{len(tets)} tetrahedra but {len(regions)} cell tags")
            arrays = (points, tets, tris, vals, regions)
            payload = (len(points), len(tets), 0 if tris is None else len(tris), tris is not None,
                       dict(tag_names or {}), regions is not None, dict(region_names or {}))
        except SolidMeshError as exc:
            error = str(exc)
    error = comm.bcast(error, root=root)
    if error:
        raise SolidMeshError(error)
    num_points, num_cells, num_tris, has_tris, tag_names, has_regions, region_names = comm.bcast(payload, root=root)
    points, tets, tris, vals, regions = (
        _scatter(a, n, width, dtype, comm, root) for a, n, width, dtype in
        zip(arrays, (num_points, num_cells, num_tris, num_tris, num_cells), (3, 4, 3, 1, 1),
            (np.float64, np.int64, np.int64, np.int32, np.int32)))
    del arrays
    return from_blocks(points, tets, tris if has_tris else None, vals, tag_names, boundaries, comm,
                       regions if has_regions else None, region_names)


def _scatter(array, n: int, width: int, dtype, comm: MPI.Comm, root: int) -> np.ndarray:
    """This rank's block (:func:`block_rows`) of the (n, width) `array` held by ``root``."""
    starts = np.array([block_rows(n, comm.size, r)[0] for r in range(comm.size)], np.int64)
    counts = np.diff(np.append(starts, n)) * width
    out = np.empty((counts[comm.rank] // width, width), dtype)
    send = None
    if comm.rank == root:
        rows = np.empty((0, width), dtype) if array is None else np.asarray(array, dtype).reshape(-1, width)
        send = [np.ascontiguousarray(rows), counts, starts * width,
                MPI._typedict[np.dtype(dtype).char]]
    comm.Scatterv(send, out, root=root)
    return out if width > 1 else out.ravel()


def exterior_midpoints(mesh) -> tuple[np.ndarray, np.ndarray]:
    """The local exterior facets and their midpoints, shape (3, n) (the ``x`` of predicates)."""
    exterior = dolfinx.mesh.exterior_facet_indices(mesh.topology)
    return exterior, dolfinx.mesh.compute_midpoints(mesh, mesh.topology.dim - 1, exterior).T


def _finish(mesh, indices, values, names, boundaries, num_points, num_cells, cell_tags=None,
            regions=None) -> SolidMesh:
    """Add predicate boundaries to the file tags and build the MeshTags."""
    tdim = mesh.topology.dim
    tags = dict(zip(indices.tolist(), values.tolist()))
    if boundaries:
        exterior, mid = exterior_midpoints(mesh)
        next_tag = max(list(names.values()) + [0]) + 1
        for name, predicate in boundaries.items():
            if name in names:
                raise SolidMeshError(f"boundary {name!r} is both in the mesh file and given as a predicate")
            selected = exterior[np.asarray(predicate(mid), dtype=bool).reshape(-1)] if len(exterior) else exterior
            for f in selected.tolist():
                tags[f] = next_tag
            names[name] = next_tag
            next_tag += 1
    order = np.array(sorted(tags), dtype=np.int32)
    vals = np.array([tags[i] for i in order.tolist()], dtype=np.int32)
    facet_tags = dolfinx.mesh.meshtags(mesh, tdim - 1, order, vals)
    facet_tags.name = "boundaries"
    # warn about named boundaries without any facet (typo in a predicate, overridden tag)
    for name, n in tag_counts(mesh, tdim - 1, facet_tags, names).items():
        if n == 0:
            warnings.warn(f"boundary {name!r} has no facets", stacklevel=3)
    return SolidMesh(mesh, facet_tags, names, num_points, num_cells, cell_tags, dict(regions or {}))


def tag_counts(mesh, dim: int, tags, names: Mapping[str, int]) -> dict[str, int]:
    """name -> the number of entities of dimension `dim` tagged with its tag in the MeshTags
    `tags` (None: none), each counted once over the ranks (owned, not ghost). Collective."""
    owned = mesh.topology.index_map(dim).size_local
    values = np.empty(0, np.int32) if tags is None else tags.values[tags.indices < owned]
    counts = mesh.comm.allreduce(np.array([np.count_nonzero(values == t) for t in names.values()], np.int64))
    return dict(zip(names, (int(n) for n in counts)))


# -- files --------------------------------------------------------------------
_TAG_KEYS = ("gmsh:physical", "medit:ref", "boundary", "tags", "CellEntityIds")


def read_mesh(path, boundaries: Mapping[str, Predicate] | None = None, tag_key: str | None = None,
              comm: MPI.Comm = MPI.COMM_WORLD, root: int = 0) -> SolidMesh:
    """Read a tet mesh file and distribute it: an ``.xdmf`` file in dolfinx's layout
    (:mod:`solid_fenicsx.xdmf_mesh`) by every rank, each its own rows (:func:`read_xdmf`), any
    other file (gmsh .msh, VTU, meshio's XDMF, ...) with meshio on ``root``, which scatters blocks.

    Facet tags come from the triangle blocks' integer cell data ``tag_key``
    (default: the first of ``gmsh:physical``, ``medit:ref``, ``boundary``,
    ``tags``, ``CellEntityIds`` present), cell tags from the tetrahedra's; gmsh physical
    names of dimension 2 and 3 name them. Second-order tetrahedra are reduced to their
    corner vertices. In dolfinx's XDMF layout ``tag_key`` names the facet tags' grid.
    """
    if Path(path).suffix.lower() == ".xdmf":
        return read_xdmf(path, boundaries, tag_key, comm, root)
    return _read_meshio(path, boundaries, tag_key, comm, root)


def _read_meshio(path, boundaries, tag_key, comm, root) -> SolidMesh:
    return _from_root(lambda: _read_on_root(str(path), tag_key), str(path), boundaries, comm, root)


def read_xdmf(path, boundaries: Mapping[str, Predicate] | None = None, facets: str | None = None,
              comm: MPI.Comm = MPI.COMM_WORLD, root: int = 0) -> SolidMesh:
    """Read an XDMF mesh (:mod:`solid_fenicsx.xdmf_mesh`) in parallel: ``root`` checks the XML,
    then each rank reads its own rows of the HDF5 file (dolfinx), so no rank holds the whole
    mesh. Input numbering: the file's rows. Facet tags (exterior facets only, named by the file's
    ``boundaries``), cell tags and ``boundaries`` predicates as for :func:`from_blocks`; an error
    names the file on every rank. A file in another layout (no grid ``mesh``) is read by meshio
    on ``root`` (:func:`read_mesh`), with `facets` its tags' cell data key."""
    found, error = None, None
    if comm.rank == root:
        try:
            found = layout(Path(path), facets)
        except ValueError as exc:
            error = f"{path}: {exc}"
    agree(comm, error)
    found = comm.bcast(found, root=root)
    if found is None:
        return _read_meshio(path, boundaries, facets, comm, root)
    mesh, facet_tags, cell_tags, error = None, None, None, None
    try:
        mesh, facet_tags, cell_tags = xdmf_mesh.read(Path(path), found, comm)
    except Exception as exc:  # noqa: BLE001 - dolfinx's and HDF5's errors, raised on every rank below
        error = f"{path}: dolfinx cannot read it ({exc})"
    agree(comm, error)
    tdim = mesh.topology.dim
    num_points = mesh.geometry.index_map().size_global
    last = comm.allreduce(int(np.max(mesh.geometry.input_global_indices, initial=-1)), op=MPI.MAX)
    if last + 1 != num_points:
        raise SolidMeshError(f"{path}: {last + 1 - num_points} of its {last + 1} points belong to no tetrahedron")
    indices, values, names = np.empty(0, np.int32), np.empty(0, np.int32), {}
    if facet_tags is not None:
        indices, values = _exterior(mesh, facet_tags)
        names = _named(facet_tags.values, found.boundaries, comm)
    regions = _named(cell_tags.values, found.regions, comm) if cell_tags is not None else {}
    return _finish(mesh, indices, values, names, boundaries, num_points, mesh.topology.index_map(tdim).size_global,
                   cell_tags, regions)


def generated_mesh(generator: str, parameters: Mapping | None = None,
                   boundaries: Mapping[str, Predicate] | None = None, comm: MPI.Comm = MPI.COMM_WORLD,
                   root: int = 0) -> SolidMesh:
    """The mesh of a generator of :mod:`transfer.generators` with its named faces as boundaries,
    distributed; ``boundaries`` add predicates as in :func:`from_arrays`. A generator that
    describes its mesh by index (``lattices``) makes on each rank only that rank's blocks
    (:func:`lattice_mesh`); any other runs on ``root``."""
    from transfer.generators import generate, lattices_of

    where = f"generator {generator!r}"
    described, error = None, None
    try:
        described = lattices_of(generator, dict(parameters or {}))
    except Exception as exc:  # noqa: BLE001 - re-raised on every rank below
        error = f"{where}: {exc}"
    agree(comm, error)
    if described is not None:
        return lattice_mesh(described, where, boundaries, comm)

    def build():
        block = generate(generator, dict(parameters or {}))
        triangles, tags = block.tagged_triangles()
        return {"points": block.points, "cells": block.cells, "triangles": triangles, "triangle_tags": tags,
                "tag_names": block.face_tags}

    return _from_root(build, where, boundaries, comm, root)


def lattice_mesh(lattices, where: str, boundaries: Mapping[str, Predicate] | None = None,
                 comm: MPI.Comm = MPI.COMM_WORLD) -> SolidMesh:
    """The mesh of `lattices` (a :class:`transfer.generators.lattices.Lattices`, the same on every
    rank), each rank making only its block of cells (:func:`block_rows`), their boundary
    triangles, the points of its own block and, to validate its cells (:class:`transfer.Mesh`),
    their vertices; an error of any rank, prefixed by `where`, raised on every rank."""
    error = None
    start, stop = block_rows(lattices.num_cells, comm.size, comm.rank)
    cells, _, triangles, tags = lattices.cells(start, stop)
    points = lattices.points(np.arange(*block_rows(lattices.num_points, comm.size, comm.rank)))
    try:
        for first in range(start, stop, VALIDATE_CELLS):  # a bounded batch: the checks' temporaries stay small
            last = min(first + VALIDATE_CELLS, stop)
            used, local = np.unique(cells[first - start:last - start], return_inverse=True)
            Mesh(lattices.points(used), local.reshape(-1, 4), "tetra", name=f"cells {first} to {last - 1}")
    except Exception as exc:  # noqa: BLE001 - re-raised on every rank below
        error = f"{where}: {exc}"
    agree(comm, error)
    named = bool(lattices.face_tags)
    return from_blocks(points, cells, triangles if named else None, tags, lattices.face_tags, boundaries, comm)


def _from_root(build, where: str, boundaries, comm, root) -> SolidMesh:
    """:func:`from_arrays` with the arrays ``build()`` makes on ``root``; its error, prefixed by
    `where`, raised on every rank."""
    args, error = {}, None
    if comm.rank == root:
        try:
            args = build()
        except Exception as exc:  # noqa: BLE001 - re-raised on every rank below
            error = f"{where}: {exc}"
    error = comm.bcast(error, root=root)
    if error:
        raise SolidMeshError(error)
    return from_arrays(comm=comm, root=root, boundaries=boundaries, **args)


def _read_on_root(path: str, tag_key: str | None) -> dict:
    import meshio

    try:
        m = meshio.read(path)
    except SystemExit:  # meshio 5.0 exits when none of the suffix's readers takes the file
        raise SolidMeshError("meshio cannot read it (not a mesh in the format its suffix names)") from None
    tets = [b.data[:, :4] for b in m.cells if b.type in ("tetra", "tetra10")]
    if not tets:
        raise SolidMeshError(f"no tetrahedra (cell blocks: {[b.type for b in m.cells]})")
    tri_blocks = [(i, b) for i, b in enumerate(m.cells) if b.type in ("triangle", "triangle6")]
    tet_blocks = [(i, b) for i, b in enumerate(m.cells) if b.type in ("tetra", "tetra10")]
    out = {"points": m.points[:, :3] if m.points.shape[1] >= 3 else m.points, "cells": np.concatenate(tets)}
    key = tag_key
    if key is None:
        key = next((k for k in _TAG_KEYS if k in m.cell_data), None)
    if key is None and tri_blocks:
        ints = [k for k, v in m.cell_data.items()
                if all(np.issubdtype(np.asarray(v[i]).dtype, np.integer) for i, _ in tri_blocks)]
        key = ints[0] if ints else None
    if key is not None and tri_blocks:
        if key not in m.cell_data:
            raise SolidMeshError(f"no cell data {key!r} (have {sorted(m.cell_data)})")
        out["triangles"] = np.concatenate([b.data[:, :3] for _, b in tri_blocks])
        out["triangle_tags"] = np.concatenate([np.asarray(m.cell_data[key][i]).ravel() for i, _ in tri_blocks])
        out["tag_names"] = _physical_names(m.field_data, 2)
    if key in m.cell_data and all(np.issubdtype(np.asarray(m.cell_data[key][i]).dtype, np.integer)
                                  for i, _ in tet_blocks):
        out["cell_tags"] = np.concatenate([np.asarray(m.cell_data[key][i]).ravel() for i, _ in tet_blocks])
        out["region_names"] = _physical_names(m.field_data, 3)
    return out


def _physical_names(field_data, dim: int) -> dict[str, int]:
    """gmsh's physical names of dimension `dim` (meshio's ``field_data``: name -> [tag, dim])."""
    names = {}
    for name, data in (field_data or {}).items():
        data = np.atleast_1d(data)
        if len(data) >= 2 and int(data[1]) == dim:
            names[name] = int(data[0])
    return names


# -- boxes --------------------------------------------------------------------
def box_mesh(lower=(0.0, 0.0, 0.0), upper=(1.0, 1.0, 1.0), shape=(4, 4, 4), axes=None,
             boundaries: Mapping[str, Predicate] | None = None,
             transform: Callable[[np.ndarray], np.ndarray] | None = None,
             comm: MPI.Comm = MPI.COMM_WORLD) -> SolidMesh:
    """A structured tet mesh of a box, faces named ``xmin, xmax, ymin, ymax, zmin, zmax``.

    Either ``lower``/``upper``/``shape`` (uniform), or ``axes`` = three increasing
    arrays of node coordinates (e.g. from :func:`transfer.generators.lattice.graded_nodes`, to refine toward
    a crack). ``boundaries`` add named predicates that override the face names
    on the facets they select (e.g. a crack disk on ``zmin``). ``transform``
    maps (n, 3) lattice points, each alone (every rank maps only the points it makes:
    :func:`lattice_mesh`), before the mesh is built (e.g. to fit a curved crack front);
    it must keep each box face in its plane.
    """
    if axes is None:
        axes = [np.linspace(lower[d], upper[d], int(shape[d]) + 1) for d in range(3)]
    axes = [np.unique(np.asarray(a, float)) for a in axes]
    if any(len(a) < 2 for a in axes):
        raise SolidMeshError("box node coordinates must be increasing, at least two per axis")
    lo = [a[0] for a in axes]
    hi = [a[-1] for a in axes]
    tol = [1e-10 * (h - l) for l, h in zip(lo, hi)]
    faces = {}
    for d in range(3):
        faces[BOX_FACES[2 * d]] = (lambda x, d=d: np.abs(x[d] - lo[d]) <= tol[d])
        faces[BOX_FACES[2 * d + 1]] = (lambda x, d=d: np.abs(x[d] - hi[d]) <= tol[d])
    faces.update(boundaries or {})
    return lattice_mesh(Lattices((axes_lattice(*axes),), {}, transform=transform), "box", faces, comm)
