"""The coupler on P MPI ranks (docs/scaling.md, step 3): ``mpirun -n P varcouple run CASE``,
or ``[coupling] ranks = P`` (``varcouple run`` then starts itself under ``mpirun -n P``:
:func:`coupler.run.job.relaunch`).

Every rank runs the same plan and loop (:class:`RanksRun`). Rank 0 starts the participants and
keeps their control verbs (announce, configure, save/restore, finish); every rank listens on its
own zenoh session, a peer, to which the participant ranks it talks to link directly
(:meth:`RanksRun.processes`). Each coupler rank talks to the participant ranks assigned to it
(round-robin, :func:`coupler.fsi.held.assigned`): it sends their requests and receives their
parts directly, no other process routing them, and holds their rows
(:class:`coupler.fsi.held.Held`); the cells it works on are its parts', but in a flow scene
the solid's: those over its grid slab (:func:`coupler.fsi.ranks.on_slabs`), whatever rank
they came from. A participant served in the coupler's process (a ``mesh_file``,
the fixed solid ``rigid_solid``: :data:`SERVED_IN_PARTS`) is served on every coupler rank, each its
own part of it (:meth:`coupler.run.local.LocalClient.exchange`): to the run, a participant of P
parts, coupler rank r holding part r. The operators are the
distributed ones of :mod:`coupler.fsi.ranks`. Whatever fails on one rank is raised on every
rank (:func:`agree`).

Nothing is gathered: each rank gives the accelerator and the loop its own rows of the interface
vector and their weights (``comm``: docs/scaling.md, step 4; a flow rate's pressure difference is
rank 0's row, and the inlet pressure it makes goes whole to each fluid part: :attr:`RanksRun.singles`,
in no piece, as the serial run writes it in no VTU), writes the piece of each
participant it works on (:meth:`RanksRun.piece`: a ``.pvtu`` of per-rank ``.vtu`` files, step
5), and the summary's figures are reduced over the ranks (rank 0 writes it; the monitors of
:data:`coupler.fsi.ranks.MONITORS_RANKS` reduce their own). A ``[check]`` of a distributed kind
(``DISTRIBUTED``) is evaluated from each rank's pieces and rows (:meth:`RanksRun.result`); the
pictures are drawn after the run by rank 0 from the written pieces
(:func:`coupler.output.publish.publish`). Operators, check kinds and monitors that need a whole
field on one process refuse P > 1 (:meth:`RanksRun.admit`; those a scene reaches all have a
distributed variant now)."""

from __future__ import annotations

import pickle
import sys
import traceback
from contextlib import ExitStack, contextmanager
from functools import partial

import numpy as np

from coupler import checks
from coupler.errors import EXIT_CODES, CouplerError, SceneError, one_line, run_status
from coupler.fsi.context import OperatorContext
from coupler.fsi.held import Held, assigned
from coupler.fsi.ranks import MONITORS_RANKS, OPERATORS_RANKS, GridSlab, RanksContext
from coupler.output.results import REDUCTIONS, Series, reduce_figures, write_summary
from coupler.protocol.participant import idle_barrier
from coupler.protocol.roles import check_geometry, check_outputs
from coupler.protocol.wire import Field
from coupler.run.client import CouplerSession, step_reports
from coupler.run.launch import Launcher
from coupler.run.local import LocalClient
from coupler.run.runner import Run, served_in_process, watched, write_series
from transfer import StructuredGrid


#: participants served in the coupler's process that a coupler on P ranks serves in P parts
SERVED_IN_PARTS = ("mesh_file", "rigid_solid")


def agree(comm, fn, *args, **kwargs):
    """``fn(*args, **kwargs)`` on every rank; when it raises on any rank, every rank raises (a rank
    that failed its own exception, the others that of the lowest failed rank). Collective."""
    failure = None
    try:
        result = fn(*args, **kwargs)
    except Exception as exc:  # noqa: BLE001 - passed on to every rank
        failure, result = exc, None
    vote(comm, failure)
    return result


def vote(comm, failure: Exception | None) -> None:
    """Raise `failure` (this rank's) or, when it is None, the failure of the lowest rank that
    has one; return when no rank has one. Collective: the ranks that come first sleep until the
    last comes (:func:`coupler.protocol.participant.idle_barrier`; in Open MPI's allgather they
    would spin, a rank without participant parts taking a core for the whole of the participants'
    solves)."""
    idle_barrier(comm)
    sent = failure
    if failure is not None:
        try:
            pickle.loads(pickle.dumps(failure))
        except Exception:  # noqa: BLE001 - an exception that does not travel: its text does
            sent = CouplerError(f"{type(failure).__name__}: {failure}")
    first = next((f for f in comm.allgather(sent) if f is not None), None)
    if failure is not None:
        raise failure
    if first is not None:
        raise first


def failed_together(comm, seconds: float) -> bool:
    """Whether every rank of `comm` calls this within `seconds`: after a failure, whether the
    other ranks failed with this one (a voted failure, or one every rank decides alike, e.g. not
    converging) or went on without it into a collective call that will never end. `comm` serves
    this alone (a duplicate: its barrier matches no other call)."""
    return idle_barrier(comm, poll=0.005, seconds=seconds)


class RanksRun(Run):
    """:class:`coupler.run.runner.Run` on the ranks of `comm` (module docstring)."""

    #: how long a rank whose run failed waits for the others to fail too before it aborts the
    #: MPI job [s] (:meth:`execute`)
    alone_seconds = 30.0

    @staticmethod
    def admit(scene, plan, comm) -> None:
        """SceneError (every rank) for what needs a whole field on one process: a ``[check]`` kind
        not ``DISTRIBUTED`` (:mod:`coupler.checks`), monitors and operators without a distributed
        variant (:data:`MONITORS_RANKS`, :data:`OPERATORS_RANKS`), participants served whole in the
        coupler's process (not :data:`SERVED_IN_PARTS`). The pictures are not refused: they are
        drawn after the run from the written pieces."""
        P = comm.size
        ranks = f"with {P} coupler ranks ([coupling] ranks or mpirun -n {P})"
        if scene.check and not getattr(checks.KINDS[scene.check["kind"]], "DISTRIBUTED", False):
            kinds = ", ".join(k for k, m in checks.KINDS.items() if getattr(m, "DISTRIBUTED", False))
            raise SceneError(f"{scene.path}: [check] kind: {scene.check['kind']!r} compares whole fields on one "
                             f"process: not {ranks}; on several ranks: {kinds}")
        whole = [name for name in plan.monitors if name not in MONITORS_RANKS]
        if whole:
            raise SceneError(f"{scene.path}: [physics] effects: the figures {', '.join(whole)} need whole "
                             f"fields on one process: not {ranks}")
        for p in plan.participants:
            if p.in_process and p.kind not in SERVED_IN_PARTS:
                raise SceneError(f"{scene.path}: [solvers.{p.name}]: {p.kind!r} is served whole in the coupler's "
                                 f"process: not {ranks}")
        for e in plan.exchanges:
            if e.operator not in OPERATORS_RANKS:
                raise SceneError(f"{scene.path}: [physics] effects: the exchange to {e.target} uses the operator "
                                 f"{e.operator!r}, which needs whole fields on one process: not {ranks}; on "
                                 f"several ranks: {', '.join(OPERATORS_RANKS)}")

    @staticmethod
    @contextmanager
    def processes(scene, plan, run_id: str, logs, comm=None):
        """Every rank its own listening session, a peer: each participant rank links directly to
        the coupler ranks it talks to (:func:`coupler.protocol.transport.part_links`: rank 0 of a
        participant to every coupler rank, rank r to coupler rank 0 and rank r mod P), so no
        session routes another's messages; rank 0 declares the coupler's liveliness token and
        keeps the launcher. With zenoh routers of the scene's own (``[messaging] connect``, or
        mode ``client``) rank 0 listens as before and every other rank is a client of the same
        routers."""
        if all(p.in_process for p in plan.participants):  # no process to start, no session
            yield None, None
            return
        with ExitStack() as stack:
            m = scene.messaging
            direct = m["mode"] == "peer" and not m["connect"]
            if direct or comm.rank == 0:  # through the scene's routers: rank 0's session routes for the others
                session = agree(comm, CouplerSession, run_id, mode=m["mode"] if direct or m["mode"] != "peer"
                                else "router", connect=m["connect"], connect_timeout=min(10.0, m["timeout"]),
                                token=comm.rank == 0)
                stack.callback(session.close)
            else:
                agree(comm, lambda: None)
            endpoints = comm.allgather(session.endpoints[0]) if direct else comm.bcast(
                session.endpoints if comm.rank == 0 else None)
            if comm.rank == 0:
                yield session, stack.enter_context(Launcher(run_id, logs, session.endpoints,
                                                            coupler_ranks=endpoints if direct else ()))
            elif direct:
                yield session, None
            else:
                yield stack.enter_context(CouplerSession(run_id, mode="client", listen_host=None, connect=endpoints,
                                                         token=False)), None

    def __init__(self, *args, comm, **kwargs):
        super().__init__(*args, **kwargs)
        self.comm, self.root = comm, comm.rank == 0
        self.failures = comm.Dup()  # for failed_together alone
        if not self.root:
            self.log = lambda line: None
        self.held: dict[str, Held] = {}

    def _on_root(self, fn, *args):
        """`fn` on rank 0, its result on every rank (its failure raised on every rank)."""
        return self.comm.bcast(agree(self.comm, fn, *args) if self.root else agree(self.comm, lambda: None))

    # -- set-up ---------------------------------------------------------------------
    def start(self) -> None:
        comm, timeout = self.comm, self.scene.messaging["timeout"]
        for p in self.plan.participants:
            watch = {}
            if p.in_process:
                self.clients[p.name] = LocalClient(p.name, served_in_process(p, self.run_id, comm))
                self.log(f"serving {p.name}: {p.kind} in this process, part r of it on coupler rank r")
                continue
            if self.root:
                self.launcher.start(p.name, p.module, ranks=p.ranks, extra_args=p.arguments)
                watch = watched(self.launcher, p.name, self.log)
                self.log(f"started {p.name}: {p.kind} ({p.ranks} rank{'s' * (p.ranks > 1)}), log in "
                         f"{self.launcher.log_dir / p.name}.log")
            self.clients[p.name] = self.session.client(p.name, timeout=timeout, **watch)
        announced, parts, meshes = {}, {}, {}
        for p in self.plan.participants:
            client = self.clients[p.name]
            configure = partial(agree, comm) if p.in_process else self._on_root  # each rank its own part
            announced[p.name] = configure(self._configure, client, p.config, timeout)
            client.parts = int(announced[p.name].get("parts", 1))
            client.mine = assigned(comm.rank, comm.size, client.parts)
            replies = agree(comm, self._exchange, client, "geometry", None, [None] * client.parts, timeout)
            header = comm.bcast(replies[0].header if self.root else None)
            self.held[p.name], parts[p.name] = self._hold(p.name, header, replies)
            if "grid" in header:
                g = header["grid"]
                meshes[p.name] = StructuredGrid(g["origin"], g["spacing"], g["shape"], name=f"{p.name} grid")
            cells = comm.allreduce(sum(len(part.get("cell_ids", ())) for part in parts[p.name]))
            self.log(f"{p.name}: {announced[p.name].get('kind')} on {meshes[p.name].num_cells if p.name in meshes else cells} "
                     f"cells; coupler rank 0 holds its ranks {client.mine}")
        self.summary["participants_announced"] = announced
        self.summary["sizes"] = {name: {"cells": meshes[name].num_cells, "vertices": meshes[name].num_points}
                                 if name in meshes else
                                 {"cells": comm.allreduce(sum(len(part["cell_ids"]) for part in parts[name])),
                                  "vertices": comm.allreduce(sum(len(np.asarray(part["points"]).reshape(-1, 3))
                                                                 for part in parts[name]))}
                                 for name in self.held}
        self.meshes = meshes
        self.context = OperatorContext(self.scene, meshes, {}, self.phases, self.log)
        ranks_context = RanksContext(self.context, comm, self.held, parts)
        self.operators = agree(comm, lambda: [OPERATORS_RANKS[e.operator](ranks_context, e)
                                              for e in self.plan.exchanges])
        self.monitors = agree(comm, lambda: {name: MONITORS_RANKS[name][0](ranks_context)
                                             for name in self.plan.monitors})
        #: (participant, field) -> operator of the inputs of one value for the whole participant (the
        #: flow-rate control's inlet pressure): each part gets it whole, they are not rows; the
        #: operator's ``delivered`` is the value, on every rank
        self.singles = {(e.target_participant, e.target_field): op for e, op in zip(self.plan.exchanges, self.operators)
                        if getattr(op, "single", False)}
        self.summary.update(self.context.summary())
        self.slabs = agree(comm, lambda: {name: GridSlab(comm, grid, f"{self.scene.path}: [geometry.{name}]")
                                          for name, grid in meshes.items()})
        self.pieces = agree(comm, lambda: {name: self.piece(name, parts[name]) for name in self.held})
        self.series = {name: Series(self.out, name, mesh, comm) for name, (mesh, _) in self.pieces.items()}

    def piece(self, name: str, geometry: list[dict]):
        """(mesh, row ids): what this rank writes of participant `name`: its slab of a grid
        (:attr:`slabs`, cell rows), or the cells it works on (:meth:`coupler.fsi.held.Held.mesh`:
        its parts', in a flow scene the solid cells over its grid slab; each cell in one piece)
        on the vertices they use (point rows). Collective."""
        if name in self.slabs:
            return self.slabs[name].part.mesh, self.slabs[name].ids
        vertices, mesh = self.held[name].mesh(geometry)
        return mesh, vertices

    def _configure(self, client, config, timeout) -> dict:
        client.wait_alive(timeout)
        announced = client.announce()
        self.phases.remote(f"{client.name} setup", client, "configure", config)
        return announced

    def _exchange(self, client, verb: str, header, parts: list, timeout=None):
        """`client`'s exchange of this rank's parts; the coupler's ranks vote once every rank has
        sent its requests, before rank 0's (which starts the participant's ranks): a rank that
        failed before votes its failure, and every rank raises it instead of waiting."""
        voted = []

        def ready():
            voted.append(True)
            vote(self.comm, None)

        try:
            client.wait_alive(timeout)
            return client.exchange(verb, header, parts, timeout, before_root=ready)
        except Exception as exc:
            if not voted:
                vote(self.comm, exc)
            raise

    def _hold(self, name: str, header: dict, replies) -> tuple[Held, list[dict]]:
        """This rank's share of participant `name` from its parts' geometry replies. A participant
        of one part may give no ids: its part is the whole, rows 0..n-1 (docs/protocol.md, "Parts").
        Collective: a part that does not fit fails every rank."""
        location = "cell_ids" if header.get("location") == "cells" else "point_ids"
        geometry = [{k: np.asarray(f.data) for k, f in part.fields.items()} for part in replies]

        def held() -> Held:
            for part in replies:  # each part's geometry against the role's contract (rows: its ids, below)
                check_geometry(name, header, part.fields)
            for part, g in zip(replies, geometry):
                if location not in g and self.clients[name].parts == 1:
                    g[location] = np.arange(StructuredGrid(header["grid"]["origin"], header["grid"]["spacing"],
                                                           header["grid"]["shape"]).num_cells if "grid" in header
                                            else len(np.asarray(g["points"]).reshape(-1, 3)))
                if location not in g:
                    raise part.fail(name, f"its geometry part has no {location!r}: the rows of its fields have no "
                                          f"owners")
            ids = [g[location].astype(np.int64) for g in geometry]
            inputs = [g.get("input_ids", g[location]).astype(np.int64) for g in geometry]
            return Held(self.comm, name, self.clients[name].mine, ids, inputs, header.get("cell_type", "tetra"),
                        "cells" if location == "cell_ids" else "points")

        return agree(self.comm, held), geometry

    # -- one coupling iteration -------------------------------------------------------
    def _advance(self, name: str, window, iteration: int, inputs: dict) -> None:
        client, held, comm = self.clients[name], self.held[name], self.comm
        parts = [None] * client.parts
        for i, r in enumerate(held.ranks):
            parts[r] = {k: Field(k, values[i], units) for k, (values, units) in inputs.items()}
        header = {"window": int(window.index), "iteration": int(iteration), "t": float(window.t_start),
                  "dt": float(window.dt)}
        replies = agree(comm, self.phases.remote, name, _Caller(self._exchange, client), "call", client,
                        "advance", header, parts, None)
        shapes = comm.bcast({k: (np.asarray(f.data).shape[1:], np.asarray(f.data).dtype)
                             for k, f in replies[0].fields.items()} if self.root else None)
        held.fields = agree(comm, _joined, name, replies, held, shapes)
        client.last_solves, client.last_figures = comm.bcast(step_reports(replies[0].header) if self.root else None)
        self._record(name, iteration, inputs)

    # -- a converged step -------------------------------------------------------------
    def max_displacement(self) -> float | None:
        solid = self.held.get("solid")
        if solid is None or "displacement" not in solid.fields:
            return None
        local = {"max_displacement": solid.max_norm("displacement")}
        return reduce_figures(local, REDUCTIONS, self.comm)["max_displacement"]

    def write_fields(self, window, x) -> None:
        """Each rank writes its piece of every participant (:meth:`piece`): the outputs and inputs
        of the step moved from the rows held here to the piece's rows. Collective."""
        accepted = {(e.target_participant, e.target_field): op.deliver(value)
                    for (e, op), value in zip(self._accelerated(), self._split(x))}
        for name in self.held:
            fields = self.piece_fields(name, {f: v for (n, f), v in accepted.items() if n == name})
            write_series(self.series[name], self.pieces[name][0], name, window, fields)

    def piece_fields(self, name: str, accepted: dict | None = None) -> dict[str, np.ndarray]:
        """Participant `name`'s latest outputs and inputs (and `accepted`, inputs per part) at the
        rows of this rank's piece (:meth:`piece`), each in its own dtype. Collective."""
        held, (_, ids) = self.held[name], self.pieces[name]
        fields = {k: held.rows.move(held.out_ids, v, ids).astype(v.dtype) for k, v in held.fields.items()}
        fields.update({k: held.rows.move(held.in_ids, _rows(v), ids)
                       for k, v in self._row_inputs(name, accepted).items()})
        return fields

    def _row_inputs(self, name: str, accepted: dict | None = None) -> dict:
        """Participant `name`'s latest inputs (and `accepted`) given by rows, per part; those of
        one value (:attr:`singles`) left to the step's figures, as the serial run's
        :func:`coupler.run.runner.mesh_fields` leaves them."""
        inputs = {**self.inputs.get(name, {}), **(accepted or {})}
        return {k: v for k, v in inputs.items() if (name, k) not in self.singles}

    def result(self) -> checks.Result:
        """Each participant's piece of this rank (:meth:`piece`) with its final fields, the rows
        held here (their coordinates, outputs and inputs moved to them), each grid's slab, the
        last figures and `comm`: what a distributed check kind sums over
        (:class:`coupler.checks.Result`); an input of one value (:attr:`singles`) whole. Collective."""
        held = {}
        for name, h in self.held.items():
            if h.points is not None:
                inputs = {k: h.rows.move(h.in_ids, _rows(v), h.out_ids) for k, v in self._row_inputs(name).items()}
                held[name] = (h.points, {**inputs, **h.fields})
        fields = {name: self.piece_fields(name) for name in self.held}
        for (name, k), op in self.singles.items():  # a check may read it (the pressure drop a flow rate found)
            fields[name][k] = op.delivered
        return checks.Result(meshes={name: mesh for name, (mesh, _) in self.pieces.items()}, fields=fields,
                             figures=dict(self.figures), comm=self.comm, held=held,
                             grids={name: (slab.G, slab.block) for name, slab in self.slabs.items()})

    def execute(self, progress) -> dict:
        """The run; a failure on this rank that the other ranks do not share within
        :attr:`alone_seconds` (an error outside any vote: the others wait in a collective call)
        ends the MPI job (:meth:`abort`) instead of hanging it."""
        try:
            return super().execute(progress and self.root)
        except Exception as exc:
            if not failed_together(self.failures, self.alone_seconds):
                self.abort(exc)
            raise

    def abort(self, exc: Exception) -> None:
        """This rank failed alone: its error on stderr (one line; the traceback too when it is no
        CouplerError), in summary.json (rank 0 is stuck in a collective call and will not write
        it), and the MPI job aborted (mpirun ends every rank)."""
        r = self.comm.rank
        line = f"coupler rank {r}: {one_line(exc)}"
        self.summary.update(status=run_status(exc), error=f"{type(exc).__name__}: {line} (the other ranks went on)")
        write_summary(self.out, self.summary)
        if not isinstance(exc, CouplerError):
            traceback.print_exception(exc, file=sys.stderr)
        sys.stderr.write(f"varcouple: error: {line}; the other coupler ranks went on without it: the MPI job "
                         f"is aborted\n")
        sys.stderr.flush()
        self.comm.Abort(EXIT_CODES["failed"])

    # -- control verbs: every rank its served parts, rank 0 the processes ------------------
    def finish(self) -> None:
        for client in self.clients.values():
            client.finished = True  # the participants' tokens go: no warning on this rank
        self._control(self._finish)

    def save(self, window) -> None:
        self._control(self._checkpoint, "save_state", window)

    def restore(self, window) -> None:
        self._control(self._checkpoint, "restore_state", window)

    def _control(self, verb, *args) -> None:
        """``verb(*args, participants)`` of a control verb: on every rank for the participants served
        here (each rank its own part), on rank 0 for those started as processes."""
        participants = self.plan.participants
        agree(self.comm, verb, *args, [p for p in participants if p.in_process])
        self._on_root(verb, *args, [p for p in participants if not p.in_process])


class _Caller:
    """``phases.remote``'s view of a call: ``stats`` of the client, the call as a verb."""

    def __init__(self, fn, client):
        self.fn, self.stats = fn, client.stats

    def call(self, *args):
        return self.fn(*args)


def _joined(name: str, replies, held: Held, shapes: dict) -> dict[str, np.ndarray]:
    """The output fields at ``held.out_ids`` from this rank's parts (each checked: rank 0's fields,
    one row per id)."""
    for part, ids in zip(replies, held.ids):  # each part's outputs against the role's contract, rows its ids
        check_outputs(name, {k: np.asarray(f.data) for k, f in part.fields.items()}, len(ids))
    out = {}
    for k, (shape, dtype) in shapes.items():
        pieces = []
        for part, ids in zip(replies, held.ids):
            if k not in part.fields or len(part.fields) != len(shapes):
                raise part.fail(name, f"its fields {sorted(part.fields)} are not rank 0's {sorted(shapes)}")
            a = np.asarray(part.fields[k].data)
            if a.shape[:1] != ids.shape:
                raise part.fail(name, f"{k!r} has {a.shape[0] if a.ndim else 0} rows, its ids {len(ids)}")
            pieces.append(a)
        out[k] = np.concatenate(pieces) if pieces else np.zeros((0, *shape), dtype)
    return out


def _rows(per_part) -> np.ndarray:
    """An input given per part (a list of arrays) as one array of rows."""
    return np.concatenate(per_part) if len(per_part) else np.zeros(0)
