"""``varcouple run`` on a coupled scene: the plan executed (docs/architecture.md).

The runner knows no physics: it starts the plan's participants as processes, configures
them with what the plan says, builds each exchange's operator once
(:data:`coupler.fsi.operators.OPERATORS`) and runs the time loop
(:func:`coupler.coupling.loop.run_coupled`). Per step, an explicit plan (no accelerated
exchange) advances each participant once; an implicit plan iterates the fixed point on the
accelerated exchanges' values x: the participants advance in the plan's order, each with
its inputs (the accelerated exchanges deliver x, the others are evaluated on the latest
outputs just before), and H(x) is the accelerated exchanges evaluated on the new outputs;
Aitken or IQN-ILS give the next x. Every advance returns each inner solve's report
(:mod:`coupler.run.solves`): a step is converged only when the coupling and every final
inner solve converged. Participants the plan marks ``in_process`` (stand-ins that solve
nothing: a fixed solid, mesh files) are served in this process through the same verbs
(:mod:`coupler.run.local`); a plan of such participants only opens no zenoh session and
starts no process.

Written to the output directory: ``<participant>_NNNN.vtu`` per output step (the
participant's outputs and the inputs it got; for an accelerated exchange its accepted
value) with ``<participant>.pvd`` time series for ParaView, ``summary.json`` (the plan,
per-step iterations, residuals, solves and figures, wall time per phase; rewritten after
every step, so a failed run keeps what it did), ``residuals.png`` for implicit plans and
``logs/`` with each participant's output.
"""

from __future__ import annotations

import logging
import re
import time
from contextlib import ExitStack, contextmanager
from dataclasses import replace
from pathlib import Path

import numpy as np

from coupler import checks
from coupler.coupling.acceleration import make_accelerator
from coupler.coupling.loop import run_coupled
from coupler.errors import CouplerError, RunFailed, SceneError, one_line, run_status
from coupler.fsi.monitors import MONITORS
from coupler.fsi.operators import OPERATORS, OperatorContext
from coupler.output.plots import residual_plot
from coupler.output.progress import ProgressBar
from coupler.output.publish import publish
from coupler.output.report import PAGE
from coupler.output.results import SUMMARY, Series, write_summary
from coupler.plan.plan import Plan, make_plan
from coupler.protocol.errors import ParticipantFailure, ParticipantInputError
from coupler.protocol.roles import check_geometry, check_outputs
from coupler.protocol.transport import new_run_id
from coupler.protocol.wire import Field
from coupler.run.client import CouplerSession
from coupler.run.launch import Launcher
from coupler.run.local import LocalClient
from coupler.run.preflight import check_memory, estimate, first_step
from coupler.run.solves import StepSolves
from transfer import Mesh, StructuredGrid
from transfer.mesh import CELL_TYPES
from transfer.meshfile import same_file


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


def _mesh_of(name: str, header: dict, fields: dict):
    """The mesh or grid a participant's ``geometry`` describes (named as its header says, e.g. a
    file); a file's orientation convention is accepted (negative volume cells reordered)."""
    if "grid" in header:
        g = header["grid"]
        return StructuredGrid(g["origin"], g["spacing"], g["shape"], name=f"{name} grid")
    if header.get("cell_type") not in CELL_TYPES:
        raise CouplerError(f"participant {name!r} gave cells of type {header.get('cell_type')!r}; "
                           f"the coupler needs a mesh of {', '.join(CELL_TYPES)} cells or a structured grid")
    return Mesh(np.array(fields["points"].data), np.array(fields["cells"].data), header["cell_type"],
                name=header.get("name", f"{name} mesh"), reorient=True)


def _as_arrays(fields: dict) -> dict:
    return {k: np.asarray(f.data if isinstance(f, Field) else f) for k, f in fields.items()}


def run(scene, log=print, progress: bool | None = True, run_id: str | None = None, comm=None,
        run_class=None) -> dict:
    """Run the coupled `scene`; return its summary (also in ``summary.json``). On a coupler of
    several ranks (`comm`, `run_class` :class:`coupler.run.ranks.RanksRun`) every rank calls it;
    rank 0 writes the summary and the report."""
    run_class = run_class or Run
    root = comm is None or comm.rank == 0
    plan = make_plan(scene)
    run_class.admit(scene, plan, comm)
    ranks = comm.size if comm is not None else 1
    estimates = estimate(scene, ranks)
    log(f"memory: {check_memory(scene, estimates, ranks)}")
    warning = first_step(scene, estimates)[1]
    if warning:
        log(f"warning: {warning}")
    out = Path(scene.output_dir)
    out.mkdir(parents=True, exist_ok=True)
    check_inputs_kept(scene, plan, out)
    for note in plan.notes:
        log(f"warning: {note}")
    run_id = run_id or new_run_id()
    phases = Phases()
    summary = {"case": str(scene.case_dir), "scene": str(scene.path), "description": scene.description,
               "run_id": run_id,
               **plan.as_dict(), "status": "running", "steps": [], "phases_seconds": phases.seconds}
    if root:
        write_summary(out, summary)
    start = time.perf_counter()
    failure = None
    try:
        with scene_input(scene), logging_to(out / "logs" / ("coupler.log" if root else f"coupler.{comm.rank}.log")), \
                run_class.processes(scene, plan, run_id, out, comm) as (session, launcher):
            result = run_class(scene, plan, session, launcher, out, phases, summary, log, run_id,
                               **({"comm": comm} if comm is not None else {})).execute(progress)
        summary.update(result, status="completed")
    except BaseException as exc:
        failure = exc
        _record_failure(summary, exc)
    summary["wall_seconds"] = time.perf_counter() - start
    if root:
        failure = _write_end(out, summary, scene.output["pictures"], log, failure)
    if failure is not None:
        raise failure
    return summary


class _LogFile(logging.FileHandler):
    """A log file that a full disk or a read-only directory silences instead of printing a
    traceback per record on the screen (the run's own error says what happened)."""

    def handleError(self, record):
        pass


@contextmanager
def logging_to(path: Path):
    """The coupler's own log records (loggers ``varcouple.*``: a participant's liveliness token
    lost, processes started and stopped, calls that wait) go to `path` for the run, not to the
    screen, where the run's one error line says what ended it."""
    path.parent.mkdir(parents=True, exist_ok=True)
    logger, handler = logging.getLogger("varcouple"), _LogFile(path, delay=True)
    handler.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s"))
    before = logger.level, logger.propagate
    logger.addHandler(handler)
    logger.setLevel(logging.INFO)
    logger.propagate = False
    try:
        yield
    finally:
        logger.removeHandler(handler)
        handler.close()
        logger.level, logger.propagate = before


def _record_failure(summary: dict, exc: BaseException) -> None:
    summary["status"] = run_status(exc)
    summary["error"] = f"{type(exc).__name__}: {one_line(exc)}"


def _write_end(out: Path, summary: dict, pictures: bool, log, failure: BaseException | None):
    """Write the run's final summary and its report; the exception the run ends with. An output
    that cannot be written (a full disk, a directory made read-only) fails a run that had
    completed; it never hides the error a run already failed with, but is added to it as a note,
    as is a summary.json that could not be updated."""
    try:
        write_summary(out, summary)
        publish(out, summary, pictures, log)
        return failure
    except OSError as exc:
        lost = exc
    if failure is None:  # it had completed: the file it could not write is its failure
        failure = RunFailed(one_line(lost))
        _record_failure(summary, failure)
    elif Path(lost.filename or "").name != SUMMARY:
        failure.add_note(f"also {one_line(lost)}")
    try:  # the status it ended with, if the directory takes it now
        write_summary(out, summary)
    except OSError as exc:
        failure.add_note(f"{out / SUMMARY} not updated ({exc.strerror or exc}): it does not say how the run ended")
    return failure


def rehearse(scene, plan: Plan, log=print) -> dict:
    """Start every participant of `plan`, configure it, read its geometry and build the
    exchanges' operators, then finish: what ``varcouple check`` does instead of running.
    Returns each participant's mesh (``{name: mesh or grid}``)."""
    import tempfile

    run_id = new_run_id()
    quiet = Phases()
    plan = replace(plan, participants=[replace(p, config={k: v for k, v in p.config.items() if k != "case_dir"})
                                       for p in plan.participants])  # a check keeps nothing
    with scene_input(scene), tempfile.TemporaryDirectory(prefix=f"varcouple-{run_id}-check-") as logs, \
            processes(scene, plan, run_id, logs) as (session, launcher):
        rehearsal = Run(scene, plan, session, launcher, Path(logs), quiet, {}, lambda line: None, run_id)
        rehearsal.start()
        rehearsal.finish()
    return rehearsal.meshes


@contextmanager
def scene_input(scene):
    """A participant's refusal of its input (:class:`ParticipantInputError`: a boundary selecting
    nothing, an unknown tag, a generator's parameters) as what it is, an error of the scene file."""
    try:
        yield
    except ParticipantInputError as exc:  # a SceneError already: named by the scene file, its notes kept
        raise exc.at(str(scene.path))


def check_inputs_kept(scene, plan: Plan, out: Path) -> None:
    """SceneError before anything is written when a file the run writes in `out` is an input of
    the scene (the scene file, a participant's mesh or file), whatever its spelling (links, ..)."""
    inputs = [scene.path] + [p.config[k] for p in plan.participants for k in ("mesh", "file")
                             if isinstance(p.config.get(k), str)]
    series = "|".join(re.escape(p.name) for p in plan.participants)
    written = re.compile(rf"({series})(\.pvd|_\d{{4,}}\.vtu)|" + "|".join(map(re.escape, (SUMMARY, PAGE, "residuals.png",
                                                                                          "convergence.png"))))
    for entry in out.iterdir():  # what is there already and would be written over
        clash = same_file(entry, inputs) if written.fullmatch(entry.name) else None
        if clash is not None:
            raise SceneError(f"{entry}: is {clash}, an input of the scene: writing there would overwrite it; "
                             f"choose another output directory")


@contextmanager
def processes(scene, plan: Plan, run_id: str, logs):
    """``(session, launcher)`` for the participant processes of `plan` (zenoh session and
    launcher, both closed on exit), or ``(None, None)`` when every participant is served in
    this process."""
    if all(p.in_process for p in plan.participants):
        yield None, None
        return
    with ExitStack() as stack:
        session = stack.enter_context(CouplerSession(run_id, mode=scene.messaging["mode"],
                                                     connect=scene.messaging["connect"],
                                                     connect_timeout=min(10.0, scene.messaging["timeout"])))
        yield session, stack.enter_context(Launcher(run_id, logs, session.endpoints))


def watched(launcher: Launcher, name: str, log) -> dict:
    """How the client of participant `name` watches its process (exited, stopped) and where it
    says that a call waits long (`log`): keyword arguments of
    :class:`~coupler.run.client.ParticipantClient`."""
    return {"process_check": lambda: launcher.check(name), "process_stopped": lambda: launcher.stopped(name),
            "waiting": log}


def served_in_process(p, run_id: str, comm=None):
    """The participant object of the in-process participant `p` (a stand-in of
    :mod:`coupler.standins`), bound to the run (and to this rank of the coupler's ranks `comm`:
    it serves that rank's part)."""
    from coupler.standins import STANDINS

    handler = STANDINS[p.kind]()
    handler.bind(run_id, p.name, comm)
    return handler


class Run:
    """One execution of a plan (set up by :meth:`start`, stepped by :meth:`execute`)."""

    #: this process writes the run's files (rank 0 of a coupler on several ranks)
    root = True
    #: the coupler's ranks when the interface vector is split by rows over them (None: one process)
    comm = None

    @staticmethod
    def admit(scene, plan: Plan, comm) -> None:
        """SceneError for what this kind of run cannot do (one process: everything)."""

    @staticmethod
    def processes(scene, plan: Plan, run_id: str, logs, comm=None):
        return processes(scene, plan, run_id, logs)

    def __init__(self, scene, plan: Plan, session, launcher, out: Path, phases: Phases, summary: dict, log,
                 run_id: str = ""):
        self.scene, self.plan, self.session, self.launcher = scene, plan, session, launcher
        self.out, self.phases, self.summary, self.log, self.run_id = out, phases, summary, log, run_id
        self.clients: dict = {}
        self.outputs: dict[str, dict] = {}  # latest outputs per participant
        self.rows: dict[str, int | None] = {}  # rows of each participant's fields (its role's contract)
        self.inputs: dict[str, dict] = {}  # latest inputs per participant
        self.figures: dict[str, dict] = {}
        self.allow = {p.name: p.allow_unconverged for p in plan.participants}
        self.solves = StepSolves(self.allow)

    # -- set-up ---------------------------------------------------------------------
    def start(self) -> None:
        """Start, configure and read the geometry of every participant; build the operators."""
        timeout = self.scene.messaging["timeout"]
        for p in self.plan.participants:
            if p.in_process:
                self.clients[p.name] = LocalClient(p.name, served_in_process(p, self.run_id))
                self.log(f"serving {p.name}: {p.kind} in this process")
                continue
            self.launcher.start(p.name, p.module, ranks=p.ranks, extra_args=p.arguments)
            self.clients[p.name] = self.session.client(p.name, timeout=timeout, **watched(self.launcher, p.name, self.log))
            self.log(f"started {p.name}: {p.kind} ({p.ranks} rank{'s' * (p.ranks > 1)}), log in "
                     f"{self.launcher.log_dir / p.name}.log")
        meshes, geometry, announced = {}, {}, {}
        for p in self.plan.participants:
            client = self.clients[p.name]
            self.phases.timed("start", client.wait_alive, timeout)
            announced[p.name] = client.announce()
            self.phases.remote(f"{p.name} setup", client, "configure", p.config)
            header, fields = self.phases.remote(f"{p.name} setup", client, "geometry")
            self.rows[p.name] = check_geometry(p.name, header, fields or {})
            meshes[p.name] = _mesh_of(p.name, header, fields)
            geometry[p.name] = _as_arrays(fields or {})
            self.log(f"{p.name}: {announced[p.name].get('kind')} on {meshes[p.name].num_cells} cells")
            if header.get("note"):
                self.log(f"{p.name}: {header['note']}")
        self.summary["participants_announced"] = announced
        self.summary["sizes"] = {name: {"cells": m.num_cells, "vertices": m.num_points} for name, m in meshes.items()}
        self.meshes = meshes
        self.context = OperatorContext(self.scene, meshes, geometry, self.phases, self.log)
        self.operators = [OPERATORS[e.operator](self.context, e) for e in self.plan.exchanges]
        self.monitors = {name: MONITORS[name][0](self.context) for name in self.plan.monitors}
        self.summary.update(self.context.summary())
        self.series = {name: Series(self.out, name, mesh) for name, mesh in meshes.items()}

    # -- one coupling iteration -------------------------------------------------------
    def _accelerated(self):
        return [(e, op) for e, op in zip(self.plan.exchanges, self.operators) if e.accelerated]

    def _split(self, x) -> list[np.ndarray]:
        """The interface vector x as the values of the accelerated exchanges."""
        sizes = [op.size for _, op in self._accelerated()]
        return np.split(np.asarray(x), np.cumsum(sizes)[:-1]) if sizes else []

    def _advance(self, name: str, window, iteration: int, inputs: dict) -> None:
        client = self.clients[name]
        fields = {k: Field(k, v, units) for k, (v, units) in inputs.items()}
        self.outputs[name] = _as_arrays(self.phases.remote(name, client, "advance", window.index, iteration,
                                                           window.t_start, window.dt, fields))
        check_outputs(name, self.outputs[name], self.rows[name])
        self._record(name, iteration, inputs)

    def _record(self, name: str, iteration: int, inputs: dict) -> None:
        """Keep the inputs `name` advanced with and how its inner solves ended (a new step's
        record from the first participant's first iteration)."""
        client = self.clients[name]
        self.inputs[name] = {k: v for k, (v, _) in inputs.items()}
        if iteration == 0 and name == self.plan.participants[0].name:
            self.solves = StepSolves(self.allow)
        self.solves.add(name, iteration, client.last_solves)
        self.figures[name] = client.last_figures

    def iterate(self, window, iteration: int, x) -> np.ndarray:
        """One pass of Steps 1-6 with the interface vector x; returns H(x)."""
        given = {id(e): value for (e, _), value in zip(self._accelerated(), self._split(x))}
        self.context.window = window
        try:
            for p in self.plan.participants:
                inputs, sources = {}, []
                for e, op in zip(self.plan.exchanges, self.operators):
                    if e.target_participant != p.name:
                        continue
                    value = given[id(e)] if e.accelerated else self.phases.timed("transfer", op.evaluate,
                                                                                 self.outputs)
                    inputs[e.target_field] = (self.phases.timed("transfer", op.deliver, value), op.units)
                    sources.append(op)
                try:
                    self._advance(p.name, window, iteration, inputs)
                except ParticipantFailure as exc:  # when and on what it failed: the step, and inputs set by a key
                    for note in (op.blame() for op in sources if hasattr(op, "blame")):
                        exc.add_note(note)
                    raise exc.at(f"{window}, coupling iteration {iteration}")
            H = [self.phases.timed("transfer", op.evaluate, self.outputs) for _, op in self._accelerated()]
        except CouplerError as exc:
            if type(exc) is not CouplerError:  # a participant's failure names itself
                raise
            raise CouplerError(f"{window}, iteration {iteration}: {exc}") from None
        return np.concatenate([np.ravel(h) for h in H]) if H else np.asarray(x)

    def unmet(self) -> str | None:
        """Why a step whose interface residual is below tolerance is not converged yet (an
        operator's own condition, e.g. a flow rate to reach), or None."""
        reasons = [op.unmet() for _, op in self._accelerated() if hasattr(op, "unmet")]
        return "; ".join(r for r in reasons if r) or None

    # -- a converged step -------------------------------------------------------------
    def on_converged(self, window, x, step) -> None:
        inner = self.solves
        record = {"step": window.index, "t": window.t_end, "iterations": step.iterations,
                  "residuals": list(step.residuals), "coupling_converged": step.converged,
                  "converged": step.converged and inner.converged, **inner.as_dict()}
        steps = self.scene.time["steps"]
        if window.index % self.scene.output["every"] == 0 or window.index == steps - 1:
            start = time.perf_counter()
            self.write_fields(window, x)
            self.phases.add("output", time.perf_counter() - start)
        record["figures"] = {name: figures for name, figures in self.figures.items() if figures}
        for op in self.operators:
            for key, figures in (op.figures() if hasattr(op, "figures") else {}).items():
                record.setdefault(key, {}).update(figures)  # operators of one kind share a key
        for name, monitor in self.monitors.items():
            record[name] = monitor.figures(self.outputs, self.figures)
        largest = self.max_displacement()
        if largest is not None:
            record["max_displacement"] = largest
        self.summary["steps"].append(record)
        self.summary.update(self.context.summary())
        write_summary(self.out, self.summary, comm=self.comm)
        for name, report in inner.accepted:
            self.log(f"warning: time step {window.index}: participant {name!r}: {report.describe()}")
        if not inner.converged:
            raise inner.error(window.index)

    def max_displacement(self) -> float | None:
        """The largest displacement of the solid's vertices (None without a solid displacement)."""
        u = self.outputs.get("solid", {}).get("displacement")
        return None if u is None else float(np.max(np.linalg.norm(u, axis=1)))

    def write_fields(self, window, x) -> None:
        """Every participant's fields of the converged step `window` in its VTU series."""
        accepted = {(e.target_participant, e.target_field): op.deliver(value)
                    for (e, op), value in zip(self._accelerated(), self._split(x))}
        for name, series in self.series.items():
            fields = {**self.outputs[name], **self.inputs.get(name, {})}
            fields.update({f: v for (n, f), v in accepted.items() if n == name})
            write_series(series, self.meshes[name], name, window, fields)

    # -- the run ----------------------------------------------------------------------
    def execute(self, progress) -> dict:
        self.start()
        scene, plan = self.scene, self.plan
        steps, dt = scene.time["steps"], scene.time["dt"]
        accelerated = self._accelerated()
        if plan.implicit:
            c = scene.coupling
            x0 = np.concatenate([op.initial() if hasattr(op, "initial") else np.zeros(op.size) for _, op in accelerated])
            weights = np.concatenate([op.weights for _, op in accelerated])
            accelerator = make_accelerator(c["acceleration"], relaxation=c["relaxation"], reuse=c["reuse"],
                                           max_columns=c["columns"], comm=self.comm)
            mode, checkpoint = "implicit", self
        else:
            x0, weights, accelerator, mode, checkpoint = np.zeros(0), None, None, "explicit", None
        bar = ProgressBar(steps, label=scene.case_dir.name, enabled=progress)
        try:
            result = run_coupled(steps, dt, self.iterate, x0, accelerator, tolerance=scene.coupling["tolerance"],
                                 max_iterations=scene.coupling["max_iterations"], checkpoint=checkpoint,
                                 on_converged=self.on_converged, progress=bar, weights=weights, coupling=mode,
                                 unmet=self.unmet, comm=self.comm)
        finally:
            bar.close()
        self.summary["accelerator"] = result.accelerator
        self.finish()
        if plan.implicit and self.root:
            residual_plot(self.out / "residuals.png", result)
        for name in self.monitors:
            for line in MONITORS[name][1](self.summary["steps"]):
                self.log(line)
        self.log(f"{steps} step{'s' * (steps > 1)} done; results in {self.out}")
        done = {"iterations": result.iterations, "converged": [r["converged"] for r in self.summary["steps"]]}
        if scene.check:
            done["check"] = checks.evaluate(scene, self.result())
            self.log(checks.describe(done["check"]))
        return done

    def result(self) -> checks.Result:
        """The final fields (outputs and inputs) of every participant on its mesh, and its last figures."""
        fields = {name: {**self.inputs.get(name, {}), **self.outputs.get(name, {})} for name in self.meshes}
        return checks.Result(meshes=self.meshes, fields=fields, figures=dict(self.figures))

    def finish(self) -> None:
        """Finish every participant (and wait for the processes to exit)."""
        self._finish(self.plan.participants)

    def _finish(self, participants) -> None:
        for p in participants:
            self.clients[p.name].finish()
            if not p.in_process:
                self.launcher.wait(p.name, timeout=30)

    # -- checkpoints of an implicit step (coupler.coupling.loop.Checkpoint) ------------
    def save(self, window) -> None:
        self._checkpoint("save_state", window, self.plan.participants)

    def restore(self, window) -> None:
        self._checkpoint("restore_state", window, self.plan.participants)

    def _checkpoint(self, verb: str, window, participants) -> None:
        for p in participants:
            self.phases.remote("checkpoint", self.clients[p.name], verb, window.index)


def write_series(series: Series, mesh, name: str, window, fields: dict) -> None:
    """Participant `name`'s `fields` on its `mesh` (or grid) as the VTU of step `window`."""
    fields = mesh_fields(fields, mesh, name)
    if isinstance(mesh, StructuredGrid):
        series.write(window.index, window.t_end, cell_data=fields)
    else:  # per point, or per cell (a P0 field)
        points = {k: v for k, v in fields.items() if len(v) == mesh.num_points}
        series.write(window.index, window.t_end, point_data=points,
                     cell_data={k: v for k, v in fields.items() if k not in points})


def mesh_fields(fields: dict, mesh, participant: str) -> dict:
    """The fields of a participant that live on its mesh (one value per point or per cell), for
    its VTU series; a single value (a boundary's, e.g. the inlet pressure of a flow-rate
    control) is left to the step's figures. Any other length is a defect, not dropped silently."""
    sizes = (mesh.num_points, mesh.num_cells)
    wrong = [f"{k} ({len(v)})" for k, v in fields.items() if len(v) not in sizes and len(v) != 1]
    if wrong:
        raise CouplerError(f"participant {participant!r}: field(s) {', '.join(wrong)} match neither its "
                           f"{mesh.num_points} points nor its {mesh.num_cells} cells")
    return {k: v for k, v in fields.items() if len(v) in sizes}
