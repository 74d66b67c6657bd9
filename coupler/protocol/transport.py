"""The zenoh transport of the participant protocol (docs/protocol.md): sessions, keys, names,
endpoints and shared memory, used by both sides (:mod:`coupler.protocol.server`, the
participant's, and :mod:`coupler.run.client`, the coupler's).

:func:`open_session` builds the zenoh configuration: peer mode on loopback by default,
multicast and gossip scouting off (nothing is discovered by chance: every process connects
to endpoints it is given), shared-memory transport on. Router endpoints and client mode are
available for runs spread over several hosts. Every exchange is a zenoh query/reply
(reliable, never dropped under load; default publishers with congestion control Drop lose
large messages silently).

Large payloads: zenoh's shared-memory transport is used on one host. zenoh 1.x does it
implicitly ("transport optimization": a message above ``message_size_threshold`` is copied
into a shared-memory pool of ``pool_size`` bytes when the link supports it);
:func:`open_session` sizes that pool (``shm_pool_size``), and :func:`zbytes` puts large
messages into an explicit pool. Messages larger than the pool fall back to the TCP link,
still reliably. See docs/protocol.md ("Shared memory") for the measurements behind this.
"""

from __future__ import annotations

import atexit
import json
import logging
import os
import re
import secrets
import socket
import threading
import time
from typing import Iterable, Mapping

import zenoh

from .errors import ProtocolError

log = logging.getLogger("varcouple.transport")

#: Root of every key of the protocol.
PREFIX = "varcouple"
#: The verbs a participant serves, in the order of a run.
VERBS = ("announce", "configure", "geometry", "advance", "save_state", "restore_state", "finish")
#: The verbs whose arrays travel per rank of a participant on several MPI ranks (docs/protocol.md, "Parts").
PART_VERBS = ("geometry", "advance")
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


def part_key(run_id: str, name: str, verb: str, rank: int) -> str:
    """``varcouple/<run_id>/<participant>/<verb>/<rank>``: rank ``rank``'s part of a verb of
    :data:`PART_VERBS` (rank 0's part travels under :func:`key`)."""
    return f"{PREFIX}/{run_id}/{name}/{verb}/{int(rank)}"


def progress_key(run_id: str, name: str) -> str:
    """``varcouple/<run_id>/<participant>/progress``: what the participant is doing while a verb runs
    (docs/protocol.md, "Progress")."""
    return f"{PREFIX}/{run_id}/{name}/progress"


def rank_alive_key(run_id: str, name: str, rank: int) -> str:
    """``varcouple/<run_id>/<participant>/alive/<rank>``: the liveliness token of rank ``rank``
    (1 and above) of a participant on several MPI ranks."""
    return f"{alive_key(run_id, name)}/{int(rank)}"


def coupler_rank_of(part: int, coupler_ranks: int) -> int:
    """The coupler rank that exchanges participant rank `part`'s parts when the coupler runs on
    `coupler_ranks` ranks: round-robin (docs/protocol.md, "Parts")."""
    return int(part) % int(coupler_ranks)


def part_links(coupler_endpoints: list[str], part: int) -> list[str]:
    """The coupler ranks' endpoints (in rank order) that participant rank `part` connects to:
    rank 0 every one (its verbs and liveliness token reach each coupler rank), any other rank
    coupler rank 0's (whose token it watches) and that of the coupler rank exchanging its parts
    (:func:`coupler_rank_of`). Every link is direct: no session routes another's messages."""
    if not coupler_endpoints or part == 0:
        return list(coupler_endpoints)
    mine = coupler_endpoints[coupler_rank_of(part, len(coupler_endpoints))]
    return list(dict.fromkeys([coupler_endpoints[0], mine]))


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
    a page fault per 4 kB, which dominates the copy (bench/messaging.py measures it).
    Allocations below ``mmap_threshold``
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
    never raises (a failure disables the explicit path, as in :func:`zbytes`)."""
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


def zbytes(buf, shm: bool = False):
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


def callback(fn, drop=None):
    """A zenoh callback run directly in zenoh's network thread (``indirect=False``).

    zenoh-python's default (indirect: a Python thread fed by a channel) adds about 4 ms
    to every message on these machines (8 kB round trip: 4.0 ms median against 0.15 ms).
    Our callbacks only append to a queue or set an event, so running them directly is safe.
    """
    try:
        return zenoh.handlers.Callback(fn, drop, indirect=False)
    except TypeError:  # the keyword is unstable: older/newer zenoh-python
        return zenoh.handlers.Callback(fn, drop)


def is_shm(zb) -> bool:
    try:
        return zb is not None and zb.as_shm() is not None
    except Exception:  # noqa: BLE001 - unstable API
        return False


def payload_bytes(zb) -> bytes:
    return zb.to_bytes() if zb is not None else b""
