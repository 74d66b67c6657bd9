"""The axis-aligned structured grid of the fluid (origin, spacing, shape).

Cells are numbered ``i + nx * (j + ny * k)`` and points ``i + (nx+1) * (j + (ny+1) * k)``
(x fastest, as in VTK structured grids and OpenFOAM's blockMesh). The grid is a
hexahedral mesh whose cells are boxes, which gives an index-based search and a
closed-form Q1 basis in the kernels.
"""

from __future__ import annotations

from functools import cached_property

import numpy as np

from .errors import MeshError
from .mesh import Mesh, check_coordinates, lattice_hexahedra


#: the six faces of an axis-aligned box (a grid, a box mesh), in the order (axis, side)
BOX_FACES = ("xmin", "xmax", "ymin", "ymax", "zmin", "zmax")


def cell_ijk(cells, shape) -> np.ndarray:
    """(n, 3): the indices (i, j, k) of the grid `cells` (numbered x fastest) of a grid of `shape`."""
    cells = np.asarray(cells, np.int64).reshape(-1)
    nx, ny, _ = (int(s) for s in shape)
    return np.stack([cells % nx, cells // nx % ny, cells // (nx * ny)], axis=1)


def box_cells(lower, upper, shape) -> np.ndarray:
    """The grid index (x fastest) of each cell of the box ``[lower, upper)``, as a (z, y, x) array."""
    i, j, k = (np.arange(lo, hi, dtype=np.int64) for lo, hi in zip(lower, upper))
    nx, ny, _ = (int(s) for s in shape)
    return (k[:, None, None] * ny + j[None, :, None]) * nx + i[None, None, :]


class StructuredGrid:
    """Boxes ``origin + spacing * [i, i+1] x [j, j+1] x [k, k+1]`` for ``0 <= (i, j, k) < shape``."""

    cell_type = "hexahedron"
    tdim = 3
    is_simplex = False

    def __init__(self, origin, spacing, shape, name: str = "grid"):
        self.name = name
        self.origin = np.asarray(origin, dtype=np.float64).reshape(3)
        self.spacing = np.asarray(spacing, dtype=np.float64).reshape(3)
        self.shape = tuple(int(n) for n in np.asarray(shape).reshape(3))
        check_coordinates(name, [self.origin, self.spacing, self.origin + self.spacing * np.asarray(self.shape)])
        if np.any(self.spacing <= 0):
            raise MeshError(f"{name}: spacing must be positive, got {self.spacing.tolist()}")
        if min(self.shape) < 1:
            raise MeshError(f"{name}: shape must be at least 1 cell per axis, got {list(self.shape)}")

    @classmethod
    def from_bounds(cls, lower, upper, shape, name: str = "grid") -> "StructuredGrid":
        lower, upper = np.asarray(lower, float), np.asarray(upper, float)
        return cls(lower, (upper - lower) / np.asarray(shape), shape, name=name)

    @property
    def num_cells(self) -> int:
        return int(np.prod(self.shape))

    @property
    def point_shape(self) -> tuple[int, int, int]:
        return tuple(n + 1 for n in self.shape)

    @property
    def num_points(self) -> int:
        return int(np.prod(self.point_shape))

    def bounding_box(self):
        return self.origin.copy(), self.origin + self.spacing * np.asarray(self.shape)

    @cached_property
    def points(self) -> np.ndarray:
        axes = [self.origin[d] + self.spacing[d] * np.arange(self.shape[d] + 1) for d in range(3)]
        z, y, x = np.meshgrid(axes[2], axes[1], axes[0], indexing="ij")
        return np.ascontiguousarray(np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1))

    @cached_property
    def cells(self) -> np.ndarray:
        return lattice_hexahedra(self.shape)

    def cell_measures(self) -> np.ndarray:
        return np.full(self.num_cells, float(np.prod(self.spacing)))

    def cell_centers(self) -> np.ndarray:
        return self.points[self.cells].mean(axis=1)

    def locate(self, x) -> np.ndarray:
        """Index of the cell containing each point (-1 outside), by arithmetic on the indices."""
        x = np.atleast_2d(np.asarray(x, dtype=np.float64))
        ijk = np.floor((x - self.origin) / self.spacing).astype(np.int64)
        shape = np.asarray(self.shape)
        upper = np.isclose(x, self.origin + self.spacing * shape, rtol=0, atol=1e-12 * self.spacing.max())
        ijk = np.where(upper & (ijk == shape), shape - 1, ijk)  # the upper faces belong to the last cells
        inside = np.all((ijk >= 0) & (ijk < shape), axis=1)
        ids = ijk[:, 0] + shape[0] * (ijk[:, 1] + shape[1] * ijk[:, 2])
        return np.where(inside, ids, -1)

    def to_mesh(self) -> Mesh:
        return Mesh(self.points, self.cells, "hexahedron", name=self.name)

    def to_meshio(self):
        import meshio

        return meshio.Mesh(self.points, [("hexahedron", self.cells)])

    def __repr__(self):
        return (f"StructuredGrid(origin={self.origin.tolist()}, spacing={self.spacing.tolist()}, "
                f"shape={list(self.shape)})")


def across_axis(shape, spacing) -> int:
    """The axis across a fracture or gap in a grid of ``shape`` and ``spacing``: of y and z (x,
    from the inlet to the outlet, is in the plane) the one of the thinner extent, leaving out one
    of a single cell (a 2D grid)."""
    extents = np.asarray(spacing, float) * np.asarray(shape)
    axes = [a for a in (1, 2) if int(shape[a]) > 1] or [1, 2]
    return min(axes, key=lambda a: extents[a])


def wall_distance(f_c, f_s, h: float):
    """Distance from the centre of a fluid-centred cell (fraction ``f_c``) to the wall in the
    direction of its solid-centred neighbour (``f_s``), spacing ``h``: ``h (3/2 - f_c - f_s)``
    clipped to ``[h / 50, h]``: the wall a sharp interface would have where the two cells'
    solid volume fractions (exact L2 projections of the solid's indicator) add up to
    ``3/2 - d/h`` (used by the fluid's ``"wall"`` penalization and the viscous traction)."""
    return np.clip(h * (1.5 - f_c - f_s), h / 50.0, h)
