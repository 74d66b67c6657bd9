"""The operators the plan's exchanges name (:attr:`coupler.plan.plan.Exchange.operator`),
between the fluid grid and the solid mesh (paper 2.3).

An operator is built once per run from an :class:`OperatorContext` (the participants'
meshes, their geometry fields, the scene) and its exchange, and then, in every coupling iteration,
``evaluate(outputs)`` turns the latest outputs of the participants (``{name: {field:
array}}``) into the exchanged quantity and ``deliver(value)`` into the target's input
array. The quantity of an accelerated exchange is the fixed point's interface vector x:
such an operator also gives its ``size`` and ``weights`` (the lumped interface mass of the
residual's M-norm). The operators of one solid and one grid share one
:class:`~coupler.fsi.interface.SolidOnGrid`, rebuilt from the deformed solid at most once
per new displacement.
"""

from __future__ import annotations

import time
import warnings

import numpy as np

from coupler.errors import CouplerError
from transfer import FunctionSpace, OverlapWarning, StructuredGrid, Transfer

from .centres import centres_inside
from .interface import SolidOnGrid, WettedInterface
from .open_gap import touching
from .viscous import FluidTraction, traction_figures


class OperatorContext:
    """What operators are built from: the scene, the participants' meshes and geometry fields,
    the phases timer and the log; :meth:`shared` builds an object once for all operators."""

    def __init__(self, scene, meshes: dict, geometry: dict, phases, log=print):
        self.scene, self.meshes, self.geometry, self.phases, self.log = scene, meshes, geometry, phases, log
        self._shared: dict = {}
        self.warnings: list[str] = []

    def shared(self, key: str, build):
        if key not in self._shared:
            self._shared[key] = build(self)
        return self._shared[key]

    def warn(self, texts) -> None:
        """Log each warning once (e.g. meshes in different length units) and keep it for summary.json."""
        for text in texts:
            if text not in self.warnings:
                self.warnings.append(text)
                self.log(f"warning: {text}")

    def summary(self) -> dict:
        """What the shared objects tell of themselves, and the warnings, for summary.json."""
        out = {"warnings": list(self.warnings)} if self.warnings else {}
        for obj in self._shared.values():
            out.update(obj.summary() if hasattr(obj, "summary") else {})
        return out


class FluidSolid:
    """The solid as the grid sees it (:class:`SolidOnGrid`) for the exchanges of a flow scene,
    updated from the solid's displacement whenever an operator asks. A solid the fluid does
    not load (no ``[coupling] interface``: a fixed solid) has no wetted interface."""

    def __init__(self, ctx: OperatorContext):
        scene = ctx.scene
        self.ctx = ctx
        self._seen = None
        start = time.perf_counter()
        triangles = ctx.geometry["solid"].get("interface_triangles")
        triangles = None if triangles is None else np.asarray(triangles)
        wetted = scene.coupling["interface"] is not None
        self.on_grid = SolidOnGrid(ctx.meshes["solid"], ctx.meshes["fluid"], triangles,
                                   f"{scene.path}: [geometry.fluid]", deform=scene.coupling["deformation"],
                                   traction=scene.coupling["traction"], wetted=wetted)
        ctx.phases.add("transfer", time.perf_counter() - start)
        interface, g = self.on_grid.interface, self.on_grid
        self.interface = ({**interface.describe(), "traction": scene.coupling["traction"]} if wetted
                          else {"method": "none (the fluid does not load the solid)"})  # as first built
        if isinstance(interface, WettedInterface):
            ctx.log(f"interface {scene.coupling['interface']}: {interface.num_vertices} vertices, "
                    f"{interface.num_triangles} triangles, pressure sampled up to {interface.offset:.3g} m into "
                    f"the fluid")
            if g.outside > 1e-9:
                ctx.log(f"the fluid grid covers the wetted interface; {g.outside:.3g} of the solid's volume lies "
                        f"outside it")
        elif wetted:  # stand-in solids without a boundary (spring_solid): the volume projection onto all vertices
            ctx.log(f"interface: no boundary triangles from the solid; pressure projected onto all "
                    f"{ctx.meshes['solid'].num_points} solid vertices (volume projection)")
        ctx.log(f"transfers: {g.to_fluid.stats['pairs_intersected']} cell pairs; solid fills "
                f"{np.count_nonzero(g.fraction > 0)} fluid cells"
                f"{'; rebuilt from the deformed solid every iteration' if g.deform else ''}")

    def update(self, outputs) -> SolidOnGrid:
        """The solid on the grid as the solid's latest displacement deforms it (two-way coupling);
        once per new output of the solid, however many operators ask."""
        u = outputs.get("solid", {}).get("displacement")
        if u is not None and u is self._seen:
            return self.on_grid
        self._seen = u
        try:
            self.ctx.phases.timed("geometry update", self.on_grid.update, u)
        except CouplerError as exc:
            largest = float(np.max(np.linalg.norm(u, axis=1))) if u is not None else 0.0
            raise CouplerError(f"the deformed solid (largest displacement {largest:.3g} m) no longer fits the "
                               f"fluid grid: {exc}") from None
        return self.on_grid

    def summary(self) -> dict:
        return {"interface": self.interface, "geometry_update": self.on_grid.describe()}


def _fluid_solid(ctx: OperatorContext) -> FluidSolid:
    return ctx.shared("fluid_solid", FluidSolid)


class PressureTrace:
    """Steps 2-3: the fluid's cell pressure traced on the wetted interface (the interface
    vector: one value per interface vertex), delivered at every solid vertex (zero off it)."""

    units = "Pa"

    def __init__(self, ctx: OperatorContext, exchange=None):
        self.fs = _fluid_solid(ctx)
        interface = self.fs.on_grid.interface
        self.size, self.weights = interface.size, self.fs.on_grid.reference_weights

    def evaluate(self, outputs) -> np.ndarray:
        return self.fs.on_grid.interface.from_fluid(outputs["fluid"]["pressure"])

    def deliver(self, x) -> np.ndarray:
        return self.fs.on_grid.interface.to_solid_vertices(x)


class OpenPressureTrace(PressureTrace):
    """Steps 2-3 in a fracture with contact: the pressure trace where the gap is open and zero
    where the faces touch (:func:`coupler.fsi.open_gap.touching`, from the solid's latest
    ``in_contact``): there the contact pressure carries the load and no fluid acts."""

    def __init__(self, ctx: OperatorContext, exchange=None):
        super().__init__(ctx, exchange)
        self.points = np.asarray(ctx.meshes["solid"].points)

    def evaluate(self, outputs) -> np.ndarray:
        return np.where(open_faces(self.fs.on_grid.interface, self.points, outputs["solid"]),
                        super().evaluate(outputs), 0.0)


def open_faces(interface, points: np.ndarray, solid: dict) -> np.ndarray:
    """Per interface vertex: whether the fluid acts there (the faces do not touch), from the
    solid's outputs (displacement, slave, in_contact)."""
    deformed = points + solid["displacement"]
    return ~touching(deformed, interface.vertices, solid["slave"] > 0.5, solid["in_contact"] > 0.5)


class ViscousTraction:
    """Steps 2-3 with the fluid's full stress: the traction (-p I + tau) n at the interface
    vertices (three values each), the wall shear from three velocity samples
    (:mod:`coupler.fsi.viscous`); its pressure and viscous forces are the step's figures."""

    units = "Pa"

    def __init__(self, ctx: OperatorContext, exchange=None):
        self.fs = _fluid_solid(ctx)
        self.traction = FluidTraction(ctx.scene.fluid_material["viscosity"])
        interface = self.fs.on_grid.interface
        self.size, self.weights = 3 * interface.size, np.repeat(self.fs.on_grid.reference_weights, 3)
        self.last: dict = {}

    def evaluate(self, outputs) -> np.ndarray:
        g = self.fs.on_grid
        wall = outputs["solid"]["velocity"][g.interface.vertices]
        parts = self.traction.parts(g, outputs["fluid"]["pressure"], outputs["fluid"]["velocity"], wall)
        self.last = {**traction_figures(g.interface.weights, *parts), "fits": self.traction.fits}
        return (parts[0] + parts[1]).ravel()

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
        self.fs = _fluid_solid(ctx)
        self.centres = (exchange.options.get("fraction", "exact") == "cell_centre") if exchange else False
        self._mask = None  # (the solid mesh it was sampled on, the mask)

    def evaluate(self, outputs) -> np.ndarray:
        on_grid = self.fs.update(outputs)
        if not self.centres:
            return on_grid.fraction
        if self._mask is None or self._mask[0] is not on_grid.current:
            self._mask = on_grid.current, centres_inside(on_grid.current, on_grid.G).astype(np.float64)
        return self._mask[1]

    def deliver(self, value) -> np.ndarray:
        return value


class SolidVelocity:
    """Step 6: the solid velocity on the grid cells, P1 (deformed solid) -> Q0, pseudo-L2; zero
    in cells the solid does not reach."""

    units = "m/s"

    def __init__(self, ctx: OperatorContext, exchange=None):
        self.fs = _fluid_solid(ctx)

    def evaluate(self, outputs) -> np.ndarray:
        return self.fs.update(outputs).to_fluid.apply(outputs["solid"]["velocity"], fill=0.0)

    def deliver(self, value) -> np.ndarray:
        return value


class Projection:
    """A field of one participant carried to another's mesh by the variational transfer of
    paper 2.1 (``T = D^-1 B``, eq. 3-4): P1/Q1 at a mesh's points or P0/Q0 in its cells on the
    source side (option ``kind``, else by the field's length), the same family on a target
    mesh and Q0 in the cells of a grid. Where the source does not reach, the target gets zero,
    or NaN with option ``fill = "nan"`` (a mesh file that records the transfer). Options
    ``quadrature_degree`` and ``threads`` go to the assembly; a ``kind`` given is assembled
    with the operators, before the first step. Figures of a step: the covered fraction, the
    uncovered dofs and the conservation error over the overlap (``projections``)."""

    def __init__(self, ctx: OperatorContext, exchange, method: str):
        (source,) = exchange.sources
        self.participant, self.field = source.split(".", 1)
        self.ctx, self.method, self.name = ctx, method, exchange.target
        self.source, self.target = ctx.meshes[self.participant], ctx.meshes[exchange.target_participant]
        options = exchange.options
        self.fill = np.nan if options.get("fill") == "nan" else 0.0
        self.assembly = {"quadrature_degree": options.get("quadrature_degree"), "nthreads": options.get("threads", 1)}
        self.units = ""
        self._transfers: dict = {}
        self._last = None  # (transfer, source values) of the last evaluation
        if "kind" in options:
            self._transfer(options["kind"])

    def _transfer(self, kind: str) -> Transfer:
        if kind not in self._transfers:
            S, G = self.source, self.target
            start = time.perf_counter()
            with warnings.catch_warnings(action="ignore", category=OverlapWarning):  # reported once, below
                T = Transfer.assemble(FunctionSpace(S, _family(S, kind)), FunctionSpace(G, _family(G, kind, grid="Q0")),
                                      self.method, **self.assembly)
            self.ctx.phases.add("transfer", time.perf_counter() - start)
            self.ctx.warn(T.warnings)
            self._transfers[kind] = T
        return self._transfers[kind]

    def evaluate(self, outputs) -> np.ndarray:
        values = np.asarray(outputs[self.participant][self.field])
        T = self._transfer("point" if len(values) == self.source.num_points else "cell")
        flat = values.reshape(len(values), -1) if values.ndim > 1 else values
        self._last = T, flat
        out = T.apply(flat, fill=self.fill)
        return out.reshape((len(out),) + values.shape[1:])

    def deliver(self, value) -> np.ndarray:
        return value

    def figures(self) -> dict:
        if self._last is None:
            return {}
        T, u = self._last
        return {"projections": {self.name: {"method": self.method, "covered_fraction": T.covered_fraction,
                                            "uncovered_dofs": int(T.uncovered.size),
                                            "conservation_error": T.conservation_error(u)}}}


def _family(mesh, kind: str, grid: str | None = None) -> str:
    """The Lagrange family of a point (degree 1) or cell (degree 0) field on `mesh`; on a grid
    `grid` when given (the fluid's cells)."""
    if isinstance(mesh, StructuredGrid):
        return grid or ("Q1" if kind == "point" else "Q0")
    return ("P" if mesh.is_simplex else "Q") + ("1" if kind == "point" else "0")


#: operator name (as plans write it) -> class, built as ``cls(context, exchange)``
OPERATORS = {"pressure_trace": PressureTrace, "open_pressure_trace": OpenPressureTrace,
             "viscous_traction": ViscousTraction,
             "solid_fraction": SolidFraction, "solid_velocity": SolidVelocity,
             "l2": lambda ctx, exchange: Projection(ctx, exchange, "l2"),
             "pseudo_l2": lambda ctx, exchange: Projection(ctx, exchange, "pseudo_l2")}
