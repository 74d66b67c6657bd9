"""``varcouple run`` on a coupled scene: the participants of the plan as processes,
the transfer operators built once, the time loop of paper 2.3, the results.

Per time step with flow (Steps 1-6): the fluid advances with the solid's
velocity and volume fraction on its grid; its pressure is carried to the solid
(T_s<-f) and loads the solid's wetted boundary (``[coupling] interface``); the
solid advances; its velocity is projected back to the grid (T_f<-s). Steps 2-3
use the solid's ``interface_triangles`` (its wetted boundary, from ``geometry``):
the grid's Q0 pressure is traced on that surface moved half a fluid cell
diagonal into the fluid along its vertex normals (:class:`WettedInterface`), so
the pressure is read in fluid cells, not in the penalized ones inside the solid;
the solid gets it at those vertices and zero elsewhere. A solid that gives no
triangles (the ``spring_solid`` stand-in) gets the fallback, the volume
projection onto all its vertices (:class:`VolumeInterface`). The interface value
of the fixed point is that pressure, accelerated as the scene says. Two-way
coupling (:class:`SolidOnGrid`): in every coupling iteration the solid fraction on
the grid, the velocity transfer and the sampling surface are rebuilt from the
deformed solid (points + displacement), so the fluid sees the aperture the pressure
made (``[coupling] deformation = false``: the undeformed solid throughout); the
rebuild is skipped while the displacement is zero or unchanged, and timed as the
phase ``geometry update``. A scene without
flow advances the solid once per step: no fluid process is ever started.

Written to the output directory: ``solid_NNNN.vtu`` (and ``fluid_NNNN.vtu``)
per output step with ``solid.pvd`` / ``fluid.pvd`` time series for ParaView,
``summary.json`` (plan, per-step iterations and residuals, wall time per phase;
rewritten after every step, so a failed run keeps what it did), ``residuals.png``
for coupled runs, and ``logs/`` with each participant's output.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import meshio
import numpy as np

from transfer import FunctionSpace, Mesh, NoOverlapError, StructuredGrid, Transfer

from .acceleration import make_accelerator
from .coupled_scene import CoupledScene
from .errors import CouplerError
from .launch import Launcher
from .loop import run_coupled
from .messaging import CouplerSession, new_run_id
from .plan import Plan, make_plan
from .progress import ProgressBar
from .protocol import Field

SUMMARY = "summary.json"


class Phases:
    """Wall time per phase (solver, transfer, messaging, output)."""

    def __init__(self):
        self.seconds: dict[str, float] = {}

    def add(self, phase: str, seconds: float) -> None:
        self.seconds[phase] = self.seconds.get(phase, 0.0) + seconds

    def timed(self, phase: str, fn, *args, **kwargs):
        start = time.perf_counter()
        try:
            return fn(*args, **kwargs)
        finally:
            self.add(phase, time.perf_counter() - start)


def participant_config(scene: CoupledScene, name: str) -> dict:
    """The part of the scene participant `name` needs (JSON)."""
    if name == "solid":
        solver = scene.solvers["solid"]
        geometry = {"mesh": str(scene.solid.mesh.resolve())} if scene.solid.mesh else {"box": scene.solid.box}
        loads = [{"type": "pressure" if load.type == "fluid_pressure" else load.type,
                  "boundary": load.boundary, "value": load.value, "components": load.components}
                 for load in scene.loads]
        config = {**geometry, "boundaries": scene.solid.boundaries, "material": scene.material,
                  "loads": loads, "degree": solver["degree"], "linear_solver": solver["linear_solver"],
                  "rtol": solver["rtol"], "dynamic": "dynamics" in scene.effects,
                  "fluid_density": (scene.fluid_material or {}).get("density", 0.0) if "flow" in scene.effects else 0.0,
                  "wetted": scene.coupling["interface"]}
        if solver["participant"] == "spring_solid":
            config["k"] = solver["stiffness"]
        return config
    solver = scene.solvers["fluid"]
    g = scene.fluid
    material = scene.fluid_material or {"density": 1000.0, "viscosity": 1e-3}
    config = {"grid": {"origin": g.origin, "spacing": g.spacing, "shape": g.shape}, "location": "cells",
              "material": material, "rho": material["density"], "mu": material["viscosity"]}
    if solver["participant"] == "replay_fluid":
        config.update(pressure=solver["pressure"], feedback=solver["feedback"])
    if solver["participant"] == "openfoam":
        flow = scene.flow or {}
        config.update({k: solver[k] for k in ("penalization", "penalization_exponent", "drag", "max_iterations",
                                              "tolerance")})
        if flow:
            config.update(inlet=flow["inlet"], outlet=flow["outlet"], walls=flow["walls"],
                          boundaries=dict(flow["faces"]))
    return config


def _mesh_of(name: str, header: dict, fields: dict):
    if "grid" in header:
        g = header["grid"]
        return StructuredGrid(g["origin"], g["spacing"], g["shape"], name=f"{name} grid")
    if header.get("cell_type") != "tetra":
        raise CouplerError(f"participant {name!r} gave cells of type {header.get('cell_type')!r}; "
                           f"the coupler needs a tetrahedral mesh or a structured grid")
    return Mesh(np.array(fields["points"].data), np.array(fields["cells"].data), "tetra", name=f"{name} mesh")


class Series:
    """VTU files per output step and a .pvd collection for ParaView."""

    def __init__(self, directory: Path, name: str, mesh):
        self.directory, self.name, self.mesh = directory, name, mesh
        self.entries: list[tuple[float, str]] = []

    def write(self, step: int, t: float, point_data=None, cell_data=None) -> Path:
        file = f"{self.name}_{step:04d}.vtu"
        cell_type = "hexahedron" if isinstance(self.mesh, StructuredGrid) else self.mesh.cell_type
        meshio.write(self.directory / file, meshio.Mesh(
            self.mesh.points, [(cell_type, self.mesh.cells)], point_data=point_data or {},
            cell_data={k: [v] for k, v in (cell_data or {}).items()}))
        self.entries.append((t, file))
        rows = "\n".join(f'    <DataSet timestep="{t:.9g}" file="{f}"/>' for t, f in self.entries)
        (self.directory / f"{self.name}.pvd").write_text(
            f'<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1">\n  <Collection>\n{rows}\n'
            f'  </Collection>\n</VTKFile>\n')
        return self.directory / file


class WettedInterface:
    """Steps 2-3 on the wetted boundary: the trace of the fluid's Q0 pressure on the solid's
    interface triangles, sampled on the fluid side.

    The interface vertices are moved along their outward normals (area-weighted means of
    the normals of the interface triangles around them) by half a fluid cell diagonal, so
    the surface lies in fluid cells and not in the penalized cells inside the solid; the
    volume -> surface transfer (pseudo-L2, :mod:`transfer.operators`) gives the pressure
    at its vertices. The interface vector of the fixed point is that pressure (one value
    per interface vertex); the solid gets it at those vertices and zero elsewhere.
    """

    method = "surface trace"

    def __init__(self, S, triangles: np.ndarray, G: StructuredGrid, where: str = "[geometry.fluid]",
                 points=None):
        triangles = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
        self.num_points = S.num_points
        self.vertices, local = np.unique(triangles, return_inverse=True)
        self.triangles = local.reshape(-1, 3)
        # the solid's points (the deformed ones, points + displacement, when given)
        points = np.asarray(S.points if points is None else points)[self.vertices]
        a, b, c = (points[self.triangles[:, i]] for i in range(3))
        area_normals = 0.5 * np.cross(b - a, c - a)  # outward (boundary_triangles orientation), |.| = area
        normals = np.zeros_like(points)
        for i in range(3):
            np.add.at(normals, self.triangles[:, i], area_normals)
        length = np.linalg.norm(normals, axis=1)
        if np.any(length <= 0):
            raise CouplerError(f"{where}: the interface has a vertex whose triangle normals cancel "
                               f"(a folded surface)")
        self.normals = normals / length[:, None]
        # half the cell's extent along the normal, scaled so that it is half the cell diagonal on
        # a cubic grid: 0.5 sqrt(3) |(n_i h_i)|; on anisotropic grids (thin cells across a fracture)
        # a vertical normal moves by 0.87 h_z, not by half the long diagonal
        h = np.asarray(G.spacing, float)
        self.offsets = 0.5 * np.sqrt(3.0) * np.linalg.norm(self.normals * h[None, :], axis=1)
        self.offset = float(self.offsets.max())
        moved = points + self.offsets[:, None] * self.normals
        # a vertex on a face of the grid's box (e.g. a fracture face meeting the inlet) stays on it
        # (a rough face's normal would tilt it out by a few micrometres): clamp the coordinates
        # that lie on the box's faces; any other vertex moved outside is an error below
        lo, hi = np.asarray(G.origin, float), np.asarray(G.origin, float) + h * np.asarray(G.shape)
        tol = 1e-9 * h
        ref = np.asarray(S.points)[self.vertices]  # undeformed: a face vertex stays on the face when it moves
        on_face = (np.abs(ref - lo) <= tol) | (np.abs(ref - hi) <= tol)
        # ... and so does an inside vertex moved out along an axis its normal is nearly tangent to
        on_face |= (points >= lo - tol) & (points <= hi + tol) & (np.abs(self.normals) < 0.5)
        moved = np.where(on_face, np.clip(moved, lo, hi), moved)
        self.surface = Mesh(moved, self.triangles, "triangle", name="interface")
        uncovered, first = len(self.vertices), ""
        try:
            self.transfer = Transfer.assemble(FunctionSpace(G, "Q0"), FunctionSpace(self.surface, "P1"),
                                              "pseudo_l2")
            uncovered = self.transfer.uncovered.size
            if uncovered:
                first = f"; first at {np.array2string(moved[self.transfer.uncovered[0]], precision=6)}"
        except NoOverlapError:
            pass
        if uncovered:
            raise CouplerError(f"{where}: the fluid grid does not cover the interface sampled "
                               f"up to {self.offset:.3g} m outside the solid ({uncovered} of {len(self.vertices)} "
                               f"vertices outside the grid{first}): extend the grid beyond the wetted boundary")
        self.weights = np.asarray(self.transfer.D.sum(axis=1)).ravel()  # lumped surface mass
        self.area = float(self.surface.cell_measures().sum())

    @property
    def size(self) -> int:
        return len(self.vertices)

    num_vertices = size

    @property
    def num_triangles(self) -> int:
        return len(self.triangles)

    def from_fluid(self, pressure) -> np.ndarray:
        """The fluid's cell pressure at the interface vertices."""
        return self.transfer.apply(pressure)

    def to_solid_vertices(self, x) -> np.ndarray:
        """The interface pressure at all solid vertices (zero off the interface)."""
        full = np.zeros(self.num_points)
        full[self.vertices] = x
        return full

    def describe(self) -> dict:
        return {"method": self.method, "vertices": int(self.size), "triangles": int(self.num_triangles),
                "offset": self.offset, "sampled_area": self.area,
                "pairs_intersected": int(self.transfer.stats["pairs_intersected"])}


class VolumeInterface:
    """The fallback of Steps 2-3 when the solid gives no interface triangles (stand-in solids
    such as ``spring_solid``): the volume projection Q0 (grid) -> P1 of the pressure onto
    every solid vertex, sampled inside the solid (where a penalized fluid sees no wall)."""

    method = "volume projection"

    def __init__(self, S, G: StructuredGrid, where: str = "[geometry.fluid]"):
        self.transfer = Transfer.assemble(FunctionSpace(G, "Q0"), FunctionSpace(S, "P1"), "pseudo_l2")
        if not np.all(self.transfer.covered):
            raise CouplerError(f"{where}: the fluid grid does not cover the solid "
                               f"({self.transfer.uncovered.size} solid vertices outside it)")
        self.weights = np.asarray(self.transfer.D.diagonal())  # lumped solid mass
        self.size = S.num_points

    def from_fluid(self, pressure) -> np.ndarray:
        return self.transfer.apply(pressure)

    def to_solid_vertices(self, x) -> np.ndarray:
        return np.asarray(x)

    def describe(self) -> dict:
        return {"method": self.method, "vertices": int(self.size),
                "pairs_intersected": int(self.transfer.stats["pairs_intersected"])}


class SolidOnGrid:
    """The solid as the fluid sees it, from the solid's current shape (two-way coupling).

    ``fraction``: the solid volume fraction per grid cell (the Q0 projection of the solid's
    indicator: exact intersection volumes / cell volume); ``to_fluid``: the P1 -> Q0 transfer
    of the solid velocity; ``interface``: the wetted surface (:class:`WettedInterface`) or the
    fallback (:class:`VolumeInterface`). :meth:`update` rebuilds all three from the deformed
    solid (points + displacement), so the flow sees the aperture the pressure made; it keeps
    the current operators when the displacement is zero (below 1e-12 of the grid spacing) or
    unchanged since the last build, and always with ``deform=False`` or the volume fallback.
    The interface vector keeps its size and vertex order (one value per interface vertex),
    so accelerators see the same unknowns; the residual norm uses the undeformed weights.
    """

    def __init__(self, S, G: StructuredGrid, triangles, where: str, deform: bool = True):
        self.S, self.G, self.where = S, G, where
        self.triangles = None if triangles is None or not len(triangles) else np.asarray(triangles)
        self.deform = bool(deform) and self.triangles is not None
        self.threshold = 1e-12 * float(np.min(G.spacing))
        self.builds, self.build_seconds, self.skipped = 0, 0.0, 0
        self.max_displacement = 0.0
        self._u = None
        self._build(None)
        self.reference_weights = self.interface.weights
        self.builds, self.build_seconds = 0, 0.0  # count the rebuilds only, not the initial build

    def _build(self, u) -> None:
        start = time.perf_counter()
        S = self.S
        if u is not None:
            try:
                S = Mesh(np.asarray(self.S.points) + u, self.S.cells, "tetra", name="deformed solid")
            except Exception as exc:  # an inverted tetrahedron: the coupling iteration ran away
                raise CouplerError(f"the deformed solid is not a valid mesh (largest displacement "
                                   f"{float(np.max(np.linalg.norm(u, axis=1))):.3g} m): {exc}; the coupling "
                                   f"iteration diverges: use [coupling] acceleration = 'iqn-ils' or 'aitken', "
                                   f"or a smaller relaxation") from exc
        to_fluid = Transfer.assemble(FunctionSpace(S, "P1"), FunctionSpace(self.G, "Q0"), "pseudo_l2")
        volumes = np.asarray(to_fluid.D.diagonal())
        self.outside = max(1.0 - float(volumes.sum()) / float(S.cell_measures().sum()), 0.0)
        if self.triangles is not None:
            interface = WettedInterface(self.S, self.triangles, self.G, self.where,
                                        points=None if u is None else S.points)
        else:
            if self.outside > 1e-9:
                raise CouplerError(f"{self.where}: the fluid grid does not cover the solid "
                                   f"({self.outside:.3g} of the solid's volume lies outside it)")
            interface = VolumeInterface(S, self.G, self.where)
        self.to_fluid, self.fraction, self.interface = to_fluid, volumes / self.G.cell_measures(), interface
        self.builds += 1
        self.build_seconds += time.perf_counter() - start

    def update(self, u) -> bool:
        """Rebuild from the displacement u (num_points, 3) if it changed; True if rebuilt."""
        if not self.deform or u is None:
            return False
        u = np.asarray(u, float).reshape(len(self.S.points), -1)
        size = float(np.max(np.abs(u))) if u.size else 0.0
        self.max_displacement = max(self.max_displacement, size)
        if size <= self.threshold:
            u = None
        if (u is None and self._u is None) or (u is not None and self._u is not None and np.array_equal(u, self._u)):
            self.skipped += 1
            return False
        self._build(u)
        self._u = None if u is None else u.copy()
        return True

    def describe(self) -> dict:
        return {"deformed": self.deform, "rebuilds": self.builds, "rebuild_seconds": self.build_seconds,
                "seconds_per_rebuild": self.build_seconds / self.builds if self.builds else None,
                "skipped": self.skipped, "solid_volume_outside_grid": self.outside,
                "fluid_cells_with_solid": int(np.count_nonzero(self.fraction > 0))}


def _as_arrays(fields: dict) -> dict:
    return {k: np.asarray(f.data if isinstance(f, Field) else f) for k, f in fields.items()}


def _write_summary(out: Path, summary: dict) -> None:
    tmp = out / (SUMMARY + ".tmp")
    tmp.write_text(json.dumps(summary, indent=2, default=float))
    tmp.replace(out / SUMMARY)


def run(scene: CoupledScene, log=print, progress: bool | None = None) -> dict:
    """Run the coupled `scene`; return its summary (also in ``summary.json``)."""
    plan = make_plan(scene)
    out = Path(scene.output_dir)
    out.mkdir(parents=True, exist_ok=True)
    for note in plan.notes:
        log(f"warning: {note}")
    run_id = new_run_id()
    phases = Phases()
    summary = {"case": str(scene.case_dir), "scene": str(scene.path), "run_id": run_id,
               **plan.as_dict(), "status": "running", "steps": [], "phases_seconds": phases.seconds}
    _write_summary(out, summary)
    start = time.perf_counter()
    try:
        with CouplerSession(run_id, mode=scene.messaging["mode"], connect=scene.messaging["connect"]) as session, \
                Launcher(run_id, out, session.endpoints) as launcher:
            result = _run(scene, plan, session, launcher, out, phases, summary, log, progress)
        summary.update(result, status="completed")
    except BaseException as exc:
        summary["status"] = "interrupted" if isinstance(exc, KeyboardInterrupt) else "failed"
        summary["error"] = f"{type(exc).__name__}: {exc}"
        raise
    finally:
        summary["wall_seconds"] = time.perf_counter() - start
        _write_summary(out, summary)
    return summary


def _run(scene, plan: Plan, session, launcher, out, phases, summary, log, progress) -> dict:
    timeout = scene.messaging["timeout"]
    clients = {}
    for p in plan.participants:
        extra = ["--kind", p.kind] if p.module == "coupler.standins" else []
        launcher.start(p.name, p.module, ranks=p.ranks, extra_args=extra)
        clients[p.name] = session.client(p.name, timeout=timeout,
                                         process_check=lambda name=p.name: launcher.check(name))
        log(f"started {p.name}: {p.kind} ({p.ranks} rank{'s' * (p.ranks > 1)}), log in {launcher.log_dir / p.name}.log")
    meshes, announced, geometry_fields = {}, {}, {}
    for name, client in clients.items():
        phases.timed("start", client.wait_alive, timeout)
        announced[name] = client.announce()
        phases.timed(f"{name} setup", client.configure, participant_config(scene, name))
        header, fields = phases.timed(f"{name} setup", client.geometry)
        meshes[name] = _mesh_of(name, header, fields)
        geometry_fields[name] = fields or {}
        log(f"{name}: {announced[name].get('kind')} on {meshes[name].num_cells} cells")
    summary["participants_announced"] = announced

    solid = clients["solid"]
    series = {name: Series(out, name, mesh) for name, mesh in meshes.items()}
    steps, dt = scene.time["steps"], scene.time["dt"]
    coupled = "fluid" in clients
    every = scene.output["every"]
    last = {}

    if coupled:
        fluid = clients["fluid"]
        S, G = meshes["solid"], meshes["fluid"]
        start = time.perf_counter()
        triangles = geometry_fields["solid"].get("interface_triangles")
        triangles = None if triangles is None else np.asarray(triangles.data)
        on_grid = SolidOnGrid(S, G, triangles, f"{scene.path}: [geometry.fluid]",
                              deform=scene.coupling["deformation"])
        interface = on_grid.interface
        summary["interface"] = interface.describe()
        if isinstance(interface, WettedInterface):
            log(f"interface {scene.coupling['interface']}: {interface.num_vertices} vertices, "
                f"{interface.num_triangles} triangles, pressure sampled up to {interface.offset:.3g} m into the fluid")
            if on_grid.outside > 1e-9:
                log(f"the fluid grid covers the wetted interface; {on_grid.outside:.3g} of the solid's volume "
                    f"lies outside it")
        else:
            # Fallback (stand-in solids such as spring_solid, which have no boundary): the volume
            # projection of the grid's pressure onto every solid vertex (the solid applies it on
            # its wetted boundary only, if it has one).
            log(f"interface: no boundary triangles from the solid; pressure projected onto all "
                f"{S.num_points} solid vertices (volume projection)")
        phases.add("transfer", time.perf_counter() - start)
        summary["geometry_update"] = on_grid.describe()
        weights = on_grid.reference_weights  # lumped interface mass (undeformed): the M-norm of the residual
        log(f"transfers: {on_grid.to_fluid.stats['pairs_intersected']} cell pairs; solid fills "
            f"{np.count_nonzero(on_grid.fraction > 0)} fluid cells"
            f"{'; rebuilt from the deformed solid every iteration' if on_grid.deform else ''}")

        def iterate(window, iteration, x):
            pressure = on_grid.interface.to_solid_vertices(x)
            solid_out = _as_arrays(phases.timed("solid", solid.advance, window.index, iteration, window.t_start,
                                                window.dt, {"pressure": Field("pressure", pressure, "Pa")}))
            # two-way: the fluid sees the deformed solid (fractions, velocity transfer, sampling surface)
            phases.timed("geometry update", on_grid.update, solid_out.get("displacement"))
            velocity = phases.timed("transfer", on_grid.to_fluid.apply, solid_out["velocity"], fill=0.0)
            fluid_in = {"solid_velocity": Field("solid_velocity", velocity, "m/s"),
                        "solid_fraction": Field("solid_fraction", on_grid.fraction, "1")}
            fluid_out = _as_arrays(phases.timed("fluid", fluid.advance, window.index, iteration, window.t_start,
                                                window.dt, fluid_in))
            last.update(solid=solid_out, fluid=fluid_out, fluid_in=velocity, fraction=on_grid.fraction)
            return phases.timed("transfer", on_grid.interface.from_fluid, fluid_out["pressure"])

        class Checkpoint:
            def save(self, window):
                for c in clients.values():
                    phases.timed("checkpoint", c.save_state, window.index)

            def restore(self, window):
                for c in clients.values():
                    phases.timed("checkpoint", c.restore_state, window.index)

        x0 = np.zeros(interface.size)
        c = scene.coupling
        accelerator = make_accelerator(c["acceleration"], relaxation=c["relaxation"], reuse=c["reuse"])
        mode, checkpoint = "implicit", Checkpoint()
    else:
        weights, x0, accelerator, mode, checkpoint = None, np.zeros(0), None, "explicit", None

        def iterate(window, iteration, x):
            last["solid"] = _as_arrays(phases.timed("solid", solid.advance, window.index, iteration,
                                                    window.t_start, window.dt, {}))
            return x

    def on_converged(window, x):
        record = {"step": window.index, "t": window.t_end}
        if window.index % every == 0 or window.index == steps - 1:
            start = time.perf_counter()
            solid_fields = dict(last["solid"])
            if coupled:
                solid_fields["pressure"] = interface.to_solid_vertices(x)
                fluid_fields = {"pressure": last["fluid"]["pressure"], "solid_fraction": last["fraction"],
                                "solid_velocity": last["fluid_in"]}
                if "velocity" in last["fluid"]:
                    fluid_fields["velocity"] = last["fluid"]["velocity"]
                series["fluid"].write(window.index, window.t_end, cell_data=fluid_fields)
            series["solid"].write(window.index, window.t_end, point_data=solid_fields)
            phases.add("output", time.perf_counter() - start)
        u = last["solid"].get("displacement")
        if u is not None:
            record["max_displacement"] = float(np.max(np.linalg.norm(u, axis=1)))
        summary["steps"].append(record)
        if coupled:
            summary["geometry_update"] = on_grid.describe()
        _write_summary(out, summary)

    bar = ProgressBar(steps, label=scene.case_dir.name, enabled=progress)
    try:
        result = run_coupled(steps, dt, iterate, x0, accelerator, tolerance=scene.coupling["tolerance"],
                             max_iterations=scene.coupling["max_iterations"], checkpoint=checkpoint,
                             on_converged=on_converged, progress=bar, weights=weights, coupling=mode)
    finally:
        bar.close()
    for record, step in zip(summary["steps"], result.steps):
        record.update(iterations=step.iterations, residuals=list(step.residuals), converged=step.converged)
    for name, client in clients.items():
        client.finish()
        launcher.wait(name, timeout=30)
        stats = client.stats
        phases.add("messaging", max(stats["seconds"] - stats["remote_seconds"], 0.0))
    if coupled:
        summary["geometry_update"] = on_grid.describe()
        _residual_plot(out / "residuals.png", result)
    log(f"{steps} step{'s' * (steps > 1)} done; results in {out}")
    done = {"iterations": result.iterations, "converged": result.converged}
    if scene.check:
        done["check"] = check_displacement(scene.check, meshes["solid"].points, last["solid"]["displacement"])
        c = done["check"]
        log(f"check: displacement error {c['error']:.3e} relative on {c['vertices']} vertices "
            f"(tolerance {c['tolerance']:g}): {'PASS' if c['passed'] else 'FAIL'}")
    return done


def check_displacement(check: dict, points: np.ndarray, u: np.ndarray) -> dict:
    """Compare the displacement with the scene's expected one ([check]): the largest
    error over the selected vertices relative to the largest expected value."""
    from .scene import evaluate_expression

    selected = np.ones(len(points), bool)
    if "where" in check:
        selected = evaluate_expression(check["where"], points) > 0.5
    if not selected.any():
        raise CouplerError(f"[check] where: {check['where']!r} selects no vertex of the solid")
    error = scale = 0.0
    for axis, c in enumerate("xyz"):
        if c in check:
            exact = evaluate_expression(check[c], points[selected])
            error = max(error, float(np.max(np.abs(u[selected, axis] - exact))))
            scale = max(scale, float(np.max(np.abs(exact))))
    relative = error / scale if scale > 0 else error
    return {"error": relative, "absolute_error": error, "tolerance": check["tolerance"],
            "passed": bool(relative <= check["tolerance"]), "vertices": int(selected.sum())}


def _residual_plot(path: Path, result) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    for step in result.steps:
        ax.semilogy(range(1, len(step.residuals) + 1), step.residuals, marker="o", ms=3,
                    label=f"step {step.window}" if len(result.steps) <= 10 else None)
    ax.axhline(result.tolerance, color="k", ls="--", lw=0.8, label="tolerance")
    ax.set_xlabel("coupling iteration")
    ax.set_ylabel("relative interface residual (mass-weighted L2)")
    ax.set_title(f"fixed-point residuals ({result.accelerator.get('name', '')})")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
