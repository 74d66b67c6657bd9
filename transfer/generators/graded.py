"""Graded blocks around a fracture (issue 30): the unknowns at the face, not in the volume.

A block of :func:`graded_blocks` has the lattice's spacing ``h`` at its fracture face and layers
growing by ``ratio`` away from it (``h``, ``h ratio``, ``h ratio^2``, ...) in two zones:

- the rough zone, the lattice of :func:`~transfer.generators.blocks.fracture_lattices` between
  the rough face and a flat plane: as few of those layers as span twice the face's relief (its
  highest minus its lowest point) and at least one spacing, each column's layers scaled to its
  own depth (so the shallowest column keeps at least half of each nominal thickness);
- the flat zone, from that plane to the block's flat end: the series continued, scaled to end
  there, and wherever a layer is at least twice as thick as its cells are wide, a transition
  layer that halves the in-plane lattice (every second node, :func:`~.blocks.stations`).

Regular layers are lattice hexahedra split by :data:`transfer.mesh.HEX_TETS` (their horizontal
faces split along the (i, j)-(i+1, j+1) diagonal). A transition cell is a box whose face towards
the fracture holds up to 2 x 2 lattice squares split that way, whose far face is one square
split the same way, and whose sides are triangulated by their own nodes alone (one rule for the
face both neighbours share): it is the cone of its centre over those triangles, all positive
(the box is convex, its centre inside), and conforming. The flat zone's planes are exactly flat,
so nothing there depends on the face's shape. The nodes of a block grow with the face's area:
one rough-zone plane per layer, the flat zone a quarter more nodes per level at most.
"""

from __future__ import annotations

import numpy as np

from ..mesh import HEX_TETS, TET_FACES, lattice_hexahedra, lattice_tetrahedra
from .blocks import BLOCK_TAGS, FACE_TAGS, Block, _layered, stations


def layer_plan(spacing: float, ratio: float, relief: float, depth: float):
    """The nominal layer thicknesses from a face of lattice `spacing` and height range `relief`
    down to `depth` below its highest point: the rough zone's (growing by `ratio` from
    `spacing`, together at least ``max(2 relief, spacing)``), the flat zone's below it (the
    series continued, scaled to end at `depth`) and, per flat layer, whether it halves the
    in-plane lattice (its thickness at least twice the width of the cells above it).
    ValueError when the rough zone leaves no room for the flat one."""
    rough = [spacing]
    while sum(rough) < 2 * relief:
        rough.append(rough[-1] * ratio)
    rest = depth - sum(rough)
    if not rest > 0.25 * rough[-1]:
        raise ValueError(f"grading: the block reaches {depth:.3g} m below its face's highest point, but its graded "
                         f"layers need {sum(rough) + 0.25 * rough[-1]:.3g} m (the face's relief {relief:.3g} m twice, "
                         f"from the spacing {spacing:.3g} m by {ratio:g}): increase height")
    flat = [rough[-1] * ratio]
    while sum(flat) < rest:
        flat.append(flat[-1] * ratio)
    if len(flat) > 1 and sum(flat[:-1]) >= rest - 0.5 * flat[-2]:  # a thin last layer: merged into the one above
        flat.pop()
    flat = np.asarray(flat) * rest / sum(flat)
    width, halve = spacing, []
    for t in flat:
        halve.append(bool(t >= 2 * width))
        width *= 2 if halve[-1] else 1
    return np.asarray(rough), flat, np.asarray(halve)


def _side(top: list, bottom: tuple) -> list:
    """The triangles of a vertical transition side: nodes `top` (2 or 3, along the side) on the
    fine plane, `bottom` (2) on the coarse one; the same for both boxes that share it."""
    if len(top) == 2:
        return [(top[0], top[1], bottom[1]), (top[0], bottom[1], bottom[0])]
    return [(top[0], top[1], bottom[0]), (top[1], bottom[1], bottom[0]), (top[1], top[2], bottom[1])]


def _transition(fine_ids, coarse_ids, sx, sy, points, centre_start):
    """The cone tets of a transition layer: `fine_ids` (nx+1, ny+1) node ids of the fine plane,
    `coarse_ids` (len(sx), len(sy)) of the coarse one, ``sx``, ``sy`` the coarse nodes as fine
    indices; `points` all points so far (the centres are appended from id `centre_start`).
    Returns the tets (unoriented) and the centres' coordinates."""
    tets, centres = [], []
    for wa in (1, 2):
        for wb in (1, 2):
            a = np.flatnonzero(np.diff(sx) == wa)
            b = np.flatnonzero(np.diff(sy) == wb)
            if not (len(a) and len(b)):
                continue
            A, B = (g.ravel() for g in np.meshgrid(a, b, indexing="ij"))
            i0, j0 = sx[A], sy[B]

            def fine(da, db):
                return fine_ids[i0 + da, j0 + db]

            def coarse(ea, eb):
                return coarse_ids[A + ea, B + eb]

            tris = []
            for da in range(wa):  # the fine face: each lattice square along its (i, j)-(i+1, j+1) diagonal
                for db in range(wb):
                    tris += [(fine(da, db), fine(da + 1, db), fine(da + 1, db + 1)),
                             (fine(da, db), fine(da + 1, db + 1), fine(da, db + 1))]
            tris += [(coarse(0, 0), coarse(1, 0), coarse(1, 1)), (coarse(0, 0), coarse(1, 1), coarse(0, 1))]
            for e, d in ((0, 0), (1, wa)):  # the sides x = const, nodes along y
                tris += _side([fine(d, db) for db in range(wb + 1)], (coarse(e, 0), coarse(e, 1)))
            for e, d in ((0, 0), (1, wb)):  # the sides y = const, nodes along x
                tris += _side([fine(da, d) for da in range(wa + 1)], (coarse(0, e), coarse(1, e)))
            corners = np.stack([fine(0, 0), fine(wa, wb), coarse(0, 0), coarse(1, 1)])
            centre = points[corners].mean(axis=0)  # the box's centre
            ids = centre_start + sum(len(c) for c in centres) + np.arange(len(A))
            centres.append(centre)
            tets += [np.column_stack([ids, *t]) for t in tris]
    return tets, (np.concatenate(centres) if centres else np.empty((0, 3)))


def _orient(points: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """`tets` with their last two vertices swapped where the volume is negative."""
    p = points[tets]
    negative = np.einsum("ij,ij->i", p[:, 1] - p[:, 0], np.cross(p[:, 2] - p[:, 0], p[:, 3] - p[:, 0])) < 0
    tets = tets.copy()
    tets[negative] = tets[negative][:, [0, 1, 3, 2]]
    return tets


def graded_block(xs, ys, face, end, ratio) -> tuple[np.ndarray, np.ndarray, dict]:
    """The lower block of a fracture, graded: points and positive tets between the flat end
    ``z = end`` and the `face` (nx+1, ny+1) on the nodes ``xs``, ``ys`` (absolute), layers
    growing by `ratio` from the lattice spacing at the face (:func:`layer_plan`); and the
    figures (layers per zone, halvings). A block above its face is this of the mirrored one."""
    xs, ys, face = (np.asarray(a, float) for a in (xs, ys, face))
    nx, ny = len(xs) - 1, len(ys) - 1
    spacing = max(float(np.diff(xs).mean()), float(np.diff(ys).mean()))
    top = float(face.max())
    rough, flat, halve = layer_plan(spacing, ratio, top - float(face.min()), top - float(end))
    plane = top - rough.sum()
    m = len(rough)
    lattice = _layered(xs, ys, np.full_like(face, plane), face, m, ratio, True, (None,) * 6, 0)
    points = [lattice.points(np.arange(lattice.num_points))]
    tets = [lattice_tetrahedra((nx, ny, m))]
    grid = (np.arange(nx + 1), np.arange(ny + 1))  # the nodes of the plane, as lattice indices
    ids = np.arange((nx + 1) * (ny + 1)).reshape(ny + 1, nx + 1).T  # [i, j] -> point id of the plane
    count, z = lattice.num_points, plane
    for k, (t, halving) in enumerate(zip(flat, halve)):
        z = float(end) if k == len(flat) - 1 else z - t
        new = tuple(g[stations(len(g) - 1, 2)] for g in grid) if halving else grid
        X, Y = np.meshgrid(xs[new[0]], ys[new[1]], indexing="ij")
        below = count + np.arange(X.size).reshape(X.shape)
        points.append(np.column_stack([X.ravel(), Y.ravel(), np.full(X.size, z)]))
        count += X.size
        if halving:
            sx, sy = (np.searchsorted(g, n) for g, n in zip(grid, new))
            cones, centres = _transition(ids, below, sx, sy, np.concatenate(points), count)
            tets += cones
            points.append(centres)
            count += len(centres)
        else:  # lattice hexahedra: k = 0 on the plane below, k = 1 on this one
            both = np.stack([below, ids], axis=-1)  # [a, b, k]
            hexes = lattice_hexahedra((len(new[0]) - 1, len(new[1]) - 1, 1))
            local = both.transpose(2, 1, 0).ravel()  # x fastest, then y, then k
            tets.append(local[hexes][:, HEX_TETS].reshape(-1, 4))
        grid, ids = new, below
    points = np.concatenate(points)
    figures = {"rough_layers": m, "flat_layers": len(flat), "halvings": int(halve.sum()),
               "first_layer": float(rough[0]), "rough_depth": float(rough.sum())}
    return points, _orient(points, np.concatenate(tets).astype(np.int64)), figures


def _boundary(points: np.ndarray, tets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The outward triangles on the boundary of `tets` (positive) and the tet each belongs to."""
    faces = tets[:, TET_FACES].reshape(-1, 3)
    key = np.sort(faces, axis=1)
    order = np.lexsort(key.T[::-1])
    key = key[order]
    new = np.concatenate([[True], np.any(key[1:] != key[:-1], axis=1), [True]])
    starts = np.flatnonzero(new)
    counts = np.diff(starts)
    if np.any(counts > 2):
        raise ValueError("grading: a face is shared by more than two tetrahedra (not a conforming mesh)")
    once = np.sort(order[starts[:-1][counts == 1]])
    return faces[once], once // 4


def graded_blocks(lower: tuple, upper: tuple, bottom: float, top: float, ratio: float, name: str,
                  info: dict | None = None) -> Block:
    """Both blocks graded (:func:`graded_block`) in one mesh: ``lower`` and ``upper`` are
    ``(xs, ys, heights)`` of the faces (absolute node coordinates, heights (nx+1, ny+1)),
    ``bottom`` and ``top`` the blocks' flat ends. Faces named as the lattices' (:data:`FACE_TAGS`,
    the sides by their planes, the rest the fracture face of its block); ``info`` gets the
    layer figures of :func:`graded_block`, ``[lower, upper]`` each. Raises MeshError on a degenerate tet (:attr:`Block.mesh`)."""
    pl, tl, fl = graded_block(*lower, bottom, ratio)
    pu, tu, fu = graded_block(upper[0], upper[1], -np.asarray(upper[2], float), -top, ratio)
    pu = pu * np.array([1.0, 1.0, -1.0])
    tu = tu[:, [0, 1, 3, 2]] + len(pl)  # mirrored: swapped back to positive
    points, tets = np.concatenate([pl, pu]), np.concatenate([tl, tu])
    tags = np.concatenate([np.full(len(tl), BLOCK_TAGS["lower_block"], np.int32),
                           np.full(len(tu), BLOCK_TAGS["upper_block"], np.int32)])
    tris, owner = _boundary(points, tets)
    on = points[tris]
    x0, x1 = lower[0][0], lower[0][-1]
    y0, y1 = lower[1][0], lower[1][-1]
    name_of = np.where(tags[owner] == BLOCK_TAGS["lower_block"], FACE_TAGS["fracture_lower"],
                       FACE_TAGS["fracture_upper"])
    for face, axis, value in (("bottom", 2, bottom), ("top", 2, top), ("xmin", 0, x0), ("xmax", 0, x1),
                              ("ymin", 1, y0), ("ymax", 1, y1)):
        name_of[np.all(on[:, :, axis] == value, axis=1)] = FACE_TAGS[face]
    faces = {n: tris[name_of == t] for n, t in FACE_TAGS.items() if np.any(name_of == t)}
    for which, xs, ys in (("fracture_lower", *lower[:2]), ("fracture_upper", *upper[:2])):
        if len(faces.get(which, ())) != 2 * (len(xs) - 1) * (len(ys) - 1):
            raise ValueError(f"grading: {len(faces.get(which, ()))} triangles on {which}, not the lattice's "
                             f"{2 * (len(xs) - 1) * (len(ys) - 1)} (not a conforming mesh)")
    figures = {f"grading_{k}": [fl[k], fu[k]] for k in fl}  # (lower block, upper block)
    block = Block(points, tets, faces, tags, name, dict(FACE_TAGS), dict(BLOCK_TAGS), {**(info or {}), **figures})
    block.mesh
    return block
