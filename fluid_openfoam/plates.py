"""Immersed parallel plates: the fluid alone, checked against the cubic law.

Two flat solid blocks (tetrahedral meshes, ``transfer.generate.box_tetrahedra``) leave a
gap of aperture ``w`` between them inside a 2D structured grid (one cell in z, ``empty``
front and back) whose lines do *not* follow the block faces: the lower wall sits at
``(2 + offset) h`` above the grid's bottom, ``h = w / n_across``. The solid volume fraction
per grid cell comes from ``transfer`` (L2 projection of the blocks' P0 indicator onto the
grid's Q0: exact intersection volumes). A pressure drop ``dp`` over the length ``L`` drives
the flow (pressure inlet at xmin, outlet at xmax); the flow rate per unit width,
``sum_j U_x h`` over a column of cells, is compared with ``Q = w^3 dp / (12 mu L)``.

Fraction handling (``method``):

* ``"binary"``: point sampling, f = 1 where the cell centre is in a block (the old mask),
  penalization ``"linear"``;
* ``"linear"``: exact fractions with the stock linear drag table;
* ``"power"``: exact fractions, drag ``D_max f^k``;
* ``"wall"``: exact fractions, sub-cell wall drag (:mod:`transfer.penalization`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .case import CaseSpec
from .solver import OpenFOAMSolver

W, L, DP, MU, RHO, NX = 1.0e-3, 2.0e-3, 1.0e-2, 1.0e-3, 1000.0, 4
METHODS = ("binary", "linear", "power", "wall")


@dataclass(frozen=True)
class Plates:
    """The physical problem: aperture ``w`` [m], length ``length`` [m] along x, pressure drop
    ``dp`` [Pa] over it, fluid ``mu`` [Pa s] and ``rho`` [kg/m^3]."""

    w: float = W
    length: float = L
    dp: float = DP
    mu: float = MU
    rho: float = RHO

    @property
    def q_cubic(self) -> float:
        """Flow rate per unit width of the cubic law, ``w^3 dp / (12 mu L)`` [m^2/s]."""
        return self.w ** 3 * self.dp / (12 * self.mu * self.length)


def geometry(n_across: int, offset: float = 0.3, w: float = W, length: float = L):
    """(grid config, lower block (lo, hi), upper block (lo, hi))."""
    h = w / n_across
    ny = n_across + 5
    y_lo = (2 + offset) * h
    grid = {"origin": [0.0, 0.0, 0.0], "spacing": [length / NX, h, h], "shape": [NX, ny, 1]}
    lower = ((0.0, 0.0, 0.0), (length, y_lo, h))
    upper = ((0.0, y_lo + w, 0.0), (length, ny * h, h))
    return grid, lower, upper


def exact_fractions(grid: dict, blocks) -> np.ndarray:
    """Solid volume fraction per grid cell from tet meshes of the blocks, with transfer."""
    from transfer import FunctionSpace, StructuredGrid, Transfer
    from transfer.generate import box_tetrahedra

    G = StructuredGrid(grid["origin"], grid["spacing"], grid["shape"])
    frac = np.zeros(G.num_cells)
    for lo, hi in blocks:
        S = box_tetrahedra((3, 2, 1), lo, hi)
        T = Transfer.assemble(FunctionSpace(S, "P0"), FunctionSpace(G, "Q0"), "l2")
        frac += np.asarray(T.D.diagonal()) / G.cell_measures()
    return np.clip(frac, 0.0, 1.0)


def centre_mask(grid: dict, blocks) -> np.ndarray:
    from .case import Grid

    c = Grid.from_config(grid).cell_centres()
    inside = np.zeros(len(c), dtype=bool)
    for lo, hi in blocks:
        inside |= np.all((c >= np.asarray(lo)) & (c <= np.asarray(hi)), axis=1)
    return inside.astype(float)


def run(n_across: int, method: str = "wall", offset: float = 0.3, workdir="plates_case",
        exponent: float = 3.0, tolerance: float = 1e-7, plates: Plates = Plates(), max_iterations: int = 5000,
        keep_fields: bool = False) -> dict:
    """One immersed-plates solve; returns errors and timings (and, with ``keep_fields``, the
    grid, the solid fractions and the cell fields U, p in Pa under ``"fields"``)."""
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    t_all = time.perf_counter()
    grid, lower, upper = geometry(n_across, offset, plates.w, plates.length)
    t0 = time.perf_counter()
    frac = centre_mask(grid, (lower, upper)) if method == "binary" else exact_fractions(grid, (lower, upper))
    t_frac = time.perf_counter() - t0
    cfg = {"grid": grid, "inlet": {"pressure": plates.dp}, "outlet": {"pressure": 0.0},
           "boundaries": {"zmin": "empty", "zmax": "empty"}, "mu": plates.mu, "rho": plates.rho,
           "max_iterations": max_iterations, "tolerance": tolerance,
           "penalization": "linear" if method == "binary" else method, "penalization_exponent": exponent}
    s = OpenFOAMSolver(Path(workdir), CaseSpec.from_config(cfg))
    t0 = time.perf_counter()
    s.setup()
    t_setup = time.perf_counter() - t0
    t0 = time.perf_counter()
    U, p = s.solve(frac)
    t_solve = time.perf_counter() - t0
    ny = grid["shape"][1]
    Q = U[:, 0].reshape(ny, NX).sum(axis=0) * grid["spacing"][1]
    err = float(Q.mean() / plates.q_cubic - 1)
    out = {"n_across": n_across, "method": method, "offset": offset, "cells": s.n, "Q": float(Q.mean()),
           "Q_cubic": plates.q_cubic, "error": err, "Q_spread": float(np.ptp(Q) / abs(Q.mean())),
           "converged": s.last_run["converged"], "iterations": s.last_run["iterations"],
           "time_fractions": t_frac, "time_setup": t_setup, "time_solve": t_solve,
           "time_total": time.perf_counter() - t_all}
    if keep_fields:
        out["fields"] = {"grid": grid, "solid_fraction": frac, "velocity": U, "pressure": p * plates.rho}
    return out
