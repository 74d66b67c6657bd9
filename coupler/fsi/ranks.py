"""The exchanges of a flow scene on a coupler of P ranks (docs/scaling.md, step 3): every rank
holds a slab of the fluid grid (:class:`GridSlab`: every rank knows the grid by origin, spacing
and shape) and works on the solid cells over it (:class:`SolidPart`: each cell, with the wetted
triangles it bounds, sent to the rank whose slab holds its centroid, :func:`on_slabs`; the rows
of the solid stay with the ranks that talk to its parts), and the operators are the
distributed ones of :func:`transfer.distributed.assemble`, rebuilt from the deformed solid
(:class:`SolidOnSlabs`): the pressure trace on the wetted interface (paper 2.3, Steps 2-3; on
the open faces of a fracture in contact; onto every solid vertex for a solid without boundary
triangles, :class:`VolumeSlabs`; none for a fixed solid the fluid does not load) or the traction
with its viscous part (``traction = "full"``, :class:`ViscousTractionRanks`: the deeper sampling
surfaces traced from the slabs too), the solid fraction (exact, or at the cell centres:
:func:`slab_centres`) and the solid velocity on the grid (Step 6, before Step 1); the projections
between two participants' meshes (``l2``, ``pseudo_l2``:
:class:`coupler.fsi.projection.ProjectionRanks`); the pressure difference of a flow rate
(:class:`FlowRateControlRanks`); and the fracture's figures per step (:class:`FractureFiguresRanks`).

The interface vector of the fixed point (one pressure, or three traction values, per interface
vertex, numbered as the serial run numbers them: by increasing solid vertex id) is split by rows
over the ranks (:class:`transfer.rows.Rows`' blocks): each rank gives the accelerator and the
loop its own rows and their weights (docs/scaling.md, step 4), nothing is gathered. The flow-rate
control's one unknown, dp, is rank 0's row; every rank knows it once delivered."""

from __future__ import annotations

import time

import numpy as np
from mpi4py import MPI

from coupler.errors import CouplerError
from coupler.protocol.slabs import slab_bounds
from transfer import Mesh, NoOverlapError, StructuredGrid
from transfer.distributed import Part, assemble
from transfer.mesh import TET_FACES
from transfer.rows import Rows, to_ranks

from . import fracture
from .centres import centre_cells
from .fracture import FractureFigures
from .context import described, loaded
from .held import Held
from .projection import ProjectionRanks
from .rate_control import FlowRateControl
from .interface import (SolidOnGrid, VolumeInterface, WettedInterface, area_normals, check_covered, folded_surface,
                        invalid_deformation, sampling_points)
from .open_gap import open_share
from .operators import OpenShare, SolidFraction, ViscousTraction, sampled_at_centres


class GridSlab:
    """This coupler rank's slab of the grid `G` along its longest axis: ``part`` (Q0 cells, global
    ids ``ids``); :meth:`rank_of` the rank whose slab holds a coordinate along the axis."""

    def __init__(self, comm, G: StructuredGrid, where: str):
        try:
            d, bounds = slab_bounds(G.shape, comm.size, "longest")
        except ValueError as exc:
            raise CouplerError(f"{where}: {comm.size} coupler ranks: {exc}") from None
        lower, upper = [0, 0, 0], list(G.shape)
        lower[d], upper[d] = bounds[comm.rank], bounds[comm.rank + 1]
        self.G, self.part = G, Part.grid_block(G, lower, upper, "Q0")
        self.block = (lower, upper)  # the cells lower <= (i, j, k) < upper
        self.ids = self.part.global_dofs
        self.cell_volume = float(np.prod(G.spacing))
        #: the slab axis and where along it the slabs meet (slab r between cuts r - 1 and r)
        self.axis, self.cuts = d, G.origin[d] + G.spacing[d] * np.asarray(bounds[1:-1], float)

    def rank_of(self, x) -> np.ndarray:
        """The rank whose slab holds each coordinate `x` along the slab axis (before the grid's
        start the first, beyond its end the last)."""
        return np.searchsorted(self.cuts, x, side="right")


def slab_centres(comm, S: Mesh, slab: GridSlab) -> np.ndarray:
    """Per cell of this rank's `slab`: whether its centre lies in a tetrahedron of `S` on any
    rank (each rank its own tetrahedra, wherever they lie): every rank finds the cells its
    tetrahedra hold a centre of (:func:`coupler.fsi.centres.centre_cells`) and the slab's owner
    of each gets their OR (a sum over the ranks through :class:`transfer.rows.Rows`); nothing
    gathered. Collective."""
    found = centre_cells(S, slab.G)
    return Rows(comm, slab.G.num_cells).move(found, np.ones(len(found)), slab.ids, add=True) > 0


def bounded(cells: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """The index of the tetrahedron of `cells` (n, 4) that each of `triangles` (m, 3) is a face
    of, -1 where none is (global vertex ids both)."""
    near = np.flatnonzero(np.count_nonzero(np.isin(cells, triangles), axis=1) >= 3)
    faces = np.sort(cells[near][:, TET_FACES].reshape(-1, 3), axis=1)
    _, key = np.unique(np.concatenate([faces, np.sort(triangles, axis=1)]), axis=0, return_inverse=True)
    face = np.full(len(faces) + len(triangles), -1)
    face[key[:len(faces)]] = np.arange(len(faces))
    found = face[key[len(faces):]]
    parent = np.full(len(triangles), -1)
    parent[found >= 0] = near[found[found >= 0] // 4]
    return parent


def on_slabs(comm, held: Held, geometry: list[dict], triangles: np.ndarray, slab: GridSlab):
    """(cells, triangles): the solid cells (global vertex ids) whose centroid along the slab axis
    lies in this rank's `slab` (before or beyond the grid: the first or last slab) and the wetted
    `triangles` that bound them, from the parts held here (`geometry`; each triangle a face of one
    of their cells) on every rank, in one alltoallv; nothing gathered. Collective."""
    cells = held.part_cells(geometry)
    vertices, local = np.unique(cells, return_inverse=True)
    x = held.coordinates(geometry, vertices, axis=slab.axis)
    rank = slab.rank_of(x[local.reshape(cells.shape)].mean(axis=1))
    parent = bounded(cells, triangles) if len(triangles) else np.zeros(0, np.int64)
    if comm.allreduce(int(np.count_nonzero(parent < 0))):
        raise CouplerError(f"participant {held.name!r}: a wetted triangle of its parts is a face of none of their "
                           f"cells: the coupler's ranks cannot place it with its cell")
    return to_ranks(comm, [cells, triangles], [rank, rank[parent]])


class SolidPart:
    """The solid cells this coupler rank works on, with the coordinates of every vertex they use
    (owned here or fetched from the rank holding it): ``vertices`` (global ids), ``reference``
    (their coordinates), ``cells`` (local), the wetted ``triangles`` of these cells (global ids)
    and the numbering of the interface vertices. The cells of this rank's solid parts
    (``geometry`` of each), or with a `slab` those over it from every rank's parts
    (:func:`on_slabs`), which ``held`` then works on (:meth:`coupler.fsi.held.Held.place`)."""

    def __init__(self, comm, held: Held, geometry: list[dict], slab: GridSlab | None = None):
        self.comm, self.held = comm, held
        triangles = [np.asarray(g["interface_triangles"], np.int64).reshape(-1, 3)
                     for g in geometry if "interface_triangles" in g]
        self.triangles = np.concatenate(triangles) if triangles else np.zeros((0, 3), np.int64)
        if slab is not None:
            cells, self.triangles = on_slabs(comm, held, geometry, self.triangles, slab)
            held.place(cells)
        self.vertices, self.mesh = held.mesh(geometry)
        self.reference, self.cells = self.mesh.points, self.mesh.cells
        self.wetted = comm.allreduce(len(self.triangles)) > 0
        self._interface_numbering()

    def _interface_numbering(self) -> None:
        """``interface_ids`` (the interface index of each of this rank's triangle vertices
        ``interface_vertices``), ``interface_count``, and ``input_interface`` (the interface index of
        each input row of the solid parts, -1 off the interface): the serial order, nothing gathered."""
        rows = self.held.rows
        self.interface_vertices = np.unique(self.triangles)
        index, self.interface_count = rows.numbering(self.interface_vertices)
        self.interface_ids = rows.move(rows.own, index, self.interface_vertices).astype(np.int64)
        self.input_interface = rows.move(rows.own, index, self.held.in_ids).astype(np.int64)

    def part(self, points=None) -> Part:
        """The P1 transfer part of these cells, at `points` (the deformed vertices) or undeformed."""
        mesh = self.mesh if points is None or not len(self.vertices) else Mesh(points, self.cells, "tetra",
                                                                                name="deformed solid part")
        return Part(mesh, "P1", self.vertices)


class WettedSlabs:
    """:class:`coupler.fsi.interface.WettedInterface` on several ranks: this rank's wetted
    triangles moved into the fluid by `depth` (normals summed over every rank's triangles), the
    pressure traced from the grid slabs (distributed pseudo-L2; with `partial`, vertices outside
    the grid read NaN); the interface vector and its weights (the lumped surface mass), the wall
    (``points``), its unit ``normals`` and the sampling ``offsets`` at this rank's rows ``block`` of
    the interface numbering."""

    method = "surface trace"

    def __init__(self, comm, solid: SolidPart, slab: GridSlab, where: str, points=None, depth: float = 1.0,
                 partial: bool = False):
        self.comm, self.solid = comm, solid
        self.rows = Rows(comm, solid.interface_count)
        self.block = self.rows.own
        self._inputs = np.maximum(solid.input_interface, 0)
        ids, vertices = solid.interface_ids, solid.interface_vertices
        at = np.searchsorted(solid.vertices, vertices)
        here = (solid.reference if points is None else points)[at]
        self.triangles = triangles = np.searchsorted(vertices, solid.triangles)
        self.reference = solid.reference[at]
        normals = self.rows.move(ids[triangles].ravel(), np.repeat(area_normals(here, triangles), 3, axis=0), ids,
                                 add=True)
        length = np.linalg.norm(normals.reshape(-1, 3), axis=1)
        if comm.allreduce(bool(np.any(length <= 0)), op=MPI.LOR):
            raise folded_surface(where)
        normals = normals.reshape(-1, 3) / length[:, None]
        moved, offsets = sampling_points(here, normals, solid.reference[at], slab.G, depth)
        self.offset = comm.allreduce(float(offsets.max()) if len(offsets) else 0.0, op=MPI.MAX)
        surface = (Mesh(moved, triangles, "triangle", name="interface") if len(triangles)
                   else Mesh.empty("triangle", "interface"))
        uncovered = solid.interface_count
        try:
            self.transfer = assemble(slab.part, Part(surface, "P1", ids), "pseudo_l2", comm)
            uncovered -= self.transfer.num_covered
        except NoOverlapError:  # on every rank
            pass
        check_covered(where, self.offset, uncovered, solid.interface_count, partial)
        self.points, self.normals, self.offsets = (self.at_block(a) for a in (here, normals, offsets))
        self.weights = self.transfer.row_sums()  # the lumped surface mass at `block`
        self.area = comm.allreduce(float(surface.cell_measures().sum()) if len(triangles) else 0.0)
        self.size = solid.interface_count
        self.num_triangles = comm.allreduce(len(triangles))

    def from_fluid(self, values) -> np.ndarray:
        """The trace at `block` of the cell values (n,) or (n, k) at this rank's slab (the pressure: the
        interface vector). Collective."""
        return self.at_block(self.transfer.apply(values))

    def from_solid(self, held: Held, name: str) -> np.ndarray:
        """The solid's latest output `name` (`held`) at `block`. Collective."""
        return self.at_block(held.fetch(name, self.solid.interface_vertices))

    def at_block(self, values) -> np.ndarray:
        """`values` (n,) or (n, k) at this rank's interface vertices at `block`. Collective."""
        ids = self.solid.interface_ids
        return self.rows.block(ids, values) if np.ndim(values) == 1 else self.rows.move(ids, values, self.block)

    def to_solid_parts(self, x) -> list[np.ndarray]:
        """The interface pressure or traction `x` ((n,) or (n, 3) at `block`, on every rank) at the input
        rows of each solid part held here (zero off the interface). Collective."""
        values = self.rows.move(self.block, x, self._inputs)
        values[self.solid.input_interface < 0] = 0.0
        held = self.solid.held
        return np.split(values, np.cumsum([len(i) for i in held.input_rows])[:-1]) if held.ranks else []

    def open_share(self, held: Held) -> np.ndarray:
        """The open share of the interface vertices (:func:`coupler.fsi.open_gap.open_share`) at
        `block`, from the solid's latest outputs `held`. Collective."""
        v, ids = self.solid.interface_vertices, self.solid.interface_ids
        share = open_share(self.reference, self.triangles, lambda name: held.fetch(name, v), self.rows, ids)
        return self.rows.block(ids, share)

    describe = WettedInterface.describe


class VolumeSlabs:
    """:class:`coupler.fsi.interface.VolumeInterface` on several ranks (a solid without boundary
    triangles): the pressure of the grid slabs projected onto every vertex of the solid cells held
    here (distributed pseudo-L2, Q0 -> P1); the interface vector is every solid vertex in its row
    order, this rank's rows ``block`` of the solid's rows, its weights the lumped solid mass there."""

    method = VolumeInterface.method

    def __init__(self, comm, solid: SolidPart, slab: GridSlab, where: str):
        self.solid, self.rows = solid, solid.held.rows
        self.block = self.rows.own
        self.size = solid.held.count
        self.transfer = assemble(slab.part, solid.part(), "pseudo_l2", comm)
        uncovered = self.size - self.transfer.num_covered
        if uncovered:
            raise CouplerError(f"{where}: the fluid grid does not cover the solid ({uncovered} solid vertices "
                               f"outside it)")
        self.weights = self.transfer.row_sums()  # D is diagonal: its row sums are VolumeInterface's weights

    def from_fluid(self, pressure) -> np.ndarray:
        """The interface vector at `block` from the cell pressure at this rank's slab. Collective."""
        return self.rows.block(self.solid.vertices, self.transfer.apply(pressure))

    def to_solid_parts(self, x) -> list[np.ndarray]:
        """The pressure `x` (at `block`) at the input rows of each solid part held here. Collective."""
        return self.solid.held.inputs(self.block, x)

    describe = VolumeInterface.describe


class SolidOnSlabs(SolidOnGrid):
    """:class:`coupler.fsi.interface.SolidOnGrid` on several ranks: ``fraction`` and ``to_fluid`` on
    this rank's slab, ``interface`` (:class:`WettedSlabs`, or :class:`VolumeSlabs` when no rank has a
    boundary triangle) and with ``traction="full"`` the ``deeper`` sampling surfaces (:class:`WettedSlabs`,
    partial; None where one leaves the grid on every rank), rebuilt from the deformed solid by the same
    rules (:meth:`update`, its reductions over the ranks)."""

    def __init__(self, comm, solid: SolidPart, slab: GridSlab, where: str, deform: bool = True,
                 traction: str = "pressure", wetted: bool = True):
        self.comm, self.solid, self.slab, self.where = comm, solid, slab, where
        self.wetted = wetted
        self._set_traction(traction, solid.wetted)
        self.deform = bool(deform) and solid.wetted
        self.num_vertices = len(solid.vertices)
        self._first_build(slab.G)

    def _build(self, u) -> None:
        start = time.perf_counter()
        comm, solid = self.comm, self.solid
        points = None if u is None else solid.reference + u
        try:
            part = solid.part(points)
            failed = ""
        except Exception as exc:  # noqa: BLE001 - an inverted tetrahedron, on some rank
            part, failed = None, str(exc)
        failed = next((f for f in comm.allgather(failed) if f), "")
        if failed:
            raise invalid_deformation(self.max_displacement, failed)
        self.to_fluid = None  # the previous shape's operator goes before the new one is made (peak memory)
        to_fluid = assemble(part, self.slab.part, "pseudo_l2", comm)
        self.received = to_fluid.stats["exchange"]  # the solid cells its assembly brought from other ranks
        volumes = to_fluid.diagonal()
        measure = float(part.mesh.cell_measures().sum()) if part.num_cells else 0.0
        inside, total = comm.allreduce(np.array([volumes.sum(), measure]))
        self.outside = max(1.0 - float(inside) / float(total), 0.0)
        self.to_fluid, self.fraction = to_fluid, volumes / self.slab.cell_volume
        self.current, self._centres = part.mesh, None
        self.interface = None  # a solid the fluid does not load has none
        if self.wetted and solid.wetted:
            self.interface = self._wetted(points)
        elif self.wetted:
            self._check_inside()
            self.interface = VolumeSlabs(comm, solid, self.slab, self.where)
        self.builds += 1
        self.build_seconds += time.perf_counter() - start

    def _centres_inside(self) -> np.ndarray:
        return slab_centres(self.comm, self.current, self.slab)

    def _surface(self, points, depth: float = 1.0, partial: bool = False) -> WettedSlabs:
        return WettedSlabs(self.comm, self.solid, self.slab, self.where, points, depth, partial)

    def cell_centres(self) -> np.ndarray:
        return self.slab.part.mesh.cell_centers()

    def _largest(self, u: np.ndarray) -> float:
        return self.comm.allreduce(super()._largest(u), op=MPI.MAX)

    def _equal(self, u: np.ndarray, v: np.ndarray) -> bool:
        return self.comm.allreduce(super()._equal(u, v), op=MPI.LAND)

    def _cells_with_solid(self) -> int:
        return self.comm.allreduce(int(np.count_nonzero(self.fraction > 0)))


class RanksContext:
    """What the operators of a coupler rank are built from: :class:`coupler.fsi.context.OperatorContext`'s
    scene, meshes (the grid whole; the solid's whole mesh is never built), phases and log, and
    `comm`, each participant's :class:`Held` share and the geometry of each part held here."""

    def __init__(self, context, comm, held: dict[str, Held], parts: dict[str, list[dict]]):
        self.context, self.comm, self.held, self.parts = context, comm, held, parts
        self.scene, self.phases, self.log, self.warn = context.scene, context.phases, context.log, context.warn

    def shared(self, key: str, build):
        return self.context.shared(key, lambda _: build(self))

    @property
    def window(self):
        """The time window of the coupling iteration under way (the runner sets the context's)."""
        return self.context.window

    def warn(self, texts) -> None:
        self.context.warn(texts)

    def summary(self) -> dict:
        return self.context.summary()


class FluidSolidRanks:
    """:class:`coupler.fsi.context.FluidSolid` on several ranks: the solid cells over this rank's
    grid slab (their vertices' rows fetched from the ranks that hold them), updated from the solid's
    latest displacement whenever an operator asks."""

    def __init__(self, ctx: RanksContext):
        scene, comm = ctx.scene, ctx.comm
        start = time.perf_counter()
        where = f"{scene.path}: [geometry.fluid]"
        self.ctx, self.solid_held, self.fluid_held = ctx, ctx.held["solid"], ctx.held["fluid"]
        self.slab = GridSlab(comm, ctx.context.meshes["fluid"], where)
        self.solid = SolidPart(comm, self.solid_held, ctx.parts["solid"], self.slab)
        self.on_grid = SolidOnSlabs(comm, self.solid, self.slab, where, deform=scene.coupling["deformation"],
                                    wetted=loaded(scene), traction=scene.coupling["traction"])
        ctx.phases.add("transfer", time.perf_counter() - start)
        interface = self.on_grid.interface
        self.interface = described(interface, scene)
        ranks = (f"{comm.size} coupler ranks: this rank {len(self.slab.ids)} grid cells, {self.solid.mesh.num_cells} "
                 f"solid cells")
        if interface is None:
            ctx.log(f"the fluid does not load the solid: its fraction only ({ranks})")
        elif self.solid.wetted:
            ctx.log(f"interface {scene.coupling['interface']}: {interface.size} vertices, {interface.num_triangles} "
                    f"triangles, pressure sampled up to {interface.offset:.3g} m into the fluid ({ranks})")
        else:
            ctx.log(f"interface: no boundary triangles from the solid; pressure projected onto all {interface.size} "
                    f"solid vertices (volume projection; {ranks})")
        self._seen = None

    def update(self, outputs=None) -> SolidOnSlabs:
        """The solid on the slabs as the solid's latest displacement (held here, not `outputs`)
        deforms it, once per new output. Collective."""
        u = self.solid_held.fields.get("displacement")
        if u is not None and u is self._seen:
            return self.on_grid
        self._seen = u
        local = None if u is None else self.solid_held.fetch("displacement", self.solid.vertices)
        self.ctx.phases.timed("geometry update", self.on_grid.update, local)
        return self.on_grid

    def holdings(self) -> list[dict]:
        """What each coupler rank holds (summary.json ``coupler_ranks``), and the solid cells and
        bytes the latest build of the solid-to-grid transfer received from the other ranks
        (:func:`transfer.distributed.gather_source`: those whose boxes meet its slab's). Collective."""
        interface, received = self.on_grid.interface, self.on_grid.received
        return self.ctx.comm.allgather({
            "grid_cells": len(self.slab.ids), "solid_cells": self.solid.mesh.num_cells,
            "solid_vertices": len(self.solid.vertices), "solid_rows": len(self.solid_held.out_ids),
            "fluid_rows": len(self.fluid_held.out_ids), "interface_triangles": len(self.solid.triangles),
            "interface_rows": len(interface.block) if interface else 0,
            "solid_to_grid_received": {"cells": received.cells_received, "bytes": received.bytes_received}})

    def summary(self) -> dict:
        return {"interface": self.interface, "geometry_update": self.on_grid.describe(),
                "coupler_ranks": self.holdings()}


def fluid_solid_ranks(ctx: RanksContext) -> FluidSolidRanks:
    return ctx.shared("fluid_solid", FluidSolidRanks)


class PressureTraceRanks:
    """:class:`coupler.fsi.operators.PressureTrace` on several ranks: ``size`` and ``weights``
    are this rank's rows of the interface vector, delivered at the input rows of the solid parts
    held here."""

    units = "Pa"

    def __init__(self, ctx: RanksContext, exchange=None):
        self.fs = fluid_solid_ranks(ctx)
        self.weights = self.fs.on_grid.reference_weights
        self.size = len(self.weights)

    def evaluate(self, outputs=None) -> np.ndarray:
        return self.fs.on_grid.interface.from_fluid(self.fs.fluid_held.fetch("pressure", self.fs.slab.ids))

    def deliver(self, x) -> list[np.ndarray]:
        return self.fs.on_grid.interface.to_solid_parts(x)


class OpenPressureTraceRanks(OpenShare, PressureTraceRanks):
    """:class:`coupler.fsi.operators.OpenPressureTrace` on several ranks: the pressure on the open
    faces at this rank's rows of the interface vector."""

    def open_share(self, outputs=None) -> np.ndarray:
        return self.fs.on_grid.interface.open_share(self.fs.solid_held)


class ViscousTractionRanks(ViscousTraction):
    """:class:`coupler.fsi.operators.ViscousTraction` on several ranks: the traction (three values) at
    this rank's rows of the interface vector from the fluid at its grid slab and the solid's velocity
    fetched at those rows, delivered at the input rows of the solid parts held here; its figures
    reduced over the ranks."""

    _fluid_solid = staticmethod(fluid_solid_ranks)

    def fields(self, outputs=None) -> tuple:
        fs, cells = self.fs, self.fs.slab.ids
        return (fs.fluid_held.fetch("pressure", cells), fs.fluid_held.fetch("velocity", cells),
                fs.on_grid.interface.from_solid(fs.solid_held, "velocity"))

    def deliver(self, x) -> list[np.ndarray]:
        return self.fs.on_grid.interface.to_solid_parts(np.asarray(x).reshape(-1, 3))


class SolidFractionRanks(SolidFraction):
    """:class:`coupler.fsi.operators.SolidFraction` on this rank's slab (exact, or at the cell
    centres: :func:`slab_centres`), delivered at the input rows of the fluid parts held here."""

    def __init__(self, ctx: RanksContext, exchange=None):
        self.fs = fluid_solid_ranks(ctx)
        self.centres = sampled_at_centres(exchange)

    def deliver(self, value) -> list[np.ndarray]:
        return self.fs.fluid_held.inputs(self.fs.slab.ids, value)


class SolidVelocityRanks(SolidFractionRanks):
    """:class:`coupler.fsi.operators.SolidVelocity` on this rank's slab (pseudo-L2 from the
    deformed solid cells held here, zero where the solid does not reach)."""

    units = "m/s"

    def evaluate(self, outputs=None) -> np.ndarray:
        on_grid = self.fs.update()
        return on_grid.to_fluid.apply(self.fs.solid_held.fetch("velocity", self.fs.solid.vertices), fill=0.0)


class OnSlab:
    """What a figure summed over the grid's slabs reads on a coupler rank: the solid as this rank's
    slab sees it (``fs``), the whole grid (``grid``), the slab's cells (``block``) and ``comm``."""

    def hold(self, ctx: RanksContext) -> None:
        self.fs = fluid_solid_ranks(ctx)
        self.comm, self.grid, self.block = ctx.comm, self.fs.slab.G, self.fs.slab.block


class FlowRateControlRanks(OnSlab, FlowRateControl):
    """:class:`coupler.fsi.rate_control.FlowRateControl` on several ranks: dp's row of the
    interface vector and its weight on rank 0, none on the others; dp known on every rank once
    delivered, given whole to each fluid part held here; the flow rate and the percolation from
    this rank's slab of the grid (taken over the ranks)."""

    def local(self, outputs=None) -> tuple[np.ndarray, np.ndarray]:
        return self.fs.fluid_held.fetch("velocity", self.fs.slab.ids), self.fs.update().fraction

    def inlet(self, pressure: float) -> list[np.ndarray]:
        return [np.array([pressure]) for _ in self.fs.fluid_held.ranks]


class FractureFiguresRanks(OnSlab, FractureFigures):
    """:class:`coupler.fsi.fracture.FractureFigures` on several ranks: the rows of the solid held
    here, this rank's slab of the grid and its rows of the interface vector; the figures summed
    (and the open cells labelled) over the ranks."""

    rate_control = FlowRateControlRanks

    def local(self, outputs=None) -> dict:
        solid, fluid, cells = self.fs.solid_held, self.fs.fluid_held, self.fs.slab.ids
        slave = solid.fields["slave"] > 0.5
        interface = self.fs.update().interface
        return {"gap": solid.fields["gap"][slave], "in_contact": solid.fields["in_contact"][slave] > 0.5,
                "weights": solid.fields["mortar_weight"][slave], "fraction": self.fs.on_grid.fraction,
                "velocity": fluid.fetch("velocity", cells), "wet": interface.weights * interface.open_share(solid),
                "pressure": interface.from_fluid(fluid.fetch("pressure", cells))}


#: the operators a coupler on several ranks has (the others refuse P > 1: coupler.run.ranks)
OPERATORS_RANKS = {"pressure_trace": PressureTraceRanks, "open_pressure_trace": OpenPressureTraceRanks,
                   "viscous_traction": ViscousTractionRanks,
                   "solid_fraction": SolidFractionRanks, "solid_velocity": SolidVelocityRanks,
                   "flow_rate_control": lambda ctx, exchange: ctx.shared("flow_rate_control", FlowRateControlRanks),
                   "l2": lambda ctx, exchange: ProjectionRanks(ctx, exchange, "l2"),
                   "pseudo_l2": lambda ctx, exchange: ProjectionRanks(ctx, exchange, "pseudo_l2")}

#: the monitors a coupler on several ranks has (as :data:`coupler.fsi.monitors.MONITORS`)
MONITORS_RANKS = {"fracture": (FractureFiguresRanks, fracture.table)}
