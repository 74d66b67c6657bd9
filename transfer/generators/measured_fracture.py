"""Two rock blocks around a measured fracture: the faces from height maps (profilometer scans,
:mod:`.height_maps`) instead of synthetic ones, meshed as the synthetic fractures are
(:func:`~transfer.generators.blocks.mortar_lattices`,
:func:`~transfer.generators.blocks.fracture_blocks`).

A map of any node count: the lattice's nodes are map nodes, every ``coarsen``-th one in x and y
(sampled, not averaged), the last lattice cell taking the remainder of the map's cells
(:func:`~transfer.generators.blocks.stations`: from half to one and a half ``coarsen``), so the
faces' heights at the lattice nodes are the map's and the rectangle is the map's extent; the
upper face's lattice is ``ratio`` times coarser again the same way (non-matching faces, for
mortar contact). ``periodic``: the map is one period of a periodic surface (its last row and
column do not repeat the first), closed by its first row and column: n nodes span n cells.
Where the aperture ``upper - lower`` is below ``min_aperture`` the upper face is raised to
``lower + min_aperture``, overlaps included. With ``min_aperture = 0`` faces that
interpenetrate by more than ``tolerance`` (default :data:`RELATIVE_TOLERANCE` of the larger
face's RMS height: the round-off of a pair in first contact) are refused, smaller overlaps
closed to touching. Each block is ``height`` thick from its face's mean plane; the rectangle
starts at the map's origin ((0, 0) for an ``.npz``). ``grading``: the blocks graded
(:mod:`.graded`: the lattice's spacing at the faces, layers growing away from them, the in-plane
lattice halved with depth) in place of ``layers`` uniform layers; made whole, not by index.
"""

from __future__ import annotations

import numpy as np

from . import number
from .blocks import FACE_TAGS, Block, lattice_block, mortar_lattices, stations
from .graded import graded_blocks
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
              "coarsen": "the lattice takes every coarsen-th map node in x and y, the last cell the remainder "
                         "(default 1: the map's grid)",
              "ratio": "the upper face's lattice is ratio times coarser (non-matching faces; default 1)",
              "periodic": "true: the map is one period, closed by its first row and column (default false)",
              "min_aperture": "smaller apertures are raised to it by lifting the upper face [m] (default 0)",
              "tolerance": "after the raise, the faces may interpenetrate by this much before the map is refused "
                           "[m] (default 1e-9 of the larger face's RMS height)",
              "grading": "ratio > 1 of successive layer thicknesses from the lattice spacing at the faces, the "
                         "in-plane lattice halved where a layer is twice as thick as its cells are wide (default: "
                         "none, layers uniform layers)"}
DEFAULTS = {"surfaces": None, "lower": None, "upper": None, "layers": 4, "coarsen": 1, "ratio": 1,
            "periodic": False, "min_aperture": 0.0, "tolerance": None, "grading": None}
#: the default tolerance, a fraction of the larger face's RMS height (round-off of touching faces)
RELATIVE_TOLERANCE = 1e-9
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


def closed_map(p: dict) -> tuple[np.ndarray, np.ndarray, tuple, tuple]:
    """:func:`read_faces`, closed by its first row and column when ``periodic``."""
    lower, upper, spacing, origin = read_faces(p)
    if p["periodic"]:
        if (all(np.array_equal(h[0], h[-1]) and np.array_equal(h[:, 0], h[:, -1]) for h in (lower, upper))
                and any(np.ptp(h) > 0 for h in (lower, upper))):  # (a flat face, a plate, repeats trivially)
            raise ValueError("periodic: the map's last row and column repeat its first already (a closed map): "
                             "closing it again would repeat them; leave periodic false")
        lower, upper = (np.pad(h, ((0, 1), (0, 1)), mode="wrap") for h in (lower, upper))
    return lower, upper, spacing, origin


def raised(lower: np.ndarray, upper: np.ndarray, min_aperture: float) -> np.ndarray:
    """The upper face lifted to ``lower + min_aperture`` where the aperture is smaller."""
    return np.where(upper - lower < min_aperture, lower + min_aperture, upper)


def _lattice(p: dict, nodes: tuple) -> tuple[np.ndarray, np.ndarray]:
    """The lower face's lattice nodes in x and y, as map node indices."""
    return stations(nodes[0] - 1, p["coarsen"]), stations(nodes[1] - 1, p["coarsen"])


def check(p: dict) -> dict:
    out = {k: _file(p, k) for k in FILES}
    if (out["surfaces"] is None) == (out["lower"] is None and out["upper"] is None):
        raise ValueError("surfaces: give either surfaces (an .npz of both faces) or lower and upper (XYZ files)")
    if out["surfaces"] is None and (out["lower"] is None or out["upper"] is None):
        raise ValueError(f"{'upper' if out['upper'] is None else 'lower'}: missing (the other face's XYZ file)")
    if not isinstance(p["periodic"], bool):
        raise ValueError(f"periodic: must be true or false, got {p['periodic']!r}")
    out.update({"height": number(p, "height", positive=True), "min_aperture": number(p, "min_aperture", minimum=0.0),
                "periodic": p["periodic"]})
    out.update({k: number(p, k, minimum=1, integer=True) for k in ("layers", "coarsen", "ratio")})
    out["grading"] = None if p["grading"] is None else number(p, "grading", positive=True)
    if out["grading"] is not None and not out["grading"] > 1:
        raise ValueError(f"grading: must be a ratio above 1 (layers growing away from the faces), got {p['grading']!r}")
    lower, upper, spacing, _ = closed_map(out)
    default = p["tolerance"] is None
    out["tolerance"] = (RELATIVE_TOLERANCE * max(float(np.std(lower)), float(np.std(upper))) if default
                        else number(p, "tolerance", minimum=0.0))
    gap = (raised(lower, upper, out["min_aperture"]) if out["min_aperture"] > 0 else upper) - lower
    if gap.min() < -out["tolerance"]:
        i, j = np.unravel_index(np.argmin(gap), gap.shape)
        raise ValueError(f"{'surfaces' if out['surfaces'] else 'upper'}: the faces interpenetrate by {-gap.min():.6g} m "
                         f"(more than the tolerance {out['tolerance']:g} m"
                         f"{f', {RELATIVE_TOLERANCE:g} of the RMS height' if default else ''}) at x = "
                         f"{i * spacing[0]:.6g}, y = {j * spacing[1]:.6g} m from the map's origin; raise them with "
                         f"min_aperture or accept them with tolerance")
    return out


def cells(p: dict) -> int:
    if p["grading"] is not None:
        return len(mesh(p).cells)
    nx, ny = (len(s) - 1 for s in _lattice(p, closed_map(p)[0].shape))
    ux, uy = len(stations(nx, p["ratio"])) - 1, len(stations(ny, p["ratio"])) - 1
    return 6 * (nx * ny + ux * uy) * p["layers"]


def _cells_note(nodes: np.ndarray) -> str:
    """How many cells of the finer lattice the cells of one axis span: "8" or "8, the last 7"."""
    steps = np.diff(nodes)
    return f"{steps[0]}" if np.all(steps == steps[0]) else f"{steps[0]}, the last {steps[-1]}"


def _uneven(nodes: np.ndarray) -> bool:
    """The cells of one axis are not all of one size (the last takes a remainder)."""
    return len(np.unique(np.diff(nodes))) > 1


def _sampled(p: dict) -> dict:
    """The map of checked parameters `p` as the blocks sample it: the faces (the upper one raised
    to ``min_aperture``), the lower face's lattice nodes ``i``, ``j`` (map node indices), the
    upper face's (``ui``, ``uj``: lower lattice node indices), the lattices' extent and axes."""
    lower, upper, spacing, origin = closed_map(p)
    i, j = _lattice(p, lower.shape)
    size = ((lower.shape[0] - 1) * spacing[0], (lower.shape[1] - 1) * spacing[1])
    return {"lower": lower, "upper": upper, "raised": raised(lower, upper, p["min_aperture"]), "spacing": spacing,
            "origin": origin, "i": i, "j": j, "ui": stations(len(i) - 1, p["ratio"]),
            "uj": stations(len(j) - 1, p["ratio"]), "size": size, "axes": (i * spacing[0], j * spacing[1])}


def _info(p: dict, m: dict) -> dict:
    """The ``info`` of :func:`mesh` from the sampled map `m` (nothing meshed)."""
    lower, i, j, size = m["lower"], m["i"], m["j"], m["size"]
    gap = m["raised"][np.ix_(i, j)] - lower[np.ix_(i, j)]
    lift = m["raised"] - m["upper"]
    if p["periodic"]:  # the closing row and column repeat the first: count each map node once
        lift = lift[:-1, :-1]
    upper = (f"; upper lattice {len(m['ui']) - 1} x {len(m['uj']) - 1}, lower cells per upper cell "
             f"{_cells_note(m['ui'])} (x), {_cells_note(m['uj'])} (y)" if p["ratio"] > 1 else "")
    return {"map_nodes": f"{lower.shape[0] - p['periodic']} x {lower.shape[1] - p['periodic']}",
            **({"periodic": f"closed by its first row and column: {len(lower) - 1} x {len(lower[0]) - 1} cells, "
                            f"{size[0]:g} x {size[1]:g} m"} if p["periodic"] else {}),
            "map_spacing": f"{m['spacing'][0]:g} x {m['spacing'][1]:g} m",
            "lattice": f"{len(i) - 1} x {len(j) - 1}, map cells per lattice cell {_cells_note(i)} (x), "
                       f"{_cells_note(j)} (y){upper}",
            "mean_aperture": surface_mean(gap, size, m["axes"]), "min_aperture": float(gap.min()),
            "max_initial_aperture": float(gap.max()), "raised_nodes": int(np.sum(lift > 0)),
            "largest_lift": float(lift.max()), "cross_section": size[0] * size[1]}


def _parts(p: dict) -> tuple[Lattices | None, dict, dict]:
    """The two blocks by index (None when graded), the ``info`` of :func:`mesh` and the sampled map."""
    m = _sampled(p)
    i, j, size, axes = m["i"], m["j"], m["size"], m["axes"]
    low, up = m["lower"][np.ix_(i, j)], m["raised"][np.ix_(i, j)]
    if p["grading"] is not None:
        return None, _info(p, m), m
    lattices = mortar_lattices((len(i) - 1, len(j) - 1, p["layers"]), size, p["height"], (low, up), p["ratio"],
                               m["origin"], bottom=surface_mean(low, size, axes) - p["height"], axes=axes)
    return lattices, _info(p, m), m


def _graded(p: dict, m: dict, info: dict) -> Block:
    """The two blocks graded (:func:`~transfer.generators.graded.graded_blocks`): the ends where
    the lattices put them, the upper face on its coarser lattice with ``ratio``."""
    i, j, size, axes = m["i"], m["j"], m["size"], m["axes"]
    low, up = m["lower"][np.ix_(i, j)], m["raised"][np.ix_(i, j)]
    xs, ys = m["origin"][0] + axes[0], m["origin"][1] + axes[1]
    ui, uj = m["ui"], m["uj"]
    bottom = surface_mean(low, size, axes) - p["height"]
    top = surface_mean(up, size, axes) + p["height"]
    return graded_blocks((xs, ys, low), (xs[ui], ys[uj], up[np.ix_(ui, uj)]), bottom, top, p["grading"], NAME, info)


def notes(p: dict) -> list[str]:
    """What was done to the map beyond sampling it: a remainder cell (of the lower or the upper
    lattice), the periodic closure, the raised apertures (for the plan and the run's summary).
    Nothing is meshed."""
    m = _sampled(p)
    info = _info(p, m)
    out = []
    if p["periodic"] or any(_uneven(m[k]) for k in ("i", "j", "ui", "uj")):
        closed = f", periodic, {info['periodic']}" if p["periodic"] else ""
        out.append(f"measured_fracture: map of {info['map_nodes']} nodes{closed}; lattice {info['lattice']}")
    if info["raised_nodes"] and p["min_aperture"] > 0:
        out.append(f"measured_fracture: {info['raised_nodes']} map nodes' apertures raised to min_aperture "
                   f"{p['min_aperture']:g} m (the upper face lifted by up to {info['largest_lift']:.3g} m)")
    elif info["raised_nodes"]:
        out.append(f"measured_fracture: {info['raised_nodes']} map nodes' overlaps closed to touching (up to "
                   f"{info['largest_lift']:.3g} m, within the tolerance {p['tolerance']:.3g} m)")
    return out


def lattices(p: dict) -> Lattices | None:
    """The two blocks by index (:mod:`.lattices`); None when graded (not a lattice: the mesh is
    made whole)."""
    return _parts(p)[0]


def mesh(p: dict) -> Block:
    """The two blocks in one mesh; ``info``: the map's nodes and spacing, the lattice, the
    aperture's mean, minimum and maximum on the lower lattice, the nodes of the map raised to
    ``min_aperture``, the cross-section (graded: also the layers per zone and the halvings)."""
    lattices, info, m = _parts(p)
    return _graded(p, m, info) if lattices is None else lattice_block(lattices, NAME, info)
