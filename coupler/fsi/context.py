"""What the operators of a run are built from (:class:`OperatorContext`) and the solid as the
fluid grid sees it, shared by them (:class:`FluidSolid`)."""

from __future__ import annotations

import time

import numpy as np

from coupler.errors import CouplerError

from .interface import SolidOnGrid, WettedInterface


class OperatorContext:
    """What operators are built from: the scene, the participants' meshes and geometry fields,
    the phases timer and the log; :meth:`shared` builds an object once for all operators."""

    def __init__(self, scene, meshes: dict, geometry: dict, phases, log=print):
        self.scene, self.meshes, self.geometry, self.phases, self.log = scene, meshes, geometry, phases, log
        self._shared: dict = {}
        self.warnings: list[str] = []
        self.window = None  # the time window of the coupling iteration under way (set by the runner)

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
        wetted = loaded(scene)
        self.on_grid = SolidOnGrid(ctx.meshes["solid"], ctx.meshes["fluid"], triangles,
                                   f"{scene.path}: [geometry.fluid]", deform=scene.coupling["deformation"],
                                   traction=scene.coupling["traction"], wetted=wetted)
        ctx.phases.add("transfer", time.perf_counter() - start)
        interface, g = self.on_grid.interface, self.on_grid
        self.interface = described(interface, scene)  # as first built
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


def loaded(scene) -> bool:
    """Whether the fluid loads the solid (a ``[coupling] interface``; not a fixed solid)."""
    return scene.coupling["interface"] is not None


def described(interface, scene) -> dict:
    """summary.json's ``interface``: what `interface` tells of itself and the traction, or none
    for a solid the fluid does not load (`interface` None)."""
    if interface is None:
        return {"method": "none (the fluid does not load the solid)"}
    return {**interface.describe(), "traction": scene.coupling["traction"]}


def fluid_solid(ctx: OperatorContext) -> FluidSolid:
    return ctx.shared("fluid_solid", FluidSolid)
