"""Two rock blocks around a matched rough fracture (cases/small_fracture, cases/fracture_flow):
the faces of :func:`~transfer.generators.surfaces.fracture_pair` (non-periodic, mean aperture
``aperture``, at least ``min_aperture``), each block ``height`` thick on an (nx, ny, nz) lattice
(:func:`~transfer.generators.blocks.fracture_blocks`), both blocks in one mesh."""

from __future__ import annotations

from . import number, numbers
from .blocks import BLOCK_TAGS, FACE_TAGS, Block, fracture_lattices, lattice_block
from .lattices import Lattices
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


def _faces(p: dict):
    return fracture_pair(p["shape"][:2], p["size"], aperture=p["aperture"], hurst=p["hurst"], rms=p["rms"],
                         seed=p["seed"], min_aperture=p["min_aperture"], periodic=False,
                         mismatch_length=p["mismatch_length"])


def lattices(p: dict, faces=None) -> Lattices:
    """The two blocks by index (:mod:`.lattices`), on the fracture `faces` (default: made from `p`)."""
    return Lattices(fracture_lattices(p["shape"], p["size"], p["height"], faces or _faces(p), grading=p["grading"]),
                    FACE_TAGS, BLOCK_TAGS)


def mesh(p: dict) -> Block:
    """The two blocks in one mesh; ``info``: the aperture's mean, minimum and maximum."""
    lower, upper = _faces(p)
    w = upper - lower
    info = {"mean_aperture": surface_mean(w, p["size"]), "min_aperture": float(w.min()),
            "max_aperture": float(w.max())}
    return lattice_block(lattices(p, (lower, upper)), NAME, info)
