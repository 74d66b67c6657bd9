"""A ``.pvtu`` file read in parts: the ranks of an MPI job each read their own pieces;
an XDMF + HDF5 mesh in dolfinx's layout (``python -m solid_fenicsx.convert``) likewise, each
rank its own rows (:meth:`Pieces.rows`), whose cells then go to the ranks of a coordinate
bisection (:func:`balanced`: a run of rows of dolfinx's cell order spans the whole mesh).

The pieces a ``.pvtu`` names (``<Piece Source="..."/>``, paths relative to it) are shared
out in order, a run of consecutive pieces per rank (rank 0 has the first). A piece is a
``.vtu`` read by :meth:`transfer.meshfile.MeshFile.read`; the points the pieces share are
the same point, found by their coordinates (:func:`numbering`), so the whole mesh is
numbered as one rank that read every piece numbers it: its points in order of first
appearance, its cells in piece order, whatever the number of ranks.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .errors import MeshFileError, TransferError
from .mesh import CELL_TYPES, Mesh
from .meshfile import MeshFile, MeshFileField
from .partition import bisect
from .spaces import FAMILIES
from .xdmf import MESH, layout


def read_in_parts(path) -> bool:
    """`path` is read in parts (a .pvtu or an .xdmf)."""
    return str(path).lower().endswith((".pvtu", ".xdmf"))


def _datasets(path) -> tuple[Path, tuple[str, tuple[int, ...]], tuple[str, tuple[int, ...]]]:
    """(HDF5 file, (topology dataset, its declared shape), (geometry dataset, its declared shape))
    of the grid ``mesh`` of the XDMF `path`."""
    path = Path(path)
    try:
        found = layout(path)
    except ValueError as exc:
        raise MeshFileError(f"{path}: {exc}") from None
    if found is None:
        raise MeshFileError(f"{path}: no grid {MESH!r} (dolfinx's layout); write it with "
                            f"python -m solid_fenicsx.convert")
    grid = next(g for g in ET.parse(path).getroot().find("Domain").findall("Grid") if g.get("Name") == MESH)
    items = [grid.find(f"{part}/DataItem") for part in ("Topology", "Geometry")]
    if any(item is None or ":" not in (item.text or "") for item in items):
        raise MeshFileError(f"{path}: grid {MESH!r}: topology and geometry must be HDF5 data items")
    try:
        shapes = [tuple(int(n) for n in item.get("Dimensions", "").split()) for item in items]
    except ValueError:
        shapes = []
    if [len(s) for s in shapes] != [2, 2]:
        raise MeshFileError(f"{path}: grid {MESH!r}: the topology and geometry DataItem Dimensions must be "
                            f"two numbers each (rows columns)")
    if shapes[0][0] != found.num_cells:
        raise MeshFileError(f"{path}: grid {MESH!r}: Topology NumberOfElements is {found.num_cells} but its "
                            f"DataItem Dimensions {shapes[0][0]} rows")
    return (path.with_suffix(".h5"), *((item.text.strip().split(":", 1)[1], shape)
                                       for item, shape in zip(items, shapes)))


#: a gap of at most this many unused geometry rows between two used ones is read through
#: (one hyperslab) rather than starting another
GAP_ROWS = 16


def hyperslabs(rows: np.ndarray, gap: int = GAP_ROWS) -> tuple[np.ndarray, np.ndarray]:
    """(starts, stops) of the runs of the sorted distinct `rows` that read them: consecutive
    rows with at most `gap` unused rows between them make one run."""
    if not len(rows):
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    cut = np.flatnonzero(np.diff(rows) > gap + 1) + 1
    return rows[np.r_[0, cut]], rows[np.r_[cut - 1, len(rows) - 1]] + 1


def read_rows(dataset, rows: np.ndarray) -> tuple[np.ndarray, int]:
    """(the sorted distinct `rows` of the HDF5 `dataset`, read by :func:`hyperslabs`; how many
    rows were read)."""
    starts, stops = hyperslabs(rows)
    if not len(starts):
        return np.zeros((0,) + dataset.shape[1:], dataset.dtype), 0
    block = np.concatenate([dataset[a:b] for a, b in zip(starts, stops)])
    offsets = np.cumsum(np.r_[0, stops - starts])[:-1]
    run = np.searchsorted(starts, rows, side="right") - 1
    return block[offsets[run] + rows - starts[run]], len(block)


def sources(path) -> list[Path]:
    """The piece files `path` names, in order."""
    path = Path(path)
    if not path.is_file():
        raise MeshFileError(f"{path}: file not found")
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as exc:
        raise MeshFileError(f"{path}: not a .pvtu file: {exc}") from None
    named = [p.get("Source") for p in root.iter("Piece")]
    if root.find("PUnstructuredGrid") is None or not named or None in named:
        raise MeshFileError(f"{path}: not a .pvtu file naming its pieces (<PUnstructuredGrid> with "
                            f"<Piece Source=...> elements)")
    return [path.parent / name for name in named]


def mine(count: int, rank: int, size: int) -> range:
    """The pieces of `rank`: piece i goes to rank i * size // count (rank 0 has piece 0)."""
    owner = np.arange(count) * size // count
    held = np.flatnonzero(owner == rank)
    return range(int(held[0]), int(held[-1]) + 1) if len(held) else range(0)


def _shape(shape) -> str:
    return " x ".join(map(str, shape)) or "a scalar"


def _owner(points: np.ndarray, size: int) -> np.ndarray:
    """A rank for every point by a hash of its coordinates (-0.0 is 0.0)."""
    bits = np.ascontiguousarray(points + 0.0).view(np.uint64).reshape(-1, 3)
    h = bits[:, 0] * np.uint64(0x9E3779B97F4A7C15) ^ bits[:, 1] * np.uint64(0xC2B2AE3D27D4EB4F) ^ bits[:, 2]
    return (h % np.uint64(size)).astype(np.int64)


def _exscan(comm, count: int) -> tuple[int, int]:
    """(sum of `count` over the lower ranks, sum over all)."""
    counts = comm.allgather(int(count))
    return sum(counts[:comm.rank]), sum(counts)


def numbering(points: np.ndarray, comm) -> tuple[np.ndarray, int]:
    """Global ids of this rank's `points` (the points of its pieces, in piece order; the ranks
    hold consecutive pieces in rank order) and how many there are: one id per distinct
    coordinate, numbered in order of first appearance over all pieces. Each point goes to the
    rank its coordinates hash to, which finds the first appearance of each and then its id.
    Collective on `comm`."""
    size = comm.size
    offset, _ = _exscan(comm, len(points))
    seen = offset + np.arange(len(points), dtype=np.int64)  # position over all pieces
    owner = _owner(points, size)
    order = np.argsort(owner, kind="stable")
    cuts = np.searchsorted(owner[order], np.arange(size + 1))
    sent = [order[cuts[q]:cuts[q + 1]] for q in range(size)]
    got = comm.alltoall([(points[s], seen[s]) for s in sent])
    coords = np.concatenate([c for c, _ in got]).reshape(-1, 3)
    where = np.concatenate([g for _, g in got])
    _, group = np.unique(coords, axis=0, return_inverse=True)
    group = group.ravel()
    first = np.full(group.max() + 1 if len(group) else 0, np.iinfo(np.int64).max)
    np.minimum.at(first, group, where)
    lengths = np.cumsum([0] + [len(g) for _, g in got])
    back = comm.alltoall([first[group[lengths[q]:lengths[q + 1]]] for q in range(size)])
    earliest = np.empty(len(points), np.int64)
    for q in range(size):
        earliest[sent[q]] = back[q]
    new = earliest == seen
    start, total = _exscan(comm, np.count_nonzero(new))
    ids = np.full(len(points), -1, np.int64)
    ids[new] = start + np.arange(np.count_nonzero(new))
    got = comm.alltoall([ids[s] for s in sent])  # the first appearances' ids to the owners, and back
    known = np.full(len(first), -1, np.int64)
    np.maximum.at(known, group, np.concatenate(got) if got else np.zeros(0, np.int64))
    back = comm.alltoall([known[group[lengths[q]:lengths[q + 1]]] for q in range(size)])
    for q in range(size):
        ids[sent[q]] = back[q]
    return ids, total


def _agreed(comm, work):
    """`work()` on every rank; a TransferError on any fails every rank with the first message."""
    failure, result = None, None
    try:
        result = work()
    except TransferError as exc:  # a bad file, or a mesh error naming it
        failure = str(exc)
    failures = [f for f in comm.allgather(failure) if f]
    if failures:
        raise MeshFileError(failures[0])
    return result


def balanced(mesh: Mesh, point_ids: np.ndarray, cell_ids: np.ndarray, comm) -> tuple[Mesh, np.ndarray, np.ndarray]:
    """The cells of this rank's `mesh` (`point_ids`, `cell_ids`: the global ids of its points
    and cells) moved to the ranks :func:`transfer.partition.bisect` gives their centres, as
    ``mpirun -n P varcouple transfer`` cuts a single file; the centres are cut on rank 0
    (24 B a cell there), the cells travel with their points. (this rank's mesh, the global ids
    of its points, of its cells in increasing order). Collective."""
    centres = mesh.points[mesh.cells].mean(axis=1) if mesh.num_cells else np.zeros((0, 3))
    every = comm.gather(centres)
    owner = comm.scatter(np.split(bisect(np.concatenate(every), comm.size), np.cumsum([len(c) for c in every])[:-1])
                         if comm.rank == 0 else None)
    del every
    sent = []
    for q in range(comm.size):
        mine = np.flatnonzero(owner == q)
        used, local = np.unique(mesh.cells[mine], return_inverse=True)
        sent.append((cell_ids[mine], point_ids[used], mesh.points[used], local.reshape(len(mine), -1)))
    got = comm.alltoall(sent)
    del sent
    ids = np.concatenate([g[0] for g in got]).astype(np.int64)
    order = np.argsort(ids)
    cells = np.concatenate([g[1][g[3]] for g in got])[order]  # global point ids
    points, first = np.unique(np.concatenate([g[1] for g in got]).astype(np.int64), return_index=True)
    coordinates = np.concatenate([g[2] for g in got])[first]
    return (Mesh.trusted(coordinates, np.searchsorted(points, cells), mesh.cell_type, mesh.name),
            points, ids[order])


@dataclass
class Pieces:
    """This rank's pieces of a ``.pvtu`` (:class:`transfer.meshfile.MeshFile` each) and the
    global ids of their points and cells (:func:`numbering`), joined in piece order; of an
    ``.xdmf``, its part of the rows (:meth:`rows`)."""

    path: str
    held: list
    cell_type: str
    point_ids: np.ndarray
    cell_ids: np.ndarray
    num_points: int
    num_cells: int
    comm: object

    @classmethod
    def open(cls, path, comm) -> "Pieces":
        """This rank's part of the .pvtu or .xdmf `path` (collective)."""
        return cls.rows(path, comm) if str(path).lower().endswith(".xdmf") else cls.read(path, comm)

    @classmethod
    def rows(cls, path, comm) -> "Pieces":
        """This rank's rows of an XDMF + HDF5 tet mesh in dolfinx's layout: topology rows
        r n / P to (r + 1) n / P, one hyperslab, and the geometry rows they use
        (:func:`read_rows`), then the cells of its part (:func:`balanced`); the global ids are
        the row numbers, the file's own numbering (collective)."""
        import h5py
        import meshio

        h5, (topology, cells_shape), (geometry, points_shape) = _agreed(comm, lambda: _datasets(path))

        def read():
            try:
                with h5py.File(h5, "r") as f:
                    top, geo = f[topology], f[geometry]
                    for name, dataset, declared in ((topology, top, cells_shape), (geometry, geo, points_shape)):
                        if dataset.shape != declared:
                            raise MeshFileError(f"{path}: {h5.name}:{name} holds {_shape(dataset.shape)} but "
                                                f"the XDMF's DataItem Dimensions say {_shape(declared)}")
                    if top.ndim != 2 or top.shape[1] != 4 or geo.ndim != 2 or geo.shape[1] != 3:
                        raise MeshFileError(f"{path}: {h5.name}: the topology must have 4 columns (tetrahedra) "
                                            f"and the geometry 3 (x, y, z); found {_shape(top.shape)} and "
                                            f"{_shape(geo.shape)}")
                    n, m = top.shape[0], geo.shape[0]
                    lo, hi = comm.rank * n // comm.size, (comm.rank + 1) * n // comm.size
                    cells = np.asarray(top[lo:hi], np.int64)
                    used, local = np.unique(cells, return_inverse=True)
                    if len(used) and (used[0] < 0 or used[-1] >= m):
                        bad = used[0] if used[0] < 0 else used[-1]
                        raise MeshFileError(f"{path}: {h5.name}:{topology} refers to point {bad}; the geometry "
                                            f"has {m} points")
                    points, read_points = read_rows(geo, used)
            except OSError as exc:
                raise MeshFileError(f"{path}: cannot read {h5.name}: {exc}") from None
            except KeyError as exc:
                raise MeshFileError(f"{path}: {h5.name} has no dataset {exc}") from None
            MeshFile.reads += 1
            MeshFile.cells_read += hi - lo
            MeshFile.points_read += read_points
            points = np.asarray(points, np.float64)
            local = local.reshape(cells.shape)
            mesh = (Mesh(points, local, "tetra", name=str(path), reorient=True) if len(cells) else
                    Mesh.empty("tetra", str(path)))
            return MeshFile(str(path), meshio.Mesh(points, [("tetra", mesh.cells)]), mesh, [0]), used, lo, n, m

        held, used, lo, n, m = _agreed(comm, read)
        mesh, point_ids, cell_ids = balanced(held.mesh, used, lo + np.arange(held.mesh.num_cells), comm)
        held = MeshFile(str(path), meshio.Mesh(mesh.points, [("tetra", mesh.cells)]), mesh, [0])
        return cls(str(path), [held] if mesh.num_cells else [], "tetra", point_ids, cell_ids, m, n, comm)

    @classmethod
    def read(cls, path, comm) -> "Pieces":
        """This rank's pieces of `path` (collective: a bad piece on any rank fails every rank)."""
        files = _agreed(comm, lambda: sources(path))
        held = _agreed(comm, lambda: [MeshFile.read(files[i]) for i in mine(len(files), comm.rank, comm.size)])
        found = sorted({t for ts in comm.allgather([f.mesh.cell_type for f in held]) for t in ts})
        if len(found) != 1:
            raise MeshFileError(f"{path}: the pieces hold {' and '.join(found)} cells; a transfer needs one type")
        points = np.concatenate([f.mesh.points for f in held]) if held else np.zeros((0, 3))
        point_ids, num_points = numbering(points, comm)
        local = sum(f.mesh.num_cells for f in held)
        first_cell, num_cells = _exscan(comm, local)
        cell_ids = first_cell + np.arange(local, dtype=np.int64)
        return cls(str(path), held, found[0], point_ids, cell_ids, num_points, num_cells, comm)

    def _cells(self) -> np.ndarray:
        """The held cells in the joined (duplicated) numbering of the held points."""
        starts = np.cumsum([0] + [f.mesh.num_points for f in self.held])
        if not self.held:
            return np.zeros((0, CELL_TYPES[self.cell_type][1]), np.int64)
        return np.concatenate([f.mesh.cells + s for f, s in zip(self.held, starts)])

    def part(self, family: str):
        """(this rank's :class:`transfer.distributed.Part` in `family`, the index of each of its
        points among the joined points of the held pieces)."""
        from .distributed import Part

        ids, first, inverse = np.unique(self.point_ids, return_index=True, return_inverse=True)
        points = np.concatenate([f.mesh.points for f in self.held]) if self.held else np.zeros((0, 3))
        mesh = Mesh.trusted(points[first], inverse.ravel()[self._cells()], self.cell_type, self.path)
        return Part(mesh, family, ids if FAMILIES[family] else self.cell_ids), first

    def field(self, name: str):
        """The field `name` of every held piece, joined: a :class:`transfer.meshfile.MeshFileField`
        (its values at the joined points or cells; the same kind on every rank)."""

        fields = _agreed(self.comm, lambda: [f.field(name) for f in self.held])
        kinds = {k for ks in self.comm.allgather([f.kind for f in fields]) for k in ks}
        if len(kinds) != 1:
            raise MeshFileError(f"{self.path}: field {name!r} is point data in some pieces, cell data in others")
        kind = kinds.pop()
        shape = self.comm.allgather(fields[0].values.shape[1:] if fields else None)
        shape = next(s for s in shape if s is not None)
        values = np.concatenate([f.values for f in fields]) if fields else np.zeros((0,) + shape)
        return MeshFileField(name, kind, values)

    def whole(self, root: int = 0):
        """The whole mesh with the data every piece has, as a :class:`transfer.meshfile.MeshFile`
        on `root` (points and cells in the order of their global ids: piece order, the file's rows); None elsewhere.
        Collective."""
        import meshio

        comm, held = self.comm, self.held
        names = comm.allgather([(set(f.raw.point_data), set(f.raw.cell_data)) for f in held])
        names = [n for ns in names for n in ns]
        point_names = sorted(set.intersection(*(p for p, _ in names)))
        cell_names = sorted(set.intersection(*(c for _, c in names)))
        join = lambda arrays: np.concatenate(arrays) if arrays else None  # noqa: E731
        points = join([f.mesh.points for f in held])
        point_data = {n: join([np.asarray(f.raw.point_data[n]) for f in held]) for n in point_names}
        cell_data = {n: join([np.concatenate([np.asarray(f.raw.cell_data[n][i]) for i in f.blocks])
                              for f in held]) for n in cell_names}
        mine = (self.point_ids, points, self.point_ids[self._cells()], point_data, cell_data, self.cell_ids)
        every = comm.gather(mine, root=root)
        if comm.rank != root:
            return None
        every = [e for e in every if len(e[0])]
        order = np.argsort(np.concatenate([e[5] for e in every]), kind="stable")  # the file's cell order
        out_points = np.empty((self.num_points, 3))
        out_point_data = {n: np.empty((self.num_points,) + every[0][3][n].shape[1:], every[0][3][n].dtype)
                          for n in point_names}
        for ids, p, _, data, _, _ in every:
            out_points[ids] = p
            for n in point_names:
                out_point_data[n][ids] = data[n]
        cells = np.concatenate([e[2] for e in every])[order]
        out_cell_data = {n: [np.concatenate([e[4][n] for e in every])[order]] for n in cell_names}
        raw = meshio.Mesh(out_points, [(self.cell_type, cells)], point_data=out_point_data, cell_data=out_cell_data)
        return MeshFile(self.path, raw, Mesh.trusted(out_points, cells, self.cell_type, self.path), [0])
