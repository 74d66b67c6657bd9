"""The coupler's side of the protocol (docs/protocol.md).

* :class:`CouplerSession` listens on a free loopback TCP port (chosen by the OS, retried if
  taken meanwhile, so parallel runs never collide), declares the coupler's liveliness token
  and hands out :class:`ParticipantClient`\\ s.
* :class:`ParticipantClient` calls one participant's verbs with a timeout per call and
  tracks its liveliness: a query to a participant that dies is answered by
  :class:`~coupler.protocol.errors.ParticipantDied` within a fraction of a second, not
  after the timeout. The timeout follows the work: it counts from the participant's latest
  progress message of the call (docs/protocol.md, "Progress"), so a slow solver that reports
  progress is never cut off and a silent one is.
"""

from __future__ import annotations

import json
import logging
import threading
import time
from typing import Callable, Iterable, Mapping

import zenoh

from coupler.protocol.errors import (ParticipantDied, ParticipantError, ParticipantFailure, ParticipantInputError,
                                     ParticipantStopped, ParticipantTimeout, ProtocolError)
from coupler.protocol.parts import Layout, Part
from coupler.protocol.transport import (COUPLER, DEFAULT_TIMEOUT, SHM_THRESHOLD, VERBS, alive_key, callback,
                                        check_name, is_shm, key, new_run_id, open_listening_session,
                                        open_session, part_key, payload_bytes, progress_key, warm_up_shm, zbytes)
from coupler.protocol.wire import Field, SolveReport, as_fields, check_finite, check_reply, decode, encode

log = logging.getLogger("varcouple.client")
#: zenoh's own limit on a query (a week): never reached; the wait follows the participant's
#: progress and cancels the query (a limit of the timeout would end a working solve that reports
#: progress as a zenoh "Timeout" error reply once the call outlasts it)
QUERY_SECONDS = 7 * 86400.0


class _Call:
    """One query of :meth:`ParticipantClient.exchange`: its key, replies and state."""

    def __init__(self, query_key: str):
        self.key, self.replies, self.done = query_key, [], threading.Event()
        self.cancel = zenoh.CancellationToken()
        self.nbytes = self.shm = 0


class ParticipantClient:
    """The coupler's handle on one participant: its verbs as methods.

    Every call is a zenoh query with a timeout (``timeout`` per call, else the client's), counted
    from the call's start or the participant's latest progress message for it, whichever is later.
    Liveliness is tracked by a subscriber on the participant's token: :attr:`alive`.
    A call to a participant that is dead, or dies while the call waits, raises
    :class:`ParticipantDied` at once (within ``poll`` seconds). ``process_check``:
    optional callable returning ``None`` while the participant's process runs and a
    reason (exit code, last log lines) once it has exited; it makes the messages
    precise and catches a process that dies before it ever comes alive. ``process_stopped``:
    optional callable returning why the participant's process is stopped (SIGSTOP: it answers
    nothing and its token goes), else ``None``: such a participant is reported as stopped, not
    died. ``waiting``: where a call that has waited ``note_every`` seconds says so, naming the
    participant, the request and the timeout, and again every ``note_every`` seconds (default:
    the log).

    Statistics of the calls are kept in :attr:`stats` (seconds, bytes each way, and the
    participant's own compute time reported in replies as ``elapsed``).
    """

    def __init__(self, session: zenoh.Session, run_id: str, name: str, timeout: float = DEFAULT_TIMEOUT,
                 *, process_check: Callable[[], str | None] | None = None,
                 process_stopped: Callable[[], str | None] | None = None,
                 waiting: Callable[[str], None] | None = None, note_every: float = 10.0, poll: float = 0.05,
                 shared_memory: bool = True):
        self.session = session
        self.run_id = check_name("run id", run_id)
        self.name = check_name("participant name", name)
        self.timeout = timeout
        self.process_check = process_check
        self.process_stopped = process_stopped
        self.waiting = waiting or log.info
        self.note_every = note_every
        self.poll = poll
        self.finished = False
        self.shared_memory = shared_memory
        self.last_solves: list[SolveReport] = []
        self.last_figures: dict[str, float] = {}
        self.stats = {"calls": 0, "seconds": 0.0, "remote_seconds": 0.0, "bytes_out": 0, "bytes_in": 0,
                      "shm_out": 0, "shm_in": 0}
        self._lock = threading.Lock()
        self._alive_event = threading.Event()
        self._alive = False
        self._lost_at: float | None = None
        #: ranks of the participant (its parts; from announce) and the layout of its fields (from geometry)
        self.parts: int | None = None
        self.layout: Layout | None = None
        #: on a coupler of several ranks: the participant's ranks this coupler rank talks to (None: all)
        self.mine: list[int] | None = None
        self._ranks_alive: set[int] = set()
        self._ranks_lost: set[int] = set()
        self._heard: tuple[float, dict] | None = None  # (when, what) of its latest progress message
        self._progress_sub = session.declare_subscriber(progress_key(run_id, name), callback(self._on_progress))
        self._sub = session.liveliness().declare_subscriber(
            alive_key(run_id, name), callback(self._on_liveliness), history=True)
        self._rank_sub = session.liveliness().declare_subscriber(
            f"{alive_key(run_id, name)}/*", callback(self._on_rank_liveliness), history=True)

    # -- liveliness
    def _on_liveliness(self, sample):
        with self._lock:
            if sample.kind == zenoh.SampleKind.PUT:
                self._alive = True
                self._alive_event.set()
            else:
                self._alive = False
                self._lost_at = time.monotonic()
        if sample.kind != zenoh.SampleKind.PUT and not self.finished:
            log.warning("participant %s: liveliness token lost", self.name)

    def _on_progress(self, sample):
        try:
            self._heard = (time.monotonic(), json.loads(payload_bytes(sample.payload)))
        except ValueError:
            log.warning("participant %s: malformed progress message ignored", self.name)

    def _progress_of(self, verb: str, header: Mapping | None, since: float) -> tuple[float, str] | None:
        """(when, message) of the participant's latest progress on this call (`verb` with `header`'s
        window and iteration, heard after `since`), or None."""
        heard = self._heard
        if heard is None or heard[0] < since:
            return None
        when, what = heard
        same = what.get("verb") == verb and all(what.get(k) == header[k] for k in ("window", "iteration")
                                                if header and k in header)
        return (when, str(what.get("message", ""))) if same else None

    def _on_rank_liveliness(self, sample):
        rank = int(str(sample.key_expr).rsplit("/", 1)[-1])
        with self._lock:
            if sample.kind == zenoh.SampleKind.PUT:
                self._ranks_alive.add(rank)
            else:
                self._ranks_alive.discard(rank)
                self._ranks_lost.add(rank)
        if sample.kind != zenoh.SampleKind.PUT and not self.finished:
            log.warning("participant %s: liveliness token of rank %d lost", self.name, rank)

    def _gone(self, reason: str) -> ParticipantFailure:
        """The error for a participant that stopped answering for `reason`: stopped when its
        process is (SIGSTOP), else died."""
        stopped = self.process_stopped() if self.process_stopped else None
        return ParticipantStopped(self.name, stopped) if stopped else ParticipantDied(self.name, reason)

    def _note_wait(self, verb: str, header: Mapping | None, waited: float, timeout: float,
                   progress: tuple[float, str] | None) -> None:
        """Say that `verb` has waited `waited` seconds for an answer, with the participant's latest
        `progress` (when, message) on it, or why it is silent when its process is stopped."""
        where = ", ".join(f"{k} {header[k]}" for k in ("window", "iteration") if header and k in header)
        if progress is not None:
            said = (f"; working, {time.monotonic() - progress[0]:.0f} s ago: {progress[1]} (the wait ends "
                    f"{timeout:g} s after its last progress: [messaging] timeout)")
        else:  # silent: why (a scan of /proc, only then)
            stopped = self.process_stopped() if self.process_stopped else None
            said = (f"; it is stopped: {stopped}" if stopped else "; no progress reported") + \
                f" (the wait ends at {timeout:g} s without progress: [messaging] timeout)"
        self.waiting(f"waiting for participant {self.name!r}: no answer to {verb!r}" + (f" ({where})" if where else "")
                     + f" for {waited:.0f} s" + said)

    @property
    def alive(self) -> bool:
        """The participant's liveliness token is present."""
        return self._alive

    @property
    def ever_alive(self) -> bool:
        return self._alive_event.is_set()

    def _death_reason(self, grace: float = 2.0) -> str | None:
        """Why the participant is gone (its process's exit and last log lines when known), or None.
        A token lost while the process still runs gets `grace` seconds to show how it ended."""
        reason = self.process_check() if self.process_check else None
        if reason:
            return reason
        if self.ever_alive and not self._alive:
            end = time.monotonic() + (grace if self.process_check else 0.0)
            while time.monotonic() < end:
                time.sleep(0.05)
                reason = self.process_check()
                if reason:
                    return reason
            return "its liveliness token disappeared (process exited or connection lost)"
        return None

    def wait_alive(self, timeout: float | None = None) -> None:
        """Wait until the participant's token appears; :class:`ParticipantDied` if its
        process exits first, :class:`ParticipantTimeout` (verb ``"start"``) after
        ``timeout`` seconds (default: the client's)."""
        timeout = self.timeout if timeout is None else timeout
        deadline = time.monotonic() + timeout
        while not self._alive:
            reason = self._death_reason()
            if reason:
                raise self._gone(reason)
            left = deadline - time.monotonic()
            if left <= 0:
                raise ParticipantTimeout(self.name, "start", timeout)
            self._alive_event.wait(min(self.poll * 2, left))

    # -- calls
    def request(self, verb: str, header: Mapping | None = None, fields=None,
                timeout: float | None = None) -> tuple[dict, dict[str, Field]]:
        """Send ``verb`` with ``header`` and ``fields``; return the checked reply
        ``(header, fields)``. Raises :class:`ParticipantError` (the participant answered
        an error), :class:`ParticipantDied`, :class:`ParticipantTimeout`,
        :class:`ProtocolError` (a reply that does not answer the request),
        :class:`transfer.errors.FieldError` (NaN/inf in an input field)."""
        part = self.exchange(verb, header, [fields], timeout)[0]
        return part.header, part.fields

    def exchange(self, verb: str, header: Mapping | None, parts: list, timeout: float | None = None,
                 before_root: Callable[[], None] | None = None) -> list[Part]:
        """Send ``verb`` with ``header`` to each rank, with ``parts[r]`` (rank r's fields): rank 0 on
        the verb's key, rank r >= 1 on its part key (docs/protocol.md, "Parts"), those first; return
        every rank's checked reply (see :meth:`request` for the errors; a rank's names it and its key).
        On a coupler of several ranks only the ranks :attr:`mine` are sent to and answer here, and
        `before_root` (a barrier of the coupler's ranks) runs after their queries, before rank 0's."""
        if verb not in VERBS:
            raise ProtocolError(f"unknown verb {verb!r}")
        timeout = self.timeout if timeout is None else timeout
        t0 = time.perf_counter()
        if not self._alive:
            reason = self._death_reason()
            if reason:
                raise self._gone(reason)
            self.wait_alive(timeout)
        ranks = [r for r in range(len(parts)) if self.mine is None or r in self.mine]
        self._wait_ranks([r for r in ranks if r], timeout)
        req = {**(header or {}), "run_id": self.run_id, "participant": self.name, "verb": verb}
        payloads = {r: encode(req, parts[r]) for r in ranks}
        calls = {r: self._query(part_key(self.run_id, self.name, verb, r), payloads[r], timeout)
                 for r in reversed(ranks) if r}
        if before_root is not None:
            before_root()
        if 0 in ranks:  # rank 0's request last: it broadcasts the verb to the others
            calls[0] = self._query(key(self.run_id, self.name, verb), payloads[0], timeout)
        calls = dict(sorted(calls.items()))
        start = time.monotonic()
        note = start + self.note_every
        try:
            while pending := [c for c in calls.values() if not c.done.is_set()]:  # one look at each
                if pending[0].done.wait(self.poll):
                    continue
                for r, c in calls.items():  # a rank that died first is named (mpirun then ends the others)
                    if r and ((c.done.is_set() and not c.replies) or r in self._ranks_lost):
                        raise self._gone(self._rank_gone(r, c.key))
                if not self._alive:
                    raise self._gone(self._death_reason() or f"lost while answering {verb!r}")
                if self.process_check and (reason := self.process_check()):
                    raise ParticipantDied(self.name, reason)
                now, progress = time.monotonic(), self._progress_of(verb, header, start)
                if now > (progress[0] if progress else start) + timeout:  # silent for `timeout` seconds
                    raise ParticipantTimeout(self.name, verb, timeout, progress is not None)
                if now > note:
                    self._note_wait(verb, header, now - start, timeout, progress)
                    note += self.note_every
        except BaseException:
            for c in calls.values():
                c.cancel.cancel()
            raise
        out = [self._checked(r, c, req, verb) for r, c in calls.items()]
        first = out[0].header if out and out[0].rank == 0 else {}
        st = self.stats
        st["calls"] += 1
        st["seconds"] += time.perf_counter() - t0
        st["remote_seconds"] += float(first.get("elapsed", 0.0))
        st["bytes_out"] += sum(len(p) for p in payloads.values())
        st["bytes_in"] += sum(c.nbytes for c in calls.values())
        st["shm_out"] += bool(first.get("rx_shm"))
        st["shm_in"] += sum(c.shm for c in calls.values())
        return out

    def _wait_ranks(self, ranks: list[int], timeout: float) -> None:
        """Wait until the tokens of `ranks` (>= 1) are seen (rank 0 declares its own after their
        queryables, but each travels on its rank's session); a lost one is :meth:`_rank_gone`."""
        deadline = time.monotonic() + timeout
        while missing := [r for r in ranks if r not in self._ranks_alive]:
            lost = [r for r in missing if r in self._ranks_lost]
            if lost:
                raise self._gone(self._rank_gone(lost[0], part_key(self.run_id, self.name, "*", lost[0])))
            if time.monotonic() > deadline:
                raise ParticipantTimeout(self.name, f"start of rank {missing[0]}", timeout)
            time.sleep(0.01)

    def _query(self, query_key: str, payload, timeout: float) -> "_Call":
        call = _Call(query_key)
        self.session.get(query_key, callback(call.replies.append, call.done.set),
                         payload=zbytes(payload, self.shared_memory),
                         timeout=QUERY_SECONDS,  # the wait in :meth:`exchange` decides; it cancels the query
                         cancellation_token=call.cancel)
        return call

    def _rank_gone(self, rank: int, query_key: str) -> str:
        """Why rank ``rank`` gave no reply on ``query_key`` (its process or connection gone)."""
        end = time.monotonic() + 2.0
        while rank not in self._ranks_lost and time.monotonic() < end and not self._death_reason(grace=0.0):
            time.sleep(0.01)
        reason = self._death_reason()
        return (f"rank {rank} gave no reply on {query_key}"
                + (" (its liveliness token is gone)" if rank in self._ranks_lost else "")
                + (f": {reason}" if reason else ""))

    def _checked(self, rank: int, call: "_Call", req: dict, verb: str) -> Part:
        where = f"rank {rank} ({call.key})"
        if not call.replies:
            if rank:
                raise self._gone(self._rank_gone(rank, call.key))
            # zenoh ends a query without reply when the participant's session goes away;
            # its liveliness token follows within milliseconds.
            end = time.monotonic() + 2.0
            while self._alive and time.monotonic() < end and not self._death_reason():
                time.sleep(0.01)
            reason = self._death_reason()
            if reason or not self._alive:
                raise self._gone(reason or f"no reply to {verb!r}")
            raise ProtocolError(f"participant {self.name!r} gave no reply to {verb!r} (no queryable)")
        if len(call.replies) > 1:
            raise ProtocolError(f"{len(call.replies)} processes answered {verb!r} as participant {self.name!r}, "
                                f"{where}")
        reply = call.replies[0]
        if reply.ok is None:
            err = reply.err.payload.to_string() if reply.err is not None else "unknown"
            raise ProtocolError(f"participant {self.name!r}: zenoh error reply to {verb!r} from {where}: {err}")
        data = payload_bytes(reply.ok.payload)
        call.nbytes = len(data)
        call.shm = is_shm(reply.ok.payload) if len(data) >= SHM_THRESHOLD else 0
        try:
            rheader, rfields = decode(data)
        except ProtocolError as exc:
            raise ProtocolError(f"participant {self.name!r}, {where}: {exc}") from None
        if "error" in rheader:
            error = ParticipantInputError if rheader.get("input") is True else ParticipantError
            raise error(self.name, str(rheader["error"]) if not rank else f"{where}: {rheader['error']}")
        try:
            check_reply(req, rheader)
        except ProtocolError as exc:
            raise ProtocolError(f"{exc} ({where})" if rank else str(exc)) from None
        return Part(rank, call.key, rheader, rfields)

    def announce(self, timeout: float | None = None) -> dict:
        """The participant's self-description (``name, kind, pid, ranks, parts, provides, accepts``)."""
        header, _ = self.request("announce", timeout=timeout)
        self.parts = int(header.get("parts", 1))
        return {k: v for k, v in header.items() if k not in ("run_id", "participant", "verb", "arrays", "v", "elapsed")}

    def configure(self, config: Mapping, timeout: float | None = None) -> None:
        self.request("configure", {"config": dict(config)}, timeout=timeout)

    def _count_parts(self, timeout: float | None) -> int:
        if self.parts is None:
            self.announce(timeout)
        return self.parts

    def geometry(self, timeout: float | None = None) -> tuple[dict, dict[str, Field]]:
        """The header and arrays of the participant's geometry, its parts joined
        (:meth:`coupler.protocol.parts.Layout.join_geometry`): the layout of its fields is kept for
        :meth:`advance`."""
        parts = self.exchange("geometry", None, [None] * self._count_parts(timeout), timeout)
        self.layout, fields = Layout.join_geometry(self.name, parts)
        header = parts[0].header
        return {k: v for k, v in header.items() if k not in ("run_id", "participant", "verb", "arrays", "v", "elapsed")}, fields

    def advance(self, window: int, iteration: int, t: float, dt: float, inputs=None,
                timeout: float | None = None) -> dict[str, Field]:
        """The participant's output fields (its parts joined); how its inner solves ended and its
        figures of the step are in :attr:`last_solves` and :attr:`last_figures` until the next call."""
        inputs = as_fields(inputs)
        for f in inputs:  # refused before anything goes out (announce included)
            check_finite(f.name, f.data)
        count = self._count_parts(timeout)
        if self.layout is None and count > 1:
            raise ProtocolError(f"participant {self.name!r} on {count} ranks: advance before geometry "
                                f"(the layout of its parts comes from geometry)")
        parts = self.layout.split({f.name: f for f in inputs}) if self.layout is not None else [inputs]
        replies = self.exchange(
            "advance", {"window": int(window), "iteration": int(iteration), "t": float(t), "dt": float(dt)},
            parts, timeout=timeout)
        self.last_solves, self.last_figures = step_reports(replies[0].header)
        return self.layout.join(replies) if self.layout is not None else replies[0].fields

    def save_state(self, window: int, timeout: float | None = None) -> None:
        self.request("save_state", {"window": int(window)}, timeout=timeout)

    def restore_state(self, window: int, timeout: float | None = None) -> None:
        self.request("restore_state", {"window": int(window)}, timeout=timeout)

    def finish(self, timeout: float | None = None) -> None:
        """Ask the participant to finish; it exits after replying."""
        self.finished = True
        try:
            self.request("finish", timeout=timeout)
        except BaseException:
            self.finished = False
            raise

    def close(self) -> None:
        for sub in (self._sub, self._rank_sub, self._progress_sub):
            try:
                sub.undeclare()
            except Exception:  # noqa: BLE001
                pass
        self._sub = self._rank_sub = self._progress_sub = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


# ----------------------------------------------------------------------------- coupler side

class CouplerSession:
    """The coupler's zenoh session: listens where participants connect, declares the
    coupler's liveliness token and makes :class:`ParticipantClient`\\ s.

    Default: peer mode on ``tcp/127.0.0.1:<free port>``; :attr:`endpoints` is what to
    pass to participants as ``--connect``. For several hosts, ``listen_host="0.0.0.0"``
    (and ``advertise`` = this host's address for the participants), or ``connect`` to
    zenoh routers (``mode="client"`` or ``"peer"``): participants then connect to the
    same routers.
    """

    def __init__(self, run_id: str | None = None, *, mode: str = "peer", listen_host: str | None = "127.0.0.1",
                 port: int | None = None, connect: Iterable[str] = (), advertise: str | None = None,
                 shared_memory: bool = True, token: bool = True, **kwargs):
        self.run_id = check_name("run id", run_id or new_run_id())
        connect = list(connect)
        if listen_host is not None and mode != "client":
            self.session, endpoint = open_listening_session(
                listen_host, port, mode=mode, connect=connect, shared_memory=shared_memory, **kwargs)
            if advertise:
                endpoint = endpoint.replace(listen_host, advertise, 1)
            self.endpoints = [endpoint] + connect
        else:
            self.session = open_session(mode=mode, connect=connect, shared_memory=shared_memory, **kwargs)
            self.endpoints = connect
        self.shared_memory = shared_memory
        if shared_memory:
            warm_up_shm()  # the first large request must not pay for the pool
        # the participants watch this token: a coupler rank other than 0 declares none (token=False)
        self._token = self.session.liveliness().declare_token(alive_key(self.run_id, COUPLER)) if token else None
        self.clients: dict[str, ParticipantClient] = {}

    def client(self, name: str, timeout: float = DEFAULT_TIMEOUT, **kwargs) -> ParticipantClient:
        kwargs.setdefault("shared_memory", self.shared_memory)
        c = ParticipantClient(self.session, self.run_id, name, timeout, **kwargs)
        self.clients[name] = c
        return c

    def close(self) -> None:
        for c in self.clients.values():
            c.close()
        try:
            if self._token is not None:
                self._token.undeclare()
        except Exception:  # noqa: BLE001
            pass
        try:
            self.session.close()
        except Exception:  # noqa: BLE001
            pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def step_reports(header: Mapping) -> tuple[list[SolveReport], dict[str, float]]:
    """How a participant's inner solves of an advance ended and its figures of the step, from
    rank 0's reply header (the participant's ranks solve together: rank 0 speaks for them)."""
    return ([SolveReport.from_dict(d) for d in header.get("solves", [])],
            {str(k): float(v) for k, v in header.get("figures", {}).items()})
