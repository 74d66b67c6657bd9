"""Two rock blocks around a measured fracture: the faces from height maps (profilometer
scans, :mod:`.height_maps`) instead of synthetic ones, meshed as the synthetic fractures are
(:func:`~transfer.generators.blocks.mortar_lattices`, :func:`~transfer.generators.blocks.fracture_blocks`).

The lattice's nodes are map nodes: every ``coarsen``-th one in x and y (sampled, not
averaged), so the faces' heights at the lattice nodes are the map's; the upper face's lattice
is ``ratio`` times coarser again (non-matching faces, for mortar contact). Where the map's
aperture ``upper - lower`` is below ``min_aperture`` the upper face is raised to
``lower + min_aperture``; faces that interpenetrate by more than ``tolerance`` are refused.
Each block is ``height`` thick from its face's mean plane; the rectangle is the map's
extent, from its origin ((0, 0) for an ``.npz``).
"""

from __future__ import annotations

import numpy as np

from . import number
from .blocks import FACE_TAGS, Block, lattice_block, mortar_lattices
from .lattices import Lattices
from .height_maps import read_npz, read_xyz
from .surfaces import surface_mean

NAME = "measured_fracture"
DESCRIPTION = "two rock blocks around a measured fracture: the faces from height maps (.npz or XYZ files)"
PARAMETERS = {"surfaces": ".npz file with arrays lower, upper (heights [m], (ny, nx)) and spacing [dx, dy], "
                          "relative to the case directory; or give lower and upper",
              "lower": "XYZ file of the lower face (x y z per line, a regular grid), relative to the case directory",
              "upper": "XYZ file of the upper face, on the lower face's grid",
              "height": "each block's thickness from its face's mean plane [m]",
              "layers": "layers of tetrahedra per block (default 4)",
              "coarsen": "the lattice takes every coarsen-th map node in x and y (default 1: the map's grid)",
              "ratio": "the upper face's lattice is ratio times coarser (non-matching faces; default 1)",
              "min_aperture": "smaller apertures are raised to it by lifting the upper face [m] (default 0)",
              "tolerance": "the faces may interpenetrate by this much before the map is refused [m] (default 0)"}
DEFAULTS = {"surfaces": None, "lower": None, "upper": None, "layers": 4, "coarsen": 1, "ratio": 1,
            "min_aperture": 0.0, "tolerance": 0.0}
#: parameters naming files: relative to the case directory (the scene resolves them)
FILES = ("surfaces", "lower", "upper")
FACES = dict(FACE_TAGS)


def _file(p: dict, key: str) -> str | None:
    value = p[key]
    if value is not None and not (isinstance(value, str) and value):
        raise ValueError(f"{key}: must be a file name, got {value!r}")
    return value


def read_faces(p: dict) -> tuple[np.ndarray, np.ndarray, tuple, tuple]:
    """The map of checked parameters `p`: ``(lower, upper, spacing, origin)``, heights (nx, ny)
    indexed [i, j] as :func:`~transfer.generators.blocks.fracture_blocks` takes them."""
    if p["surfaces"] is not None:
        try:
            (lower, upper), spacing = read_npz(p["surfaces"])
        except ValueError as exc:
            raise ValueError(f"surfaces: {exc}") from None
        return lower.T, upper.T, spacing, (0.0, 0.0)
    grids = {}
    for key in ("lower", "upper"):
        try:
            grids[key] = read_xyz(p[key])
        except ValueError as exc:
            raise ValueError(f"{key}: {exc}") from None
    (lower, spacing, origin), (upper, spacing_up, origin_up) = grids["lower"], grids["upper"]
    for what, a, b in (("nodes (ny, nx)", lower.shape, upper.shape), ("spacing", spacing, spacing_up),
                       ("origin", origin, origin_up)):
        if not np.allclose(a, b, rtol=1e-9, atol=0.0):
            raise ValueError(f"upper: the faces have different extents: {what} {tuple(b)} against the lower "
                             f"face's {tuple(a)}")
    return lower.T, upper.T, spacing, origin


def _lattice(p: dict, nodes: tuple) -> tuple[int, int]:
    """Lattice cells (nx, ny) of the lower face: the map's cells over ``coarsen``."""
    stride = p["coarsen"] * p["ratio"]
    cells = [n - 1 for n in nodes]
    if any(c % stride for c in cells):
        raise ValueError(f"coarsen: coarsen x ratio = {stride} must divide the map's {cells[0]} x {cells[1]} cells")
    return cells[0] // p["coarsen"], cells[1] // p["coarsen"]


def check(p: dict) -> dict:
    out = {k: _file(p, k) for k in FILES}
    if (out["surfaces"] is None) == (out["lower"] is None and out["upper"] is None):
        raise ValueError("surfaces: give either surfaces (an .npz of both faces) or lower and upper (XYZ files)")
    if out["surfaces"] is None and (out["lower"] is None or out["upper"] is None):
        raise ValueError(f"{'upper' if out['upper'] is None else 'lower'}: missing (the other face's XYZ file)")
    out.update({"height": number(p, "height", positive=True), "min_aperture": number(p, "min_aperture", minimum=0.0),
                "tolerance": number(p, "tolerance", minimum=0.0)})
    out.update({k: number(p, k, minimum=1, integer=True) for k in ("layers", "coarsen", "ratio")})
    lower, upper, spacing, _ = read_faces(out)
    _lattice(out, lower.shape)
    gap = upper - lower
    if gap.min() < -out["tolerance"]:
        i, j = np.unravel_index(np.argmin(gap), gap.shape)
        raise ValueError(f"{'surfaces' if out['surfaces'] else 'upper'}: the faces interpenetrate by {-gap.min():.6g} m "
                         f"(more than the tolerance {out['tolerance']:g} m) at x = {i * spacing[0]:.6g}, "
                         f"y = {j * spacing[1]:.6g} m from the map's origin")
    return out


def cells(p: dict) -> int:
    nx, ny = _lattice(p, read_faces(p)[0].shape)
    r, nz = p["ratio"], p["layers"]
    return 6 * nx * ny * nz + 6 * (nx // r) * (ny // r) * nz


def _parts(p: dict) -> tuple[Lattices, dict]:
    """The two blocks by index and the ``info`` of :func:`mesh`."""
    lower, upper, spacing, origin = read_faces(p)
    raised = upper - lower < p["min_aperture"]
    upper = np.where(raised, lower + p["min_aperture"], upper)
    nx, ny = _lattice(p, lower.shape)
    c = p["coarsen"]
    size = ((lower.shape[0] - 1) * spacing[0], (lower.shape[1] - 1) * spacing[1])
    low, up = lower[::c, ::c], upper[::c, ::c]
    lattices = mortar_lattices((nx, ny, p["layers"]), size, p["height"], (low, up), p["ratio"], origin,
                               bottom=surface_mean(low, size) - p["height"])
    gap = up - low
    info = {"map_nodes": f"{lower.shape[0]} x {lower.shape[1]}", "map_spacing": f"{spacing[0]:g} x {spacing[1]:g} m",
            "lattice": f"{nx} x {ny}", "mean_aperture": surface_mean(gap, size), "min_aperture": float(gap.min()),
            "max_initial_aperture": float(gap.max()), "raised_nodes": int(raised.sum()),
            "cross_section": size[0] * size[1]}
    return lattices, info


def lattices(p: dict) -> Lattices:
    """The two blocks by index (:mod:`.lattices`)."""
    return _parts(p)[0]


def mesh(p: dict) -> Block:
    """The two blocks in one mesh; ``info``: the map's nodes and spacing, the lattice, the
    aperture's mean, minimum and maximum on the lower lattice, the nodes of the map raised to
    ``min_aperture``, the cross-section."""
    lattices, info = _parts(p)
    return lattice_block(lattices, NAME, info)
