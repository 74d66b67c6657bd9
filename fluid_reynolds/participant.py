"""``ReynoldsParticipant``: the Reynolds fluid as a protocol participant (docs/protocol.md), a
fluid of the same grid, inputs and outputs as the 3D fluids (:mod:`fluid_chorin.participant`).

Config: :mod:`fluid_reynolds.spec`. Inputs of ``advance``: ``solid_fraction`` (n_cells,) of the
fluid grid (the coupler's exact fractions of the deformed solid), whose columns give the local
aperture (:mod:`fluid_reynolds.columns`), and ``inlet_pressure`` (1,) Pa, the pressure of the
inlet xmin (a flow driven by a rate). Outputs at the fluid grid's cells, x fastest:
``pressure`` (n_cells,) Pa, the plane's pressure on every cell of its column (the coupler
traces it onto both faces of the fracture as a 3D fluid's), and ``velocity`` (n_cells, 3) m/s,
the plane's flux shared among a column's open cells, so the coupler's flow rate through the
sections x = const and its fracture figures are the Reynolds flow's.

State: the last solid fraction and inlet pressure (the solve is steady and depends on nothing
else); ``save_state``/``restore_state`` copy them."""

from __future__ import annotations

import logging
import time

import numpy as np

from coupler.protocol.participant import Participant
from coupler.protocol.roles import INLET_PRESSURE, PRESSURE, SOLID_FRACTION, VELOCITY
from coupler.protocol.wire import Field

from .reynolds import ReynoldsFlow, solve
from .spec import ReynoldsSpec

log = logging.getLogger("varcouple.fluid_reynolds")
#: the relative residual of the direct solve below which it is converged
TOLERANCE = 1e-9


class ReynoldsParticipant(Participant):
    kind = "reynolds_fluid"

    def __init__(self):
        self.spec: ReynoldsSpec | None = None
        self.state: dict = {}
        self.saved: dict[int, dict] = {}

    def announce(self) -> dict:
        return {"kind": self.kind, "provides": [PRESSURE, VELOCITY],
                "accepts": [SOLID_FRACTION, INLET_PRESSURE], "location": "cells"}

    def configure(self, config: dict) -> None:
        self.spec = spec = ReynoldsSpec.from_config(config)
        grid = spec.columns.grid
        self.state = {"fraction": np.zeros(grid.num_cells), "pressures": dict(spec.pressures)}
        self.saved = {}
        log.info("fluid_reynolds: fluid grid %s, across %s, plane grid %s x %s cells, mu %g", list(grid.shape),
                 "xyz"[spec.columns.across], spec.columns.plane[1], spec.columns.plane[0], spec.mu)

    def geometry(self):
        if self.spec is None:
            raise RuntimeError("geometry before configure")
        g = self.spec.columns.grid
        return {"grid": {"origin": g.origin.tolist(), "spacing": g.spacing.tolist(), "shape": list(g.shape)},
                "location": "cells"}, None

    def advance(self, window, iteration, t, dt, inputs):
        if self.spec is None:
            raise RuntimeError("advance before configure")
        spec, n = self.spec, self.spec.columns.grid.num_cells
        for name, shape in ((SOLID_FRACTION, (n,)), (INLET_PRESSURE, (1,))):
            if name in inputs:
                data = np.asarray(inputs[name].data, dtype=float)
                if data.shape != shape or not np.all(np.isfinite(data)):
                    raise ValueError(f"input {name!r}: expected {shape} finite values, got shape {data.shape}")
        if SOLID_FRACTION in inputs:
            self.state["fraction"] = np.array(inputs[SOLID_FRACTION].data, dtype=float)
        if INLET_PRESSURE in inputs:
            self.state["pressures"]["xmin"] = float(np.asarray(inputs[INLET_PRESSURE].data)[0])
        t0 = time.perf_counter()
        flow = self.solve()
        log.info("window %d iteration %d: Reynolds flow rate %.6g m^3/s, %d of %d plane cells solved, residual "
                 "%.3g, %.3f s", window, iteration, flow.flow_rate, int(flow.solved.sum()), flow.solved.size,
                 flow.residual, time.perf_counter() - t0)
        if not flow.percolating:
            log.warning("window %d iteration %d: no open path in the plane from the inlet xmin to the outlet xmax: "
                        "no flow", window, iteration)
        if flow.dropped:
            log.warning("window %d iteration %d: %.3g m^3/s of the inlet velocity's flow enters open cells that "
                        "reach no outlet and is dropped (%.3g m^3/s taken)", window, iteration, flow.dropped,
                        flow.flow_rate)
        self.report_solve("Reynolds (SuperLU)", flow.residual <= TOLERANCE, 1, flow.residual, TOLERANCE,
                          f"{int(flow.solved.sum())} of {flow.solved.size} plane cells open and connected")
        columns = spec.columns
        return {PRESSURE: Field(PRESSURE, columns.spread(flow.pressure), "Pa"),
                VELOCITY: Field(VELOCITY, columns.velocity(flow.flux_x, flow.flux_y, self.state["fraction"]),
                                  "m/s")}

    def solve(self) -> ReynoldsFlow:
        """The Reynolds flow of the current solid fraction and face pressures."""
        spec = self.spec
        aperture = spec.columns.aperture(self.state["fraction"])
        aperture = np.where(aperture < spec.closed, 0.0, aperture)
        inflow = None
        if spec.inlet_velocity is not None:  # through the open part of each inlet cell
            inflow = spec.inlet_velocity * aperture[:, 0] * spec.columns.spacing[1]
        return solve(aperture, spec.columns.spacing, spec.mu, self.state["pressures"], inflow)

    def save_state(self, window):
        state = self.state
        self.saved[int(window)] = {"fraction": state["fraction"].copy(), "pressures": dict(state["pressures"])}
        for w in [w for w in self.saved if w < int(window) - 1]:
            del self.saved[w]  # keep the last two windows

    def restore_state(self, window):
        if int(window) not in self.saved:
            raise KeyError(f"no state saved for window {window} (saved: {sorted(self.saved)})")
        saved = self.saved[int(window)]
        self.state = {"fraction": saved["fraction"].copy(), "pressures": dict(saved["pressures"])}
