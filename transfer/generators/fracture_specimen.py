"""The fracture closure specimen (paper 4.1, figures 6-10): two rock blocks around a
synthetic self-affine fracture (:func:`transfer.generators.surfaces.fracture_pair`), meshed
on different lattices (the lower face ``ratio`` times finer: non-matching faces, for mortar
contact). The specimen is a square box or, as in the paper, a cylinder: the square lattice
mapped onto a disc by the concentric map (:func:`square_to_disc`) after the rough faces are
built, so the face heights stay the generator's functions of the lattice's (x, y).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from . import choice, number, numbers
from .blocks import FACE_TAGS, Block, lattice_block, mortar_lattices
from .lattices import Lattices
from .surfaces import fracture_pair

NAME = "fracture_specimen"
DESCRIPTION = "the closure specimen: two blocks around a rough fracture, box or cylinder, non-matching faces"
SHAPES = ("box", "cylinder")
PARAMETERS = {"shape": "'box' (size x size) or 'cylinder' (diameter size), default 'cylinder'",
              "size": "side of the box or diameter of the cylinder [m] (default 0.1)",
              "height": "each block's thickness [m] (default 0.04)",
              "lattice": "[nx, ny, layers per block] of the lower (fine) block (default [16, 16, 5])",
              "ratio": "the upper face's lattice is ratio times coarser; divides nx and ny (default 2)",
              "aperture": "mean initial aperture [m] (default 2e-4)", "rms": "RMS roughness of each face [m] (2e-4)",
              "hurst": "Hurst exponent in (0, 1] (0.8)",
              "mismatch_length": "the faces are identical at longer wavelengths [m] (0.02)",
              "min_aperture": "smallest initial aperture [m] (1e-6)", "seed": "random seed (5)"}
DEFAULTS = {"shape": "cylinder", "size": 0.1, "height": 0.04, "lattice": [16, 16, 5], "ratio": 2, "aperture": 2.0e-4,
            "rms": 2.0e-4, "hurst": 0.8, "mismatch_length": 0.02, "min_aperture": 1.0e-6, "seed": 5}
FACES = dict(FACE_TAGS)


def square_to_disc(x, y):
    """Shirley's concentric map of the square [-1, 1]^2 onto the unit disc: the square
    of half-side m = max(|x|, |y|) goes to the circle of radius m, uniformly in angle
    along each side. Continuous, piecewise smooth (kinks on the diagonals), with the
    constant Jacobian pi/4 (equal-area: cell volumes scale uniformly). Cells on the
    diagonals get an angle near 180 degrees: where the lattice's diagonal edges cross the
    ray, tets flatten to a quality of about pi / (2 n) at the outline (n cells across)."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    wide = np.abs(x) >= np.abs(y)
    radius = np.where(wide, x, y)  # signed: a negative radius turns the angle by pi
    safe = np.where(radius != 0, radius, 1.0)
    angle = np.where(wide, np.pi / 4 * y / safe, np.pi / 2 - np.pi / 4 * x / safe)
    return radius * np.cos(angle), radius * np.sin(angle)


def check(p: dict) -> dict:
    out = {"shape": choice(p, "shape", SHAPES), "lattice": numbers(p, "lattice", 3, positive=True, integer=True),
           "ratio": number(p, "ratio", minimum=1, integer=True), "hurst": number(p, "hurst", positive=True),
           "seed": number(p, "seed", minimum=0, integer=True), "min_aperture": number(p, "min_aperture", minimum=0.0)}
    out.update({k: number(p, k, positive=True) for k in ("size", "height", "aperture", "rms", "mismatch_length")})
    nx, ny, _ = out["lattice"]
    if nx % out["ratio"] or ny % out["ratio"]:
        raise ValueError(f"ratio: {out['ratio']} does not divide the lattice's nx, ny {[nx, ny]}")
    if not out["min_aperture"] < out["aperture"]:
        raise ValueError(f"min_aperture: {out['min_aperture']:g} m must be below the mean aperture {out['aperture']:g} m")
    return out


def cells(p: dict) -> int:
    (nx, ny, nz), r = p["lattice"], p["ratio"]
    return 6 * nx * ny * nz + 6 * (nx // r) * (ny // r) * nz


def _parts(p: dict) -> tuple[Lattices, dict]:
    """The specimen by index (the cylinder's points mapped onto the disc) and its ``info``."""
    shape, size, height = p["shape"], p["size"], p["height"]
    (nx, ny, nz), r = p["lattice"], p["ratio"]
    square = (float(size), float(size))
    lower, upper = fracture_pair((nx, ny), square, aperture=p["aperture"], hurst=p["hurst"], rms=p["rms"],
                                 mismatch_length=p["mismatch_length"], seed=p["seed"],
                                 min_aperture=p["min_aperture"], periodic=False)
    lattices = mortar_lattices((nx, ny, nz), square, height, (lower, upper), r)
    if shape == "cylinder":
        half = size / 2

        def disc(points):
            x, y = square_to_disc(points[:, 0] / half - 1, points[:, 1] / half - 1)
            points[:, 0], points[:, 1] = half * (1 + x), half * (1 + y)
            return points

        lattices = replace(lattices, transform=disc)
    area = size ** 2 if shape == "box" else np.pi * (size / 2) ** 2
    return lattices, {"cross_section": float(area), "max_initial_aperture": float((upper - lower).max())}


def lattices(p: dict) -> Lattices:
    """The two blocks by index (:mod:`.lattices`)."""
    return _parts(p)[0]


def mesh(p: dict) -> Block:
    """The two blocks of a closure specimen in one mesh, faces ``bottom``, ``top``,
    ``fracture_lower`` (the fine face), ``fracture_upper`` and the sides. ``info``: the
    nominal cross-section (size^2, or pi (size / 2)^2) and the largest initial aperture on
    the lattice (what a contact search must reach across). Raises MeshError on a bad cell."""
    lattices, info = _parts(p)
    return lattice_block(lattices, f"{p['shape']} specimen", info)
