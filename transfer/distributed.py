"""Distributed assembly of the transfer operators over MPI (paper section 2.1).

Each rank holds its own cells of the source and of the target, partitioned in any way: a
:class:`Part` is the mesh of those cells (or a block of a structured grid) and the global id
of each of its dofs. Assembly keeps the kernels' organisation per target cell (eq. 3):

1. boxes: every rank clusters its target cells into a few boxes; the ranks' overall source
   and target boxes are allgathered (12 numbers per rank), and the cluster boxes go to the
   ranks whose source reaches them;
2. the source cells meeting a rank's cluster boxes travel to it, point to point (vertex
   coordinates and global dof ids per cell); a structured grid is known to every rank by
   its origin, spacing and shape, so a rank takes the block of it that it needs and nothing
   travels;
3. each rank runs the serial kernel on its own target cells against the source cells it
   now holds and maps the rows to global dof ids;
4. the rows go to distributed PETSc matrices B and D (:mod:`transfer.petsc`), where apply
   and the l2 solve run.

The result is the serial operator (to rounding: shared rows are summed in another order).
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field

import numpy as np
from mpi4py import MPI

from .errors import NoOverlapError, OverlapWarning, TransferError
from .grid import StructuredGrid
from .heap import give_back
from .mesh import Mesh
from .partition import bisection
from .assembly import (METHODS, assemble_rows, boxes_overlap, integration_rule, no_overlap_message,
                       overlap_warnings, pairing)
from .spaces import FAMILIES, FunctionSpace

#: target cells of a rank are clustered on a grid of this many bins per axis (step 1)
CLUSTER_BINS = 4

#: cluster boxes grow by this fraction of the rank's largest target cell, more than any
#: tolerance of the kernels' searches (the volume search, the trace's ownership probe)
BOX_MARGIN = 1e-5


@dataclass
class Part:
    """One rank's share of a distributed function space.

    ``mesh`` holds the rank's own cells (an empty :meth:`Mesh.empty` when it holds none),
    ``global_dofs[i]`` is the global id of local dof ``i`` (vertex ids for P1/Q1, cell ids
    for P0/Q0; a dof on cells of several ranks appears on each). ``grid`` is the whole grid
    when ``mesh`` is a block of it (:meth:`grid_block`)."""

    mesh: Mesh | StructuredGrid
    family: str
    global_dofs: np.ndarray
    grid: StructuredGrid | None = None
    _space: FunctionSpace | None = field(default=None, init=False, repr=False)

    def __post_init__(self):
        self.global_dofs = np.ascontiguousarray(self.global_dofs, dtype=np.int64)
        if self.global_dofs.shape != (self.space.num_dofs,):
            raise TransferError(f"{self.mesh.name}: {len(self.global_dofs)} global dof ids for "
                                f"{self.space.num_dofs} local {self.family} dofs")

    @property
    def space(self) -> FunctionSpace:
        if self._space is None:
            self._space = FunctionSpace(self.mesh, self.family)
        return self._space

    @property
    def template(self) -> FunctionSpace:
        """A space of the same kind on every rank (the whole grid, or this rank's mesh):
        what the choice of quadrature looks at."""
        return FunctionSpace(self.grid, self.family) if self.grid is not None else self.space

    @property
    def num_cells(self) -> int:
        return self.mesh.num_cells

    @classmethod
    def of_cells(cls, mesh: Mesh, cells, family: str) -> "Part":
        """The part made of `cells` (indices) of a `mesh` every rank holds whole."""
        cells = np.asarray(cells, dtype=np.int64)
        if len(cells) == 0:
            return cls(Mesh.empty(mesh.cell_type, mesh.name), family, np.zeros(0, np.int64))
        vertices, local = np.unique(mesh.cells[cells], return_inverse=True)
        local_mesh = Mesh(mesh.points[vertices], local.reshape(len(cells), -1), mesh.cell_type, name=mesh.name)
        return cls(local_mesh, family, vertices if FAMILIES[family] else cells)

    @classmethod
    def grid_block(cls, grid: StructuredGrid, lower, upper, family: str) -> "Part":
        """Cells ``lower <= (i, j, k) < upper`` of `grid` (an empty block if any upper <= lower)."""
        lower, upper = np.asarray(lower, np.int64), np.asarray(upper, np.int64)
        shape = np.asarray(grid.shape)
        lower, upper = np.clip(lower, 0, shape), np.clip(upper, 0, shape)
        if np.any(upper <= lower):
            return cls(Mesh.empty("hexahedron", grid.name), family, np.zeros(0, np.int64), grid)
        block = StructuredGrid(grid.origin + grid.spacing * lower, grid.spacing, upper - lower, name=grid.name)
        degree = FAMILIES[family]
        n = upper - lower + degree  # points (degree 1) or cells (degree 0) of the block per axis
        stride = shape + degree
        k, j, i = np.meshgrid(*(np.arange(n[d]) + lower[d] for d in (2, 1, 0)), indexing="ij")
        ids = (i + stride[0] * (j + stride[1] * k)).ravel()
        return cls(block, family, ids, grid)


# -- boxes ---------------------------------------------------------------------------------
EMPTY_BOX = np.array([[np.inf] * 3, [-np.inf] * 3])


def _cell_boxes(mesh) -> np.ndarray:
    """(m, 2, 3) lower and upper corners of every cell."""
    if mesh.num_cells == 0:
        return np.zeros((0, 2, 3))
    corners = [mesh.points[c] for c in mesh.cells.T]  # a reduction over the short axis is slow
    lower, upper = corners[0].copy(), corners[0].copy()
    for c in corners[1:]:
        np.minimum(lower, c, out=lower)
        np.maximum(upper, c, out=upper)
    return np.stack([lower, upper], axis=1)


def _union(boxes) -> np.ndarray:
    return np.stack([boxes[:, 0].min(axis=0), boxes[:, 1].max(axis=0)]) if len(boxes) else EMPTY_BOX.copy()


def _clusters(boxes, bins: int = CLUSTER_BINS) -> np.ndarray:
    """Boxes of the cells grouped by the bin (of a bins^3 grid over their union) of their centres."""
    if len(boxes) == 0:
        return np.zeros((0, 2, 3))
    whole = _union(boxes)
    centre = boxes.mean(axis=1)
    extent = np.where(whole[1] > whole[0], whole[1] - whole[0], 1.0)
    ijk = np.clip(((centre - whole[0]) / extent * bins).astype(np.int64), 0, bins - 1)
    key = ijk[:, 0] + bins * (ijk[:, 1] + bins * ijk[:, 2])
    order = np.argsort(key, kind="stable")
    starts = np.flatnonzero(np.r_[True, np.diff(key[order]) != 0])
    return np.stack([np.minimum.reduceat(boxes[order, 0], starts), np.maximum.reduceat(boxes[order, 1], starts)],
                    axis=1)


def _meets(boxes, others) -> np.ndarray:
    """Mask of `boxes` (m, 2, 3) that overlap at least one of `others` (b, 2, 3).

    The boxes are sorted by their lower x once; each of `others` tests only those whose lower
    x lies within its x range widened by the widest box (a contiguous run of the order)."""
    hit = np.zeros(len(boxes), dtype=bool)
    if len(boxes) == 0 or len(others) == 0:
        return hit
    order = np.argsort(boxes[:, 0, 0], kind="stable")
    lo = [np.ascontiguousarray(boxes[order, 0, d]) for d in range(3)]
    hi = [np.ascontiguousarray(boxes[order, 1, d]) for d in range(3)]
    scale = max(np.abs(lo[0]).max(), np.abs(hi[0]).max(), np.abs(others[:, :, 0]).max())
    width = float(np.max(hi[0] - lo[0])) + 8 * np.spacing(scale)  # rounding of the subtraction below
    sorted_hit = np.zeros(len(boxes), dtype=bool)
    for (olo, ohi) in others:
        run = slice(np.searchsorted(lo[0], olo[0] - width, side="left"),
                    np.searchsorted(lo[0], ohi[0], side="right"))
        meets = hi[0][run] >= olo[0]
        for d in (1, 2):
            meets &= lo[d][run] <= ohi[d]
            meets &= hi[d][run] >= olo[d]
        sorted_hit[run] |= meets
    hit[order] = sorted_hit
    return hit


def _overlap(a, b) -> bool:
    return bool(np.all(a[0] <= b[1]) and np.all(b[0] <= a[1]))


@dataclass
class _Extent:
    """The global bounding box of a distributed mesh, for the serial overlap checks."""

    name: str
    lo: np.ndarray
    hi: np.ndarray

    def bounding_box(self):
        return self.lo, self.hi


# -- step 2: the source cells a rank needs -----------------------------------------------------
def _cells_of(part: Part, mask) -> tuple[np.ndarray, np.ndarray]:
    """Vertex coordinates (n, k, 3) and global dof ids (n, nb) of the part's cells in `mask`."""
    return part.mesh.points[part.mesh.cells[mask]], part.global_dofs[part.space.cell_dofs[mask]]


def _held_part(part: Part, coords: np.ndarray, dofs: np.ndarray) -> Part:
    """The source cells a rank holds: its own `part` followed by the received cells
    (vertex coordinates (n, k, 3), global dof ids (n, nb)). With vertex dofs the own points
    keep their numbers and a received vertex is added once, unless the rank has it already."""
    if len(coords) == 0:
        return part
    mesh = part.mesh
    n, k, _ = coords.shape
    if not FAMILIES[part.family]:  # cell dofs: each received cell brings its own points
        points = np.concatenate([mesh.points, coords.reshape(-1, 3)])
        cells = np.concatenate([mesh.cells, len(mesh.points) + np.arange(n * k).reshape(n, k)])
        ids = np.concatenate([part.global_dofs, dofs.ravel()])
    else:
        own = part.global_dofs
        order = np.argsort(own, kind="stable")
        ids, first, inverse = np.unique(dofs.ravel(), return_index=True, return_inverse=True)
        local = np.zeros(len(ids), np.int64)
        known = np.zeros(len(ids), bool)
        if len(own):
            at = order[np.minimum(np.searchsorted(own[order], ids), len(own) - 1)]
            known = own[at] == ids
            local[known] = at[known]
        local[~known] = len(own) + np.arange(np.count_nonzero(~known))
        points = np.concatenate([mesh.points, coords.reshape(-1, 3)[first[~known]]])
        cells = np.concatenate([mesh.cells, local[inverse].reshape(n, k)])
        ids = np.concatenate([own, ids[~known]])
    return Part(Mesh.trusted(points, cells, mesh.cell_type, mesh.name), part.family, ids)


def _grid_cover(part: Part, box) -> Part:
    """The block of the source grid covering `box`."""
    grid = part.grid
    if not np.all(np.isfinite(box)):
        return Part.grid_block(grid, (0, 0, 0), (0, 0, 0), part.family)
    lower = np.floor((box[0] - grid.origin) / grid.spacing).astype(np.int64)
    upper = np.floor((box[1] - grid.origin) / grid.spacing).astype(np.int64) + 1
    return Part.grid_block(grid, np.maximum(lower, 0), np.minimum(upper, grid.shape), part.family)


@dataclass
class Exchange:
    """What step 2 moved: neighbours, cells and bytes sent and received by this rank."""

    sent_to: list = field(default_factory=list)
    received_from: list = field(default_factory=list)
    cells_sent: int = 0
    cells_received: int = 0
    bytes_sent: int = 0
    bytes_received: int = 0


def gather_source(source: Part, target_clusters: np.ndarray, comm, boxes: np.ndarray,
                  cell_boxes: np.ndarray) -> tuple[Part, Exchange]:
    """The source cells that meet this rank's `target_clusters` (boxes grown by the margin),
    from every rank. `boxes` (size, 2, 2, 3) are all ranks' [target box, source box];
    `cell_boxes` those of the own source cells."""
    rank, size = comm.rank, comm.size
    log = Exchange()
    if source.grid is not None:
        return _grid_cover(source, _union(target_clusters)), log
    mine = boxes[rank]
    log.received_from = [q for q in range(size) if q != rank and _overlap(boxes[q, 1], mine[0])]
    log.sent_to = [q for q in range(size) if q != rank and _overlap(mine[1], boxes[q, 0])]
    requests = [comm.isend(target_clusters, dest=q, tag=1) for q in log.received_from]
    for q in log.sent_to:
        theirs = comm.recv(source=q, tag=1)
        c, d = _cells_of(source, _meets(cell_boxes, theirs))
        requests.append(comm.isend((c, d), dest=q, tag=2))
        log.cells_sent += len(c)
        log.bytes_sent += c.nbytes + d.nbytes
    k, nb = source.mesh.cells.shape[1], source.space.basis_per_cell
    coords, dofs = [np.zeros((0, k, 3))], [np.zeros((0, nb), np.int64)]
    for q in log.received_from:  # the own cells stay: the kernel's search passes over those it does not need
        c, d = comm.recv(source=q, tag=2)
        coords.append(c.reshape(-1, k, 3))
        dofs.append(d.reshape(-1, nb))
        log.cells_received += len(c)
        log.bytes_received += c.nbytes + d.nbytes
    for r in requests:
        r.wait()
    return _held_part(source, np.concatenate(coords), np.concatenate(dofs)), log


# -- the whole assembly ---------------------------------------------------------------------
def _global_extent(comm, part: Part, box) -> _Extent:
    lo, hi = np.empty(3), np.empty(3)
    comm.Allreduce(np.ascontiguousarray(box[0], dtype=float), lo, op=MPI.MIN)
    comm.Allreduce(np.ascontiguousarray(box[1], dtype=float), hi, op=MPI.MAX)
    return _Extent(part.mesh.name, lo, hi)


def _search_distance(comm, target: Part) -> float:
    """Half the mean longest edge of the whole target surface (as the serial default)."""
    mesh = target.mesh
    total = float(mesh.longest_edges().sum()) if mesh.num_cells else 0.0
    total, count = comm.allreduce(np.array([total, mesh.num_cells], dtype=float))
    return 0.5 * total / max(count, 1.0)


def assemble(source: Part, target: Part, method: str, comm, *, quadrature_degree: int | None = None,
             search_distance: float | None = None, max_normal_angle: float = 45.0, nthreads: int = 1):
    """Distributed ``T = D^-1 B`` from `source` to `target` (each this rank's :class:`Part`):
    a :class:`transfer.petsc.DistributedTransfer`. Collective on `comm`."""
    from .petsc import destroy_dropped

    destroy_dropped(comm)  # the transfers dropped before this one go before its kernel runs (peak memory)
    give_back()  # so does whatever the caller freed: the kernel's large arrays do not reuse the heap's holes
    transfer = _assembled(source, target, method, comm, quadrature_degree=quadrature_degree,
                          search_distance=search_distance, max_normal_angle=max_normal_angle, nthreads=nthreads)
    give_back()  # the kernel's and the matrices' intermediates, freed by now, leave the resident memory
    return transfer


def _assembled(source: Part, target: Part, method: str, comm, *, quadrature_degree, search_distance,
               max_normal_angle, nthreads):
    from .petsc import DistributedTransfer

    if method not in METHODS:
        raise TransferError(f"unknown method {method!r}; use one of {METHODS}")
    for part in (source, target):
        if not isinstance(part, Part):
            raise TransferError(f"with comm=, the source and target are this rank's transfer.distributed.Part "
                                f"of each space, not {type(part).__name__}")
    start = time.perf_counter()
    rule = integration_rule(source.template, target.template, quadrature_degree)
    kind = pairing(source.template.mesh, target.template.mesh)
    surface = kind == "surface"
    if search_distance is None:
        search_distance = _search_distance(comm, target) if surface else 0.0

    target_boxes = _cell_boxes(target.mesh)
    source_boxes = _cell_boxes(source.mesh) if source.grid is None else None
    margin = search_distance + BOX_MARGIN * (np.linalg.norm(target_boxes[:, 1] - target_boxes[:, 0], axis=1).max()
                                             if len(target_boxes) else 0.0)
    clusters = _clusters(target_boxes)
    clusters[:, 0] -= margin
    clusters[:, 1] += margin
    source_box = (_union(source_boxes) if source.grid is None else
                  np.stack(source.grid.bounding_box()))
    boxes = np.array(comm.allgather(np.stack([_union(clusters), source_box])))
    extents = (_global_extent(comm, source, _union(source_boxes) if source.grid is None else source_box),
               _global_extent(comm, target, _union(target_boxes)))
    if not surface and not boxes_overlap(*extents):
        raise NoOverlapError(no_overlap_message(*extents))
    held, exchange = gather_source(source, clusters, comm, boxes, source_boxes)
    exchange_seconds = time.perf_counter() - start

    start = time.perf_counter()
    if held.num_cells and target.num_cells:
        raw = assemble_rows(held.space, target.space, method, rule, search_distance=search_distance,
                            max_normal_angle=max_normal_angle, nthreads=nthreads)
    else:
        raw = _no_rows(target)
    kernel_seconds = time.perf_counter() - start
    start = time.perf_counter()
    comm.Barrier()  # the ranks' kernels differ in time: what the fastest waits is imbalance
    wait_seconds = time.perf_counter() - start

    tested, intersected, covered_any = comm.allreduce(
        np.array([raw["pairs_tested"], raw["pairs_intersected"], int(np.any(raw["overlap"] > 0))], dtype=np.int64))
    if not covered_any:
        raise NoOverlapError(no_overlap_message(*extents))
    found = overlap_warnings(*extents, proximity=surface)
    for text in found:
        warnings.warn(text, OverlapWarning, stacklevel=4)
    rows = {"B": (raw.pop("B"), target.global_dofs, held.global_dofs),
            "D": (raw.pop("D"), target.global_dofs, target.global_dofs)}
    cells, nb = target.space.cell_dofs, target.space.basis_per_cell
    per_dof = {name: np.bincount(cells.ravel(), np.repeat(raw[name], nb), target.space.num_dofs)
               for name in ("measure", "overlap")}
    stats = {"pairs_tested": int(tested), "pairs_intersected": int(intersected),
             "quadrature_degree": rule.degree, "quadrature_points": len(rule.weights), "nthreads": nthreads,
             "warnings": found, "ranks": comm.size,
             "assembly_seconds": comm.allreduce(kernel_seconds, op=MPI.MAX),
             "exchange_seconds": exchange_seconds, "kernel_seconds": kernel_seconds, "wait_seconds": wait_seconds,
             "source_cells_held": held.num_cells, "target_cells": target.num_cells,
             "exchange": exchange}
    return DistributedTransfer(source, target, method, comm, rows, per_dof, stats)


def _no_rows(target: Part) -> dict:
    empty = (np.zeros(target.space.num_dofs + 1, np.int64), np.zeros(0, np.int32), np.zeros(0))
    zeros = np.zeros(target.num_cells)
    return {"B": empty, "D": empty, "overlap": zeros, "measure": zeros, "pairs_tested": 0, "pairs_intersected": 0}


def scatter(mesh: Mesh | None, family: str, values, comm, root: int = 0) -> tuple[Part, np.ndarray | None]:
    """This rank's :class:`Part` of `mesh`, which `root` alone holds (None elsewhere), and the
    `values` at its dofs (None if `values` is None): `root` cuts the cells by
    :func:`transfer.partition.bisection`, as every rank would cut a mesh it held whole, and
    sends each rank its cells, their points and global dof ids, one rank at a time (the parts
    are not all held at once). Collective on `comm`."""

    if comm.rank == root:
        owner = bisection(mesh, comm.size)
        head = (mesh.cell_type, mesh.name)
        comm.bcast(head, root=root)
        for r in [*(q for q in range(comm.size) if q != root), root]:
            part = Part.of_cells(mesh, np.flatnonzero(owner == r), family)
            piece = (part.mesh.points, part.mesh.cells, part.global_dofs,
                     None if values is None else values[part.global_dofs])
            if r != root:
                comm.send(piece, dest=r, tag=3)
    else:
        head = comm.bcast(None, root=root)
        piece = comm.recv(source=root, tag=3)
    points, cells, dofs, local = piece
    return Part(Mesh.trusted(points, cells, *head), family, dofs), local


def gather(part: Part, values, comm, root: int = 0):
    """The whole field (global dof order) on `root` from every rank's values at its local
    dofs (a dof on several ranks takes one of their equal values); None elsewhere."""
    values = np.asarray(values)
    pieces = comm.gather((part.global_dofs, values), root=root)
    if comm.rank != root:
        return None
    n = max((int(ids.max()) + 1 for ids, _ in pieces if len(ids)), default=0)
    out = np.empty((n,) + values.shape[1:], dtype=values.dtype)
    for ids, v in pieces:
        out[ids] = v
    return out
