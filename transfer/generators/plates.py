"""Two flat solid blocks leaving a gap of aperture ``w`` between them, and the 2D fluid grid made
for them (an immersed-boundary study against the cubic law, cases/parallel_plates).

The grid has ``columns`` cells along the length ``L`` (x, inlet to outlet), ``n + 5`` across
the gap (y, ``h = w / n`` with ``n = cells_across``) and one in z (depth h, for 2D ``empty``
faces). The grid's lines do not follow the block faces unless ``offset`` is 0: the lower
block fills ``0 <= y <= (2 + offset) h``, the upper one ``(2 + offset) h + w <= y <= (n + 5) h``,
both the grid's full length and depth (tetrahedral lattices of 3 x 2 x 1 hexahedra each).
"""

from __future__ import annotations

import numpy as np

from . import number
from .blocks import BLOCK_TAGS, Block, lattice_block
from .lattices import Lattices, axes_lattice

NAME = "plates"
DESCRIPTION = "two flat blocks with a gap of aperture w, and the 2D fluid grid made for them"
PARAMETERS = {"aperture": "w, the gap between the blocks [m]",
              "length": "L, the blocks' and the grid's length along x (inlet to outlet) [m]",
              "cells_across": "n, grid cells across the aperture (h = w / n)",
              "offset": "where the lower block's face cuts a grid cell, in cells, in [0, 1) (default 0)",
              "columns": "grid cells along x (default 4)"}
DEFAULTS = {"offset": 0.0, "columns": 4}
FACES: dict = {}  # a fixed solid: no named boundary


def check(parameters: dict) -> dict:
    return {"aperture": number(parameters, "aperture", positive=True),
            "length": number(parameters, "length", positive=True),
            "cells_across": number(parameters, "cells_across", minimum=1, integer=True),
            "offset": number(parameters, "offset", minimum=0.0, below=1.0),
            "columns": number(parameters, "columns", minimum=1, integer=True)}


def blocks(p: dict):
    """(lower, upper) blocks as (lower corner, upper corner)."""
    w, n = p["aperture"], p["cells_across"]
    h = w / n
    y_lo = (2 + p["offset"]) * h
    return ((0.0, 0.0, 0.0), (p["length"], y_lo, h)), ((0.0, y_lo + w, 0.0), (p["length"], (n + 5) * h, h))


def grid(p: dict) -> dict:
    h = p["aperture"] / p["cells_across"]
    return {"origin": [0.0, 0.0, 0.0], "spacing": [p["length"] / p["columns"], h, h],
            "shape": [p["columns"], p["cells_across"] + 5, 1]}


def cells(p: dict) -> int:
    return 2 * 6 * 3 * 2 * 1


def lattices(p: dict) -> Lattices:
    """Both blocks by index (:mod:`.lattices`), 3 x 2 x 1 hexahedra each."""
    return Lattices(tuple(axes_lattice(*(np.linspace(lo[d], hi[d], n + 1) for d, n in enumerate((3, 2, 1))), tag=tag)
                          for (lo, hi), tag in zip(blocks(p), (BLOCK_TAGS["lower_block"], BLOCK_TAGS["upper_block"]))),
                    {}, BLOCK_TAGS)


def mesh(p: dict) -> Block:
    """Cells tagged ``lower_block`` and ``upper_block``; no named faces."""
    return lattice_block(lattices(p), NAME)
