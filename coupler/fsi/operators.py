"""The operators the plan's exchanges name (:attr:`coupler.plan.plan.Exchange.operator`),
between the fluid grid and the solid mesh (paper 2.3).

An operator is built once per run from an :class:`OperatorContext` (the participants'
meshes, their geometry fields, the scene) and its exchange, and then, in every coupling iteration,
``evaluate(outputs)`` turns the latest outputs of the participants (``{name: {field:
array}}``) into the exchanged quantity and ``deliver(value)`` into the target's input
array. The quantity of an accelerated exchange is the fixed point's interface vector x:
such an operator also gives its ``size`` and ``weights`` (the lumped interface mass of the
residual's M-norm), and may give ``initial()`` (its part of the first iterate, else zero) and
``unmet()`` (a condition of convergence besides the residual: :mod:`.rate_control`). The operators of one solid and one grid share one
:class:`~coupler.fsi.interface.SolidOnGrid`, rebuilt from the deformed solid at most once
per new displacement.
"""

from __future__ import annotations

import numpy as np

from coupler.protocol.roles import PRESSURE, SOLID_FRACTION, SOLID_VELOCITY, VELOCITY

from .context import OperatorContext, fluid_solid
from . import open_gap
from .projection import Projection
from .rate_control import FlowRateControl
from .viscous import FluidTraction, traction_figures


class PressureTrace:
    """Steps 2-3: the fluid's cell pressure traced on the wetted interface (the interface
    vector: one value per interface vertex), delivered at every solid vertex (zero off it)."""

    units = "Pa"

    def __init__(self, ctx: OperatorContext, exchange=None):
        self.fs = fluid_solid(ctx)
        interface = self.fs.on_grid.interface
        self.size, self.weights = interface.size, self.fs.on_grid.reference_weights

    def evaluate(self, outputs) -> np.ndarray:
        return self.fs.on_grid.interface.from_fluid(outputs["fluid"][PRESSURE])

    def deliver(self, x) -> np.ndarray:
        return self.fs.on_grid.interface.to_solid_vertices(x)


class OpenShare:
    """The trace of a fracture with contact (mixed into a pressure trace, serial or on ranks):
    the pressure times the open share of each interface vertex, zero where the faces touch
    (:func:`coupler.fsi.open_gap.open_share`, from the solid's latest ``in_contact``): there the
    contact pressure carries the load and no fluid acts."""

    def evaluate(self, outputs=None) -> np.ndarray:
        return self.open_share(outputs) * super().evaluate(outputs)


class OpenPressureTrace(OpenShare, PressureTrace):
    """Steps 2-3 in a fracture with contact: :class:`PressureTrace` on the open faces (:class:`OpenShare`)."""

    def __init__(self, ctx: OperatorContext, exchange=None):
        super().__init__(ctx, exchange)
        self.points = np.asarray(ctx.meshes["solid"].points)

    def open_share(self, outputs) -> np.ndarray:
        return open_share(self.fs.on_grid.interface, self.points, outputs["solid"])


def open_share(interface, points: np.ndarray, solid: dict) -> np.ndarray:
    """Per vertex of the serial `interface`: the share of it where the fluid acts
    (:func:`coupler.fsi.open_gap.open_share`), from the solid's outputs at its `points`."""
    v = interface.vertices
    return open_gap.open_share(points[v], interface.triangles, lambda name: solid[name][v])


class ViscousTraction:
    """Steps 2-3 with the fluid's full stress: the traction (-p I + tau) n at the interface
    vertices (three values each), the wall shear from three velocity samples
    (:mod:`coupler.fsi.viscous`); its pressure and viscous forces are the step's figures."""

    units = "Pa"
    #: the solid as the grid sees it, shared with the other operators (on the coupler's ranks: theirs)
    _fluid_solid = staticmethod(fluid_solid)

    def __init__(self, ctx: OperatorContext, exchange=None):
        self.fs = self._fluid_solid(ctx)
        self.traction = FluidTraction(ctx.scene.fluid_material["viscosity"])
        self.weights = np.repeat(self.fs.on_grid.reference_weights, 3)
        self.size = len(self.weights)
        self.last: dict = {}

    def evaluate(self, outputs) -> np.ndarray:
        g = self.fs.on_grid
        parts = self.traction.parts(g, *self.fields(outputs))
        self.last = {**traction_figures(g.interface.weights, *parts, g.comm), "fits": self.traction.fits}
        return (parts[0] + parts[1]).ravel()

    def fields(self, outputs) -> tuple:
        """(the fluid's cell pressure, its cell velocity, the solid's velocity at the interface vertices)."""
        wall = outputs["solid"][VELOCITY][self.fs.on_grid.interface.vertices]
        return outputs["fluid"][PRESSURE], outputs["fluid"][VELOCITY], wall

    def deliver(self, x) -> np.ndarray:
        return self.fs.on_grid.interface.to_solid_vertices(np.asarray(x).reshape(-1, 3))

    def figures(self) -> dict:
        """How much the viscous part matters, for the step's record (``traction``)."""
        return {"traction": self.last}


class SolidFraction:
    """Before Step 1: the solid volume fraction of every grid cell, option ``fraction``:
    ``exact`` (default) the intersection volumes of the deformed solid's indicator (P0 -> Q0),
    ``cell_centre`` 1 where the cell's centre is in the solid and 0 elsewhere (the binary mask
    the exact fractions replace: the wall moves to the nearest cell faces)."""

    units = "1"

    def __init__(self, ctx: OperatorContext, exchange=None):
        self.fs = fluid_solid(ctx)
        self.centres = sampled_at_centres(exchange)

    def evaluate(self, outputs=None) -> np.ndarray:
        on_grid = self.fs.update(outputs)
        return on_grid.centre_fraction() if self.centres else on_grid.fraction

    def deliver(self, value) -> np.ndarray:
        return value


def sampled_at_centres(exchange) -> bool:
    """Whether the solid fraction of `exchange` is sampled at the cell centres (option ``fraction``)."""
    return (exchange.options.get("fraction", "exact") == "cell_centre") if exchange else False


class SolidVelocity:
    """Step 6: the solid velocity on the grid cells, P1 (deformed solid) -> Q0, pseudo-L2; zero
    in cells the solid does not reach."""

    units = "m/s"

    def __init__(self, ctx: OperatorContext, exchange=None):
        self.fs = fluid_solid(ctx)

    def evaluate(self, outputs) -> np.ndarray:
        return self.fs.update(outputs).to_fluid.apply(outputs["solid"][VELOCITY], fill=0.0)

    def deliver(self, value) -> np.ndarray:
        return value


#: operator name (as plans write it) -> class, built as ``cls(context, exchange)``
OPERATORS = {"pressure_trace": PressureTrace, "open_pressure_trace": OpenPressureTrace,
             "viscous_traction": ViscousTraction,
             SOLID_FRACTION: SolidFraction, SOLID_VELOCITY: SolidVelocity,
             "flow_rate_control": lambda ctx, exchange: ctx.shared("flow_rate_control", FlowRateControl),
             "l2": lambda ctx, exchange: Projection(ctx, exchange, "l2"),
             "pseudo_l2": lambda ctx, exchange: Projection(ctx, exchange, "pseudo_l2")}
