"""A flow driven by a flow rate (``[flow] flow_rate``): the pressure difference dp between the
inlet (xmin) and the outlet (xmax) becomes one more unknown of the coupling's fixed point, one
more entry of its interface vector x. For Stokes flow in a fixed geometry the flow rate is
linear in dp (the cubic law Q = W e^3 dp / (12 mu L) between plates, paper 1), so

    H(dp) = dp Q_target / Q(dp)

is the dp the target needs in the geometry of the iteration, and the fixed point dp = H(dp) is
Q = Q_target; Aitken or IQN-ILS treat it with the pressure on the faces. A step converges only
when, besides the interface residual, |Q / Q_target - 1| is below the coupling tolerance
(:meth:`FlowRateControl.unmet`). A rate no pressure difference can reach (a step that converges
with no open path from inlet to outlet) and, with a platen, an inlet pressure at the step's confining stress (the
fracture's faces would separate) stop the run with one line.

On a coupler of P ranks (:class:`coupler.fsi.ranks.FlowRateControlRanks`, the same code through
:meth:`FlowRateControl.hold`, :meth:`~FlowRateControl.local` and :meth:`~FlowRateControl.inlet`)
rank 0 holds dp's row of the interface vector and its weight, the other ranks none; every rank
knows dp once it is delivered, and the flow rate, the percolation and the open volume are sums
(and a labelling) over the ranks' grid slabs, so every rank decides alike."""

from __future__ import annotations

import numpy as np

from coupler.coupling.row_sums import RowSums
from coupler.errors import CouplerError
from coupler.protocol.roles import VELOCITY
from transfer.grid import across_axis

from .flow_rate import percolates, section_flow_rates
from .context import OperatorContext, fluid_solid


class FlowRateControl:
    """The exchange ``fluid.velocity -> fluid.inlet_pressure`` (accelerated): its value is dp,
    delivered as the inlet pressure outlet + dp, evaluated as dp Q_target / Q. Every figure is a
    sum over the grid cells :meth:`local` gives (``block``), taken over the coupler's ranks
    (``comm``; serially None, the whole grid)."""

    units = "Pa"
    #: its value is one number for the whole fluid, not one per row: each of its parts gets it whole
    #: and no VTU has it (the step's figures do; coupler.run.ranks.RanksRun.singles), :attr:`delivered`
    single = True
    comm = None
    block = None  # the grid cells whose velocity and fraction :meth:`local` gives (None: all)

    def __init__(self, ctx: OperatorContext, exchange=None):
        scene = ctx.scene
        flow = scene.effect_settings["flow"]
        self.ctx, self.scene = ctx, scene
        self.hold(ctx)
        self.size = 1 if self.comm is None or self.comm.rank == 0 else 0  # dp's row: rank 0's
        self.target, self.outlet = flow["inlet"]["flow_rate"], flow["outlet"]["pressure"]
        self.tolerance = scene.coupling["tolerance"]
        self.where = f"{scene.path}: [flow] flow_rate"
        wetted = bool(scene.coupling["interface"])
        # in the residual's M-norm dp counts as a pressure over the whole wetted interface
        weight = RowSums(self.comm).sum(float(np.sum(self.fs.on_grid.reference_weights))) if wetted else 1.0
        self.weights = self.row(weight)
        self.pressure_drop = self.first_guess()  # the dp of the latest delivery
        self.flow_rate: float | None = None  # the Q the fluid passed with it
        self.blocked: str | None = None  # why the latest Q cannot be adjusted (no open path), or None

    def hold(self, ctx) -> None:
        """What :meth:`local` reads: the solid on the whole grid (serial)."""
        self.fs, self.grid = fluid_solid(ctx), ctx.meshes["fluid"]

    def local(self, outputs) -> tuple[np.ndarray, np.ndarray]:
        """The fluid velocity and the solid fraction of the deformed solid at the cells of ``block``."""
        return outputs["fluid"][VELOCITY], self.fs.update(outputs).fraction

    def inlet(self, pressure: float):
        """The input ``inlet_pressure`` of the fluid: one value."""
        return np.array([pressure])

    def row(self, value: float) -> np.ndarray:
        """`value` as this rank's rows of the interface vector: dp's row on rank 0, none on the others."""
        return np.array([value][:self.size])

    def first_guess(self) -> float:
        """dp0 = 12 mu L Q / (W e^3) of the cubic law, e the mean open height of the grid's
        columns across (the thinnest transverse extent with more than one cell) in the
        undeformed geometry, W the other transverse extent."""
        g = self.grid
        extents = np.asarray(g.spacing) * np.asarray(g.shape)
        across = across_axis(g.shape, g.spacing)
        width, length = extents[3 - across], extents[0]
        open_cells = RowSums(self.comm).sum(float(np.sum(1.0 - np.asarray(self.fs.on_grid.fraction))))
        open_volume = open_cells * float(np.prod(g.spacing))
        e = open_volume / (length * width)
        if not e > 0:
            raise CouplerError(f"{self.where}: the fluid grid has no open cells in the undeformed geometry: no flow "
                               f"rate can be driven")
        return 12.0 * self.scene.fluid_material["viscosity"] * length * self.target / (width * e ** 3)

    def initial(self) -> np.ndarray:
        """The first iterate of the run's first step (this rank's rows)."""
        return self.row(self.pressure_drop)

    def deliver(self, x):
        """dp from its row (rank 0's, known to every rank after): the inlet pressure outlet + dp."""
        dp = float(np.ravel(x)[0]) if self.size else None
        self.pressure_drop = dp = dp if self.comm is None else self.comm.bcast(dp)
        self._below_confinement(self.outlet + dp)
        return self.inlet(self.outlet + dp)

    @property
    def delivered(self) -> np.ndarray:
        """The inlet pressure of the latest delivery, one value (the same on every rank)."""
        return np.array([self.outlet + self.pressure_drop])

    def evaluate(self, outputs) -> np.ndarray:
        """dp Q_target / Q; while no open path connects inlet and outlet (an iterate may close
        it), dp unchanged: the step stops if it converges so (:meth:`unmet`)."""
        velocity, fraction = self.local(outputs)
        q = float(section_flow_rates(self.grid, velocity, self.block, self.comm).mean())
        self.flow_rate, self.blocked = q, None
        conductance = q / self.pressure_drop if self.pressure_drop else 0.0
        if not percolates(self.grid, fraction, block=self.block, comm=self.comm):
            self.blocked = (f"no open path connects the inlet (xmin) with the outlet (xmax) (every path crosses cells "
                            f"at least half solid): no pressure difference drives {self.target:g} m^3/s through the "
                            f"fracture (percolation lost)")
        elif not conductance > 0:
            self.blocked = (f"the fluid passed {q:.3g} m^3/s under a pressure difference of {self.pressure_drop:.6g} "
                            f"Pa: the rate {self.target:g} m^3/s cannot be reached by adjusting it")
        return self.row(self.pressure_drop if self.blocked else self.target / conductance)

    def unmet(self) -> str | None:
        """None when the latest flow rate is the target to the coupling tolerance, else why not;
        CouplerError when the step converged with no flow to adjust."""
        if self.blocked:
            raise CouplerError(f"{self.ctx.window}: {self.where}: {self.blocked}")
        error = abs(self.flow_rate / self.target - 1.0)
        if error <= self.tolerance:
            return None
        return (f"the flow rate {self.flow_rate:.6g} m^3/s differs from [flow] flow_rate {self.target:g} by "
                f"{error:.3g} (relative, tolerance {self.tolerance:g})")

    def blame(self) -> str:
        """The key behind the inlet pressure delivered, for a fluid that failed on it."""
        return (f"its inlet pressure comes from {self.where} = {self.target:g} m^3/s: a pressure difference of "
                f"{self.pressure_drop:.3g} Pa was asked of it; check that flow rate")

    def figures(self) -> dict:
        """The dp found and the rate reached (the last iteration's), for the step's record."""
        reached = self.flow_rate if self.flow_rate is not None else float("nan")
        return {"flow_rate_control": {"target": self.target, "flow_rate": reached,
                                      "relative_error": abs(reached / self.target - 1.0),
                                      "pressure_drop": self.pressure_drop,
                                      "inlet_pressure": self.outlet + self.pressure_drop}}

    def _below_confinement(self, inlet: float) -> None:
        """With a platen: stop at an inlet pressure at or above the step's confining stress."""
        window = self.ctx.window
        for i, load in enumerate(self.scene.loads, start=1):
            if load.type == "platen" and window is not None and inlet >= load.value[window.index]:
                raise CouplerError(f"{self.where}: the inlet pressure {inlet:.6g} Pa (pressure difference "
                                   f"{inlet - self.outlet:.6g} Pa) reaches the confining stress "
                                   f"{load.value[window.index]:g} Pa of [loads.{i}] stress at this step: the "
                                   f"fracture's faces would separate (loss of contact); ask for a smaller flow rate "
                                   f"or a larger confining stress")
