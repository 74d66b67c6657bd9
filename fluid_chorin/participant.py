"""``ChorinParticipant``: the Chorin fluid as a protocol participant (docs/protocol.md).

Config: :mod:`fluid_chorin.spec` (the same grid, fluid and face conditions as the OpenFOAM
fluid; the flow rule fills them from the scene). Inputs of ``advance``: ``solid_fraction``
(n_cells,) in [0, 1] (clipped) and ``solid_velocity`` (n_cells, 3) m/s, applied per cell
(:mod:`fluid_chorin.solver`), and ``inlet_pressure`` (1,) Pa, the new pressure of the inlet
face xmin (a flow driven by a rate: the coupler adjusts it each coupling iteration). Outputs: ``pressure`` (n_cells,) Pa and ``velocity``
(n_cells, 3) m/s at the cell centres, x fastest.

MPI: started on N ranks (``[solvers.fluid] ranks = N``), every rank receives the verbs and the
rows of its input cells (``input_ids``: its slab, the ghost layer and the cells the drag of a
ghost reads, one more plane on each side with the "wall" penalization), steps its slab of the
grid (:mod:`fluid_chorin.slabs`) and answers with its own cells' fields (``cell_ids``;
docs/protocol.md, "Parts"): nothing is gathered. Rigid bodies (``solid_velocity = "bodies"``)
are labelled across the slabs from those inputs (:func:`transfer.bodies.rigid_bodies`: one
allgather of each slab's face planes and one of its bodies' sums).

Steady (no ``transient``): each ``advance`` makes pseudo-time steps (or Newton steps,
``steady = "newton"``) from the current state (a warm start) to the tolerance, and with
``error_estimate`` solves the same flow on the grid coarsened across the gap
(:mod:`fluid_chorin.coarsened`) from its own last state, reporting its flow rate as the figure
``coarse_flow_rate`` (``report_figures``). Transient: from ``t`` over ``dt``. Each reports the
stepping and the pressure Poisson solves (``report_solve``).

State: in memory. ``save_state(w)`` copies the velocity, pressure and time (of the coarse flow too);
``restore_state(w)`` goes back to the copy, so a repeated window gives identical outputs.
"""

from __future__ import annotations

import logging
import time

import numpy as np

from coupler.protocol.participant import Participant
from coupler.protocol.roles import (COARSE_FLOW_RATE, INLET_PRESSURE, PRESSURE, SOLID_FRACTION, SOLID_VELOCITY,
                                    VELOCITY)
from coupler.protocol.wire import Field

from .coarsened import CoarsenedFlow, across_direction
from .solver import ChorinSolver, Run, State
from .spec import ChorinSpec

log = logging.getLogger("varcouple.fluid_chorin")
#: the inputs of ``advance`` and their shapes (None: one row per input cell of the rank)
INPUT_SHAPES = {SOLID_FRACTION: (None,), SOLID_VELOCITY: (None, 3), INLET_PRESSURE: (1,)}


class ChorinParticipant(Participant):
    kind = "chorin_fluid"

    def __init__(self):
        self.solver: ChorinSolver | None = None
        #: the steady flow on the grid coarsened across the gap (``error_estimate``; None: none)
        self.coarse: CoarsenedFlow | None = None
        self.saved: dict[int, tuple[State, State | None]] = {}

    def announce(self) -> dict:
        return {"kind": self.kind, "provides": [PRESSURE, VELOCITY],
                "accepts": [SOLID_FRACTION, SOLID_VELOCITY, INLET_PRESSURE], "location": "cells"}

    def configure(self, config: dict) -> None:
        spec = ChorinSpec.from_config(config)
        self.solver, self.saved = ChorinSolver(spec, self.comm), {}
        across = across_direction(spec)
        self.coarse = (CoarsenedFlow(self.solver, across)
                       if spec.error_estimate and not spec.transient and across is not None else None)
        slabs = self.solver.slabs
        log.info("fluid_chorin: grid %s (%d cells), nu %g, drag %g 1/s, %s%s", spec.grid.shape, spec.grid.num_cells,
                 spec.nu, self.solver.d_max, "transient" if spec.transient else f"steady ({spec.steady})",
                 f"; rank {self.rank} of {self.size}: cells {slabs.lo} to {slabs.hi - 1} along {'xyz'[slabs.d]}, "
                 f"{int(np.prod(slabs.input_shape))} input cells"
                 if self.size > 1 else "")

    def geometry(self):
        if self.solver is None:
            raise RuntimeError("geometry before configure")
        g = self.solver.spec.grid
        return ({"grid": {"origin": g.origin.tolist(), "spacing": g.spacing.tolist(), "shape": list(g.shape)},
                 "location": "cells"},
                {"cell_ids": self.solver.slabs.cell_ids(), "input_ids": self.solver.slabs.input_ids()})

    def advance(self, window, iteration, t, dt, inputs):
        if self.solver is None:
            raise RuntimeError("advance before configure")
        solver = self.solver
        problem = self.input_problem(inputs)
        if problem:
            raise ValueError(problem)
        arrays = {name: np.asarray(inputs[name].data, dtype=float) for name in INPUT_SHAPES if name in inputs}
        solvers = [s for s in (solver, self.coarse) if s is not None]
        if INLET_PRESSURE in arrays:
            pressure = float(arrays.pop(INLET_PRESSURE)[0])
            for s in solvers:
                s.set_inlet_pressure(pressure)
        if arrays:
            fraction = arrays.get(SOLID_FRACTION, solver.solid_fraction)
            for s in solvers:
                s.set_solid(fraction, arrays.get(SOLID_VELOCITY))
        self.solved(window, iteration, lambda: solver.transient(t, dt) if solver.spec.transient else solver.steady())
        if self.coarse is not None:  # a diagnostic: unconverged, it gives no figure and fails nothing
            run = self.solved(window, iteration, self.coarse.steady, "error estimate")
            if run.converged and all(p.converged for p in run.poisson):
                self.report_figures(**{COARSE_FLOW_RATE: self.coarse.flow_rate()})
        pressure, velocity = solver.part_fields()
        return {PRESSURE: Field(PRESSURE, pressure, "Pa"), VELOCITY: Field(VELOCITY, velocity, "m/s")}

    def solved(self, window, iteration, solve, diagnostic: str = "") -> Run:
        """Run ``solve`` (returns a :class:`fluid_chorin.solver.Run`), log and report it; a
        ``diagnostic`` solve (named by it) is reported accepted: its fields are not the step's."""
        t0 = time.perf_counter()
        run = solve()
        log.info("window %d iteration %d: %s, %d iterations, residual %.3g, %d Poisson solves, %.3f s", window,
                 iteration, run.report.solver, run.report.iterations, run.report.residual, len(run.poisson),
                 time.perf_counter() - t0)
        self.report(run, diagnostic)
        return run

    def input_problem(self, inputs) -> str | None:
        """An input whose shape is not one row per input cell of this rank (:data:`INPUT_SHAPES`)
        or that holds NaN/inf."""
        if self.solver is None:
            return "advance before configure"
        slabs = self.solver.slabs
        n = int(np.prod(slabs.input_shape))
        for name, shape in INPUT_SHAPES.items():
            if name not in inputs:
                continue
            data = np.asarray(inputs[name].data, dtype=float)
            want = tuple(n if k is None else k for k in shape)
            if data.shape != want:
                mine = "" if None not in shape or self.size == 1 else (
                    f" (rank {self.rank}'s input_ids: planes {slabs.input_planes[0]} to "
                    f"{slabs.input_planes[1] - 1} along {'xyz'[slabs.d]})")
                return f"input {name!r} has shape {data.shape}, expected {want}{mine}"
            if not np.all(np.isfinite(data)):
                return f"input {name!r} holds NaN/inf at index {int(np.argmin(np.isfinite(data)))}"
        return None

    def report(self, run: Run, diagnostic: str = "") -> None:
        """The stepping and, in one report, its pressure Poisson solves (the worst of them); those of
        a ``diagnostic`` solve (its stepping names it already) accepted unconverged, its Poisson
        solves named by it."""
        r, named = run.report, f" ({diagnostic})" if diagnostic else ""
        self.report_solve(r.solver, r.converged, r.iterations, r.residual, r.tolerance, r.detail,
                          accepted=bool(diagnostic))
        if run.poisson:
            first = run.poisson[0]
            self.report_solve(f"pressure Poisson ({first.method}){named}", all(r.converged for r in run.poisson),
                              max(r.iterations for r in run.poisson), max(r.residual for r in run.poisson),
                              first.tolerance, f"{len(run.poisson)} solves; iterations and residual of the worst",
                              accepted=bool(diagnostic))

    def save_state(self, window):
        if self.solver is None:
            raise RuntimeError("save_state before configure")
        self.saved[int(window)] = (self.solver.state.copy(),
                                   None if self.coarse is None else self.coarse.solver.state.copy())
        for w in [w for w in self.saved if w < int(window) - 1]:
            del self.saved[w]  # keep the last two windows

    def restore_state(self, window):
        if int(window) not in self.saved:
            raise KeyError(f"no state saved for window {window} (saved: {sorted(self.saved)})")
        fine, coarse = self.saved[int(window)]
        self.solver.state = fine.copy()
        if self.coarse is not None:
            self.coarse.solver.state = coarse.copy()
