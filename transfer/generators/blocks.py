"""Tetrahedral meshes with named boundary faces (:class:`Block`), and the rock blocks
around a rough fracture.

:func:`fracture_blocks` builds two tetrahedral meshes: the lower block from
``z = -height`` up to the lower surface, the upper block from the upper surface
up to a flat top. Each is a lattice whose z-coordinates are stretched column by
column (like :func:`transfer.generate.box_tetrahedra` with a vertical map);
every lattice hexahedron is split in the six tets of
:data:`transfer.mesh.HEX_TETS`. Each of those tets has one vertical edge, so its
volume is (projected triangle area) x (vertical edge) / 3 > 0: any column-wise
monotone stretching keeps every tet positively oriented. Boundary triangles are
named ``fracture_lower`` (top of the lower block), ``fracture_upper`` (bottom of
the upper block), ``bottom``, ``top`` and ``xmin, xmax, ymin, ymax`` (the sides),
oriented outward, with the integer tags of :data:`FACE_TAGS`. :meth:`Block.write`
writes a block for meshio and :func:`solid_fenicsx.mesh.read_mesh` (triangle
blocks with ``gmsh:physical`` cell data, names in ``field_data``).
:attr:`FractureBlocks.solid` is both blocks in one mesh (two disjoint pieces),
the solid the coupler works with. :class:`Block` is also what every generator of
:mod:`transfer.generators` returns.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..mesh import Mesh
from .lattices import Lattice, Lattices
from .surfaces import surface_mean

#: integer tag of each named boundary (gmsh physical tags of dimension 2)
FACE_TAGS = {"bottom": 1, "top": 2, "fracture_lower": 3, "fracture_upper": 4,
             "xmin": 5, "xmax": 6, "ymin": 7, "ymax": 8}

#: integer tag of the tetrahedra of each block (gmsh physical tags of dimension 3)
BLOCK_TAGS = {"lower_block": 1, "upper_block": 2}


@dataclass(frozen=True)
class Block:
    """A tetrahedral mesh with named boundary triangles: what every generator returns.

    Attributes
    ----------
    points : (n, 3); cells : (m, 4) positively oriented tetrahedra (VTK order)
    faces : name -> (k, 3) outward-oriented boundary triangles (indices into points)
    cell_tags : (m,) integer tag of each tet (``cell_names``)
    name : label (used in error messages and files)
    face_tags : name -> integer tag of the faces (gmsh physical tags of dimension 2)
    cell_names : name -> integer tag of the cells (gmsh physical tags of dimension 3)
    info : figures of the generated geometry (e.g. a specimen's cross-section), for people
    """

    points: np.ndarray
    cells: np.ndarray
    faces: dict
    cell_tags: np.ndarray
    name: str = "block"
    face_tags: dict = field(default_factory=lambda: dict(FACE_TAGS))
    cell_names: dict = field(default_factory=lambda: dict(BLOCK_TAGS))
    info: dict = field(default_factory=dict)
    _mesh: list = field(default_factory=list, init=False, repr=False, compare=False)

    @property
    def mesh(self) -> Mesh:
        """The tets as a :class:`transfer.Mesh` (validated: no inverted or degenerate cell)."""
        if not self._mesh:
            self._mesh.append(Mesh(self.points, self.cells, "tetra", name=self.name))
        return self._mesh[0]

    @property
    def num_points(self) -> int:
        return len(self.points)

    @property
    def num_cells(self) -> int:
        return len(self.cells)

    @classmethod
    def of(cls, lattices: Lattices, name: str = "block", info: dict | None = None) -> "Block":
        """The whole mesh of `lattices` (:meth:`Lattices.arrays`) with its tags and names."""
        points, cells, faces, tags = lattices.arrays()
        return cls(points, cells, faces, tags, name, dict(lattices.face_tags), dict(lattices.cell_names),
                   info=dict(info or {}))

    def volume(self) -> float:
        return float(self.mesh.cell_measures().sum())

    def face_mesh(self, name) -> Mesh:
        """One named boundary as a triangle :class:`transfer.Mesh` (same point array)."""
        return Mesh(self.points, self.faces[name], "triangle", name=f"{self.name}:{name}")

    def named_faces(self) -> list[str]:
        """The names of the non-empty faces, in the order of their tags."""
        return [n for n in self.face_tags if n in self.faces and len(self.faces[n])]

    def tagged_triangles(self) -> tuple[np.ndarray, np.ndarray]:
        """Every named face's triangles, (k, 3), and the tag of each, (k,)."""
        names = self.named_faces()
        if not names:
            return np.empty((0, 3), np.int64), np.empty(0, np.int32)
        return (np.concatenate([self.faces[n] for n in names]),
                np.concatenate([np.full(len(self.faces[n]), self.face_tags[n], np.int32) for n in names]))

    def to_meshio(self):
        """A :class:`meshio.Mesh`: the tets, then one triangle block per named boundary, with
        ``gmsh:physical``/``gmsh:geometrical`` cell data and gmsh ``field_data`` names."""
        import meshio

        names = self.named_faces()
        cells = [("tetra", self.cells)] + [("triangle", self.faces[n]) for n in names]
        tags = [np.asarray(self.cell_tags, np.int32)] + [np.full(len(self.faces[n]), self.face_tags[n], np.int32)
                                                         for n in names]
        field_data = {n: np.array([self.face_tags[n], 2]) for n in names}
        for n, t in self.cell_names.items():
            if np.any(self.cell_tags == t):
                field_data[n] = np.array([t, 3])
        return meshio.Mesh(self.points, cells, cell_data={"gmsh:physical": tags, "gmsh:geometrical": tags},
                           field_data=field_data)

    def write(self, path, binary=True) -> Path:
        """Write for meshio and :func:`solid_fenicsx.mesh.read_mesh`: ``.msh`` as gmsh 2.2,
        anything else in the format meshio infers from the suffix (``.vtu``, ``.xdmf``, ...)."""
        import meshio

        path = Path(path)
        m = self.to_meshio()
        if path.suffix == ".msh":
            meshio.write(path, m, file_format="gmsh22", binary=binary)
        elif path.suffix == ".vtu":
            meshio.write(path, m, binary=binary, compression="zlib" if binary else None)
        else:
            meshio.write(path, m)
        return path

    def describe(self) -> str:
        """Counts, the z-range of each named face and the :attr:`info` figures, one per line."""
        lines = [f"{len(self.points)} points, {len(self.cells)} tetrahedra"]
        for n in self.named_faces():
            z = self.points[np.unique(self.faces[n]), 2]
            lines.append(f"face {n}: {len(self.faces[n])} triangles, z in [{z.min():.6g}, {z.max():.6g}]")
        lines += [f"{k}: {v:.6g}" if isinstance(v, float) else f"{k}: {v}" for k, v in self.info.items()]
        return "\n".join(lines)


@dataclass(frozen=True)
class FractureBlocks:
    """The two rock blocks of a fracture and the surfaces they were built on.

    ``lower``, ``upper``: one :class:`Block` each; ``solid``: both in one mesh (two
    disjoint pieces; the upper block's points follow the lower's); ``heights``: the
    (lower, upper) node-grid surfaces; ``size``, ``origin``: the rectangle in x, y.
    """

    lower: Block
    upper: Block
    solid: Block
    heights: tuple
    size: tuple
    origin: tuple

    @property
    def aperture(self) -> np.ndarray:
        """upper - lower at the grid nodes, (nx+1, ny+1)."""
        return self.heights[1] - self.heights[0]


def _layers(nz, grading, fine_at_top):
    """nz+1 increasing parameters in [0, 1]; cells grow by ``grading`` away from the fine end."""
    if nz < 1:
        raise ValueError(f"need at least one layer per block, got {nz}")
    if grading <= 0:
        raise ValueError(f"grading must be positive, got {grading}")
    steps = float(grading) ** np.arange(nz)  # from the fine end outward
    t = np.concatenate([[0.0], np.cumsum(steps)]) / steps.sum()
    t[-1] = 1.0
    return 1.0 - t[::-1] if fine_at_top else t


def _layered(xs, ys, z_bottom, z_top, nz, grading, fine_at_top, names, tag) -> Lattice:
    """The lattice of a block between two node-grid surfaces z_bottom, z_top (nx+1, ny+1) in nz
    layers, its faces named ``names`` (i=0, i=nx, j=0, j=ny, k=0, k=nz), its cells tagged ``tag``."""
    t = _layers(nz, grading, fine_at_top)

    def node(i, j, k):
        z = z_bottom[i, j] + t[k] * (z_top[i, j] - z_bottom[i, j])
        z = np.where(k == 0, z_bottom[i, j], np.where(k == nz, z_top[i, j], z))  # the faces carry the surfaces
        return np.column_stack([xs[i], ys[j], z])

    return Lattice((len(xs) - 1, len(ys) - 1, nz), node, tuple(names), tag)


def lattice_block(lattices: Lattices, name: str, info: dict | None = None) -> Block:
    """The :class:`Block` of `lattices`, validated: raises MeshError on an inverted or degenerate tet."""
    block = Block.of(lattices, name, info)
    block.mesh
    return block


def fracture_blocks(shape, size, height, heights, origin=(0.0, 0.0), top=None, grading=1.0,
                    bottom=None) -> FractureBlocks:
    """Two tetrahedral rock blocks with a rough fracture between them (the arguments of
    :func:`fracture_lattices`)."""
    low, up = fracture_lattices(shape, size, height, heights, origin, top, grading, bottom)
    return FractureBlocks(lattice_block(Lattices((low,), FACE_TAGS, BLOCK_TAGS), "lower_block"),
                          lattice_block(Lattices((up,), FACE_TAGS, BLOCK_TAGS), "upper_block"),
                          lattice_block(Lattices((low, up), FACE_TAGS, BLOCK_TAGS), "solid"),
                          tuple(np.asarray(h, float) for h in heights), (float(size[0]), float(size[1])),
                          (float(origin[0]), float(origin[1])))


def fracture_lattices(shape, size, height, heights, origin=(0.0, 0.0), top=None, grading=1.0,
                      bottom=None, axes=None) -> tuple[Lattice, Lattice]:
    """The lattices of two tetrahedral rock blocks with a rough fracture between them.

    Parameters
    ----------
    shape : (nx, ny, nz) lattice cells: nx x ny in the plane (the surfaces' grid), nz layers per block
    size : (Lx, Ly); origin : (x0, y0) of the rectangle
    height : thickness of each block, measured from the mean plane of its fracture face
    heights : (lower, upper) node-grid surfaces of shape (nx+1, ny+1), e.g. from
        :func:`fracture_pair` (parallel plates: ``(np.zeros(n), np.full(n, w))``)
    top : z of the upper block's top; default ``surface_mean(upper) + height``
    bottom : z of the lower block's bottom; default ``-height`` (a lower face of zero mean)
    grading : ratio of successive layer thicknesses away from the fracture (1: uniform;
        > 1: thin layers at the fracture)
    axes : (xs, ys) node coordinates from the origin, increasing from 0 to ``size`` (default
        uniform)

    The lower block spans ``z = bottom`` .. lower(x, y) (faces ``bottom``, ``fracture_lower``),
    the upper block upper(x, y) .. ``top`` (faces ``fracture_upper``, ``top``); both have
    the sides ``xmin, xmax, ymin, ymax``. Raises ValueError if a surface does not lie strictly
    between the bottom and the top (:func:`fracture_blocks` also :class:`transfer.MeshError` on
    a bad cell).
    """
    nx, ny, nz = (int(n) for n in shape)
    size = (float(size[0]), float(size[1]))
    lower, upper = (np.asarray(h, float) for h in heights)
    for h, which in ((lower, "lower"), (upper, "upper")):
        if h.shape != (nx + 1, ny + 1):
            raise ValueError(f"{which} heights have shape {h.shape}, expected {(nx + 1, ny + 1)} for shape {shape}")
        if not np.all(np.isfinite(h)):
            raise ValueError(f"{which} heights contain NaN or inf")
    if np.any(upper < lower):
        raise ValueError(f"the surfaces cross: upper - lower down to {np.min(upper - lower):.3g}")
    bottom = -float(height) if bottom is None else float(bottom)
    xs, ys = axes if axes is not None else (np.linspace(0.0, size[0], nx + 1), np.linspace(0.0, size[1], ny + 1))
    top = surface_mean(upper, size, (xs, ys)) + float(height) if top is None else float(top)
    if not np.all(lower > bottom):
        raise ValueError(f"the lower surface reaches below the bottom z = {bottom:g} (min {lower.min():.3g}); "
                         f"increase height")
    if not np.all(upper < top):
        raise ValueError(f"the upper surface reaches above the top z = {top:g} (max {upper.max():.3g}); "
                         f"increase height")
    xs, ys = origin[0] + np.asarray(xs, float), origin[1] + np.asarray(ys, float)
    sides = ("xmin", "xmax", "ymin", "ymax")
    low = _layered(xs, ys, np.full_like(lower, bottom), lower, nz, grading, True, sides + ("bottom", "fracture_lower"),
                   BLOCK_TAGS["lower_block"])
    up = _layered(xs, ys, upper, np.full_like(upper, top), nz, grading, False, sides + ("fracture_upper", "top"),
                  BLOCK_TAGS["upper_block"])
    return low, up


def stations(cells: int, stride: int) -> np.ndarray:
    """The node indices of a row of `cells` cells taken `stride` at a time: 0, stride, 2 stride,
    ... and `cells`, round(cells / stride) (at least one) coarse cells, the last taking the
    remainder (from stride / 2 to 3 stride / 2 cells; every ``stride``-th node when it divides)."""
    n = max(1, int(np.floor(cells / stride + 0.5)))
    return np.append(stride * np.arange(n), cells)


def mortar_lattices(shape, size, height, heights, ratio, origin=(0.0, 0.0), top=None, bottom=None,
                    axes=None) -> Lattices:
    """Two blocks around a fracture with non-matching faces, for mortar contact: the lower
    block on the (nx, ny, nz) lattice, the upper on one ``ratio`` times coarser in x and y
    (its nodes the lower lattice's :func:`stations`: every ratio-th node, the last cell taking the
    remainder; its face the upper heights there), both in one mesh (the upper block's points
    follow the lower's). ``top`` defaults to the mean of the full upper surface plus
    ``height``; the other arguments as in :func:`fracture_lattices`."""
    nx, ny, nz = (int(n) for n in shape)
    lower, upper = (np.asarray(h, float) for h in heights)
    xs, ys = axes if axes is not None else (np.linspace(0.0, size[0], nx + 1), np.linspace(0.0, size[1], ny + 1))
    if top is None:
        top = surface_mean(upper, size, (xs, ys)) + float(height)
    fine = fracture_lattices((nx, ny, nz), size, height, (lower, upper), origin, top=top, bottom=bottom,
                             axes=(xs, ys))[0]
    i, j = stations(nx, ratio), stations(ny, ratio)
    coarse = fracture_lattices((len(i) - 1, len(j) - 1, nz), size, height, (lower[np.ix_(i, j)], upper[np.ix_(i, j)]),
                               origin, top=top, bottom=bottom, axes=(np.asarray(xs)[i], np.asarray(ys)[j]))[1]
    return Lattices((fine, coarse), FACE_TAGS, BLOCK_TAGS)
