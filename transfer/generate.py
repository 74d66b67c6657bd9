"""Simple mesh generators: boxes split into tetrahedra or hexahedra, and surfaces.

Non-matching meshes of one domain are made by choosing different resolutions
and moving interior vertices at random (`jitter`, a fraction of the spacing,
below 0.25 so no cell inverts). Used by the tests, the benchmarks and the demo.
"""

from __future__ import annotations

import numpy as np

from .mesh import Mesh, lattice_hexahedra, lattice_tetrahedra

_QUAD_TRIS = np.array([[0, 1, 2], [0, 2, 3]])


def _lattice(shape, lower, upper, jitter, seed):
    """Points of a (nx+1)(ny+1)(nz+1) lattice (x fastest) with interior jitter."""
    shape = np.asarray(shape)
    lower, upper = np.asarray(lower, float), np.asarray(upper, float)
    axes = [np.linspace(lower[d], upper[d], shape[d] + 1) for d in range(len(shape))]
    index = np.meshgrid(*[np.arange(n + 1) for n in shape[::-1]], indexing="ij")[::-1]
    idx = np.stack([g.ravel() for g in index], axis=1)  # lattice index of each point
    points = np.stack([axes[d][idx[:, d]] for d in range(len(shape))], axis=1)
    if jitter:
        points = points + jitter_moves(idx, shape, lower, upper, jitter, seed)
    return points


def jitter_moves(idx, shape, lower, upper, jitter: float, seed: int, rows=None) -> np.ndarray:
    """The random moves of lattice points of index `idx` (n, d) of :func:`_lattice`: uniform in
    +-`jitter` times the spacing, zero on the boundary faces. ``rows``: the points' numbers (x
    fastest), to draw only their rows of the whole lattice's random array (by advancing the
    generator: the same values as drawing every row); default all points in order."""
    shape, lower, upper = np.asarray(shape), np.asarray(lower, float), np.asarray(upper, float)
    d = len(shape)
    if rows is None:
        draws = np.random.default_rng(seed).uniform(-jitter, jitter, (len(idx), d))
    else:
        rows = np.asarray(rows, np.int64)
        order = np.argsort(rows, kind="stable")
        ordered = rows[order]
        starts = np.flatnonzero(np.diff(ordered, prepend=-2) != 1)  # runs of consecutive rows
        draws = np.empty((len(rows), d))
        for first, last in zip(starts, np.append(starts[1:], len(rows))):
            generator = np.random.PCG64(seed)  # np.random.default_rng's bit generator
            generator.advance(d * int(ordered[first]))  # one 64-bit draw per uniform double
            draws[order[first:last]] = np.random.Generator(generator).uniform(-jitter, jitter, (last - first, d))
    on_face = (idx == 0) | (idx == shape)  # vertices on a boundary face stay on it
    return np.where(on_face, 0.0, draws * (upper - lower) / shape)


def box_hexahedra(shape, lower=(0, 0, 0), upper=(1, 1, 1), jitter=0.0, seed=0, name="box") -> Mesh:
    """Hexahedral mesh of a box with `shape` = (nx, ny, nz) cells."""
    return Mesh(_lattice(shape, lower, upper, jitter, seed), lattice_hexahedra(shape), "hexahedron", name=name)


def box_tetrahedra(shape, lower=(0, 0, 0), upper=(1, 1, 1), jitter=0.0, seed=0, name="box") -> Mesh:
    """Tetrahedral mesh of a box: every hexahedron of the lattice split in six tets
    (:data:`transfer.mesh.HEX_TETS`, conforming across faces)."""
    points = _lattice(shape, lower, upper, jitter, seed)
    cells = lattice_tetrahedra(shape)
    return Mesh(points, cells, "tetra", name=name)


def tetrahedra_with_cells(target_cells: int, **kwargs) -> Mesh:
    """A box tet mesh with about `target_cells` cells (6 per lattice hexahedron)."""
    n = max(1, int(round((target_cells / 6) ** (1 / 3))))
    return box_tetrahedra((n, n, n), **kwargs)


def rectangle(shape, lower=(0, 0), upper=(1, 1), cell_type="triangle", jitter=0.0, seed=0,
              height=None, name="surface") -> Mesh:
    """A surface mesh of a rectangle in 3D, z = height(x, y) (0 by default)."""
    points2 = _lattice(shape, lower, upper, jitter, seed)
    z = np.zeros(len(points2)) if height is None else height(points2[:, 0], points2[:, 1])
    points = np.column_stack([points2, z])
    nx, ny = shape
    j, i = np.meshgrid(np.arange(ny), np.arange(nx), indexing="ij")
    base = (i + (nx + 1) * j).ravel()
    quads = base[:, None] + np.array([0, 1, nx + 2, nx + 1])[None, :]
    if cell_type == "quad":
        return Mesh(points, quads, "quad", name=name)
    return Mesh(points, quads[:, _QUAD_TRIS].reshape(-1, 3), "triangle", name=name)
