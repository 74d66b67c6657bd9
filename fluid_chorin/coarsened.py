"""The same steady flow on the grid coarsened two times across the thin gap: its flow rate
``Q_c`` is the fine solve's second grid for the coupler's Richardson estimate of the error of the
hydraulic aperture (:func:`coupler.fsi.resolution.aperture_error`).

Across is the direction of the grid's thinnest extent among y and z (the flow runs along x,
inlet xmin to outlet xmax) with more than one cell. Each pair of cells along it merges into one
cell of twice the height: its solid fraction is the mean of the pair's (the solid volume in it:
the fractions stay exact, paper eq. 10), its solid velocity the fraction-weighted mean of the
pair's (the solid's momentum). With an odd number of cells across the last plane is doubled (the
grid grows by one fine cell on that side: the same solid where that plane is solid, as the
blocks around a fracture are). The coarse grid's drag follows the same rule as the fine one's
(:meth:`fluid_chorin.spec.ChorinSpec.drag_value`): the same scene on the coarser grid.

On several ranks the coarse grid is cut in slabs of its own (:mod:`fluid_chorin.slabs`); each
rank joins the fine inputs of the owned cells of every rank (one allgather of the fraction and
velocity per new solid) to merge the pairs, so the coarse solve and ``Q_c`` are the serial ones.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from transfer.grid import StructuredGrid, across_axis

from .slabs import Slabs
from .solver import ChorinSolver
from .spec import ChorinSpec
from .staggered import AXIS, along


def across_direction(spec: ChorinSpec) -> int | None:
    """The direction (1 or 2) of the thinnest extent among y and z with more than one cell (None: neither)."""
    g = spec.grid
    return across_axis(g.shape, g.spacing) if g.shape[1] > 1 or g.shape[2] > 1 else None


def coarsened_spec(spec: ChorinSpec, d: int) -> ChorinSpec:
    """``spec`` on its grid with pairs of cells along direction ``d`` merged (an odd last cell doubled)."""
    g = spec.grid
    spacing, shape = g.spacing.copy(), np.array(g.shape)
    spacing[d], shape[d] = 2.0 * spacing[d], (shape[d] + 1) // 2
    return dataclasses.replace(spec, grid=StructuredGrid(g.origin, spacing, shape))


def merge_pairs(fraction: np.ndarray, velocity: np.ndarray | None, d: int) -> tuple[np.ndarray, np.ndarray | None]:
    """The (nz, ny, nx) solid fractions and (nz, ny, nx, 3) velocities (or None) of a whole grid
    with pairs of cells along direction ``d`` merged: the mean fraction, the fraction-weighted
    mean velocity (the plain mean where the pair holds no solid)."""
    a = AXIS[d]

    def paired(x):
        if x.shape[a] % 2:
            x = np.concatenate([x, x[along(a, slice(-1, None))]], axis=a)
        return x.reshape(x.shape[:a] + (x.shape[a] // 2, 2) + x.shape[a + 1:])

    f = paired(fraction)
    merged = f.mean(axis=a + 1)
    if velocity is None:
        return merged, None
    v, w = paired(velocity), f[..., None]
    total = w.sum(axis=a + 1)
    weighted = np.divide((w * v).sum(axis=a + 1), total, out=v.mean(axis=a + 1), where=total > 0)
    return merged, weighted


class CoarsenedFlow:
    """The steady flow of the fine solver ``fine`` (a :class:`fluid_chorin.solver.ChorinSolver`)
    on its grid coarsened across (:func:`coarsened_spec`), on the same ranks, warm-started from its
    own last state."""

    def __init__(self, fine, d: int):
        self.fine, self.d = fine, d
        spec = coarsened_spec(fine.spec, d)
        try:
            self.solver = ChorinSolver(spec, fine.slabs.comm)
        except ValueError as exc:
            raise ValueError(f"error_estimate: the grid coarsened across {'xyz'[d]} ({list(spec.grid.shape)} cells) "
                             f"cannot be cut over the ranks: {exc}; set [solvers.fluid] error_estimate = false or "
                             f"fewer ranks") from None

    def whole(self, values: np.ndarray) -> np.ndarray:
        """Per-cell ``values`` of the fine solver's input cells on the whole fine grid, (nz, ny, nx, ...)."""
        slabs: Slabs = self.fine.slabs
        mine = np.ascontiguousarray(slabs.from_inputs(values)[slabs.owned()])
        if slabs.comm is None:
            return mine
        return np.concatenate(slabs.comm.allgather(mine), axis=slabs.axis)

    def set_solid(self, fraction, velocity=None) -> None:
        """The fine solver's solid inputs (per input cell of this rank, as
        :meth:`fluid_chorin.solver.ChorinSolver.set_solid` takes them), merged onto the coarse grid."""
        f = self.whole(np.clip(np.asarray(fraction, dtype=float).reshape(-1), 0.0, 1.0))
        v = None if velocity is None else self.whole(np.asarray(velocity, dtype=float).reshape(-1, 3))
        merged, moving = merge_pairs(f, v, self.d)
        rows = self.solver.slabs.input_ids()
        self.solver.set_solid(merged.reshape(-1)[rows], None if moving is None else moving.reshape(-1, 3)[rows])

    def set_inlet_pressure(self, pressure: float) -> None:
        self.solver.set_inlet_pressure(pressure)

    def steady(self):
        """The coarse steady solve (:meth:`fluid_chorin.solver.ChorinSolver.steady`), its report
        named as the coarse grid's."""
        run = self.solver.steady()
        run.report = dataclasses.replace(run.report, solver=f"{run.report.solver} on the grid coarsened 2x across "
                                                            f"{'xyz'[self.d]} (error estimate)")
        return run

    def flow_rate(self) -> float:
        """``Q_c`` [m^3/s]: the coarse cells' x velocity at their centres times their face area,
        summed over each section x = const and averaged over the sections (as the coupler's
        :func:`coupler.fsi.flow_rate.section_flow_rates` on the fine grid)."""
        s = self.solver
        q, owned = s.state.q[0], s.slabs.owned()
        centre = 0.5 * (q[along(AXIS[0], slice(None, -1))] + q[along(AXIS[0], slice(1, None))])[owned]
        sections = np.zeros(s.spec.grid.shape[0])
        first = s.slabs.lo if s.slabs.d == 0 else 0
        sections[first:first + centre.shape[2]] = centre.sum(axis=(0, 1))
        if s.slabs.comm is not None:
            sections = s.slabs.comm.allreduce(sections)
        h = s.spec.grid.spacing
        return float(sections.mean() * h[1] * h[2])
