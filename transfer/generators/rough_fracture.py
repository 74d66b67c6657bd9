"""Two rock blocks around a matched rough fracture (cases/small_fracture, cases/fracture_flow):
the faces of :func:`~transfer.generators.surfaces.fracture_pair` (non-periodic, mean aperture
``aperture``, at least ``min_aperture``), each block ``height`` thick on an (nx, ny, nz) lattice
(:func:`~transfer.generators.blocks.fracture_blocks`), both blocks in one mesh."""

from __future__ import annotations

from . import number, numbers
from .blocks import FACE_TAGS, Block, fracture_blocks
from .surfaces import fracture_pair, surface_mean

NAME = "rough_fracture"
DESCRIPTION = "two rock blocks around a matched self-affine rough fracture"
PARAMETERS = {"shape": "[nx, ny, nz]: lattice cells in the plane and layers per block",
              "size": "[Lx, Ly]: the fracture's extent [m]",
              "height": "each block's thickness from its face's mean plane [m]",
              "aperture": "mean aperture [m]", "min_aperture": "smallest aperture [m]",
              "rms": "RMS height of each face [m]", "hurst": "Hurst exponent in (0, 1]",
              "mismatch_length": "the faces are identical at longer wavelengths [m]", "seed": "random seed",
              "grading": "ratio of successive layer thicknesses away from the fracture (default 1)"}
DEFAULTS = {"hurst": 0.8, "seed": 0, "grading": 1.0}
FACES = dict(FACE_TAGS)


def check(p: dict) -> dict:
    out = {"shape": numbers(p, "shape", 3, positive=True, integer=True), "size": numbers(p, "size", 2, positive=True),
           "hurst": number(p, "hurst", positive=True), "seed": number(p, "seed", minimum=0, integer=True)}
    out.update({k: number(p, k, positive=True) for k in ("height", "aperture", "rms", "mismatch_length", "grading")})
    out["min_aperture"] = number(p, "min_aperture", minimum=0.0)
    return out


def cells(p: dict) -> int:
    nx, ny, nz = p["shape"]
    return 2 * 6 * nx * ny * nz


def mesh(p: dict) -> Block:
    """The two blocks in one mesh; ``info``: the aperture's mean, minimum and maximum."""
    lower, upper = fracture_pair(p["shape"][:2], p["size"], aperture=p["aperture"], hurst=p["hurst"], rms=p["rms"],
                                 seed=p["seed"], min_aperture=p["min_aperture"], periodic=False,
                                 mismatch_length=p["mismatch_length"])
    blocks = fracture_blocks(p["shape"], p["size"], p["height"], (lower, upper), grading=p["grading"])
    w = blocks.aperture
    info = {"mean_aperture": surface_mean(w, blocks.size), "min_aperture": float(w.min()),
            "max_aperture": float(w.max())}
    s = blocks.solid
    return Block(s.points, s.cells, s.faces, s.cell_tags, NAME, info=info)
