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

from ..mesh import Mesh, lattice_tetrahedra
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


def _stretched_lattice(xs, ys, z_of_layer):
    """Points of an (nx+1)(ny+1)(nz+1) lattice, x fastest, z per column; z_of_layer: (nz+1, nx+1, ny+1)."""
    nz = z_of_layer.shape[0] - 1
    k, j, i = np.meshgrid(np.arange(nz + 1), np.arange(len(ys)), np.arange(len(xs)), indexing="ij")
    idx = np.stack([i.ravel(), j.ravel(), k.ravel()], axis=1)
    points = np.column_stack([xs[idx[:, 0]], ys[idx[:, 1]], z_of_layer[idx[:, 2], idx[:, 0], idx[:, 1]]])
    return points, idx


def _boundary_faces(cells, idx, shape, names):
    """Outward boundary triangles of a positively oriented lattice tet mesh, by lattice face.

    names: the six face names in the order (i=0, i=nx, j=0, j=ny, k=0, k=nz)."""
    # faces opposite vertex 0, 1, 2, 3, ordered so their normal points out of a positive tet
    local = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])
    # a tet face whose three vertices lie on one face of the lattice (in index space) is on the
    # boundary, in one tet only: no search for unmatched faces is needed
    on_face = np.zeros(len(idx), bool)
    for axis in range(3):
        on_face |= (idx[:, axis] == 0) | (idx[:, axis] == shape[axis])
    tris = cells[:, local].reshape(-1, 3)
    tris = tris[on_face[tris].all(axis=1)]
    lat = idx[tris]  # (f, 3 vertices, 3 axes)
    faces = {}
    for axis in range(3):
        for side, value in enumerate((0, shape[axis])):
            sel = np.all(lat[:, :, axis] == value, axis=1)
            faces[names[2 * axis + side]] = tris[sel]
    return faces


def _block(xs, ys, z_bottom, z_top, nz, grading, fine_at_top, names, tag, name):
    nx, ny = len(xs) - 1, len(ys) - 1
    t = _layers(nz, grading, fine_at_top)
    z = z_bottom[None] + t[:, None, None] * (z_top - z_bottom)[None]
    z[0], z[-1] = z_bottom, z_top  # the faces carry the surface heights exactly
    points, idx = _stretched_lattice(xs, ys, z)
    cells = lattice_tetrahedra((nx, ny, nz))
    faces = _boundary_faces(cells, idx, (nx, ny, nz), names)
    block = Block(points, cells, faces, np.full(len(cells), tag, np.int32), name=name)
    block.mesh  # validate now: raises MeshError on an inverted or degenerate tet
    return block


def _combine(a: Block, b: Block, name="solid") -> Block:
    off = len(a.points)
    faces = {}
    for n in FACE_TAGS:
        parts = [f for f in (a.faces.get(n), None if b.faces.get(n) is None else b.faces[n] + off)
                 if f is not None and len(f)]
        if parts:
            faces[n] = np.concatenate(parts)
    return Block(np.concatenate([a.points, b.points]), np.concatenate([a.cells, b.cells + off]), faces,
                 np.concatenate([a.cell_tags, b.cell_tags]), name=name)


def fracture_blocks(shape, size, height, heights, origin=(0.0, 0.0), top=None, grading=1.0,
                    bottom=None) -> FractureBlocks:
    """Two tetrahedral rock blocks with a rough fracture between them.

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

    The lower block spans ``z = bottom`` .. lower(x, y) (faces ``bottom``, ``fracture_lower``),
    the upper block upper(x, y) .. ``top`` (faces ``fracture_upper``, ``top``); both have
    the sides ``xmin, xmax, ymin, ymax``. Raises ValueError if a surface does not lie strictly
    between the bottom and the top, and :class:`transfer.MeshError` on a bad cell.
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
    top = surface_mean(upper, size) + float(height) if top is None else float(top)
    if not np.all(lower > bottom):
        raise ValueError(f"the lower surface reaches below the bottom z = {bottom:g} (min {lower.min():.3g}); "
                         f"increase height")
    if not np.all(upper < top):
        raise ValueError(f"the upper surface reaches above the top z = {top:g} (max {upper.max():.3g}); "
                         f"increase height")
    xs = origin[0] + np.linspace(0.0, size[0], nx + 1)
    ys = origin[1] + np.linspace(0.0, size[1], ny + 1)
    sides = ("xmin", "xmax", "ymin", "ymax")
    low = _block(xs, ys, np.full_like(lower, bottom), lower, nz, grading, True,
                 sides + ("bottom", "fracture_lower"), BLOCK_TAGS["lower_block"], "lower_block")
    up = _block(xs, ys, upper, np.full_like(upper, top), nz, grading, False,
                sides + ("fracture_upper", "top"), BLOCK_TAGS["upper_block"], "upper_block")
    return FractureBlocks(low, up, _combine(low, up), (lower, upper), size, (float(origin[0]), float(origin[1])))


def mortar_blocks(shape, size, height, heights, ratio, origin=(0.0, 0.0), top=None, bottom=None) -> Block:
    """Two blocks around a fracture with non-matching faces, for mortar contact: the lower
    block on the (nx, ny, nz) lattice, the upper on one ``ratio`` times coarser in x and y
    (its face the upper heights at every ratio-th node; ratio divides nx and ny), both in one
    mesh (the upper block's points follow the lower's). ``top`` defaults to the mean of the
    full upper surface plus ``height``; the other arguments as in :func:`fracture_blocks`."""
    nx, ny, nz = (int(n) for n in shape)
    lower, upper = (np.asarray(h, float) for h in heights)
    if top is None:
        top = surface_mean(upper, size) + float(height)
    fine = fracture_blocks((nx, ny, nz), size, height, (lower, upper), origin, top=top, bottom=bottom).lower
    coarse = fracture_blocks((nx // ratio, ny // ratio, nz), size, height, (lower[::ratio, ::ratio],
                             upper[::ratio, ::ratio]), origin, top=top, bottom=bottom).upper
    return _combine(fine, coarse)
