"""What a run writes for people and scripts: VTU series with .pvd files for ParaView and
summary.json (rewritten atomically after every step).

On several coupler ranks (``comm``, docs/scaling.md step 5) every rank writes the piece of
its own points and cells (``<name>_<step>_p<rank>.vtu``), rank 0 the ``.pvtu`` that joins
the pieces, the ``.pvd`` and summary.json; the figures of the summary are reduced over the
ranks (:func:`reduce_figures`). Serially, or on one rank, the files are those of the serial
code."""

from __future__ import annotations

import copy
import json
from pathlib import Path

import meshio
import numpy as np

from coupler.errors import CouplerError
from transfer import StructuredGrid
from transfer.atomic import atomic_path, write_text
from transfer.meshfile import write_pvd

SUMMARY = "summary.json"

#: how the figures the coupler itself computes per step combine over the ranks' parts
REDUCTIONS = {"max_displacement": "max"}

_OPS = ("max", "min", "sum")


def _comm(comm):
    """`comm` when it has several ranks, else None (the serial code)."""
    return comm if comm is not None and comm.Get_size() > 1 else None


class Series:
    """VTU files per output step and a .pvd collection for ParaView; with `comm` (several
    ranks) a .pvtu per step of the ranks' .vtu pieces, `mesh` being this rank's part."""

    def __init__(self, directory: Path, name: str, mesh, comm=None):
        self.directory, self.name, self.mesh = directory, name, mesh
        self.comm = _comm(comm)
        self.entries: list[tuple[float, str]] = []

    def write(self, step: int, t: float, point_data=None, cell_data=None) -> Path:
        """Write one step (collective with `comm`); the path of its .vtu (.pvtu)."""
        cell_type = "hexahedron" if isinstance(self.mesh, StructuredGrid) else self.mesh.cell_type
        mesh = meshio.Mesh(self.mesh.points, [(cell_type, self.mesh.cells)], point_data=point_data or {},
                           cell_data={k: [v] for k, v in (cell_data or {}).items()})
        if self.comm is None:
            file = f"{self.name}_{step:04d}.vtu"
            with atomic_path(self.directory / file) as tmp:
                meshio.write(tmp, mesh)
        else:
            file = self._write_pieces(step, mesh)
        self.entries.append((t, file))
        if self.comm is None or self.comm.Get_rank() == 0:
            write_pvd(self.directory / f"{self.name}.pvd", self.entries)
        return self.directory / file

    def _write_pieces(self, step: int, mesh: meshio.Mesh) -> str:
        """This rank's piece, and on rank 0 the .pvtu naming the pieces of the ranks that hold cells."""
        rank = self.comm.Get_rank()
        piece = f"{self.name}_{step:04d}_p{rank}.vtu"
        held = len(mesh.cells[0].data) > 0
        if held:
            with atomic_path(self.directory / piece) as tmp:
                meshio.write(tmp, mesh)
        layouts = self.comm.allgather((held, piece, _layout(mesh)))
        pieces = [(r, p, layout) for r, (h, p, layout) in enumerate(layouts) if h]
        for r, _, layout in pieces[1:]:
            if layout != pieces[0][2]:
                raise CouplerError(f"series {self.name!r}, step {step}: rank {r}'s fields {layout} differ from "
                                   f"rank {pieces[0][0]}'s {pieces[0][2]}")
        file = f"{self.name}_{step:04d}.pvtu"
        if rank == 0:
            write_text(self.directory / file, _pvtu(pieces[0][2] if pieces else _layout(mesh),
                                                    [p for _, p, _ in pieces]))
        return file


def _vtk_type(a: np.ndarray) -> str:
    kind = {"f": "Float", "i": "Int", "u": "UInt"}[np.asarray(a).dtype.kind]
    return f"{kind}{np.asarray(a).dtype.itemsize * 8}"


def _arrays(data: dict) -> list[tuple[str, str, int]]:
    return [(k, _vtk_type(v), int(np.prod(np.shape(v)[1:], dtype=int))) for k, v in data.items()]


def _layout(mesh: meshio.Mesh) -> tuple:
    """The arrays of a piece (name, VTK type, components), what the .pvtu declares."""
    return (_vtk_type(mesh.points), _arrays(mesh.point_data),
            _arrays({k: v[0] for k, v in mesh.cell_data.items()}))


def _pvtu(layout: tuple, pieces: list[str]) -> str:
    points, point_data, cell_data = layout

    def arrays(rows):
        return "".join(f'      <PDataArray type="{t}" Name="{n}" NumberOfComponents="{c}"/>\n' for n, t, c in rows)

    sources = "".join(f'    <Piece Source="{p}"/>\n' for p in pieces)
    return ('<?xml version="1.0"?>\n<VTKFile type="PUnstructuredGrid" version="0.1" byte_order="LittleEndian">\n'
            '  <PUnstructuredGrid GhostLevel="0">\n'
            f"    <PPointData>\n{arrays(point_data)}    </PPointData>\n"
            f"    <PCellData>\n{arrays(cell_data)}    </PCellData>\n"
            f'    <PPoints>\n      <PDataArray type="{points}" NumberOfComponents="3"/>\n    </PPoints>\n'
            f"{sources}  </PUnstructuredGrid>\n</VTKFile>\n")


def write_pieces(mesh: meshio.Mesh, path: Path, owner: np.ndarray) -> None:
    """`mesh` (one cell block) as the .pvtu `path` of one .vtu piece per value of `owner`
    (the piece of every cell), each piece with its cells' points and their point data, as a
    coupler on ranks writes a step; for files given to ``varcouple transfer`` in pieces."""
    path = Path(path)
    block, names = mesh.cells[0], []
    for i in range(int(owner.max()) + 1):
        cells = block.data[owner == i]
        used, local = np.unique(cells, return_inverse=True)
        piece = meshio.Mesh(mesh.points[used], [(block.type, local.reshape(cells.shape))],
                            point_data={k: np.asarray(v)[used] for k, v in mesh.point_data.items()},
                            cell_data={k: [np.asarray(v[0])[owner == i]] for k, v in mesh.cell_data.items()})
        names.append(f"{path.stem}_p{i}.vtu")
        with atomic_path(path.parent / names[-1]) as tmp:
            meshio.write(tmp, piece)
    write_text(path, _pvtu(_layout(piece), names))


def reduce_figures(figures: dict, how: dict[str, str], comm=None) -> dict:
    """The figures of this rank's part combined over the ranks (collective; the same on every rank).

    `how` maps a figure's key (``"a.b"`` for ``figures["a"]["b"]``) to ``"max"``, ``"min"`` or
    ``"sum"``; all figures of one kind travel in one allreduce. A number without a rule cannot be
    reduced this way (a mean, a ratio, a connectivity) and raises, naming it; other values
    (text, lists) are taken from this rank. Serially (`comm` None or one rank) `figures` is
    returned as it is."""
    comm = _comm(comm)
    if comm is None:
        return figures
    from mpi4py import MPI

    flat = dict(_numbers(figures))
    unknown = sorted(k for k in flat if k not in how)
    if unknown:
        raise CouplerError(f"summary figures {', '.join(unknown)}: no rule to combine them over the coupler's "
                           f"ranks (max, min or sum)")
    wrong = sorted(k for k in flat if how[k] not in _OPS)
    if wrong:
        raise CouplerError(f"summary figures {', '.join(wrong)}: the rule must be one of {', '.join(_OPS)}")
    out = copy.deepcopy(figures)
    for op, mpi_op in zip(_OPS, (MPI.MAX, MPI.MIN, MPI.SUM)):
        keys = sorted(k for k in flat if how[k] == op)
        total = np.empty(len(keys))
        comm.Allreduce(np.array([flat[k] for k in keys], dtype=float), total, op=mpi_op)
        for k, v in zip(keys, total):
            *path, last = k.split(".")
            node = out
            for p in path:
                node = node[p]
            node[last] = _like(flat[k], v)
    return out


def _like(value, reduced: float):
    """`reduced` as the type of this rank's `value` (bool, int or float)."""
    if isinstance(value, (bool, np.bool_)):
        return bool(reduced)
    return int(reduced) if isinstance(value, (int, np.integer)) else float(reduced)


def _numbers(figures: dict, prefix: str = ""):
    """(dotted key, number) of every number in nested dicts (booleans are numbers too)."""
    for k, v in figures.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict):
            yield from _numbers(v, key + ".")
        elif isinstance(v, (int, float, np.integer, np.floating, np.bool_)):
            yield key, v


def read_summary(out: Path, name: str = SUMMARY) -> dict:
    """The summary (or another JSON file `name`) in `out` as last written; {} when there is none
    or it cannot be read (every write replaces it whole: a file is never half written)."""
    try:
        return json.loads((Path(out) / name).read_text())
    except (OSError, ValueError):
        return {}


def write_summary(out: Path, summary: dict, name: str = SUMMARY, comm=None) -> None:
    """`summary` as JSON in ``out/name``, written atomically (by rank 0 of `comm` alone)."""
    if comm is not None and comm.Get_rank() != 0:
        return
    write_text(out / name, json.dumps(summary, indent=2, default=float))
