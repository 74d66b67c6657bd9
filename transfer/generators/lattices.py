"""Tetrahedral meshes described by index: lattices whose points, cells and boundary triangles
are made for any range of indices alone.

A :class:`Lattices` is one or more :class:`Lattice` numbered one after the other (points
and cells), each an (nx, ny, nz) lattice of points (x fastest) split into the tets of
:func:`transfer.mesh.lattice_tetrahedra`, whose node coordinates a function of the lattice
index gives. The solid participant makes on each MPI rank only its block of cells and of
points (:func:`solid_fenicsx.mesh.generated_mesh`), so no rank builds the whole mesh;
:meth:`Lattices.arrays` makes them all (what :class:`~transfer.generators.blocks.Block`
holds). A generator that describes its mesh so defines ``lattices(parameters)``.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np

from ..generate import jitter_moves
from ..mesh import TET_FACES, lattice_tetrahedra


@dataclass(frozen=True)
class Lattice:
    """An (nx, ny, nz) lattice of tets: ``node(i, j, k)`` (index arrays) gives the (n, 3) node
    coordinates; ``faces`` names its six faces i = 0, i = nx, j = 0, j = ny, k = 0, k = nz (None:
    unnamed); ``tag`` is its cells' tag."""

    shape: tuple
    node: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]
    faces: tuple = (None,) * 6
    tag: int = 0

    @property
    def num_points(self) -> int:
        nx, ny, nz = self.shape
        return (nx + 1) * (ny + 1) * (nz + 1)

    @property
    def num_cells(self) -> int:
        nx, ny, nz = self.shape
        return 6 * nx * ny * nz

    def index(self, ids: np.ndarray) -> np.ndarray:
        """The lattice index (i, j, k) of points ``ids``, shape (n, 3)."""
        px, py = self.shape[0] + 1, self.shape[1] + 1
        ids = np.asarray(ids, np.int64)
        return np.column_stack([ids % px, (ids // px) % py, ids // (px * py)])

    def points(self, ids: np.ndarray) -> np.ndarray:
        i, j, k = self.index(ids).T
        return np.asarray(self.node(i, j, k), np.float64).reshape(-1, 3)

    def boundary(self, cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The outward triangles of `cells` (lattice tets) on a face of the lattice, in cell order,
        and the face (0 to 5) each lies on. A tet face whose three vertices lie on one face of the
        lattice (in index space) is on the boundary, in one tet only: no search for unmatched faces
        is needed. Temporaries of a few bytes per cell: the faces are tested one vertex set at a time."""
        used, local = np.unique(cells, return_inverse=True)
        lat = self.index(used)  # lattice index of each vertex the cells use
        on_face = ((lat == 0) | (lat == np.asarray(self.shape))).any(axis=1)
        local = local.reshape(-1, 4)
        keys, tris = [], []
        for f, vertices in enumerate(TET_FACES):
            hit = np.flatnonzero(on_face[local[:, vertices]].all(axis=1))  # candidates: every vertex on a face
            keys.append(4 * hit + f)
            tris.append(local[hit][:, vertices])
        order = np.argsort(np.concatenate(keys), kind="stable")  # cell by cell, face by face
        tris = np.concatenate(tris)[order]
        corners = lat[tris]  # (f, 3 vertices, 3 axes)
        face = np.full(len(tris), -1, np.int64)
        for axis in range(3):
            for side, value in enumerate((0, self.shape[axis])):
                face[np.all(corners[:, :, axis] == value, axis=1)] = 2 * axis + side
        on = face >= 0
        return used[tris[on]], face[on]


@dataclass(frozen=True)
class Lattices:
    """A tet mesh of lattices numbered one after the other; ``transform`` maps the (n, 3)
    points pointwise after the lattices' coordinates (e.g. a square to a disc); ``face_tags``
    tags the named faces, ``cell_names`` names the cell tags."""

    pieces: tuple
    face_tags: dict
    cell_names: dict = field(default_factory=dict)
    transform: Callable[[np.ndarray], np.ndarray] | None = None

    @property
    def num_points(self) -> int:
        return sum(p.num_points for p in self.pieces)

    @property
    def num_cells(self) -> int:
        return sum(p.num_cells for p in self.pieces)

    def _spans(self, sizes):
        start = 0
        for piece, size in zip(self.pieces, sizes):
            yield piece, start, start + size
            start += size

    def points(self, ids) -> np.ndarray:
        """The coordinates of points ``ids`` (global), shape (n, 3)."""
        ids = np.asarray(ids, np.int64)
        out = np.empty((len(ids), 3))
        for piece, first, last in self._spans([p.num_points for p in self.pieces]):
            mine = (ids >= first) & (ids < last)
            out[mine] = piece.points(ids[mine] - first)
        return out if self.transform is None else np.asarray(self.transform(out), np.float64)

    def cells(self, start: int = 0, stop: int | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Cells ``start`` to ``stop`` (global point ids), their tags, and their boundary triangles
        on named faces (global point ids, outward) with the face tags."""
        stop = self.num_cells if stop is None else stop
        cells, tags, tris, tri_tags = [], [], [], []
        point_start = 0
        for piece, first, last in self._spans([p.num_cells for p in self.pieces]):
            lo, hi = max(start, first), min(stop, last)
            if lo < hi:
                c = lattice_tetrahedra(piece.shape, lo - first, hi - first)
                t, face = piece.boundary(c)
                names = np.array([self.face_tags.get(n, -1) if n else -1 for n in piece.faces])
                named = names[face] >= 0
                cells.append(c + point_start)
                tags.append(np.full(len(c), piece.tag, np.int32))
                tris.append(t[named] + point_start)
                tri_tags.append(names[face[named]].astype(np.int32))
            point_start += piece.num_points
        if not cells:
            return (np.empty((0, 4), np.int64), np.empty(0, np.int32), np.empty((0, 3), np.int64),
                    np.empty(0, np.int32))
        return tuple(np.concatenate(a) for a in (cells, tags, tris, tri_tags))

    def arrays(self) -> tuple[np.ndarray, np.ndarray, dict, np.ndarray]:
        """The whole mesh: points, cells, named faces (name -> outward triangles, in the order
        of :attr:`face_tags`) and cell tags."""
        cells, tags, tris, tri_tags = self.cells()
        faces = {n: tris[tri_tags == t] for n, t in self.face_tags.items() if np.any(tri_tags == t)}
        return self.points(np.arange(self.num_points)), cells, faces, tags


def axes_lattice(xs, ys, zs, tag: int = 0) -> Lattice:
    """The lattice with nodes (xs[i], ys[j], zs[k]) (the points of
    :func:`transfer.generators.lattice.box_arrays`), no named face."""
    xs, ys, zs = (np.asarray(a, float) for a in (xs, ys, zs))
    return Lattice((len(xs) - 1, len(ys) - 1, len(zs) - 1), lambda i, j, k: np.column_stack([xs[i], ys[j], zs[k]]),
                   tag=tag)


def box_lattices(shape, lower, upper, jitter: float = 0.0, seed: int = 0) -> Lattices:
    """The tet lattice of a box, ``shape`` = (nx, ny, nz) hexahedra between the corners ``lower``
    and ``upper``, interior points moved by ``jitter`` (the points and cells of
    :func:`transfer.generate.box_tetrahedra`), no named face."""
    lattice = axes_lattice(*(np.linspace(lower[d], upper[d], int(shape[d]) + 1) for d in range(3)))
    if not jitter:
        return Lattices((lattice,), {})

    def node(i, j, k):
        rows = i + (lattice.shape[0] + 1) * (j + (lattice.shape[1] + 1) * k)
        return lattice.node(i, j, k) + jitter_moves(np.column_stack([i, j, k]), lattice.shape, lower, upper, jitter,
                                                    seed, rows)

    return Lattices((replace(lattice, node=node),), {})
