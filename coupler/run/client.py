"""The coupler's side of the protocol (docs/protocol.md).

* :class:`CouplerSession` listens on a free loopback TCP port (chosen by the OS, retried if
  taken meanwhile, so parallel runs never collide), declares the coupler's liveliness token
  and hands out :class:`ParticipantClient`\\ s.
* :class:`ParticipantClient` calls one participant's verbs with a timeout per call and
  tracks its liveliness: a query to a participant that dies is answered by
  :class:`~coupler.protocol.errors.ParticipantDied` within a fraction of a second, not
  after the timeout.
"""

from __future__ import annotations

import logging
import threading
import time
from typing import Callable, Iterable, Mapping

import zenoh

from coupler.protocol.errors import ParticipantDied, ParticipantError, ParticipantTimeout, ProtocolError
from coupler.protocol.transport import (COUPLER, DEFAULT_TIMEOUT, SHM_THRESHOLD, VERBS, alive_key, callback,
                                        check_name, is_shm, key, new_run_id, open_listening_session,
                                        open_session, payload_bytes, warm_up_shm, zbytes)
from coupler.protocol.wire import Field, SolveReport, check_reply, decode, encode

log = logging.getLogger("varcouple.client")

class ParticipantClient:
    """The coupler's handle on one participant: its verbs as methods.

    Every call is a zenoh query with a timeout (``timeout`` per call, else the client's).
    Liveliness is tracked by a subscriber on the participant's token: :attr:`alive`.
    A call to a participant that is dead, or dies while the call waits, raises
    :class:`ParticipantDied` at once (within ``poll`` seconds). ``process_check``:
    optional callable returning ``None`` while the participant's process runs and a
    reason (exit code, last log lines) once it has exited; it makes the messages
    precise and catches a process that dies before it ever comes alive.

    Statistics of the calls are kept in :attr:`stats` (seconds, bytes each way, and the
    participant's own compute time reported in replies as ``elapsed``).
    """

    def __init__(self, session: zenoh.Session, run_id: str, name: str, timeout: float = DEFAULT_TIMEOUT,
                 *, process_check: Callable[[], str | None] | None = None, poll: float = 0.05,
                 shared_memory: bool = True):
        self.session = session
        self.run_id = check_name("run id", run_id)
        self.name = check_name("participant name", name)
        self.timeout = timeout
        self.process_check = process_check
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
        self._sub = session.liveliness().declare_subscriber(
            alive_key(run_id, name), callback(self._on_liveliness), history=True)

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
                raise ParticipantDied(self.name, reason)
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
        if verb not in VERBS:
            raise ProtocolError(f"unknown verb {verb!r}")
        timeout = self.timeout if timeout is None else timeout
        t0 = time.perf_counter()
        if not self._alive:
            reason = self._death_reason()
            if reason:
                raise ParticipantDied(self.name, reason)
            self.wait_alive(timeout)
        req = {**(header or {}), "run_id": self.run_id, "participant": self.name, "verb": verb}
        payload = encode(req, fields)
        replies: list = []
        done = threading.Event()
        cancel = zenoh.CancellationToken()
        self.session.get(
            key(self.run_id, self.name, verb),
            callback(replies.append, done.set),
            payload=zbytes(payload, self.shared_memory),
            timeout=timeout + 5.0,  # ours below fires first
            cancellation_token=cancel,
        )
        deadline = time.monotonic() + timeout
        try:
            while not done.wait(self.poll):
                if not self._alive:
                    raise ParticipantDied(self.name, self._death_reason() or f"lost while answering {verb!r}")
                if self.process_check and (reason := self.process_check()):
                    raise ParticipantDied(self.name, reason)
                if time.monotonic() > deadline:
                    raise ParticipantTimeout(self.name, verb, timeout)
        except BaseException:
            cancel.cancel()
            raise
        if not replies:
            # zenoh ends a query without reply when the participant's session goes away;
            # its liveliness token follows within milliseconds.
            end = time.monotonic() + 2.0
            while self._alive and time.monotonic() < end and not self._death_reason():
                time.sleep(0.01)
            reason = self._death_reason()
            if reason or not self._alive:
                raise ParticipantDied(self.name, reason or f"no reply to {verb!r}")
            raise ProtocolError(f"participant {self.name!r} gave no reply to {verb!r} (no queryable)")
        if len(replies) > 1:
            raise ProtocolError(f"{len(replies)} processes answered {verb!r} as participant {self.name!r}")
        reply = replies[0]
        if reply.ok is None:
            err = reply.err.payload.to_string() if reply.err is not None else "unknown"
            raise ProtocolError(f"participant {self.name!r}: zenoh error reply to {verb!r}: {err}")
        data = payload_bytes(reply.ok.payload)
        rheader, rfields = decode(data)
        if "error" in rheader:
            raise ParticipantError(self.name, str(rheader["error"]))
        check_reply(req, rheader)
        st = self.stats
        st["calls"] += 1
        st["seconds"] += time.perf_counter() - t0
        st["remote_seconds"] += float(rheader.get("elapsed", 0.0))
        st["bytes_out"] += len(payload)
        st["bytes_in"] += len(data)
        st["shm_out"] += bool(rheader.get("rx_shm"))
        st["shm_in"] += is_shm(reply.ok.payload) if len(data) >= SHM_THRESHOLD else 0
        return rheader, rfields

    def announce(self, timeout: float | None = None) -> dict:
        """The participant's self-description (``name, kind, pid, ranks, provides, accepts``)."""
        header, _ = self.request("announce", timeout=timeout)
        return {k: v for k, v in header.items() if k not in ("run_id", "participant", "verb", "arrays", "v", "elapsed")}

    def configure(self, config: Mapping, timeout: float | None = None) -> None:
        self.request("configure", {"config": dict(config)}, timeout=timeout)

    def geometry(self, timeout: float | None = None) -> tuple[dict, dict[str, Field]]:
        header, fields = self.request("geometry", timeout=timeout)
        return {k: v for k, v in header.items() if k not in ("run_id", "participant", "verb", "arrays", "v", "elapsed")}, fields

    def advance(self, window: int, iteration: int, t: float, dt: float, inputs=None,
                timeout: float | None = None) -> dict[str, Field]:
        """The participant's output fields; how its inner solves ended and its figures of
        the step are in :attr:`last_solves` and :attr:`last_figures` until the next call."""
        header, fields = self.request(
            "advance", {"window": int(window), "iteration": int(iteration), "t": float(t), "dt": float(dt)},
            inputs, timeout=timeout)
        self.last_solves = [SolveReport.from_dict(d) for d in header.get("solves", [])]
        self.last_figures = {str(k): float(v) for k, v in header.get("figures", {}).items()}
        return fields

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
        if self._sub is not None:
            try:
                self._sub.undeclare()
            except Exception:  # noqa: BLE001
                pass
            self._sub = None

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
                 shared_memory: bool = True, **kwargs):
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
        self._token = self.session.liveliness().declare_token(alive_key(self.run_id, COUPLER))
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
