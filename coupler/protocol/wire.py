"""The wire format of the participant protocol (docs/protocol.md, "Wire format").

One message is one binary payload::

    [8 bytes: little-endian uint64 N][N bytes: UTF-8 JSON header][padding][array bytes ...]

The array section starts at the first multiple of 64 after the header, and every array
starts at a 64-byte aligned offset *relative to the start of the array section* (so the
offsets do not depend on the header's length). The header always holds ``v`` (the
protocol version), ``run_id``, ``participant``, ``verb`` and ``arrays``, a list of
``{"name", "dtype", "shape", "units", "offset", "nbytes"}``. No pickling: the dtype is a
numpy type string with explicit byte order (``"<f8"``), the bytes are the array's raw
C-ordered buffer.

:func:`decode` returns read-only numpy views of the payload (``np.frombuffer``), no copy.
:func:`check_reply` rejects a reply that does not answer its request (stale window or
iteration, another run, another participant or verb).
"""

from __future__ import annotations

import json
import math
import struct
from dataclasses import dataclass
from typing import Iterable, Mapping

import numpy as np

from coupler.protocol.errors import ProtocolError
from transfer.errors import FieldError

#: Version of the wire format, written in every header as ``"v"``.
VERSION = 1
#: Alignment (bytes) of the array section and of every array in it.
ALIGN = 64
_LEN = struct.Struct("<Q")
#: numpy kinds that may travel: bool, signed/unsigned int, float, complex.
_KINDS = "biufc"
#: Header keys :func:`check_reply` compares between a request and its reply.
MATCH_KEYS = ("run_id", "participant", "verb", "window", "iteration")


def _align(n: int) -> int:
    return (n + ALIGN - 1) // ALIGN * ALIGN


@dataclass
class Field:
    """A named array with its physical units (``""`` when dimensionless / unknown).

    ``data`` is any numeric numpy array (bool, int, uint, float, complex), of any shape
    (0-d and empty included). Fields from :func:`decode` are read-only views of the
    received payload: copy them (``field.data.copy()``) to modify them.
    """

    name: str
    data: np.ndarray
    units: str = ""

    def __post_init__(self):
        self.data = np.asarray(self.data)

    @property
    def shape(self) -> tuple[int, ...]:
        return self.data.shape

    @property
    def dtype(self) -> np.dtype:
        return self.data.dtype


@dataclass
class SolveReport:
    """How one inner solve of an ``advance`` ended, as a participant reports it to the coupler
    (header ``solves`` of the reply): a run never claims more than its solvers did.

    ``solver`` names the solve (``"simpleFoam"``, ``"static CG+GAMG"``, ``"active_set"``);
    ``residual`` is the final value of the solver's own stopping criterion and ``tolerance``
    the value it had to reach; ``iterations`` what it took; ``detail`` a short reason
    (``"iteration limit"``, a PETSc reason). ``accepted``: the participant was told to accept
    this solve unconverged (a scene key such as ``allow_unconverged``). ``history``: the
    criterion after each iteration, for solvers that keep it (the convergence plot).
    """

    solver: str
    converged: bool
    iterations: int
    residual: float
    tolerance: float
    detail: str = ""
    accepted: bool = False
    history: tuple = ()

    def as_dict(self) -> dict:
        """JSON-ready (non-finite numbers as strings, which JSON has no words for)."""
        out = {"solver": self.solver, "converged": bool(self.converged), "iterations": int(self.iterations),
               "residual": json_number(self.residual), "tolerance": json_number(self.tolerance),
               "detail": self.detail, "accepted": bool(self.accepted)}
        if self.history:
            out["history"] = [json_number(h) for h in self.history]
        return out

    @classmethod
    def from_dict(cls, d: Mapping) -> "SolveReport":
        try:
            return cls(str(d["solver"]), bool(d["converged"]), int(d["iterations"]), float(d["residual"]),
                       float(d["tolerance"]), str(d.get("detail", "")), bool(d.get("accepted", False)),
                       tuple(float(h) for h in d.get("history", ())))
        except (KeyError, TypeError, ValueError) as exc:
            raise ProtocolError(f"malformed solve report {d!r}: {exc}") from None

    @property
    def ok(self) -> bool:
        """Converged, or accepted unconverged on purpose."""
        return self.converged or self.accepted

    def describe(self) -> str:
        """One line: ``simpleFoam did not converge: residual 3.2e-03 > 1e-07 after 2000 iterations``."""
        state = "converged" if self.converged else "did not converge"
        relation = "<=" if self.converged else ">"
        text = (f"{self.solver} {state}: residual {self.residual:.3g} {relation} {self.tolerance:.3g} after "
                f"{self.iterations} iteration{'s' * (self.iterations != 1)}")
        if self.detail:
            text += f" ({self.detail})"
        if self.accepted and not self.converged:
            text += "; accepted (allow_unconverged)"
        return text


def json_number(x: float):
    """``x`` for a JSON header: finite numbers as they are, inf and NaN as the strings
    ``"inf"``, ``"-inf"``, ``"nan"`` (``float()`` reads them back)."""
    x = float(x)
    return x if math.isfinite(x) else str(x)


def as_fields(fields) -> list[Field]:
    """Normalize ``fields``: ``None``, an iterable of :class:`Field`, or a mapping of
    name to :class:`Field` or array (units ``""``)."""
    if fields is None:
        return []
    if isinstance(fields, Mapping):
        out = []
        for name, value in fields.items():
            if isinstance(value, Field):
                if value.name != name:
                    raise FieldError(f"mapped to a Field named {value.name!r}", field=name)
                out.append(value)
            else:
                out.append(Field(name, value))
        return out
    out = list(fields)
    for f in out:
        if not isinstance(f, Field):
            raise ProtocolError(f"expected Field objects, got {type(f).__name__}")
    return out


def check_finite(name: str, data: np.ndarray) -> None:
    """Raise :class:`FieldError` naming the field if a float/complex array holds NaN/inf.

    Two reductions (min and max propagate NaN and show inf), no temporary array; the
    count of bad values is computed only on the error path."""
    if data.dtype.kind not in "fc" or data.size == 0:
        return
    flat = data.reshape(-1)
    if data.dtype.kind == "c":
        flat = flat.copy().view(flat.real.dtype) if not flat.flags.c_contiguous else flat.view(flat.real.dtype)
    lo, hi = flat.min(), flat.max()
    if math.isfinite(lo) and math.isfinite(hi):
        return
    bad = ~np.isfinite(flat)
    n_nan = int(np.isnan(flat).sum())
    first = int(np.argmax(bad)) // (2 if data.dtype.kind == "c" else 1)
    raise FieldError(f"{int(bad.sum())} non-finite value(s) ({n_nan} NaN) out of {flat.size}, "
                     f"first at flat index {first}: refusing to send it", field=name)


def _check_name(name) -> None:
    if not isinstance(name, str) or not name:
        raise FieldError("a field name must be a non-empty string", field=str(name))


def encode(header: Mapping, fields=None, *, check: bool = True) -> bytearray:
    """Encode ``header`` (a JSON-serializable dict) and ``fields`` into one payload.

    ``fields``: see :func:`as_fields`. The returned ``bytearray`` is the whole message;
    arrays are copied once into it (non-contiguous arrays made contiguous first).
    With ``check`` (the default) float and complex arrays holding NaN or inf are refused
    with a :class:`FieldError` naming the field: nothing non-finite is ever sent.
    """
    if not isinstance(header, Mapping):
        raise ProtocolError(f"header must be a dict, got {type(header).__name__}")
    if "arrays" in header:
        raise ProtocolError("header key 'arrays' is reserved for the encoder")
    flist = as_fields(fields)
    arrays, descr, seen, offset = [], [], set(), 0
    for f in flist:
        _check_name(f.name)
        if f.name in seen:
            raise FieldError("appears twice in one message", field=f.name)
        seen.add(f.name)
        data = np.asarray(f.data)
        if data.dtype.kind not in _KINDS:
            raise FieldError(f"dtype {data.dtype} cannot travel (numeric dtypes only)", field=f.name)
        if check:
            check_finite(f.name, data)
        if not data.flags.c_contiguous:
            data = data.copy(order="C")  # (np.ascontiguousarray would make 0-d arrays 1-d)
        nbytes = int(data.nbytes)
        descr.append({
            "name": f.name,
            "dtype": data.dtype.str,
            "shape": list(data.shape),
            "units": str(f.units or ""),
            "offset": offset,
            "nbytes": nbytes,
        })
        arrays.append(data)
        offset = _align(offset + nbytes)
    full = dict(header)
    full.setdefault("v", VERSION)
    full["arrays"] = descr
    try:
        hbytes = json.dumps(full, separators=(",", ":"), allow_nan=False).encode("utf-8")
    except (TypeError, ValueError) as exc:
        raise ProtocolError(f"header is not JSON-serializable (finite numbers only): {exc}") from None
    start = _align(_LEN.size + len(hbytes))
    end = start + (descr[-1]["offset"] + descr[-1]["nbytes"] if descr else 0)
    buf = bytearray(end)
    _LEN.pack_into(buf, 0, len(hbytes))
    buf[_LEN.size:_LEN.size + len(hbytes)] = hbytes
    view = np.frombuffer(buf, dtype=np.uint8) if end else None
    for d, data in zip(descr, arrays):
        if d["nbytes"]:
            o = start + d["offset"]
            view[o:o + d["nbytes"]] = data.reshape(-1).view(np.uint8)
    return buf


def decode_header(payload) -> tuple[dict, int]:
    """The header of ``payload`` and the start of its array section (no array access)."""
    mv = memoryview(payload).cast("B")
    if mv.nbytes < _LEN.size:
        raise ProtocolError(f"truncated message: {mv.nbytes} bytes, no header length")
    (n,) = _LEN.unpack_from(mv, 0)
    if n > mv.nbytes - _LEN.size:
        raise ProtocolError(f"truncated message: header of {n} bytes announced, {mv.nbytes - _LEN.size} present")
    try:
        header = json.loads(bytes(mv[_LEN.size:_LEN.size + n]).decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ProtocolError(f"malformed message header: {exc}") from None
    if not isinstance(header, dict):
        raise ProtocolError("malformed message header: not a JSON object")
    if header.get("v", VERSION) != VERSION:
        raise ProtocolError(f"protocol version {header.get('v')!r}, this side speaks {VERSION}")
    return header, _align(_LEN.size + n)


def decode(payload) -> tuple[dict, dict[str, Field]]:
    """Decode a payload (bytes, bytearray, memoryview) into ``(header, fields)``.

    ``fields`` maps names to :class:`Field` in message order; the arrays are views of
    ``payload`` (no copy; read-only when ``payload`` is ``bytes``). The ``arrays`` list
    stays in the header. Raises :class:`ProtocolError` on a malformed or truncated message.
    """
    header, start = decode_header(payload)
    descr = header.get("arrays", [])
    if not isinstance(descr, list):
        raise ProtocolError("malformed message header: 'arrays' is not a list")
    total = memoryview(payload).nbytes
    fields: dict[str, Field] = {}
    for d in descr:
        try:
            name, dtype = d["name"], np.dtype(d["dtype"])
            shape = tuple(int(s) for s in d["shape"])
            offset, nbytes, units = int(d["offset"]), int(d["nbytes"]), d.get("units", "")
        except (KeyError, TypeError, ValueError) as exc:
            raise ProtocolError(f"malformed array descriptor {d!r}: {exc}") from None
        if dtype.kind not in _KINDS:
            raise ProtocolError(f"array {name!r}: dtype {dtype} is not allowed")
        count = math.prod(shape)
        if min(shape, default=0) < 0 or count * dtype.itemsize != nbytes:
            raise ProtocolError(f"array {name!r}: shape {list(shape)} of {dtype} does not make {nbytes} bytes")
        if offset < 0 or start + offset + nbytes > total:
            raise ProtocolError(f"truncated message: array {name!r} ends past the payload ({total} bytes)")
        if name in fields:
            raise ProtocolError(f"array {name!r} appears twice in one message")
        data = np.frombuffer(payload, dtype=dtype, count=count, offset=start + offset) if count else np.empty(0, dtype)
        fields[name] = Field(name, data.reshape(shape), units)
    return header, fields


def check_reply(request: Mapping, reply: Mapping) -> None:
    """Reject a reply that does not answer ``request`` (docs/protocol.md).

    Every key of :data:`MATCH_KEYS` present in the request header must be present in
    the reply with the same value; otherwise :class:`ProtocolError` (stale or
    mismatched data is never used). Error replies are the caller's business
    (``"error"`` in the reply: :class:`coupler.errors.ParticipantError`).
    """
    for key in MATCH_KEYS:
        if key not in request:
            continue
        if key not in reply:
            raise ProtocolError(
                f"reply of {request.get('participant')!r} to {request.get('verb')!r} has no {key!r} "
                f"(expected {request[key]!r}): rejected"
            )
        if reply[key] != request[key]:
            raise ProtocolError(
                f"stale or mismatched reply of {request.get('participant')!r} to {request.get('verb')!r}: "
                f"{key} is {reply[key]!r}, expected {request[key]!r}: rejected"
            )


def payload_nbytes(fields: Iterable[Field]) -> int:
    """Total array bytes of ``fields`` (for statistics)."""
    return sum(int(f.data.nbytes) for f in fields)
