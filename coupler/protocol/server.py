"""The participant's side of the protocol (docs/protocol.md): :class:`ParticipantServer`
serves one participant's verbs: one queryable per verb, a liveliness token, and a loop that
runs the handler's methods in the calling (main) thread and answers each query, errors
included; while a verb runs, its log records are published as progress (:class:`Progress`)."""

from __future__ import annotations

import json
import logging
import os
import queue
import time
from typing import Mapping

import zenoh

from .errors import InputError, ProtocolError
from .transport import (COUPLER, PART_VERBS, SHM_THRESHOLD, VERBS, alive_key, callback, check_name, is_shm, key,
                        part_key, payload_bytes, progress_key, rank_alive_key, warm_up_shm, zbytes)
from .wire import Field, as_fields, decode, encode, json_number

log = logging.getLogger("varcouple.server")

#: at most one progress message per this many seconds (docs/protocol.md, "Progress")
PROGRESS_EVERY = 0.5

class _Stop:
    def __init__(self, reason: str):
        self.reason = reason


def answer(query, reply_key: str, base: dict, shared_memory: bool, run) -> None:
    """Decode ``query``, reply ``run(request, fields)`` -> ``(header, fields)`` under ``reply_key``
    with ``base`` (run id, participant, verb; :func:`send_reply`); any failure becomes an error
    reply ``{"error": "<Type>: <message>"}`` (never raises for them)."""
    t0 = time.perf_counter()
    header = out = error = None
    try:
        request, fields = request_of(query, base)
        header, out = run(request, fields)
    except (Exception, SystemExit) as exc:  # noqa: BLE001 - every failure becomes an error reply
        # (SystemExit: library code that calls sys.exit, e.g. meshio on a file no reader accepts)
        error = exc
    send_reply(query, reply_key, base, shared_memory, t0, header, out, error)


def request_of(query, base: dict) -> tuple[dict, dict[str, Field]]:
    """The request header and fields of ``query``; copies its window and iteration into the
    reply's ``base``; ProtocolError when it was meant for another run, participant or verb."""
    if query.payload is not None and len(query.payload) >= SHM_THRESHOLD:
        base["rx_shm"] = is_shm(query.payload)
    request, fields = decode(payload_bytes(query.payload)) if query.payload else ({}, {})
    for k in ("window", "iteration"):
        if k in request:
            base[k] = request[k]
    for k in ("run_id", "participant", "verb"):
        if k in request and request[k] != base[k]:
            raise ProtocolError(f"request for {k}={request[k]!r} reached {base[k]!r}")
    return request, fields


def send_reply(query, reply_key: str, base: dict, shared_memory: bool, t0: float, header=None, fields=None,
               error: BaseException | None = None) -> None:
    """Reply ``header`` and ``fields`` (or ``error``) to ``query`` with ``base`` and ``elapsed``
    (seconds since ``t0``); a reply that cannot be encoded (NaN in a field) becomes the error."""
    payload = None
    if error is None:
        try:
            payload = encode({**(header or {}), **base, "elapsed": time.perf_counter() - t0}, fields)
        except (Exception, SystemExit) as exc:  # noqa: BLE001
            error = exc
    if error is not None:
        log.error("%s: %s failed: %s: %s", base["participant"], reply_key, type(error).__name__, error,
                  exc_info=error)
        payload = encode({**base, "elapsed": time.perf_counter() - t0, "error": f"{type(error).__name__}: {error}",
                          **({"input": True} if isinstance(error, InputError) else {})})
    try:
        query.reply(reply_key, zbytes(payload, shared_memory))
    finally:
        query.drop()
    log.debug("%s: %s answered in %.3f s (%d bytes)", base["participant"], reply_key, time.perf_counter() - t0,
              len(payload))


class Progress(logging.Handler):
    """While a verb runs: the participant's log records (level INFO and above, any logger) published
    on its progress key as ``{"verb", "window", "iteration", "message"}`` (``base``: the reply's
    run id, participant, verb, window and iteration), at most one per :data:`PROGRESS_EVERY`
    seconds. A solver that logs while it works is seen working; one that hangs logs nothing."""

    def __init__(self, publisher, base: dict):
        super().__init__(logging.INFO)
        self.publisher, self.base = publisher, base
        self.sent = -PROGRESS_EVERY
        self._busy = False

    def emit(self, record) -> None:
        now = time.monotonic()
        if self._busy or now - self.sent < PROGRESS_EVERY:
            return
        self._busy, self.sent = True, now
        try:
            self.publisher.put(json.dumps({k: self.base.get(k) for k in ("verb", "window", "iteration")}
                                          | {"message": record.getMessage()}))
        except Exception:  # noqa: BLE001 - progress must never fail the verb
            pass
        finally:
            self._busy = False


class CouplerGone(ConnectionError):
    """The coupler's liveliness token disappeared: the participant should exit."""


class ParticipantServer:
    """Serve one participant's verbs (docs/protocol.md) from a ``handler`` object.

    ``handler`` has the methods of :class:`coupler.participant.Participant`. Queries are
    received by zenoh threads and queued; :meth:`serve_forever` (call it from the main
    thread) runs the handler for each in turn and replies. A handler exception is logged
    and answered as ``{"error": "<Type>: <message>"}``, the server keeps serving.

    ``watch_coupler``: also watch the coupler's liveliness token; once seen, its loss
    ends :meth:`serve_forever` with :class:`CouplerGone` (the participant does not
    outlive a coupler that crashed).
    """

    def __init__(self, session: zenoh.Session, run_id: str, name: str, handler, *,
                 watch_coupler: bool = True, extra_announce: Mapping | None = None,
                 shared_memory: bool = True):
        self.session = session
        self.run_id = check_name("run id", run_id)
        self.name = check_name("participant name", name)
        self.handler = handler
        self.extra_announce = dict(extra_announce or {})
        self.shared_memory = shared_memory
        self.finished = False
        self._queue: queue.Queue = queue.Queue()
        self._coupler_seen = False
        self._closed = False
        self._queryables = [
            session.declare_queryable(key(run_id, name, verb), callback(self._queue.put), complete=True)
            for verb in VERBS
        ]
        self._progress = session.declare_publisher(progress_key(run_id, name))
        self._coupler_sub = None
        if watch_coupler:
            self._coupler_sub = session.liveliness().declare_subscriber(
                alive_key(run_id, COUPLER), callback(self._on_coupler), history=True)
        if shared_memory:
            warm_up_shm()  # the first large reply must not pay for the pool
        # The token comes last: a client that sees it finds every queryable declared.
        self._token = session.liveliness().declare_token(alive_key(run_id, name))
        log.info("%s: serving %s", name, key(run_id, name, "*"))

    def _on_coupler(self, sample):
        if sample.kind == zenoh.SampleKind.PUT:
            self._coupler_seen = True
        elif self._coupler_seen:
            self._queue.put(_Stop("the coupler's liveliness token disappeared (coupler stopped or crashed)"))

    def serve_forever(self, poll: float = 0.2) -> None:
        """Answer queries until ``finish`` has been answered (then return).

        Raises :class:`CouplerGone` if the coupler disappears. Signals (SIGTERM, SIGINT)
        are handled between queries and at least every ``poll`` seconds."""
        while not self.finished:
            try:
                item = self._queue.get(timeout=poll)
            except queue.Empty:
                continue
            if isinstance(item, _Stop):
                raise CouplerGone(f"{self.name}: {item.reason}")
            self.handle(item)

    def handle(self, query) -> None:
        """Run the handler for one query and reply (never raises for handler errors)."""
        verb = str(query.key_expr).rsplit("/", 1)[-1]
        base = {"run_id": self.run_id, "participant": self.name, "verb": verb}
        progress, root = Progress(self._progress, base), logging.getLogger()
        root.addHandler(progress)
        try:
            answer(query, key(self.run_id, self.name, verb), base, self.shared_memory,
                   lambda request, fields: self.dispatch(verb, request, fields))
        finally:
            root.removeHandler(progress)
        if verb == "finish":
            self.finished = True

    def dispatch(self, verb: str, request: dict, fields: dict[str, Field]):
        """Call the handler for ``verb``: returns ``(reply_header, reply_fields)``."""
        h = self.handler
        if verb == "announce":
            info = {"name": self.name, "pid": os.getpid(), "ranks": 1, **self.extra_announce}
            info.update(h.announce() or {})
            return info, None
        if verb == "configure":
            h.configure(request.get("config", {}))
            return {}, None
        if verb == "geometry":
            header, out = h.geometry()
            return dict(header or {}), out
        if verb == "advance":
            missing = [k for k in ("window", "iteration", "t", "dt") if k not in request]
            if missing:
                raise ProtocolError(f"advance request without {missing}")
            out = h.advance(request["window"], request["iteration"], request["t"], request["dt"], fields)
            solves, figures = h.take_reports() if hasattr(h, "take_reports") else ([], {})
            return ({"solves": [s.as_dict() for s in solves], "figures": {k: json_number(v) for k, v in figures.items()}},
                    as_fields(out))
        if verb in ("save_state", "restore_state"):
            if "window" not in request:
                raise ProtocolError(f"{verb} request without 'window'")
            getattr(h, verb)(request["window"])
            return {}, None
        if verb == "finish":
            h.finish()
            return {}, None
        raise ProtocolError(f"unknown verb {verb!r}")

    def close(self) -> None:
        """Undeclare the token (the coupler sees the participant go) and the queryables."""
        if self._closed:
            return
        self._closed = True
        for entity in [self._token, self._coupler_sub, self._progress, *self._queryables]:
            if entity is not None:
                try:
                    entity.undeclare()
                except Exception:  # noqa: BLE001 - session may be closed already
                    pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


class PartServer:
    """Rank ``rank`` (1 and above) of a participant on several MPI ranks: the queryables of its
    parts of :data:`PART_VERBS` (``varcouple/<run>/<participant>/<verb>/<rank>``) and its own
    liveliness token (``.../alive/<rank>``). The coupler sends each rank's request (its inputs)
    before rank 0's; when rank 0 broadcasts the verb, :meth:`take` finds the rank's request, the
    handler runs, and :meth:`reply` answers it with the rank's part."""

    def __init__(self, session: zenoh.Session, run_id: str, name: str, rank: int, shared_memory: bool = True):
        self.run_id, self.name, self.rank = check_name("run id", run_id), check_name("participant name", name), rank
        self.shared_memory = shared_memory
        self._queue: queue.Queue = queue.Queue()
        self._queryables = [session.declare_queryable(part_key(run_id, name, verb, rank), callback(self._queue.put),
                                                      complete=True) for verb in PART_VERBS]
        if shared_memory:
            warm_up_shm()
        self._token = session.liveliness().declare_token(rank_alive_key(run_id, name, rank))

    def key(self, verb: str) -> str:
        return part_key(self.run_id, self.name, verb, self.rank)

    def take(self, verb: str, expect: Mapping, timeout: float):
        """``(query, base, t0, fields)``: the coupler's request for this rank's part of ``verb`` whose
        window and iteration are those of ``expect`` (rank 0's request); an older one (a call the
        coupler gave up) is answered with an error and skipped. ProtocolError naming the key when
        none comes within ``timeout`` seconds or it is malformed."""
        deadline = time.monotonic() + timeout
        want = self.key(verb)
        while True:
            try:
                query = self._queue.get(timeout=max(0.0, deadline - time.monotonic()))
            except queue.Empty:
                raise ProtocolError(f"no request on {want} within {timeout:g} s") from None
            t0 = time.perf_counter()
            base = {"run_id": self.run_id, "participant": self.name, "verb": verb, "rank": self.rank}
            try:
                request, fields = request_of(query, base)
            except ProtocolError as exc:
                send_reply(query, str(query.key_expr), base, self.shared_memory, t0, error=exc)
                raise ProtocolError(f"{query.key_expr}: {exc}") from None
            stale = [k for k in ("window", "iteration") if request.get(k) != expect.get(k)]
            if str(query.key_expr) != want or stale:
                send_reply(query, str(query.key_expr), base, self.shared_memory, t0, error=ProtocolError(
                    f"stale request (window {request.get('window')}, iteration {request.get('iteration')}) "
                    f"while serving {want}"))
                continue
            return query, base, t0, fields

    def reply(self, query, base: dict, t0: float, header=None, fields=None, error=None) -> None:
        send_reply(query, str(query.key_expr), base, self.shared_memory, t0, header, as_fields(fields), error)

    def close(self) -> None:
        for entity in [self._token, *self._queryables]:
            try:
                entity.undeclare()
            except Exception:  # noqa: BLE001 - session may be closed already
                pass
