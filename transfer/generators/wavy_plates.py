"""Two blocks whose gap is a smooth sinusoidal aperture, and the fluid grid made for them (the
lubrication limits of a fracture, cases/lubrication).

The aperture is ``e(s) = e0 (1 + a sin(2 pi s / lambda))`` over ``wavelengths`` whole periods,
with ``s = x`` (``direction = "along"``: the aperture varies along the flow, x inlet to outlet;
the apertures act in series) or ``s = y`` (``"across"``: it varies across the flow; in
parallel). The gap is across z, as in every fracture: the lower block fills
``0 <= z <= (2 + offset) h``, its face flat, the upper one ``(2 + offset) h + e(s) <= z <= top``,
``h = e0 (1 - a) / n`` with ``n = cells_across`` the grid cells across the smallest aperture.

The grid (and the plane the blocks cover) is ``wavelengths * lambda`` long in s with
``cells_per_wavelength`` cells per period, and ``columns`` cells along the flow when the
aperture varies across it (the flow does not vary along x then); one cell of depth h in y when
it varies along it (a 2D flow: ``empty`` y faces). The blocks' faces are named as those of
every fracture (``fracture_lower``, ``fracture_upper``, ...), the upper face's lattice
``solid_refinement`` times finer in s than the grid.
"""

from __future__ import annotations

import math

import numpy as np

from . import choice, number
from .blocks import BLOCK_TAGS, FACE_TAGS, Block, fracture_lattices, lattice_block
from .lattices import Lattices

NAME = "wavy_plates"
DESCRIPTION = "two blocks with a sinusoidal aperture along or across the flow, and the fluid grid made for them"
PARAMETERS = {"aperture": "e0, the mean aperture [m]",
              "amplitude": "a, the relative amplitude in [0, 1): e = e0 (1 + a sin(2 pi s / lambda))",
              "wavelength": "lambda, the period of the aperture [m]",
              "direction": "'along' (s = x, the flow's direction: series) or 'across' (s = y: parallel) (default 'along')",
              "wavelengths": "whole periods over the grid (default 1)",
              "cells_across": "n, grid cells across the smallest aperture e0 (1 - a) (h = e0 (1 - a) / n)",
              "cells_per_wavelength": "grid cells per period along s (default 32)",
              "columns": "grid cells along the flow (x) when the aperture varies across it (default 4)",
              "offset": "where the lower block's face cuts a grid cell, in cells, in [0, 1) (default 0)",
              "solid_refinement": "the blocks' lattice cells per grid cell along s (default 2)"}
DEFAULTS = {"direction": "along", "wavelengths": 1, "cells_per_wavelength": 32, "columns": 4, "offset": 0.0,
            "solid_refinement": 2}
DIRECTIONS = ("along", "across")
FACES = dict(FACE_TAGS)


def check(parameters: dict) -> dict:
    return {"aperture": number(parameters, "aperture", positive=True),
            "amplitude": number(parameters, "amplitude", minimum=0.0, below=1.0),
            "wavelength": number(parameters, "wavelength", positive=True),
            "direction": choice(parameters, "direction", DIRECTIONS),
            "wavelengths": number(parameters, "wavelengths", minimum=1, integer=True),
            "cells_across": number(parameters, "cells_across", minimum=1, integer=True),
            "cells_per_wavelength": number(parameters, "cells_per_wavelength", minimum=2, integer=True),
            "columns": number(parameters, "columns", minimum=1, integer=True),
            "offset": number(parameters, "offset", minimum=0.0, below=1.0),
            "solid_refinement": number(parameters, "solid_refinement", minimum=1, integer=True)}


def aperture(p: dict, s: np.ndarray) -> np.ndarray:
    """e(s) = e0 (1 + a sin(2 pi s / lambda))."""
    return p["aperture"] * (1.0 + p["amplitude"] * np.sin(2.0 * np.pi * np.asarray(s) / p["wavelength"]))


def spacing_across(p: dict) -> float:
    """h: the grid spacing across the gap, the smallest aperture over cells_across."""
    return p["aperture"] * (1.0 - p["amplitude"]) / p["cells_across"]


def _lower_face(p: dict) -> float:
    return (2.0 + p["offset"]) * spacing_across(p)


def grid(p: dict) -> dict:
    h = spacing_across(p)
    extent = p["wavelengths"] * p["wavelength"]
    along_s = p["wavelengths"] * p["cells_per_wavelength"]
    nz = math.ceil((_lower_face(p) + p["aperture"] * (1.0 + p["amplitude"])) / h) + 2
    if p["direction"] == "along":
        return {"origin": [0.0, 0.0, 0.0], "spacing": [extent / along_s, h, h], "shape": [along_s, 1, nz]}
    return {"origin": [0.0, 0.0, 0.0], "spacing": [extent / p["columns"], extent / along_s, h],
            "shape": [p["columns"], along_s, nz]}


def _lattice(p: dict) -> tuple[int, int]:
    """The blocks' lattice cells in x and y."""
    along_s = p["wavelengths"] * p["cells_per_wavelength"] * p["solid_refinement"]
    return (along_s, 1) if p["direction"] == "along" else (p["columns"], along_s)


def cells(p: dict) -> int:
    nx, ny = _lattice(p)
    return 2 * 6 * nx * ny * 2


def lattices(p: dict) -> Lattices:
    """Both blocks by index (:mod:`.lattices`), two layers each, with the named faces of a fracture."""
    g = grid(p)
    nx, ny = _lattice(p)
    size = (g["spacing"][0] * g["shape"][0], g["spacing"][1] * g["shape"][1])
    xs, ys = np.linspace(0.0, size[0], nx + 1), np.linspace(0.0, size[1], ny + 1)
    x, y = np.meshgrid(xs, ys, indexing="ij")  # the surfaces' node grid, (nx + 1, ny + 1)
    s = x if p["direction"] == "along" else y
    lower = np.full(s.shape, _lower_face(p))
    top = g["spacing"][2] * g["shape"][2]
    return Lattices(fracture_lattices((nx, ny, 2), size, top, (lower, lower + aperture(p, s)), bottom=0.0, top=top),
                    FACE_TAGS, BLOCK_TAGS)


def mesh(p: dict) -> Block:
    """Both blocks in one mesh, two layers each, with the named faces of a fracture."""
    return lattice_block(lattices(p), NAME, {"smallest_aperture": float(p["aperture"] * (1 - p["amplitude"])),
                                             "largest_aperture": float(p["aperture"] * (1 + p["amplitude"]))})
