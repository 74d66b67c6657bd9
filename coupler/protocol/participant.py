"""The participant side of the protocol (docs/protocol.md): the interface every solver
implements, and :func:`main`, the entry point of every participant process.

A participant module ends with::

    from coupler.protocol.participant import Participant, main

    class MySolver(Participant):
        ...

    if __name__ == "__main__":
        main(MySolver)

and the coupler starts it as ``[mpirun -n N] python -m my_module --run-id R --name NAME
--connect tcp/127.0.0.1:PORT`` (see :class:`coupler.launch.Launcher`).

MPI: when the process is one of several MPI ranks, every rank has its own zenoh session; rank 0
serves the verbs and broadcasts each (its header, never the inputs) to the other ranks, which call
the same method of their own participant object (so collective solver code runs on all ranks).
``geometry`` and ``advance`` are answered per rank: each rank takes the coupler's request for its
part (its own rows of the inputs) and answers with its own part (docs/protocol.md, "Parts"); the
other verbs' reply is rank 0's return value. A non-root rank whose method raises aborts
the MPI job (the coupler then sees the participant die, with the log), unless the ranks agreed on
the failure (:func:`agree`: :class:`~coupler.protocol.errors.RanksError`, every rank's error reply).
Between verbs the other ranks sleep (:func:`idle_barrier`) instead of spinning in the broadcast: a
waiting rank leaves its core to the solvers that run meanwhile (the other participant, its ranks).
"""

from __future__ import annotations

import abc
import argparse
import logging
import os
import signal
import sys
import tempfile
import time
from pathlib import Path
from typing import Callable, Mapping

from coupler.errors import CouplerError
from coupler.protocol.errors import ProtocolError, RanksError
from coupler.protocol.transport import PART_VERBS
from coupler.protocol.wire import Field, SolveReport

log = logging.getLogger("varcouple.participant")


def scratch_dir(run_id: str, name: str) -> Path:
    """A new temporary directory (under ``TMPDIR``) for participant ``name`` of run ``run_id``,
    named ``varcouple-<run_id>-<name>-XXXXXXXX`` so that :meth:`Launcher.stop_all` can remove
    it when the participant could not (SIGKILL)."""
    return Path(tempfile.mkdtemp(prefix=f"varcouple-{run_id}-{name}-"))


class Participant(abc.ABC):
    """What a participant does for each verb of the protocol (docs/protocol.md).

    Before the first verb, :func:`main` sets ``run_id``, ``name``, ``comm`` (an
    ``mpi4py`` communicator, or ``None`` for a single process), ``rank``, ``size`` and
    ``extra_args`` (command-line arguments :func:`main` did not know). An exception
    raised by a method is sent to the coupler as an error reply
    (``ParticipantError(name, "<Type>: <message>")``); the participant keeps serving.

    During ``advance`` a participant reports every inner solve with :meth:`report_solve`
    (converged or not, iterations, final residual against its tolerance) and may add
    scalar figures of the step with :meth:`report_figures`; both travel in the reply's
    header (``solves``, ``figures``) and end up in summary.json. A solve that did not
    converge is reported, not raised: the coupler decides what the run may claim.
    """

    run_id: str = ""
    name: str = ""
    comm = None
    rank: int = 0
    size: int = 1
    extra_args: list[str] = []

    def report_solve(self, solver: str, converged: bool, iterations: int, residual: float, tolerance: float,
                     detail: str = "", accepted: bool = False, history=()) -> SolveReport:
        """Record how an inner solve of the current ``advance`` ended (see :class:`SolveReport`)."""
        report = SolveReport(solver, bool(converged), int(iterations), float(residual), float(tolerance), detail,
                             bool(accepted), tuple(float(h) for h in history))
        self.__dict__.setdefault("_solves", []).append(report)
        return report

    def report_figures(self, **figures: float) -> None:
        """Record scalar figures of the current ``advance`` (e.g. contact area fraction)."""
        self.__dict__.setdefault("_figures", {}).update({k: float(v) for k, v in figures.items()})

    def take_reports(self) -> tuple[list[SolveReport], dict[str, float]]:
        """The solves and figures reported since the last call (the server sends them with the reply)."""
        solves, figures = self.__dict__.pop("_solves", []), self.__dict__.pop("_figures", {})
        return solves, figures

    def bind(self, run_id: str, name: str, comm=None, extra_args=()) -> None:
        """Called by :func:`main` before serving."""
        self.run_id, self.name, self.comm = run_id, name, comm
        self.rank = comm.Get_rank() if comm is not None else 0
        self.size = comm.Get_size() if comm is not None else 1
        self.extra_args = list(extra_args)

    @abc.abstractmethod
    def announce(self) -> dict:
        """Verb ``announce``: describe this participant.

        Return ``{"kind": str, "provides": [field names], "accepts": [field names]}``
        and anything else useful; ``name``, ``pid`` and ``ranks`` are filled in."""

    @abc.abstractmethod
    def configure(self, config: dict) -> None:
        """Verb ``configure``: this participant's part of the scene (a JSON object)."""

    @abc.abstractmethod
    def geometry(self) -> tuple[dict, Mapping[str, Field] | None]:
        """Verb ``geometry``: the mesh or grid the participant's fields live on.

        Either ``({"cell_type": ..., "boundaries": {...}}, {"points": (n,3), "cells": (m,k)})``
        or ``({"grid": {"origin": [...], "spacing": [...], "shape": [...]}}, None)``. On several
        ranks, each rank's part with its ids (``point_ids``, ``cell_ids``; docs/protocol.md,
        "Parts"): ``advance`` then gets and returns the rows of those ids."""

    @abc.abstractmethod
    def advance(self, window: int, iteration: int, t: float, dt: float,
                inputs: Mapping[str, Field]) -> Mapping[str, Field]:
        """Verb ``advance``: solve time window ``window`` (from ``t`` to ``t + dt``),
        fixed-point iteration ``iteration``, with the coupler's ``inputs``; return the
        output fields (a mapping of name to :class:`Field` or array).

        Input arrays are read-only views of the received message: copy to keep them.
        The state the participant advances from is its current state: the coupler calls
        :meth:`restore_state` before repeating a window."""

    def input_problem(self, inputs: Mapping[str, Field]) -> str | None:
        """Why this rank cannot take ``inputs`` for ``advance`` (None: it can), e.g. rows missing
        from its part. On several ranks every rank asks before ``advance`` and the ranks agree,
        so one rank's problem becomes every rank's error reply naming it (instead of that rank
        failing alone inside the solver's collective code)."""
        return None

    def save_state(self, window: int) -> None:
        """Verb ``save_state``: checkpoint the state at the start of ``window``
        (implicit coupling). Repeating a window after :meth:`restore_state` must give
        identical outputs."""
        raise NotImplementedError(f"{type(self).__name__} does not support checkpoints (save_state)")

    def restore_state(self, window: int) -> None:
        """Verb ``restore_state``: go back to the state saved for ``window``."""
        raise NotImplementedError(f"{type(self).__name__} does not support checkpoints (restore_state)")

    def finish(self) -> None:
        """Verb ``finish``: release resources; the process exits after the reply."""


# ------------------------------------------------------------------------------ MPI

_VERB_METHODS = ("announce", "configure", "geometry", "advance", "save_state", "restore_state", "finish")


def _mpi_world_size() -> int:
    for var in ("OMPI_COMM_WORLD_SIZE", "PMI_SIZE", "PMIX_SIZE", "MPI_LOCALNRANKS"):
        if os.environ.get(var, "").isdigit():
            return int(os.environ[var])
    return 1


#: seconds a rank waits for the coupler's request for its part once rank 0 has the verb (the
#: coupler sends the ranks' requests before rank 0's: they are normally there already)
PART_WAIT = 30.0


def _problems(comm, problem: str | None) -> str | None:
    """Every rank's problem (None: none), gathered on every rank: ``rank r: <problem>; ...`` or None."""
    problems = [(r, p) for r, p in enumerate(comm.allgather(problem)) if p]
    return "; ".join(f"rank {r}: {p}" for r, p in problems) or None


def agree(comm, problem: str | None, error: type[Exception] = RanksError) -> None:
    """Every rank of ``comm`` learns each rank's ``problem`` (None: it has none; collective, the
    ranks that come first sleep in :func:`idle_barrier`) and, when any rank has one, raises
    `error` naming each such rank: so no rank goes on alone into collective code, and every rank
    answers the verb with that error instead of aborting the MPI job (a :class:`ProtocolError`
    when a rank lacks its request, a :class:`RanksError` when the work failed on a rank)."""
    idle_barrier(comm)
    if (text := _problems(comm, problem)) is not None:
        raise error(text)


def on_root(comm, work, *args):
    """``work(*args)`` run by rank 0 of ``comm`` alone, its result returned on every rank (the
    others sleep meanwhile, :func:`idle_barrier`); its exception is raised on rank 0 as it is and
    is the other ranks' :class:`RanksError`. ``comm`` None: ``work(*args)``."""
    if comm is None:
        return work(*args)
    out = error = None
    if comm.Get_rank() == 0:
        try:
            out = work(*args)
        except Exception as exc:  # noqa: BLE001 - shared with the other ranks, raised below
            error = exc
    idle_barrier(comm)
    out, text = comm.bcast((out, None if error is None else f"{type(error).__name__}: {error}"), root=0)
    if error is not None:
        raise error
    if text is not None:
        raise RanksError(f"rank 0: {text}")
    return out


def on_each(comm, work, *args):
    """``work(*args)`` on every rank of ``comm``; a rank's exception is every rank's
    :class:`RanksError` naming it (:func:`agree`). ``comm`` None: ``work(*args)``."""
    if comm is None:
        return work(*args)
    out = problem = None
    try:
        out = work(*args)
    except Exception as exc:  # noqa: BLE001 - agreed below
        problem = f"{type(exc).__name__}: {exc}"
    agree(comm, problem)
    return out


class _MpiRoot:
    """Rank 0's handler: broadcasts each call (a small header, never the inputs) to the other
    ranks, then runs it. Rank 0's part of ``geometry`` and ``advance`` is its reply; the other
    ranks answer their own parts (:class:`coupler.protocol.server.PartServer`)."""

    def __init__(self, handler: Participant, comm):
        self.handler, self.comm = handler, comm

    def take_reports(self):  # rank 0's own reports: nothing to broadcast
        return self.handler.take_reports()

    def __getattr__(self, verb):
        if verb not in _VERB_METHODS:
            raise AttributeError(verb)
        method = getattr(self.handler, verb)

        def call(*args):
            self._send((verb, args[:4] if verb == "advance" else args))  # rank 0's inputs stay here
            if verb in PART_VERBS:
                agree(self.comm, self.handler.input_problem(args[4]) if verb == "advance" else None, ProtocolError)
            return method(*args)

        return call

    def _send(self, message):
        self.comm.Ibarrier().Wait()  # the other ranks wait in theirs (idle_barrier)
        self.comm.bcast(message, root=0)

    def stop(self):
        self._send(("__stop__", ()))


def idle_barrier(comm, poll: float = 1e-3, seconds: float | None = None) -> bool:
    """Wait until every rank of ``comm`` has come here (rank 0 with its next call to broadcast),
    sleeping between tests of a nonblocking barrier: Open MPI's blocking collectives poll without
    yielding, so a rank waiting in ``bcast`` for the next verb (or for rank 0's solver) would take
    a core for the whole of the other participants' solves. With `seconds`, give up after that
    long: False when some rank did not come."""
    request = comm.Ibarrier()
    deadline = None if seconds is None else time.monotonic() + seconds
    while not request.Test():
        if deadline is not None and time.monotonic() > deadline:
            return False
        time.sleep(poll)
    return True


def _mpi_worker(handler: Participant, comm, parts) -> None:
    """A rank other than 0: run each verb rank 0 broadcasts; for :data:`PART_VERBS` take this
    rank's request from ``parts`` (a :class:`~coupler.protocol.server.PartServer`) and answer it
    with this rank's part."""
    while True:
        idle_barrier(comm)
        verb, args = comm.bcast(None, root=0)
        if verb == "__stop__":
            return
        request = None
        if verb in PART_VERBS:
            expect = {"window": args[0], "iteration": args[1]} if verb == "advance" else {}
            problem = None
            try:
                request = parts.take(verb, expect, PART_WAIT)
                if verb == "advance" and (problem := handler.input_problem(request[3])):
                    problem = f"{parts.key(verb)}: {problem}"
            except ProtocolError as exc:
                problem = str(exc)
            try:
                agree(comm, problem, ProtocolError)
            except ProtocolError as exc:
                if request is not None:
                    parts.reply(*request[:3], error=exc)
                continue
            if verb == "advance":
                args = (*args, request[3])
        try:
            out = getattr(handler, verb)(*args)
            handler.take_reports()  # rank 0 reports for all ranks
        except RanksError as exc:  # every rank has it (agree): rank 0 answers it too
            handler.take_reports()
            if request is not None:
                parts.reply(*request[:3], error=exc)
            continue
        except Exception:  # noqa: BLE001
            log.exception("rank %d: %s failed; aborting the MPI job", comm.Get_rank(), verb)
            comm.Abort(1)
        if request is not None:
            header, fields = out if verb == "geometry" else ({}, out)
            parts.reply(*request[:3], header=header, fields=fields)
        if verb == "finish":
            return


# ------------------------------------------------------------------------------ main

class _Terminated(BaseException):
    def __init__(self, signum):
        self.signum = signum
        super().__init__(signal.Signals(signum).name)


def _on_signal(signum, frame):
    raise _Terminated(signum)


def build_parser(prog: str | None = None) -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog=prog, description="A varcouple participant process (docs/protocol.md).")
    p.add_argument("--run-id", required=True, help="run id of the coupled run (key prefix varcouple/<run-id>/)")
    p.add_argument("--name", required=True, help="this participant's name in the run")
    p.add_argument("--connect", action="append", default=[], metavar="ENDPOINT",
                   help="zenoh endpoint to connect to, e.g. tcp/127.0.0.1:7447 (repeatable)")
    p.add_argument("--coupler-rank", action="append", default=[], metavar="ENDPOINT",
                   help="the endpoint of each rank of a coupler on several ranks, in rank order (repeatable): "
                        "rank 0 connects to every one, rank r to coupler rank 0's and rank r mod P's, "
                        "besides --connect")
    p.add_argument("--listen", action="append", default=[], metavar="ENDPOINT",
                   help="zenoh endpoint to listen on (repeatable; rarely needed)")
    p.add_argument("--mode", default="peer", choices=["peer", "client"], help="zenoh mode (default: peer)")
    p.add_argument("--no-shm", action="store_true", help="disable zenoh's shared-memory transport")
    p.add_argument("--connect-timeout", type=float, default=10.0, help="seconds to reach the coupler (default 10)")
    p.add_argument("--log-file", help="also write this process's log to this file")
    p.add_argument("--log-level", default=os.environ.get("VARCOUPLE_LOG_LEVEL", "INFO"))
    return p


def _setup_logging(args, rank: int) -> None:
    fmt = f"%(asctime)s {args.name}[{rank}] %(levelname)s %(name)s: %(message)s"
    handlers: list[logging.Handler] = [logging.StreamHandler(sys.stderr)]
    if args.log_file:
        handlers.append(logging.FileHandler(args.log_file))
    logging.basicConfig(level=args.log_level.upper(), format=fmt, handlers=handlers, force=True)


def run(participant_factory: Callable[[], Participant], argv=None, prog: str | None = None) -> int:
    """Parse ``argv``, serve the participant made by ``participant_factory()``, return the
    exit code: 0 after ``finish``, 1 on an error, 128 + signal number on SIGTERM/SIGINT."""
    args, extra = build_parser(prog).parse_known_args(argv)
    from coupler.protocol.server import CouplerGone, ParticipantServer, PartServer
    from coupler.protocol.transport import check_name, open_session, part_links

    size = _mpi_world_size()
    comm = None
    if size > 1:
        from mpi4py import MPI

        comm = MPI.COMM_WORLD
    rank = comm.Get_rank() if comm is not None else 0
    _setup_logging(args, rank)
    who = f"participant {args.name!r}"
    old = {s: signal.signal(s, _on_signal) for s in (signal.SIGTERM, signal.SIGINT)}
    session = server = None
    handler = None
    try:
        check_name("run id", args.run_id)
        check_name("participant name", args.name)
        connect = list(dict.fromkeys(args.connect + part_links(args.coupler_rank, rank)))
        if not connect and not args.listen:
            raise CouplerError("give at least one --connect ENDPOINT (where the coupler listens)")
        handler = participant_factory()
        handler.bind(args.run_id, args.name, comm, extra)
        t0 = time.perf_counter()
        # every rank has its own session (its parts travel from it); only rank 0 listens where asked
        session = open_session(args.mode, connect, args.listen if rank == 0 else (), not args.no_shm,
                               connect_timeout=args.connect_timeout)
        log.info("%s: zenoh session open (%s) in %.2f s, pid %d, rank %d of %d",
                 who, ", ".join(connect + args.listen), time.perf_counter() - t0, os.getpid(), rank, size)
        if rank != 0:
            server = PartServer(session, args.run_id, args.name, rank, shared_memory=not args.no_shm)
            comm.Barrier()  # every rank's queryables before rank 0's liveliness token
            _mpi_worker(handler, comm, server)
            return 0
        if comm is not None:
            comm.Barrier()
        server = ParticipantServer(session, args.run_id, args.name,
                                   _MpiRoot(handler, comm) if comm is not None else handler,
                                   extra_announce={"ranks": size, "parts": size}, shared_memory=not args.no_shm)
        server.serve_forever()
        log.info("%s: finished", who)
        return 0
    except _Terminated as exc:
        log.warning("%s: %s received, exiting", who, exc)
        return 128 + exc.signum
    except CouplerGone as exc:
        print(f"varcouple: {who}: error: {exc}", file=sys.stderr)
        return 1
    except Exception as exc:  # noqa: BLE001 - one clear line, the traceback in the log
        log.debug("traceback", exc_info=True)
        print(f"varcouple: {who}: error: {type(exc).__name__}: {exc}", file=sys.stderr)
        return 1
    finally:
        for s in old:  # a second signal must not interrupt the cleanup
            signal.signal(s, signal.SIG_IGN)
        if comm is not None and rank == 0 and handler is not None and not (server and server.finished):
            try:  # release the other ranks waiting for the next verb
                _MpiRoot(handler, comm).stop()
            except Exception:  # noqa: BLE001
                pass
        if server is not None:
            server.close()
        if session is not None:
            try:
                session.close()
            except Exception:  # noqa: BLE001
                pass
        for s, h in old.items():
            signal.signal(s, h)


def main(participant_factory: Callable[[], Participant], argv=None, prog: str | None = None):
    """Entry point of a participant process: :func:`run`, then exit with its code
    (never returns)."""
    code = run(participant_factory, argv, prog)
    logging.shutdown()
    sys.stdout.flush()
    sys.stderr.flush()
    raise SystemExit(code)
