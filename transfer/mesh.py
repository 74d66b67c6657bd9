"""Meshes: tetrahedra and hexahedra (volume), triangles and quadrilaterals in 3D (surface).

Vertex order is VTK's (and meshio's) for every cell type. A mesh is validated
when it is made: finite coordinates within :data:`COORDINATE_LIMIT`, indices in range, no repeated vertex in a
cell, no degenerate cell and, for volume cells, no inverted cell. Tolerances
are relative to each cell's own size, so a mesh in metres and the same mesh in
millimetres are judged alike.

Orientation: the constructor is strict, since the coupler builds deformed meshes
with the same cells and an inverted cell there is a real failure. Mesh files,
though, number cells in either orientation (scipy's Delaunay and many mesh
generators give negative tetrahedra), so :meth:`Mesh.from_meshio` passes
``reorient=True``: a cell with negative orientation throughout (a tetrahedron,
or a hexahedron whose eight corner Jacobians are all negative) gets its mirror
vertex order (:data:`MIRROR`) and is counted in ``Mesh.reoriented``. Cells keep
their index, so cell data stays attached. A partly inverted hexahedron and a
degenerate cell stay errors.
"""

from __future__ import annotations

from dataclasses import InitVar, dataclass, field

import numpy as np

from .errors import MeshError

#: cell type -> (topological dimension, vertices per cell)
CELL_TYPES = {
    "tetra": (3, 4),
    "hexahedron": (3, 8),
    "triangle": (2, 3),
    "quad": (2, 4),
}

#: the faces of a tet opposite vertex 0, 1, 2, 3, ordered so their normal points out of a positive tet
TET_FACES = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])

#: tetrahedra splitting a hexahedron along its 0-6 diagonal (same as the kernels)
HEX_TETS = np.array([[0, 1, 2, 6], [0, 2, 3, 6], [0, 3, 7, 6], [0, 7, 4, 6], [0, 4, 5, 6], [0, 5, 1, 6]])



def lattice_hexahedra(shape, hexes=None) -> np.ndarray:
    """Hexahedra (VTK order) of an (nx, ny, nz) lattice of (nx+1)(ny+1)(nz+1) points
    numbered x fastest; cells numbered x fastest too (only those of index ``hexes`` if given)."""
    nx, ny, nz = (int(n) for n in shape)
    px, py = nx + 1, ny + 1
    h = np.arange(nx * ny * nz) if hexes is None else np.asarray(hexes, np.int64)
    i, j, k = h % nx, (h // nx) % ny, h // (nx * ny)
    base = i + px * (j + py * k)
    offsets = np.array([0, 1, 1 + px, px, px * py, 1 + px * py, 1 + px + px * py, px + px * py])
    return np.ascontiguousarray(base[:, None] + offsets[None, :], dtype=np.int64)


def lattice_tetrahedra(shape, start: int = 0, stop: int | None = None) -> np.ndarray:
    """The hexahedra of :func:`lattice_hexahedra` split by :data:`HEX_TETS` (conforming): tets
    ``start`` to ``stop`` (6 per hexahedron, in hexahedron order; default all)."""
    nx, ny, nz = (int(n) for n in shape)
    stop = 6 * nx * ny * nz if stop is None else int(stop)
    first = int(start) // 6
    hexes = np.arange(first, -(-stop // 6)) if stop > start else np.empty(0, np.int64)
    tets = lattice_hexahedra(shape, hexes)[:, HEX_TETS].reshape(-1, 4)
    return np.ascontiguousarray(tets[int(start) - 6 * first: stop - 6 * first])


#: a cell whose measure is below this times (longest edge)^dim is degenerate
DEGENERATE_RTOL = 1e-13

#: the largest coordinate magnitude a mesh or grid may have: the intersections' volumes and moments
#: multiply up to six coordinates, which overflow double precision (1.8e308) beyond about 1e51; a
#: P1 -> Q1 transfer of a linear field is exact at 1e50 and wrong at 1e60 (measured), and a mesh
#: at 1e300 was reported as not overlapping its partner
COORDINATE_LIMIT = 1e50


def check_coordinates(name: str, points) -> None:
    """MeshError unless every coordinate of `points` is finite and within :data:`COORDINATE_LIMIT`."""
    points = np.asarray(points, dtype=np.float64)
    if not np.all(np.isfinite(points)):
        bad = int(np.argwhere(~np.isfinite(points.reshape(-1, points.shape[-1])))[0, 0])
        raise MeshError(f"{name}: point {bad} has a non-finite coordinate")
    largest = float(np.max(np.abs(points), initial=0.0))
    if largest > COORDINATE_LIMIT:
        raise MeshError(f"{name}: coordinates up to {largest:.3g} in magnitude overflow double precision in the "
                        f"volumes and moments of the transfers (at most {COORDINATE_LIMIT:g}); give the geometry in "
                        f"other units")

#: vertex order of the mirror image of a volume cell: its orientation reversed (two
#: vertices of a tetrahedron swapped; the bottom and top quads of a hexahedron swapped)
MIRROR = {"tetra": [0, 2, 1, 3], "hexahedron": [4, 5, 6, 7, 0, 1, 2, 3]}

#: the corner tetrahedra of a hexahedron (a corner and its three neighbours, right-handed):
#: their volumes are the signs of the Jacobian at the eight corners
HEX_CORNERS = np.array([[0, 1, 3, 4], [1, 2, 0, 5], [2, 3, 1, 6], [3, 0, 2, 7],
                        [4, 7, 5, 0], [5, 4, 6, 1], [6, 5, 7, 2], [7, 6, 4, 3]])


def _signed_tet_volumes(p: np.ndarray) -> np.ndarray:
    """Signed volumes of tetrahedra given as (n, 4, 3) vertex arrays: a . (b x c) / 6 by
    components (np.cross copies its operands)."""
    a, b, c = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]
    a0, a1, a2, b0, b1, b2, c0, c1, c2 = a[:, 0], a[:, 1], a[:, 2], b[:, 0], b[:, 1], b[:, 2], c[:, 0], c[:, 1], c[:, 2]
    return (a0 * (b1 * c2 - b2 * c1) + a1 * (b2 * c0 - b0 * c2) + a2 * (b0 * c1 - b1 * c0)) / 6.0


def _longest_edges(p: np.ndarray) -> np.ndarray:
    """The longest distance between two vertices of each cell given as (n, k, 3) vertex arrays."""
    longest = np.zeros(len(p))
    coords = np.ascontiguousarray(p.transpose(1, 2, 0))  # (k, 3, n): contiguous differences
    for i, j in zip(*np.triu_indices(p.shape[1], 1)):  # vertex pairs, over all cells at once
        d = coords[i] - coords[j]
        d *= d
        squared = d[0] + d[1]
        squared += d[2]
        np.maximum(longest, squared, out=longest)
    return np.sqrt(longest)


def _triangle_areas(p: np.ndarray) -> np.ndarray:
    return 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)


@dataclass(frozen=True)
class Mesh:
    """An unstructured mesh of one cell type.

    Parameters
    ----------
    points : (n, 3) float array (2D points are padded with z = 0)
    cells : (m, k) integer array of vertex indices, VTK order
    cell_type : ``"tetra"``, ``"hexahedron"``, ``"triangle"`` or ``"quad"``
    name : label used in error messages (e.g. the file it was read from)
    reorient : give volume cells with negative orientation their mirror vertex
        order instead of rejecting them as inverted (see the module docstring);
        ``reoriented`` is then the number of cells reordered
    """

    points: np.ndarray
    cells: np.ndarray
    cell_type: str
    name: str = "mesh"
    reorient: InitVar[bool] = False
    _cache: dict = field(default_factory=dict, init=False, repr=False, compare=False)
    reoriented: int = field(default=0, init=False, compare=False)

    def __post_init__(self, reorient: bool):
        points = np.asarray(self.points, dtype=np.float64)
        if points.ndim != 2 or points.shape[1] not in (2, 3):
            raise MeshError(f"{self.name}: points must have shape (n, 3), got {points.shape}")
        if points.shape[1] == 2:
            points = np.hstack([points, np.zeros((len(points), 1))])
        object.__setattr__(self, "points", np.ascontiguousarray(points))
        if self.cell_type not in CELL_TYPES:
            raise MeshError(f"{self.name}: unsupported cell type {self.cell_type!r}; "
                            f"use one of {sorted(CELL_TYPES)}")
        cells = np.ascontiguousarray(np.asarray(self.cells, dtype=np.int64))
        object.__setattr__(self, "cells", cells)
        self._validate(reorient)

    # -- construction ---------------------------------------------------
    @classmethod
    def from_meshio(cls, mesh, cell_type: str | None = None, name: str = "mesh", reorient: bool = True) -> "Mesh":
        """The cells of one type of a :class:`meshio.Mesh` (by default its
        highest-dimensional supported type; blocks of that type are joined),
        reoriented by default: a file's orientation is a convention."""
        present = [b.type for b in mesh.cells if b.type in CELL_TYPES]
        if cell_type is None:
            if not present:
                raise MeshError(f"{name}: no tetra, hexahedron, triangle or quad cells "
                                f"(found {[b.type for b in mesh.cells]})")
            cell_type = max(present, key=lambda t: CELL_TYPES[t][0])
            others = {t for t in present if t != cell_type and CELL_TYPES[t][0] == CELL_TYPES[cell_type][0]}
            if others:
                raise MeshError(f"{name}: mixed cell types {sorted(others | {cell_type})} of the same "
                                f"dimension; pass cell_type to choose one")
        blocks = [b.data for b in mesh.cells if b.type == cell_type]
        if not blocks:
            raise MeshError(f"{name}: no cells of type {cell_type!r}")
        return cls(mesh.points, np.concatenate(blocks), cell_type, name=name, reorient=reorient)

    @classmethod
    def trusted(cls, points, cells, cell_type: str, name: str = "mesh") -> "Mesh":
        """A mesh made of cells of meshes already validated, not checked again (the source
        cells a rank gathers from the others'), or without cells (the part of a distributed
        mesh on a rank that holds none; the constructor rejects empty meshes)."""
        if cell_type not in CELL_TYPES:
            raise MeshError(f"{name}: unsupported cell type {cell_type!r}; use one of {sorted(CELL_TYPES)}")
        mesh = object.__new__(cls)
        for key, value in (("points", np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)),
                           ("cells", np.ascontiguousarray(cells, dtype=np.int64).reshape(-1, CELL_TYPES[cell_type][1])),
                           ("cell_type", cell_type), ("name", name), ("_cache", {}), ("reoriented", 0)):
            object.__setattr__(mesh, key, value)
        return mesh

    @classmethod
    def empty(cls, cell_type: str, name: str = "mesh") -> "Mesh":
        """A mesh without cells (see :meth:`trusted`)."""
        return cls.trusted(np.zeros((0, 3)), np.zeros((0, CELL_TYPES.get(cell_type, (0, 1))[1])), cell_type, name)

    def to_meshio(self):
        import meshio

        return meshio.Mesh(self.points, [(self.cell_type, self.cells)])

    # -- properties -----------------------------------------------------
    @property
    def tdim(self) -> int:
        return CELL_TYPES[self.cell_type][0]

    @property
    def num_cells(self) -> int:
        return len(self.cells)

    @property
    def num_points(self) -> int:
        return len(self.points)

    @property
    def is_simplex(self) -> bool:
        return self.cell_type in ("tetra", "triangle")

    def bounding_box(self) -> tuple[np.ndarray, np.ndarray]:
        """Lowest and highest coordinates of the points the cells use."""
        if "box" not in self._cache:
            used = np.zeros(self.num_points, bool)
            used[self.cells.ravel()] = True
            points = self.points[used] if self.num_cells else self.points
            self._cache["box"] = points.min(axis=0), points.max(axis=0)
        lo, hi = self._cache["box"]
        return lo.copy(), hi.copy()

    def cell_vertices(self) -> np.ndarray:
        """(m, k, 3) coordinates of the vertices of each cell."""
        return self.points[self.cells]

    def cell_measures(self, signed: bool = False) -> np.ndarray:
        """Volume (3D cells) or area (surface cells) of each cell.

        Hexahedra are measured as the union of the six tets of :data:`HEX_TETS`,
        the same decomposition the intersection kernels use."""
        key = ("measures", signed)
        if key not in self._cache:
            if not signed and self.cell_type in ("tetra", "hexahedron"):
                self._cache[key] = np.abs(self.cell_measures(signed=True))
                return self._cache[key]
            self._cache[key] = self._measures(self.cell_vertices(), signed)
        return self._cache[key]

    def _measures(self, p: np.ndarray, signed: bool) -> np.ndarray:
        """cell_measures from the cell vertices `p`."""
        if self.cell_type == "tetra":
            m = _signed_tet_volumes(p)
        elif self.cell_type == "hexahedron":
            m = sum(_signed_tet_volumes(p[:, t]) for t in HEX_TETS)
        elif self.cell_type == "triangle":
            m = _triangle_areas(p)
        else:
            m = _triangle_areas(p[:, [0, 1, 2]]) + _triangle_areas(p[:, [0, 2, 3]])
        return m if signed else np.abs(m)

    def longest_edges(self) -> np.ndarray:
        """The longest distance between two vertices of each cell."""
        return _longest_edges(self.cell_vertices())

    # -- validation -------------------------------------------------------
    def _validate(self, reorient: bool):
        tdim, nverts = CELL_TYPES[self.cell_type]
        if self.cells.ndim != 2 or self.cells.shape[1] != nverts:
            raise MeshError(f"{self.name}: {self.cell_type} cells need {nverts} vertices, "
                            f"got cells of shape {self.cells.shape}")
        check_coordinates(self.name, self.points)
        if self.num_cells == 0:
            raise MeshError(f"{self.name}: mesh has no cells")
        if self.cells.min() < 0 or self.cells.max() >= self.num_points:
            raise MeshError(f"{self.name}: cell vertex index out of range [0, {self.num_points})")
        s = np.sort(self.cells, axis=1)
        rep = np.flatnonzero((s[:, 1:] == s[:, :-1]).any(axis=1))
        if rep.size:
            raise MeshError(f"{self.name}: cell {rep[0]} repeats a vertex ({self.cells[rep[0]].tolist()}); "
                            f"{rep.size} such cell(s)")
        if self.cell_type == "tetra":  # both in one pass, the same values
            from . import _kernels

            h, volumes = _kernels.tet_shapes(self.points, self.cells)
            self._cache.setdefault(("measures", True), volumes)
        else:
            p = self.cell_vertices()  # gathered once for both
            h = _longest_edges(p)
            signed = tdim == 3 and self.cell_type == "hexahedron"
            self._cache.setdefault(("measures", signed), self._measures(p, signed))
            del p
        measure = self.cell_measures()
        degenerate = np.flatnonzero(measure <= DEGENERATE_RTOL * h**tdim)
        if degenerate.size:
            raise MeshError(f"{self.name}: cell {degenerate[0]} is degenerate (measure {measure[degenerate[0]]:.3e} "
                            f"for edge length {h[degenerate[0]]:.3e}); {degenerate.size} such cell(s)")
        if tdim == 3:
            self._check_orientation(DEGENERATE_RTOL * h**3, reorient)

    def _corner_volumes(self) -> np.ndarray:
        """(m, 1) signed volumes of tetrahedra, (m, 8) of the corner tetrahedra of hexahedra."""
        if self.cell_type == "tetra":
            return self.cell_measures(signed=True)[:, None]
        p = self.cell_vertices()
        return np.stack([_signed_tet_volumes(p[:, c]) for c in HEX_CORNERS], axis=1)

    def _check_orientation(self, small: np.ndarray, reorient: bool):
        """MeshError on a cell whose corner volume is below `small`; with `reorient`
        first mirror the cells negative at every corner."""
        vol = self._corner_volumes()
        if reorient:
            mirrored = np.all(vol < -small[:, None], axis=1)
            if mirrored.any():
                cells = self.cells.copy()
                cells[mirrored] = cells[mirrored][:, MIRROR[self.cell_type]]
                object.__setattr__(self, "cells", cells)
                object.__setattr__(self, "reoriented", int(mirrored.sum()))
                self._cache.clear()
                vol = self._corner_volumes()
        inverted = np.flatnonzero(vol.min(axis=1) <= small)
        if inverted.size:
            raise MeshError(f"{self.name}: cell {inverted[0]} is inverted (negative orientation, "
                            f"vertices {self.cells[inverted[0]].tolist()}); {inverted.size} such cell(s)")
