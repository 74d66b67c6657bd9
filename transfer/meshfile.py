"""Mesh files read and written with meshio, and the fields they carry.

A file may hold several cell blocks (meshio ``cells``): the blocks of the
highest topological dimension are the mesh (they must be of one supported
type: tetra, hexahedron, triangle or quad); lower-dimensional blocks (boundary
faces, edges, vertices of e.g. Gmsh files) are ignored. Cells numbered with
negative orientation are reordered (:meth:`transfer.Mesh.from_meshio`). A
field is looked up by name in ``point_data`` (degree 1: P1 on simplices, Q1 on
hexahedra and quads) or in ``cell_data`` (degree 0: P0 / Q0), where meshio
keeps one array per cell block and the blocks of the mesh's type are joined in
file order, as :meth:`transfer.Mesh.from_meshio` joins their cells.
"""

from __future__ import annotations

import contextlib
import os
import threading
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .mesh import CELL_TYPES, Mesh
from .spaces import FunctionSpace

from .atomic import atomic_path, write_text
from .errors import MeshFileError, without_content

#: meshio cell-type prefix -> topological dimension ("tetra10" is a "tetra", ...)
_DIMENSIONS = (("vertex", 0), ("line", 1), ("triangle", 2), ("quad", 2), ("polygon", 2),
               ("tetra", 3), ("hexahedron", 3), ("wedge", 3), ("pyramid", 3), ("polyhedron", 3))

KINDS = ("point", "cell")

#: zlib level of the .vtu files MeshFile writes: meshio compresses at zlib's default, 6,
#: and offers no level; level 1 writes the same standard zlib-compressed VTU about three
#: times faster, a few per cent larger
VTU_ZLIB_LEVEL = 1
_vtu_lock = threading.Lock()

try:  # Intel ISA-L's zlib streams (PyPI isal): the same format, deflated and inflated faster
    from isal import isal_zlib
except ImportError:  # pragma: no cover - isal is a dependency; plain zlib still reads and writes
    isal_zlib = None

#: the zlib levels ISA-L compresses at (its level 0 compresses too: zlib's 0 stores)
ISAL_LEVELS = range(1, 4)


class _Zlib:
    """The zlib module as meshio's VTU reader and writer call it: `compress` at `level`,
    by ISA-L when it is installed and has that level, and `decompress` by ISA-L when
    installed (standard zlib streams either way)."""

    def __init__(self, level: int, fast=None):
        self.level = level
        self.fast = fast

    def compress(self, data: bytes) -> bytes:
        if self.fast is not None and self.level in ISAL_LEVELS:
            return self.fast.compress(data, self.level)
        return zlib.compress(data, self.level)

    def decompress(self, data: bytes) -> bytes:
        return (self.fast or zlib).decompress(data)

    def __getattr__(self, name):
        return getattr(zlib, name)


@contextlib.contextmanager
def vtu_zlib_level(level: int):
    """meshio's VTU writer compresses at zlib `level`, and its reader decompresses, inside
    this block through :class:`_Zlib` (ISA-L when installed)."""
    from meshio.vtu import _vtu

    with _vtu_lock:
        saved, _vtu.zlib = _vtu.zlib, _Zlib(level, isal_zlib)
        try:
            yield
        finally:
            _vtu.zlib = saved


def cell_dimension(cell_type: str) -> int | None:
    """Topological dimension of a meshio cell type (None if unknown)."""
    for prefix, dim in _DIMENSIONS:
        if cell_type.startswith(prefix):
            return dim
    return None


def one_line(exc: BaseException) -> str:
    """An exception as a single line: its message, or its type when it has none."""
    text = " ".join(str(exc).split())
    return text or type(exc).__name__


def _meshio_read(path: Path, name: str):
    """meshio.read, with its failures turned into one MeshFileError: meshio 5.0
    raises many exception types on malformed files, and when no reader accepts
    a file it prints to stdout and stderr and calls sys.exit(1). What it prints
    is kept for the message (on failure) or passed on to stderr (warnings)."""
    import contextlib
    import io
    import sys

    import meshio

    captured = io.StringIO()
    failure = None
    try:
        vtu = str(path).lower().endswith(".vtu")  # only meshio's VTU reader inflates through the shim
        with contextlib.redirect_stdout(captured), contextlib.redirect_stderr(captured), \
                (vtu_zlib_level(VTU_ZLIB_LEVEL) if vtu else contextlib.nullcontext()):
            raw = meshio.read(path)
    except SystemExit:
        failure = ""
    except Exception as exc:  # noqa: BLE001 - any reader error is a bad input file
        failure = without_content(one_line(exc))
    said = [" ".join(without_content(line).split()) for line in captured.getvalue().splitlines() if line.strip()]
    said = [line.removeprefix("Error:").strip() for line in said]
    if failure is not None:
        reason = "; ".join(dict.fromkeys([*said, failure] if failure else said)) or "unknown reason"
        raise MeshFileError(f"{name}: cannot read the mesh with meshio: {reason}")
    for line in said:
        print(f"meshio: {line}", file=sys.stderr)
    return raw


def mesh_format(path) -> tuple[str, str] | None:
    """(extension, format) meshio writes `path` in, by its longest known extension; None if unknown."""
    import meshio

    name = Path(path).name.lower()
    known = [ext for ext in meshio.extension_to_filetypes if name.endswith(ext)]
    if not known:
        return None
    ext = max(known, key=len)
    return ext, meshio.extension_to_filetypes[ext][0]


def same_file(path, files) -> str | None:
    """The one of `files` that `path` is (whatever the spelling: symbolic or hard links,
    ``..``), or None."""
    path = Path(path)
    if not path.exists():
        return None
    return next((str(f) for f in files if Path(f).exists() and os.path.samefile(path, f)), None)


def check_writable(path, inputs=()) -> None:
    """Fail early (before any work) when meshio cannot write `path` or `path` is one of
    the `inputs` files."""
    path = Path(path)
    if mesh_format(path) is None:
        raise MeshFileError(f"{path}: unknown mesh format (extension {''.join(path.suffixes) or 'missing'}); "
                           f"use one meshio writes, e.g. .vtu, .vtk")
    if path.is_dir():
        raise MeshFileError(f"{path}: is a directory")
    if not path.parent.is_dir():
        raise MeshFileError(f"{path}: directory {str(path.parent)!r} does not exist")
    clash = same_file(path, inputs)
    if clash is not None:
        raise MeshFileError(f"{path}: is the input file {clash}; writing there would overwrite it; "
                           f"choose another output file")


def _same_values(read, written: np.ndarray) -> bool:
    """`read` back is `written` (NaN where it is NaN, to rounding)."""
    return (read is not None and np.shape(read) == written.shape
            and np.allclose(read, written, rtol=1e-12, atol=0, equal_nan=True))


def write_pvd(path, entries) -> None:
    """A ParaView collection ``.pvd`` listing the files of a time series: `entries` are
    (time, file name relative to the collection) pairs, in order."""
    rows = "\n".join(f'    <DataSet timestep="{t:.12g}" file="{name}"/>' for t, name in entries)
    write_text(path, '<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1">\n  <Collection>\n'
                     f"{rows}\n  </Collection>\n</VTKFile>\n")


def family(mesh: Mesh, kind: str) -> str:
    """Lagrange family of a point (degree 1) or cell (degree 0) field on `mesh`."""
    return ("P" if mesh.is_simplex else "Q") + ("1" if kind == "point" else "0")


@dataclass
class MeshFileField:
    """A named field of a mesh file: its kind (point or cell data) and dof values of shape
    (n,) or (n, ...). (:class:`coupler.protocol.wire.Field` is another thing: a named array
    with units travelling between processes.)"""

    name: str
    kind: str  # "point" or "cell"
    values: np.ndarray

    @property
    def components(self) -> int:
        return int(np.prod(self.values.shape[1:], dtype=int))

    @property
    def flat(self) -> np.ndarray:
        """Values as (n,) for scalars, (n, k) for vectors and tensors."""
        n = self.values.shape[0]
        return self.values.reshape(n) if self.values.ndim == 1 else self.values.reshape(n, -1)

    def describe(self) -> str:
        if self.values.ndim == 1:
            shape = "scalar"
        elif self.values.ndim == 2:
            shape = f"{self.values.shape[1]} component{'s' if self.values.shape[1] != 1 else ''}"
        else:
            shape = f"{'x'.join(map(str, self.values.shape[1:]))} tensor"
        return f"field {self.name!r} ({self.kind} data, {shape})"


@dataclass
class MeshFile:
    """A mesh file: the meshio mesh, the :class:`transfer.Mesh` of its main cell
    type and the indices of the cell blocks that make it up."""

    path: str
    raw: object  # meshio.Mesh
    mesh: Mesh
    blocks: list[int]
    ignored: dict[str, int] = field(default_factory=dict)  # lower-dimensional cell type -> count

    #: files this process has read, the cells and points it read of them (``mpirun varcouple
    #: transfer`` says what each rank read)
    reads = cells_read = points_read = 0

    @classmethod
    def read(cls, path) -> "MeshFile":
        name = str(path)
        MeshFile.reads += 1
        p = Path(path)
        if not p.exists():
            raise MeshFileError(f"{name}: file not found")
        if p.is_dir():
            raise MeshFileError(f"{name}: is a directory, not a mesh file")
        raw = _meshio_read(p, name)
        types = [b.type for b in raw.cells]
        if not types:
            raise MeshFileError(f"{name}: the file has no cells")
        unknown = sorted({t for t in types if cell_dimension(t) is None})
        if unknown:
            raise MeshFileError(f"{name}: unsupported cell type(s) {unknown}; varcouple transfers between "
                               f"{', '.join(CELL_TYPES)} cells")
        top = max(cell_dimension(t) for t in types)
        unsupported = sorted({t for t in types if cell_dimension(t) == top and t not in CELL_TYPES})
        if unsupported:
            raise MeshFileError(f"{name}: unsupported cell type(s) {unsupported}; varcouple transfers between "
                               f"{', '.join(CELL_TYPES)} cells")
        mesh = Mesh.from_meshio(raw, name=name)  # MeshError (a TransferError) names the file
        MeshFile.cells_read += sum(len(b.data) for b in raw.cells)
        MeshFile.points_read += len(raw.points)
        blocks = [i for i, b in enumerate(raw.cells) if b.type == mesh.cell_type]
        ignored: dict[str, int] = {}
        for b in raw.cells:
            if b.type != mesh.cell_type:
                ignored[b.type] = ignored.get(b.type, 0) + len(b.data)
        return cls(name, raw, mesh, blocks, ignored)

    def describe(self) -> str:
        m = self.mesh
        text = f"{m.num_cells} {m.cell_type} cells, {m.num_points} points"
        if self.ignored:
            text += " (ignoring " + ", ".join(f"{n} {t}" for t, n in self.ignored.items()) + " cells)"
        if m.reoriented:
            text += (f"; note: {m.reoriented} of {m.num_cells} {m.cell_type} cells had negative orientation "
                     f"and were reordered (vertex order only)")
        return text

    def space(self, kind: str) -> FunctionSpace:
        return FunctionSpace(self.mesh, family(self.mesh, kind))

    def field_names(self) -> dict[str, list[str]]:
        return {"point": list(self.raw.point_data), "cell": list(self.raw.cell_data)}

    def field(self, name: str) -> MeshFileField:
        """The field `name`: point data if there is such, else cell data of the mesh's blocks."""
        raw = self.raw
        if name in raw.point_data:
            kind, values, expected = "point", raw.point_data[name], self.mesh.num_points
        elif name in raw.cell_data:
            kind, expected = "cell", self.mesh.num_cells
            values = np.concatenate([np.asarray(raw.cell_data[name][i]) for i in self.blocks])
        else:
            names = self.field_names()
            raise MeshFileError(f"{self.path}: no field {name!r} (point data: {names['point'] or 'none'}; "
                               f"cell data: {names['cell'] or 'none'})")
        values = np.asarray(values)
        if not np.issubdtype(values.dtype, np.number) or np.issubdtype(values.dtype, np.complexfloating):
            raise MeshFileError(f"{self.path}: field {name!r} is not real-valued (dtype {values.dtype})")
        values = values.astype(np.float64)
        if values.ndim == 0 or values.shape[0] != expected:
            raise MeshFileError(f"{self.path}: {kind} field {name!r} has shape {values.shape}; expected "
                               f"{expected} values, one per {kind} of the {self.mesh.cell_type} mesh")
        bad = ~np.isfinite(values.reshape(expected, -1)).all(axis=1)
        if bad.any():
            raise MeshFileError(f"{self.path}: field {name!r} has {int(bad.sum())} NaN/inf value(s) "
                               f"(first at {kind} {int(np.flatnonzero(bad)[0])})")
        return MeshFileField(name, kind, values)

    def check_keeps(self, path, fields: dict[str, tuple[str, np.ndarray]]) -> None:
        """Fail early unless the format of `path` keeps this mesh's cells and `fields`
        (name -> (kind, values); only their dtype and trailing shape count). Many
        formats meshio writes drop point or cell data (``.msh`` as ANSYS, ``.inp``,
        ``.stl``, ...) or the volume cells (``.ply``, ``.stl``): two cells of the mesh
        carrying such fields, a NaN among them (uncovered dofs), are written to a
        temporary file of the same format, read back and compared."""
        import contextlib
        import io
        import tempfile

        import meshio

        cells = self.mesh.cells[:2]
        used, local = np.unique(cells, return_inverse=True)
        local = local.reshape(cells.shape)
        sample = {}
        for name, (kind, values) in fields.items():
            values = np.asarray(values)
            shape = (len(used) if kind == "point" else len(cells),) + values.shape[1:]
            v = np.arange(1, 1 + int(np.prod(shape))).reshape(shape).astype(values.dtype)
            if np.issubdtype(v.dtype, np.floating):
                v = v / 3
                v.flat[0] = np.nan
            sample[name] = (kind, v)
        probe = meshio.Mesh(self.mesh.points[used], [(self.mesh.cell_type, local)],
                            point_data={n: v for n, (k, v) in sample.items() if k == "point"},
                            cell_data={n: [v] for n, (k, v) in sample.items() if k == "cell"})
        ext, fmt = mesh_format(path)
        with tempfile.TemporaryDirectory() as tmp:
            file = Path(tmp) / Path(path).name
            try:  # quietly: meshio prints what it skips, the comparison below says it
                with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
                    meshio.write(file, probe)
            except Exception as exc:  # noqa: BLE001 - meshio raises many exception types
                raise MeshFileError(f"{path}: meshio cannot write {self.mesh.cell_type} cells with these "
                                   f"fields as {fmt!r} ({ext}): {one_line(exc)}; use .vtu or .vtk") from None
            try:
                back = _meshio_read(file, str(path))
            except MeshFileError:  # nothing comes back
                back = meshio.Mesh(np.zeros((0, 3)), [])
        index = next((i for i, b in enumerate(back.cells)
                      if b.type == self.mesh.cell_type and np.array_equal(b.data, local)), None)
        if index is None:
            lost = f"the {self.mesh.cell_type} cells"
        else:
            read = {name: back.point_data.get(name) if kind == "point" else
                    back.cell_data.get(name, [None] * len(back.cells))[index] for name, (kind, _) in sample.items()}
            names = [name for name, (_, v) in sample.items() if not _same_values(read[name], v)]
            kinds = " and ".join(sorted({sample[name][0] for name in names}))
            lost = names and f"the {kinds} data {', '.join(map(repr, names))}"
        if lost:
            raise MeshFileError(f"{path}: meshio writes {fmt!r} files ({ext}) without {lost}; use .vtu or .vtk")

    def write(self, path, fields: dict[str, tuple[str, np.ndarray]]) -> None:
        """Write this mesh (its main cell blocks, joined) with its own data and
        `fields` (name -> (kind, values)) to `path`, format by extension."""
        import meshio

        raw = self.raw
        point_data = {k: np.asarray(v) for k, v in raw.point_data.items()
                      if len(v) == self.mesh.num_points}
        cell_data = {k: [np.concatenate([np.asarray(v[i]) for i in self.blocks])]
                     for k, v in raw.cell_data.items()}
        for name, (kind, values) in fields.items():
            point_data.pop(name, None)
            cell_data.pop(name, None)
            if kind == "point":
                point_data[name] = values
            else:
                cell_data[name] = [values]
        out = meshio.Mesh(self.mesh.points, [(self.mesh.cell_type, self.mesh.cells)],
                          point_data=point_data, cell_data=cell_data)
        try:
            with vtu_zlib_level(VTU_ZLIB_LEVEL), atomic_path(path) as tmp:
                meshio.write(tmp, out)
        except Exception as exc:  # meshio raises many exception types (format, I/O)
            raise MeshFileError(f"{path}: cannot write the mesh: {one_line(exc)}") from exc
