"""Messaging between the coupler and its participants over eclipse-zenoh (docs/protocol.md).

* :func:`open_session` builds the zenoh configuration: peer mode on loopback by default,
  multicast and gossip scouting off (nothing is discovered by chance: every process
  connects to endpoints it is given), shared-memory transport on. Router endpoints and
  client mode are available for runs spread over several hosts.
* :class:`CouplerSession` is the coupler's side: it listens on a free loopback TCP port
  (chosen by the OS, retried if taken meanwhile, so parallel runs never collide),
  declares the coupler's liveliness token and hands out :class:`ParticipantClient`\\ s.
* :class:`ParticipantServer` is a participant's side: one queryable per verb, a
  liveliness token, and a loop that runs the handler's methods in the calling (main)
  thread and answers each query, errors included.
* :class:`ParticipantClient` calls one participant's verbs with a timeout per call and
  tracks its liveliness: a query to a participant that dies is answered by
  :class:`ParticipantDied` within a fraction of a second, not after the timeout.

Every exchange is a zenoh query/reply (reliable, never dropped under load; default
publishers with congestion control Drop lose large messages silently).

Large payloads: zenoh's shared-memory transport is used on one host. zenoh 1.x does it
implicitly ("transport optimization": a message above ``message_size_threshold`` is
copied into a shared-memory pool of ``pool_size`` bytes when the link supports it);
:func:`open_session` sizes that pool (``shm_pool_size``). Messages larger than the pool
fall back to the TCP link, still reliably. See docs/protocol.md ("Shared memory") for the
measurements behind this choice.
"""

from __future__ import annotations

import atexit
import json
import logging
import os
import queue
import re
import secrets
import socket
import threading
import time
from typing import Callable, Iterable, Mapping

import zenoh

from .errors import (
    ParticipantDied,
    ParticipantError,
    ParticipantTimeout,
    ProtocolError,
)
from .protocol import Field, SolveReport, as_fields, check_reply, decode, encode, json_number

log = logging.getLogger("varcouple.messaging")

#: Root of every key of the protocol.
PREFIX = "varcouple"
#: The verbs a participant serves, in the order of a run.
VERBS = ("announce", "configure", "geometry", "advance", "save_state", "restore_state", "finish")
#: Name under which the coupler declares its own liveliness token.
COUPLER = "coupler"
#: Default size of the shared-memory pool of each process (bytes; lazily allocated).
SHM_POOL_SIZE = 256 * 2**20
#: Messages at least this large go through shared memory (when the link supports it).
SHM_THRESHOLD = 64 * 2**10
#: Default timeout of one call (seconds) when neither the client nor the call sets one.
DEFAULT_TIMEOUT = 60.0

_NAME = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_.\-]*$")


def check_name(what: str, value: str) -> str:
    """A run id or participant name must be one zenoh key chunk: ``[A-Za-z0-9_.-]``."""
    if not isinstance(value, str) or not _NAME.match(value):
        raise ProtocolError(f"{what} {value!r} must be letters, digits, '_', '.', '-' (no '/', '*', spaces)")
    return value


_ENDPOINT = re.compile(r"^(?P<proto>[a-z0-9-]+)/(?P<address>[^?#\s]+)(\?[^#\s]*)?(#\S*)?$")
_IP_PROTOCOLS = ("tcp", "udp", "tls", "quic", "ws")


def check_endpoint(endpoint: str) -> str:
    """A zenoh endpoint ``<protocol>/<address>``; for IP protocols the address is
    ``host:port`` (``[v6]:port``) with a port in 1..65535. ValueError says what is wrong."""
    m = _ENDPOINT.match(endpoint) if isinstance(endpoint, str) else None
    if m is None:
        raise ValueError(f"{endpoint!r} is not a zenoh endpoint <protocol>/<address>, e.g. tcp/127.0.0.1:7447")
    if m["proto"] in _IP_PROTOCOLS:
        host, _, port = m["address"].rpartition(":")
        if not host or not port.isdigit() or not 1 <= int(port) <= 65535:
            raise ValueError(f"{endpoint!r}: the address must be host:port with a port in 1..65535, "
                             f"e.g. {m['proto']}/127.0.0.1:7447")
    return endpoint


def _zenoh_text(exc: BaseException) -> str:
    """zenoh's message without the Rust source locations it appends (``at /.../x.rs:388.``)."""
    return re.sub(r"\s+at \S+\.rs:\d+\.?", "", str(exc)).strip()


def key(run_id: str, name: str, verb: str) -> str:
    """``varcouple/<run_id>/<participant>/<verb>``."""
    return f"{PREFIX}/{run_id}/{name}/{verb}"


def alive_key(run_id: str, name: str) -> str:
    """``varcouple/<run_id>/<participant>/alive``: the liveliness token."""
    return f"{PREFIX}/{run_id}/{name}/alive"


def new_run_id() -> str:
    """A fresh run id: time, pid and random bits (unique across parallel runs)."""
    return f"{time.strftime('%Y%m%d-%H%M%S')}-{os.getpid()}-{secrets.token_hex(3)}"


# ----------------------------------------------------------------------------- malloc

_malloc_tuned = False


def tune_malloc(mmap_threshold: int = 256 * 2**20, trim_threshold: int = 512 * 2**20,
                top_pad: int = 64 * 2**20) -> bool:
    """Keep large message buffers on the heap (glibc ``mallopt``), once per process.

    Every message is copied a few times (encode, zenoh, receive); with glibc's defaults a
    buffer of more than a few MB is a fresh ``mmap`` each time and the copy into it pays
    a page fault per 4 kB: on these machines an 8 MB round trip took 20-32 ms instead of
    12 ms, an 80 MB copy 58 ms instead of 16 ms. Allocations below ``mmap_threshold``
    come from the heap, and up to ``trim_threshold`` bytes of freed heap are kept for
    reuse. Set ``VARCOUPLE_MALLOC_TUNING=0`` to leave malloc alone. Returns whether the
    settings were applied (glibc only).
    """
    global _malloc_tuned
    if _malloc_tuned or os.environ.get("VARCOUPLE_MALLOC_TUNING", "1") == "0":
        return _malloc_tuned
    try:
        import ctypes

        libc = ctypes.CDLL("libc.so.6")
        M_TRIM_THRESHOLD, M_TOP_PAD, M_MMAP_THRESHOLD = -1, -2, -3
        ok = all(libc.mallopt(ctypes.c_int(opt), ctypes.c_int(val)) == 1 for opt, val in (
            (M_MMAP_THRESHOLD, mmap_threshold), (M_TRIM_THRESHOLD, trim_threshold), (M_TOP_PAD, top_pad)))
    except (OSError, AttributeError):
        ok = False
    _malloc_tuned = ok
    return ok


# ----------------------------------------------------------------------------- sessions

_open_sessions: list = []


def _close_all_sessions():
    # A session whose Python callbacks are still declared keeps the interpreter from
    # exiting (zenoh 1.10): close every session we opened.
    for s in list(_open_sessions):
        try:
            s.close()
        except Exception:  # noqa: BLE001 - best effort at exit
            pass


atexit.register(_close_all_sessions)


def session_config(
    mode: str = "peer",
    connect: Iterable[str] = (),
    listen: Iterable[str] = (),
    shared_memory: bool = True,
    *,
    shm_pool_size: int = SHM_POOL_SIZE,
    shm_threshold: int = SHM_THRESHOLD,
    connect_timeout: float | None = 10.0,
    overrides: Mapping[str, object] | None = None,
) -> zenoh.Config:
    """The zenoh configuration of :func:`open_session` (see there)."""
    if mode not in ("peer", "client", "router"):
        raise ValueError(f"zenoh mode must be peer, client or router, got {mode!r}")
    connect, listen = [check_endpoint(e) for e in connect], [check_endpoint(e) for e in listen]
    if mode == "client" and not connect:
        raise ValueError("client mode needs at least one router endpoint to connect to")
    conf = zenoh.Config()
    put = lambda k, v: conf.insert_json5(k, json.dumps(v))  # noqa: E731
    put("mode", mode)
    put("scouting/multicast/enabled", False)
    put("scouting/gossip/enabled", False)
    put("connect/endpoints", connect)
    put("listen/endpoints", listen)
    if connect and connect_timeout is not None:
        # Fail (zenoh.open raises) instead of retrying forever when nobody listens.
        put("connect/timeout_ms", int(connect_timeout * 1000))
        put("connect/exit_on_failure", True)
    put("transport/shared_memory/enabled", bool(shared_memory))
    if shared_memory:
        put("transport/shared_memory/transport_optimization/enabled", True)
        put("transport/shared_memory/transport_optimization/pool_size", int(shm_pool_size))
        put("transport/shared_memory/transport_optimization/message_size_threshold", int(shm_threshold))
    for k, v in (overrides or {}).items():
        put(k, v)
    return conf


def open_session(
    mode: str = "peer",
    connect: Iterable[str] = (),
    listen: Iterable[str] = (),
    shared_memory: bool = True,
    **kwargs,
) -> zenoh.Session:
    """Open a zenoh session for the protocol.

    ``mode``: ``"peer"`` (default; one host, or hosts that reach each other directly),
    ``"client"`` (connect to zenoh routers only) or ``"router"``. ``connect``/``listen``:
    zenoh endpoints such as ``tcp/127.0.0.1:7447`` or ``tcp/[::]:7447``. Scouting is
    off: a session talks to the endpoints it is given, so several runs on one machine
    never meet. ``shared_memory``: zenoh's shared-memory transport between processes of
    one host (``shm_pool_size``, ``shm_threshold`` tune it). ``connect_timeout``
    (seconds, default 10): ``zenoh.open`` fails if no ``connect`` endpoint answers.
    ``overrides``: further zenoh configuration, ``{"json5/key/path": value}``.
    Also applies :func:`tune_malloc` to this process.
    """
    conf = session_config(mode, connect, listen, shared_memory, **kwargs)
    tune_malloc()
    try:
        session = zenoh.open(conf)
    except zenoh.ZError as exc:
        text = _zenoh_text(exc)
        if connect and "Unable to connect" in text:
            timeout = kwargs.get("connect_timeout", 10.0)
            raise Unreachable(f"cannot reach {', '.join(connect)} within {timeout:g} s: no zenoh router or peer "
                              f"answers there ({mode} mode)") from None
        where = ", ".join(list(connect) + list(listen)) or "no endpoint"
        raise ConnectionError(f"cannot open a zenoh session ({mode}, {where}): {text}") from None
    _open_sessions[:] = [s for s in _open_sessions if not s.is_closed()] + [session]
    return session


def free_tcp_port(host: str = "127.0.0.1") -> int:
    """A TCP port that is free now on ``host`` (the OS picks it)."""
    with socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((host, 0))
        return s.getsockname()[1]


class Unreachable(ConnectionError):
    """No zenoh router or peer answers at the endpoints to connect to."""


def open_listening_session(host: str = "127.0.0.1", port: int | None = None, attempts: int = 8, **kwargs):
    """Open a session listening on ``tcp/<host>:<port>``; ``port=None`` takes a free port
    chosen by the OS (retried if another process takes it first). Returns
    ``(session, endpoint)``."""
    last = None
    for _ in range(attempts if port is None else 1):
        p = port or free_tcp_port(host)
        endpoint = f"tcp/[{host}]:{p}" if ":" in host else f"tcp/{host}:{p}"
        try:
            return open_session(listen=[endpoint], **kwargs), endpoint
        except Unreachable:  # another port would not help
            raise
        except ConnectionError as exc:
            last = exc
    raise ConnectionError(f"could not listen on {host}: {last}")


# ------------------------------------------------------------------------ payload helpers

#: How large messages get into shared memory (when the session has it enabled):
#: ``"explicit"`` (default): this module allocates each message of at least
#: :data:`SHM_THRESHOLD` bytes in its own shared-memory pool (``zenoh.shm``, an API
#: zenoh marks unstable) and zenoh passes a reference; ``"implicit"``: zenoh's transport
#: optimization copies the message into its pool itself (one copy more: 8 MB round trip
#: 11.8 ms against 9.8 ms). Any failure of the explicit path (pool full, message larger
#: than the pool, API change) falls back to the implicit one. Environment:
#: ``VARCOUPLE_SHM_MODE``.
SHM_MODE = os.environ.get("VARCOUPLE_SHM_MODE", "explicit")
#: Size of the first explicit shared-memory pool (bytes). Making a pool costs time in
#: proportion to its size (the segment is written once: about 0.45 ms per MB on these
#: machines, 0.12 s for 256 MB and up to 0.9 s while the other processes of a run
#: compute on two cores), so a process starts with a small pool, made during set-up by
#: :func:`warm_up_shm`, and replaces it by a larger one (a power of two at least four
#: times the message, at most :data:`SHM_POOL_SIZE`) when a message does not fit in half
#: of it. Environment: ``VARCOUPLE_SHM_INITIAL_POOL`` (bytes).
SHM_INITIAL_POOL = int(os.environ.get("VARCOUPLE_SHM_INITIAL_POOL", 16 * 2**20))
_providers: list = []  # [(size, provider)], newest last; older pools are kept for the buffers in flight
_provider_lock = threading.Lock()
_explicit_broken = False


def _pool_size_for(nbytes: int) -> int:
    size = max(SHM_INITIAL_POOL, 1)
    while size < 4 * nbytes and size < SHM_POOL_SIZE:
        size *= 2
    return min(size, SHM_POOL_SIZE)


def _shm_provider(nbytes: int = 0):
    """The explicit shared-memory pool for a message of `nbytes`: ``(provider, size)``,
    made (or grown) as :data:`SHM_INITIAL_POOL` explains."""
    with _provider_lock:
        if _providers and (2 * nbytes <= _providers[-1][0] or _providers[-1][0] >= SHM_POOL_SIZE):
            size, provider = _providers[-1]
            return provider, size
        import zenoh.shm as zshm

        size = _pool_size_for(nbytes)
        t0 = time.perf_counter()
        provider = zshm.ShmProvider.default_backend(size)
        _providers.append((size, provider))
        log.debug("shared-memory pool of %d MB made in %.3f s", size >> 20, time.perf_counter() - t0)
        return provider, size


def warm_up_shm() -> float:
    """Make this process's first shared-memory pool and allocate from it once, so that the
    first large message of a run does not pay for it (a participant calls it before it
    declares itself alive, the coupler when its session opens). Returns the seconds spent;
    never raises (a failure disables the explicit path, as in :func:`_zbytes`)."""
    global _explicit_broken
    if SHM_MODE != "explicit" or _explicit_broken:
        return 0.0
    t0 = time.perf_counter()
    try:
        import zenoh.shm as zshm

        provider, _ = _shm_provider(SHM_THRESHOLD)
        provider.alloc(SHM_THRESHOLD, zshm.GarbageCollect())  # dropped at once: back to the pool
    except Exception as exc:  # noqa: BLE001 - unstable API
        _explicit_broken = True
        log.warning("explicit shared memory unavailable (%s: %s); using zenoh's transport optimization",
                    type(exc).__name__, exc)
    return time.perf_counter() - t0


def _zbytes(buf, shm: bool = False):
    """What zenoh sends for the encoded message ``buf``: a shared-memory buffer (see
    :data:`SHM_MODE`) or ``buf`` itself (zenoh copies it, into its shared-memory pool when
    the transport optimization applies)."""
    global _explicit_broken
    if not shm or SHM_MODE != "explicit" or _explicit_broken or len(buf) < SHM_THRESHOLD:
        return buf
    try:
        import zenoh.shm as zshm

        provider, size = _shm_provider(len(buf))
        policy = zshm.GarbageCollect()
    except Exception as exc:  # noqa: BLE001 - unstable API: never let it break a message
        _explicit_broken = True
        log.warning("explicit shared memory unavailable (%s: %s); using zenoh's transport optimization",
                    type(exc).__name__, exc)
        return buf
    if len(buf) > size // 2:
        return buf
    try:
        m = provider.alloc(len(buf), policy)
    except Exception as exc:  # noqa: BLE001 - pool full (buffers still held): this message by copy
        log.debug("shared-memory pool full (%s); message of %d bytes sent by copy", exc, len(buf))
        return buf
    m[:] = buf
    return zenoh.ZBytes(m)


def _callback(fn, drop=None):
    """A zenoh callback run directly in zenoh's network thread (``indirect=False``).

    zenoh-python's default (indirect: a Python thread fed by a channel) adds about 4 ms
    to every message on these machines (8 kB round trip: 4.0 ms median against 0.15 ms).
    Our callbacks only append to a queue or set an event, so running them directly is safe.
    """
    try:
        return zenoh.handlers.Callback(fn, drop, indirect=False)
    except TypeError:  # the keyword is unstable: older/newer zenoh-python
        return zenoh.handlers.Callback(fn, drop)


def _is_shm(zb) -> bool:
    try:
        return zb is not None and zb.as_shm() is not None
    except Exception:  # noqa: BLE001 - unstable API
        return False


def _payload_bytes(zb) -> bytes:
    return zb.to_bytes() if zb is not None else b""


# ----------------------------------------------------------------------------- server

class _Stop:
    def __init__(self, reason: str):
        self.reason = reason


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
            session.declare_queryable(key(run_id, name, verb), _callback(self._queue.put), complete=True)
            for verb in VERBS
        ]
        self._coupler_sub = None
        if watch_coupler:
            self._coupler_sub = session.liveliness().declare_subscriber(
                alive_key(run_id, COUPLER), _callback(self._on_coupler), history=True)
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
        t0 = time.perf_counter()
        if query.payload is not None and len(query.payload) >= SHM_THRESHOLD:
            base["rx_shm"] = _is_shm(query.payload)
        try:
            request, fields = decode(_payload_bytes(query.payload)) if query.payload else ({}, {})
            for k in ("window", "iteration"):
                if k in request:
                    base[k] = request[k]
            for k in ("run_id", "participant", "verb"):
                if k in request and request[k] != base[k]:
                    raise ProtocolError(f"request for {k}={request[k]!r} reached {base[k]!r}")
            header, out = self.dispatch(verb, request, fields)
            base["elapsed"] = time.perf_counter() - t0
            payload = encode({**header, **base}, out)
        except (Exception, SystemExit) as exc:  # noqa: BLE001 - every failure becomes an error reply
            # (SystemExit: library code that calls sys.exit, e.g. meshio on a file no reader accepts)
            message = f"{type(exc).__name__}: {exc}"
            log.exception("%s: %s failed", self.name, verb)
            base["elapsed"] = time.perf_counter() - t0
            payload = encode({**base, "error": message})
            if verb == "finish":
                self.finished = True
        try:
            query.reply(key(self.run_id, self.name, verb), _zbytes(payload, self.shared_memory))
        finally:
            query.drop()
        log.debug("%s: %s answered in %.3f s (%d bytes)", self.name, verb, base["elapsed"], len(payload))

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
            self.finished = True
            return {}, None
        raise ProtocolError(f"unknown verb {verb!r}")

    def close(self) -> None:
        """Undeclare the token (the coupler sees the participant go) and the queryables."""
        if self._closed:
            return
        self._closed = True
        for entity in [self._token, self._coupler_sub, *self._queryables]:
            if entity is not None:
                try:
                    entity.undeclare()
                except Exception:  # noqa: BLE001 - session may be closed already
                    pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


# ----------------------------------------------------------------------------- client

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
            alive_key(run_id, name), _callback(self._on_liveliness), history=True)

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
        :class:`coupler.errors.FieldError` (NaN/inf in an input field)."""
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
            _callback(replies.append, done.set),
            payload=_zbytes(payload, self.shared_memory),
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
        data = _payload_bytes(reply.ok.payload)
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
        st["shm_in"] += _is_shm(reply.ok.payload) if len(data) >= SHM_THRESHOLD else 0
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
