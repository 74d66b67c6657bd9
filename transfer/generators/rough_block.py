"""A rock block with a flat top and a self-affine rough bottom face (cases/rock_obstacle,
paper figure 15): the upper block of :func:`~transfer.generators.blocks.fracture_lattices` on a
non-periodic :func:`~transfer.generators.surfaces.rough_surface` of zero mean."""

from __future__ import annotations

from dataclasses import replace

from . import number, numbers
from .blocks import BLOCK_TAGS, FACE_TAGS, Block, fracture_lattices, lattice_block
from .lattices import Lattices
from .surfaces import rough_surface

NAME = "rough_block"
DESCRIPTION = "a rock block with a flat top and a self-affine rough bottom face"
PARAMETERS = {"size": "[Lx, Ly, height]: the block, its height above the rough face's mean plane [m]",
              "cells": "[nx, ny, nz]: lattice cells", "rms": "RMS height of the bottom face [m]",
              "hurst": "Hurst exponent in (0, 1]", "seed": "random seed"}
DEFAULTS = {"hurst": 0.8, "seed": 1}
FACES = {n: FACE_TAGS[n] for n in ("bottom", "top", "xmin", "xmax", "ymin", "ymax")}


def check(p: dict) -> dict:
    return {"size": numbers(p, "size", 3, positive=True), "cells": numbers(p, "cells", 3, positive=True, integer=True),
            "rms": number(p, "rms", positive=True), "hurst": number(p, "hurst", positive=True),
            "seed": number(p, "seed", minimum=0, integer=True)}


def cells(p: dict) -> int:
    nx, ny, nz = p["cells"]
    return 6 * nx * ny * nz


def lattices(p: dict) -> Lattices:
    """The block by index (:mod:`.lattices`): the upper block of a fracture, its face ``bottom``."""
    (nx, ny, nz), (lx, ly, height) = p["cells"], p["size"]
    rough = rough_surface((nx, ny), (lx, ly), p["hurst"], p["rms"], p["seed"], periodic=False)
    upper = fracture_lattices((nx, ny, nz), (lx, ly), height, (rough - p["rms"], rough))[1]
    faces = tuple("bottom" if n == "fracture_upper" else n for n in upper.faces)
    return Lattices((replace(upper, faces=faces),), FACE_TAGS, BLOCK_TAGS)


def mesh(p: dict) -> Block:
    """Faces ``bottom`` (the rough face), ``top`` and the sides; ``info``: its lowest point."""
    block = lattice_block(lattices(p), NAME)
    return replace(block, info={"lowest_point": float(block.points[:, 2].min())})
