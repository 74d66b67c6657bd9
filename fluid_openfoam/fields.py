"""Read and write the ``internalField`` of OpenFOAM (v1912) volScalarField / volVectorField
files, ASCII or binary, without OpenFOAM and without foamlib.

foamlib (the issue's suggestion) was not used: its current release (1.7.10) requires
numpy>=2, aioshutil, multicollections and rich, none of which are in the venv (Debian's
numpy 1.24 must stay for dolfinx). The subset needed here is small:

* ``internalField uniform <value>;`` with a scalar ``1.5`` or a vector ``(1 2 3)``;
* ``internalField nonuniform List<scalar> N(...);`` / ``List<vector>``: in ASCII the
  values one per line (or inline for short lists, ``3(1 2 3)``), vectors as ``(x y z)``;
  in binary (``format binary;`` in the FoamFile header) ``N`` in text, then ``(``,
  ``N*8`` (scalar) or ``N*24`` (vector) bytes of little-endian float64, then ``)``.
  The header's ``arch`` must say ``scalar=64`` (checked).

Values are numbered as the mesh's cells (blockMesh: x fastest, then y, then z).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from transfer.atomic import atomic_path

_NCOMP = {"scalar": 1, "vector": 3}
_CLASS = {"scalar": "volScalarField", "vector": "volVectorField"}


class FieldFormatError(ValueError):
    """A field file this module cannot read."""


def _header(data: bytes, path) -> dict:
    m = re.search(rb"FoamFile\s*\{(.*?)\}", data, re.S)
    if not m:
        raise FieldFormatError(f"{path}: no FoamFile header")
    out = {}
    for key, val in re.findall(rb"(\w+)\s+([^;]*);", m.group(1)):
        out[key.decode()] = val.decode().strip().strip('"')
    return out


def _parse_internal(data: bytes, start: int, binary: bool, path, n_cells: int | None):
    """Parse the internalField entry whose value starts at ``start``.
    Returns (array, end) where ``end`` is the offset just after the terminating ';'."""
    s = data[start:start + 64].lstrip()
    skip = len(data[start:start + 64]) - len(s)
    pos = start + skip
    if s.startswith(b"uniform"):
        end = data.index(b";", pos)
        txt = data[pos + len(b"uniform"):end].decode().strip()
        vals = np.array([float(v) for v in txt.strip("()").split()], dtype=np.float64)
        if n_cells is None:
            raise FieldFormatError(f"{path}: uniform internalField needs n_cells to expand")
        arr = np.tile(vals, (n_cells, 1)) if len(vals) == 3 else np.full(n_cells, vals[0])
        return arr, end + 1
    m = re.match(rb"nonuniform\s+List<(\w+)>\s*(\d+)\s*", data[pos:pos + 200])
    if not m:
        raise FieldFormatError(f"{path}: cannot parse internalField at {data[pos:pos + 40]!r}")
    kind, n = m.group(1).decode(), int(m.group(2))
    if kind not in _NCOMP:
        raise FieldFormatError(f"{path}: unsupported List<{kind}>")
    ncomp = _NCOMP[kind]
    pos += m.end()
    opener = data[pos:pos + 1]
    if opener == b"{":  # uniform list N{value}
        end = data.index(b"}", pos)
        vals = np.array([float(v) for v in data[pos + 1:end].decode().strip("() \n").split()])
        arr = np.tile(vals, (n, 1)) if ncomp == 3 else np.full(n, vals[0])
        end = data.index(b";", end)
        return arr, end + 1
    if opener != b"(":
        raise FieldFormatError(f"{path}: expected '(' after List<{kind}> {n}, got {opener!r}")
    pos += 1
    if binary and n > 0:
        nbytes = 8 * ncomp * n
        arr = np.frombuffer(data, dtype="<f8", count=ncomp * n, offset=pos).copy()
        pos += nbytes
        if data[pos:pos + 1] != b")":
            raise FieldFormatError(f"{path}: binary List<{kind}> of {n} not closed by ')'")
        end = data.index(b";", pos)
    else:
        end = data.index(b";", pos)
        body = data[pos:end].decode()
        body = body[:body.rindex(")")]
        arr = np.array(body.replace("(", " ").replace(")", " ").split(), dtype=np.float64)
        if arr.size != ncomp * n:
            raise FieldFormatError(f"{path}: List<{kind}> {n} holds {arr.size} numbers")
    if ncomp == 3:
        arr = arr.reshape(n, 3)
    return arr, end + 1


def read_internal_field(path, n_cells: int | None = None) -> np.ndarray:
    """The internalField of a vol field file: (n,) for scalars, (n, 3) for vectors.
    ``n_cells`` is needed to expand a ``uniform`` value (and checked otherwise)."""
    path = Path(path)
    data = path.read_bytes()
    hdr = _header(data, path)
    binary = hdr.get("format", "ascii") == "binary"
    arch = hdr.get("arch", "")
    if binary and "scalar=" in arch and "scalar=64" not in arch:
        raise FieldFormatError(f"{path}: arch {arch!r}: only 64-bit scalars are supported")
    m = re.search(rb"\binternalField\s", data)
    if not m:
        raise FieldFormatError(f"{path}: no internalField")
    arr, _ = _parse_internal(data, m.end(), binary, path, n_cells)
    if n_cells is not None and len(arr) != n_cells:
        raise FieldFormatError(f"{path}: {len(arr)} values, expected {n_cells}")
    return arr


def format_list(values, binary: bool) -> bytes:
    """``nonuniform List<scalar|vector> N(...);`` for a field entry (internalField or a
    patch ``value``); binary lists for files with ``format binary``."""
    return _format_internal(values, binary)


def _format_internal(values: np.ndarray, binary: bool) -> bytes:
    values = np.asarray(values, dtype=np.float64)
    if values.ndim == 1:
        kind = "scalar"
    elif values.ndim == 2 and values.shape[1] == 3:
        kind = "vector"
    else:
        raise ValueError(f"values must be (n,) or (n, 3), got shape {values.shape}")
    if not np.all(np.isfinite(values)):
        raise ValueError("values hold NaN or inf")
    n = len(values)
    head = f"nonuniform List<{kind}> \n{n}\n(".encode()
    if binary:
        body = np.ascontiguousarray(values, dtype="<f8").tobytes()
    elif kind == "scalar":
        body = ("\n" + "\n".join(repr(float(v)) for v in values) + "\n").encode()
    else:
        body = ("\n" + "\n".join(f"({x!r} {y!r} {z!r})" for x, y, z in values.tolist()) + "\n").encode()
    return head + body + b")\n;"


def write_field(path, values, boundary: str, *, obj: str | None = None, dimensions: str = "[0 0 0 0 0 0 0]",
                binary: bool = True, location: str | None = None) -> None:
    """Write a complete vol field file (class from the shape of ``values``) with the
    given ``boundaryField`` body (the text between its braces). Atomic (write + rename)."""
    path = Path(path)
    values = np.asarray(values, dtype=np.float64)
    cls = _CLASS["scalar" if values.ndim == 1 else "vector"]
    hdr = ["FoamFile", "{", "    version     2.0;", f"    format      {'binary' if binary else 'ascii'};"]
    if binary:
        hdr.append('    arch        "LSB;label=32;scalar=64";')
    hdr += [f"    class       {cls};"]
    if location is not None:
        hdr.append(f'    location    "{location}";')
    hdr += [f"    object      {obj or path.name};", "}", ""]
    out = ("\n".join(hdr) + f"\ndimensions      {dimensions};\n\ninternalField   ").encode()
    out += _format_internal(values, binary)
    bnd = boundary if isinstance(boundary, bytes) else boundary.encode()
    out += b"\n\nboundaryField\n{\n" + bnd + b"\n}\n"
    with atomic_path(path) as tmp:
        tmp.write_bytes(out)


def replace_internal_field(path, values) -> None:
    """Replace the internalField of an existing field file, keeping its header, format
    and boundaryField."""
    path = Path(path)
    data = path.read_bytes()
    hdr = _header(data, path)
    binary = hdr.get("format", "ascii") == "binary"
    m = re.search(rb"\binternalField\s", data)
    if not m:
        raise FieldFormatError(f"{path}: no internalField")
    _, end = _parse_internal(data, m.end(), binary, path, len(values))
    out = data[:m.end()] + b"  " + _format_internal(values, binary) + data[end:]
    with atomic_path(path) as tmp:
        tmp.write_bytes(out)


def read_label_list(path) -> np.ndarray:
    """A polyMesh label list file (``owner``, ``neighbour``), ASCII or binary (32-bit labels)."""
    path = Path(path)
    data = path.read_bytes()
    hdr = _header(data, path)
    binary = hdr.get("format", "ascii") == "binary"
    if binary and "label=" in hdr.get("arch", "") and "label=32" not in hdr["arch"]:
        raise FieldFormatError(f"{path}: arch {hdr['arch']!r}: only 32-bit labels are supported")
    body_start = data.index(b"}", data.index(b"FoamFile")) + 1
    m = re.compile(rb"\s*(?://[^\n]*\n\s*|/\*.*?\*/\s*)*(\d+)\s*\(", re.S).match(data, body_start)
    if not m:
        raise FieldFormatError(f"{path}: no label list")
    n, pos = int(m.group(1)), m.end()
    if binary:
        arr = np.frombuffer(data, dtype="<i4", count=n, offset=pos).astype(np.int64)
    else:
        end = data.index(b")", pos)
        arr = np.array(data[pos:end].split(), dtype=np.int64)
    if arr.size != n:
        raise FieldFormatError(f"{path}: {arr.size} labels, expected {n}")
    return arr


def read_patches(path) -> dict[str, tuple[int, int]]:
    """``constant/polyMesh/boundary``: {patch: (startFace, nFaces)}."""
    text = Path(path).read_text(errors="replace")
    _header(text.encode(), path)  # FieldFormatError naming the file without one
    text = text[text.index("}", text.index("FoamFile")) + 1:]
    out = {}
    for name, body in re.findall(r"(\w+)\s*\{([^}]*)\}", text):
        n = re.search(r"nFaces\s+(\d+);", body)
        s = re.search(r"startFace\s+(\d+);", body)
        if n and s:
            out[name] = (int(s.group(1)), int(n.group(1)))
    return out
