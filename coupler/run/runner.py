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
of the fixed point is that pressure, accelerated as the scene says (``[coupling]
traction = "full"``: the traction (-p I + tau) n with the viscous wall shear, three
values per vertex, :mod:`coupler.viscous`). Two-way
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

import time
from pathlib import Path

import numpy as np

from transfer import Mesh, StructuredGrid

from coupler.coupling.acceleration import make_accelerator
from coupler.scene.coupled import CoupledScene
from coupler.errors import CouplerError, run_status
from coupler.run.launch import Launcher
from coupler.coupling.loop import run_coupled
from coupler.run.client import CouplerSession
from coupler.protocol.transport import new_run_id
from coupler.plan.plan import Plan, make_plan
from coupler.run.preflight import check_memory, estimate
from coupler.output.progress import ProgressBar
from coupler.fsi.interface import SolidOnGrid, WettedInterface
from coupler.fsi.viscous import FluidTraction, traction_figures
from coupler.protocol.wire import Field
from coupler.output.results import Series, check_displacement, residual_plot, write_summary
from coupler.run.solves import StepSolves


class Phases:
    """Wall time per phase (each solver, transfer, messaging, output): a call to a
    participant counts the participant's own time (the ``elapsed`` of its reply) in
    its phase and the rest of the round trip in ``messaging``."""

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

    def remote(self, phase: str, client, verb: str, *args):
        """``client.<verb>(*args)``, its time split into `phase` and ``messaging``."""
        before = client.stats["seconds"], client.stats["remote_seconds"]
        try:
            return getattr(client, verb)(*args)
        finally:
            total = client.stats["seconds"] - before[0]
            own = client.stats["remote_seconds"] - before[1]
            self.add(phase, own)
            self.add("messaging", max(total - own, 0.0))


def participant_config(scene: CoupledScene, name: str) -> dict:
    """The part of the scene participant `name` needs (JSON)."""
    if name == "solid":
        solver = scene.solvers["solid"]
        geometry = {"mesh": str(scene.solid.mesh.resolve())} if scene.solid.mesh else {"box": scene.solid.box}
        loads = [{"type": "pressure" if load.type == "fluid_pressure" else load.type, "key": f"[loads.{i}]",
                  "boundary": load.boundary, "value": load.value, "components": load.components}
                 for i, load in enumerate(scene.loads, start=1)]
        config = {**geometry, "boundaries": scene.solid.boundaries, "material": scene.material,
                  "loads": loads, "degree": solver["degree"], "linear_solver": solver["linear_solver"],
                  "rtol": solver["rtol"], "max_iterations": solver["max_iterations"], "dynamic": "dynamics" in scene.effects,
                  # rho_f of eq. 13 is for a volume-coupled immersed solid; here the fluid loads the rock
                  # through its wetted surface only (the penalized fluid inside it passes its inertia to
                  # the penalty, not to the surface pressure: tests/test_fluid_transient.py, piston), so
                  # the rock keeps its own inertia rho_s
                  "fluid_density": 0.0,
                  "wetted": scene.coupling["interface"], "traction": scene.coupling["traction"]}
        if scene.contact is not None:  # loads ramped over the steps (solid_fenicsx/participant.py)
            config.update(contact=scene.contact, steps=scene.time["steps"])
        if solver["participant"] == "spring_solid":
            config["k"] = solver["stiffness"]
        return config
    solver = scene.solvers["fluid"]
    g = scene.fluid
    config = {"grid": {"origin": g.origin, "spacing": g.spacing, "shape": g.shape}, "location": "cells",
              "rho": scene.fluid_material["density"], "mu": scene.fluid_material["viscosity"]}
    if solver["participant"] == "replay_fluid":
        config.update(pressure=solver["pressure"], feedback=solver["feedback"], unconverged=solver["unconverged"])
    if solver["participant"] == "openfoam":
        flow = scene.flow or {}
        config.update({k: solver[k] for k in ("penalization", "penalization_exponent", "drag", "max_iterations",
                                              "tolerance", "decomposition", "substeps", "outer_correctors",
                                              "solid_velocity")}, ranks=solver["solver_ranks"])
        config.update(transient="dynamics" in scene.effects, dt=scene.time["dt"])
        if solver["keep_case"]:
            config["case_dir"] = str((Path(scene.output_dir) / "logs" / "fluid_case").resolve())
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


def _as_arrays(fields: dict) -> dict:
    return {k: np.asarray(f.data if isinstance(f, Field) else f) for k, f in fields.items()}


def run(scene: CoupledScene, log=print, progress: bool | None = None, run_id: str | None = None) -> dict:
    """Run the coupled `scene`; return its summary (also in ``summary.json``)."""
    plan = make_plan(scene)
    log(f"memory: {check_memory(scene, estimate(scene))}")
    out = Path(scene.output_dir)
    out.mkdir(parents=True, exist_ok=True)
    for note in plan.notes:
        log(f"warning: {note}")
    run_id = run_id or new_run_id()
    phases = Phases()
    summary = {"case": str(scene.case_dir), "scene": str(scene.path), "run_id": run_id,
               **plan.as_dict(), "status": "running", "steps": [], "phases_seconds": phases.seconds}
    write_summary(out, summary)
    start = time.perf_counter()
    try:
        with CouplerSession(run_id, mode=scene.messaging["mode"], connect=scene.messaging["connect"],
                            connect_timeout=min(10.0, scene.messaging["timeout"])) as session, \
                Launcher(run_id, out, session.endpoints) as launcher:
            result = _run(scene, plan, session, launcher, out, phases, summary, log, progress)
        summary.update(result, status="completed")
    except BaseException as exc:
        summary["status"] = run_status(exc)
        summary["error"] = f"{type(exc).__name__}: {exc}"
        raise
    finally:
        summary["wall_seconds"] = time.perf_counter() - start
        write_summary(out, summary)
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
        phases.remote(f"{name} setup", client, "configure", participant_config(scene, name))
        header, fields = phases.remote(f"{name} setup", client, "geometry")
        meshes[name] = _mesh_of(name, header, fields)
        geometry_fields[name] = fields or {}
        log(f"{name}: {announced[name].get('kind')} on {meshes[name].num_cells} cells")
    summary["participants_announced"] = announced

    solid = clients["solid"]
    series = {name: Series(out, name, mesh) for name, mesh in meshes.items()}
    steps, dt = scene.time["steps"], scene.time["dt"]
    coupled = "fluid" in clients
    every = scene.output["every"]
    last = {"figures": {}}
    allow = {name: bool(scene.solvers[name].get("allow_unconverged")) for name in clients}
    solves = {"step": StepSolves(allow)}

    def advance(name, window, iteration, inputs):
        """One participant's advance: its fields (arrays); its solve reports and figures recorded."""
        client = clients[name]
        fields = _as_arrays(phases.remote(name, client, "advance", window.index, iteration, window.t_start,
                                          window.dt, inputs))
        if iteration == 0 and name == next(iter(clients)):
            solves["step"] = StepSolves(allow)
        solves["step"].add(name, iteration, client.last_solves)
        last["figures"][name] = client.last_figures
        return fields

    if coupled:
        fluid = clients["fluid"]
        S, G = meshes["solid"], meshes["fluid"]
        start = time.perf_counter()
        triangles = geometry_fields["solid"].get("interface_triangles")
        triangles = None if triangles is None else np.asarray(triangles.data)
        full = scene.coupling["traction"] == "full"  # the viscous stress too (coupler/viscous.py)
        on_grid = SolidOnGrid(S, G, triangles, f"{scene.path}: [geometry.fluid]",
                              deform=scene.coupling["deformation"], traction=scene.coupling["traction"])
        traction = FluidTraction(scene.fluid_material["viscosity"]) if full else None
        interface = on_grid.interface
        summary["interface"] = {**interface.describe(), "traction": scene.coupling["traction"]}
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

        def to_solid(x):
            if full:  # x: the traction (-p I + tau) n per interface vertex, flattened
                return {"traction": Field("traction", on_grid.interface.to_solid_vertices(x.reshape(-1, 3)), "Pa")}
            return {"pressure": Field("pressure", on_grid.interface.to_solid_vertices(x), "Pa")}

        def iterate(window, iteration, x):
            solid_out = advance("solid", window, iteration, to_solid(x))
            # two-way: the fluid sees the deformed solid (fractions, velocity transfer, sampling surface)
            try:
                phases.timed("geometry update", on_grid.update, solid_out.get("displacement"))
            except CouplerError as exc:
                u = solid_out.get("displacement")
                largest = float(np.max(np.linalg.norm(u, axis=1))) if u is not None else 0.0
                raise CouplerError(f"{window}, iteration {iteration}: the deformed solid (largest displacement "
                                   f"{largest:.3g} m) no longer fits the fluid grid: {exc}") from None
            velocity = phases.timed("transfer", on_grid.to_fluid.apply, solid_out["velocity"], fill=0.0)
            fluid_in = {"solid_velocity": Field("solid_velocity", velocity, "m/s"),
                        "solid_fraction": Field("solid_fraction", on_grid.fraction, "1")}
            fluid_out = advance("fluid", window, iteration, fluid_in)
            last.update(solid=solid_out, fluid=fluid_out, fluid_in=velocity, fraction=on_grid.fraction)
            if full:
                wall = solid_out["velocity"][on_grid.interface.vertices]
                parts = phases.timed("transfer", traction.parts, on_grid, fluid_out["pressure"],
                                     fluid_out["velocity"], wall)
                last["traction"] = {**traction_figures(on_grid.interface.weights, *parts),
                                    "fits": traction.fits}
                return (parts[0] + parts[1]).ravel()
            return phases.timed("transfer", on_grid.interface.from_fluid, fluid_out["pressure"])

        class Checkpoint:
            def save(self, window):
                for c in clients.values():
                    phases.remote("checkpoint", c, "save_state", window.index)

            def restore(self, window):
                for c in clients.values():
                    phases.remote("checkpoint", c, "restore_state", window.index)

        x0 = np.zeros(interface.size * (3 if full else 1))
        if full:
            weights = np.repeat(weights, 3)
        c = scene.coupling
        accelerator = make_accelerator(c["acceleration"], relaxation=c["relaxation"], reuse=c["reuse"],
                                       max_columns=c["columns"])
        mode, checkpoint = "implicit", Checkpoint()
    else:
        weights, x0, accelerator, mode, checkpoint = None, np.zeros(0), None, "explicit", None

        def iterate(window, iteration, x):
            last["solid"] = advance("solid", window, iteration, {})
            return x

    def on_converged(window, x, step):
        inner = solves["step"]
        record = {"step": window.index, "t": window.t_end, "iterations": step.iterations,
                  "residuals": list(step.residuals), "coupling_converged": step.converged,
                  "converged": step.converged and inner.converged, **inner.as_dict()}
        if window.index % every == 0 or window.index == steps - 1:
            start = time.perf_counter()
            solid_fields = dict(last["solid"])
            if coupled:  # the coupled load: the pressure, or with traction 'full' the traction vector
                solid_fields.update(_as_arrays(to_solid(x)))
                fluid_fields = {"pressure": last["fluid"]["pressure"], "solid_fraction": last["fraction"],
                                "solid_velocity": last["fluid_in"]}
                if "velocity" in last["fluid"]:
                    fluid_fields["velocity"] = last["fluid"]["velocity"]
                series["fluid"].write(window.index, window.t_end, cell_data=fluid_fields)
            series["solid"].write(window.index, window.t_end, point_data=solid_fields)
            phases.add("output", time.perf_counter() - start)
        record["figures"] = {name: figures for name, figures in last["figures"].items() if figures}
        if "traction" in last:  # how much the viscous part matters ([coupling] traction = "full")
            record["traction"] = last["traction"]
        u = last["solid"].get("displacement")
        if u is not None:
            record["max_displacement"] = float(np.max(np.linalg.norm(u, axis=1)))
        summary["steps"].append(record)
        if coupled:
            summary["geometry_update"] = on_grid.describe()
        write_summary(out, summary)
        if not inner.converged:
            raise inner.error(window.index)

    bar = ProgressBar(steps, label=scene.case_dir.name, enabled=progress)
    try:
        result = run_coupled(steps, dt, iterate, x0, accelerator, tolerance=scene.coupling["tolerance"],
                             max_iterations=scene.coupling["max_iterations"], checkpoint=checkpoint,
                             on_converged=on_converged, progress=bar, weights=weights, coupling=mode)
    finally:
        bar.close()
    summary["accelerator"] = result.accelerator
    for name, client in clients.items():
        client.finish()
        launcher.wait(name, timeout=30)
    if coupled:
        residual_plot(out / "residuals.png", result)
    log(f"{steps} step{'s' * (steps > 1)} done; results in {out}")
    done = {"iterations": result.iterations, "converged": [r["converged"] for r in summary["steps"]]}
    if scene.check:
        done["check"] = check_displacement(scene.check, meshes["solid"].points, last["solid"]["displacement"])
        c = done["check"]
        log(f"check: displacement error {c['error']:.3e} relative on {c['vertices']} vertices "
            f"(tolerance {c['tolerance']:g}): {'PASS' if c['passed'] else 'FAIL'}")
    return done
