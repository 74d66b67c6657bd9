"""The quarter model of a penny-shaped crack (cases/pressurized_fracture, paper 4.2): a lattice
graded toward the crack front and bent so that the front is a row of mesh edges."""

from __future__ import annotations

import numpy as np

from . import number
from .blocks import Block
from .lattice import graded_nodes
from .lattices import Lattices, axes_lattice

NAME = "penny_crack"
DESCRIPTION = "the quarter model of a penny-shaped crack, graded toward its front"
PARAMETERS = {"a": "the crack's radius [m] (default 0.1)", "extent": "the model is extent * a on each side (8)",
              "h_tip": "cell size at the front [m] (default a / 32)", "growth": "cell growth ratio away from it (1.3)"}
DEFAULTS = {"a": 0.1, "extent": 8.0, "h_tip": None, "growth": 1.3}
FACES = {}


def check(p: dict) -> dict:
    out = {"a": number(p, "a", positive=True), "extent": number(p, "extent", minimum=2.0),
           "growth": number(p, "growth", minimum=1.0), "h_tip": p["h_tip"]}
    if out["h_tip"] is not None:
        out["h_tip"] = number(p, "h_tip", positive=True)
    return out


def mesh(p: dict) -> Block:
    """The quarter model [0, L]^2 x [0, H] (L = H = extent * a) of a penny crack of
    radius ``a`` in the plane z = 0 (no named faces: scenes select them by expressions).

    A lattice graded toward x = a, y = a (spacing ``h_tip``, default a/32,
    growing by ``growth`` toward 0 and L) and toward z = 0 is morphed in the
    (x, y) plane so that the square max(x, y) = rho becomes the circle r = rho
    for rho <= a + 2 h_tip (blended back to the lattice at rho = 2a): the crack
    front r = a is a row of mesh edges, refined, with no staircase.
    """
    return Block.of(lattices(p), NAME)


def lattices(p: dict) -> Lattices:
    """The quarter model of :func:`mesh` by index (:mod:`.lattices`)."""
    a, growth = p["a"], p["growth"]
    h = a / 32 if p["h_tip"] is None else p["h_tip"]
    L = p["extent"] * a
    axis = np.unique(np.concatenate([graded_nodes(a, 0.0, h, 0.0, growth), graded_nodes(a, L, h, 0.0, growth)]))
    zs = graded_nodes(0.0, L, h, 0.0, growth)
    r1, r2 = a + 2.0 * h, 2.0 * a

    def morph(points):
        x, y = points[:, 0], points[:, 1]
        rho, r = np.maximum(x, y), np.hypot(x, y)
        with np.errstate(invalid="ignore", divide="ignore"):
            to_circle = np.where(r > 0, rho / r, 1.0)
        w = np.clip((r2 - rho) / (r2 - r1), 0.0, 1.0)
        scale = w * to_circle + (1.0 - w)
        points[:, 0] *= scale
        points[:, 1] *= scale
        return points

    return Lattices((axes_lattice(axis, axis, zs),), {}, {}, transform=morph)
