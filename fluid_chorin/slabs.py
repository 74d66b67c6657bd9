"""The grid of the Chorin fluid cut into slabs along one direction, one slab per MPI rank.

Rank r owns the cells ``[lo_r, hi_r)`` along the slab direction ``d`` (array axis
``AXIS[d]``) and holds one more layer of cells on each side that has a neighbour rank (the
ghost layer): its local grid is a :class:`fluid_chorin.staggered.Staggered` of those cells,
whose sides towards a neighbour have the face kind ``"neighbour"`` (no condition: their values
come from the neighbour). Every stencil of the projection (paper eq. 12) reaches one cell, so
an owned value computed on the local grid from correct ghost values is the serial one.

Owned faces of the component normal to the slabs: ``[lo_r, hi_r)``, and the last face too on
the last rank (a face between two slabs belongs to the upper one). :meth:`Slabs.exchange`
copies the owned planes next to a neighbour into its ghost planes; :meth:`Slabs.gather`
collects owned cell values on rank 0 in the grid's order (x fastest) (tests and benchmarks; the
participant answers each rank's owned cells, numbered by :meth:`Slabs.cell_ids`). The pressure unknowns
are numbered rank by rank (:attr:`Slabs.numbering`), each slab's cells in the grid's order.

The inputs (the solid's fraction and velocity per cell) reach a rank for its *input cells*
only: the planes ``[lo_r - L, hi_r + L)`` within the grid, ``L = input_layers`` (the ghost layer
plus the reach of the drag's stencil: :data:`transfer.penalization.REACH`), numbered by
:meth:`Slabs.input_ids`; :meth:`Slabs.from_inputs` cuts the local part out of them.

One rank (``comm`` None or of size 1) is the whole grid: no ghosts, every exchange and sum
local.
"""

from __future__ import annotations

import numpy as np

from coupler.protocol.slabs import slab_bounds
from transfer.grid import BOX_FACES

from .staggered import AXIS, along


class Slabs:
    """The slabs of a grid of ``shape`` with face conditions ``faces`` over the ranks of ``comm``,
    cut along ``slab_axis`` (:data:`coupler.protocol.slabs.SLAB_AXES`), each rank receiving its
    inputs on ``input_layers`` planes beyond its slab."""

    def __init__(self, shape, faces: dict, comm=None, slab_axis: str = "longest", input_layers: int = 1,
                 whole: int | None = None):
        self.comm = comm if comm is not None and comm.Get_size() > 1 else None
        self.rank = self.comm.Get_rank() if self.comm else 0
        self.size = self.comm.Get_size() if self.comm else 1
        self.shape = tuple(int(n) for n in shape)
        self.d, self.bounds = slab_bounds(self.shape, self.size, slab_axis, whole)
        self.axis = AXIS[self.d]
        n = self.shape[self.d]
        self.lo, self.hi = self.bounds[self.rank], self.bounds[self.rank + 1]
        self.below = self.rank - 1 if self.rank > 0 else None
        self.above = self.rank + 1 if self.rank < self.size - 1 else None
        self.ghost = (int(self.below is not None), int(self.above is not None))
        self.start = self.lo - self.ghost[0]  # the first local cell along the slab direction
        local = list(self.shape)
        local[self.d] = self.hi - self.lo + sum(self.ghost)
        #: (nx, ny, nz) of the local grid, ghosts included
        self.local_shape = tuple(local)
        #: the conditions of the grid's faces, and of the local grid's (towards a neighbour: "neighbour")
        self.grid_faces, self.faces = faces, dict(faces)
        for side, neighbour in enumerate((self.below, self.above)):
            if neighbour is not None:
                self.faces[BOX_FACES[2 * self.d + side]] = {"kind": "neighbour", "value": None}
        layer = int(np.prod(self.shape)) // n
        #: the first PETSc number of this rank and the count of its cells
        self.offset, self.count = layer * self.lo, layer * (self.hi - self.lo)
        #: the PETSc number of every local cell (ghosts: the neighbour's number)
        self.numbering = self.cells(self._numbers())
        if input_layers < 1:
            raise ValueError(f"input_layers must reach the ghost layer (at least 1), got {input_layers}")
        #: the planes [first, end) along the slab direction of this rank's input cells
        self.input_planes = (max(0, self.lo - input_layers), min(n, self.hi + input_layers))
        inputs = list(self.shape)
        inputs[self.d] = self.input_planes[1] - self.input_planes[0]
        #: (nx, ny, nz) of the block of input cells
        self.input_shape = tuple(inputs)

    @property
    def box(self) -> tuple[np.ndarray, np.ndarray]:
        """``(lower, upper)`` cell indices (x, y, z) of the owned cells: this rank's box of the grid."""
        lower, upper = np.zeros(3, np.int64), np.asarray(self.shape, np.int64)
        lower[self.d], upper[self.d] = self.lo, self.hi
        return lower, upper

    def _numbers(self) -> np.ndarray:
        cells = self.shape[::-1]
        out = np.empty(cells, dtype=np.int64)
        first = 0
        for lo, hi in zip(self.bounds[:-1], self.bounds[1:]):
            block = out[along(self.axis, slice(lo, hi))]
            block[...] = first + np.arange(block.size).reshape(block.shape)
            first += block.size
        return out

    # ------------------------------------------------------------------ local parts of global arrays
    def cells(self, array: np.ndarray) -> np.ndarray:
        """The local part (ghosts included) of a cell array of the whole grid, ``(nz, ny, nx, ...)``."""
        return array[along(self.axis, slice(self.start, self.hi + self.ghost[1]))]

    def _grid_ids(self, first: int, end: int) -> np.ndarray:
        """The grid index (x fastest) of each cell of the planes [first, end) along the slab
        direction, in the grid's order (without an array of the whole grid)."""
        ranges = [np.arange(n, dtype=np.int64) for n in self.shape]
        ranges[self.d] = np.arange(first, end, dtype=np.int64)
        nx, ny, _ = self.shape
        return ((ranges[2][:, None, None] * ny + ranges[1][None, :, None]) * nx + ranges[0][None, None, :]).ravel()

    def input_ids(self) -> np.ndarray:
        """The grid index (x fastest) of each input cell, in the grid's order."""
        return self._grid_ids(*self.input_planes)

    def from_inputs(self, values: np.ndarray) -> np.ndarray:
        """The local part (ghosts included) of per-cell ``values`` of the input cells (the order
        of :meth:`input_ids`; ``(n,)`` or ``(n, k)``)."""
        values = np.asarray(values)
        block = values.reshape(*self.input_shape[::-1], *values.shape[1:])
        first = self.start - self.input_planes[0]
        return block[along(self.axis, slice(first, first + self.local_shape[self.d]))]

    def owned(self, c: int | None = None) -> tuple:
        """The index of the owned values in a local array: cells (``c`` None) or the faces of component c."""
        last = self.ghost[0] + self.hi - self.lo
        if c == self.d and self.above is None:
            last += 1
        return along(self.axis, slice(self.ghost[0], last))

    # ------------------------------------------------------------------ communication
    def exchange(self, array: np.ndarray, c: int | None = None) -> None:
        """Fill the ghost planes of a local cell array (``c`` None) or of component c's faces
        from the neighbours' owned planes (in place). Normal faces: the plane below the slab from
        below, the two from the slab's upper face up from above."""
        if self.comm is None:
            return
        a, g0 = self.axis, self.ghost[0]
        m = self.hi - self.lo
        up = 2 if c == self.d else 1  # planes the slab above sends down
        self._send(array, along(a, slice(g0, g0 + up)), along(a, slice(-up, None)), self.below, self.above)
        first = g0 + m - 1  # the last owned cell, or the last face below the upper face
        self._send(array, along(a, slice(first, first + 1)), along(a, slice(0, 1)), self.above, self.below)

    def _send(self, array, send, receive, to, source) -> None:
        from mpi4py import MPI

        out = np.ascontiguousarray(array[send]) if to is not None else np.empty(0)
        into = np.empty_like(array[receive]) if source is not None else np.empty(0)
        self.comm.Sendrecv(out, MPI.PROC_NULL if to is None else to, recvbuf=into,
                           source=MPI.PROC_NULL if source is None else source)
        if source is not None:
            array[receive] = into

    def cell_ids(self) -> np.ndarray:
        """The grid index (x fastest) of each owned cell, in the order of ``array[self.owned()].ravel()``."""
        return self._grid_ids(self.lo, self.hi)

    def gather(self, array: np.ndarray) -> np.ndarray | None:
        """The owned cells of a local cell array from every rank, joined on rank 0 (None elsewhere)."""
        mine = array[self.owned()]
        if self.comm is None:
            return mine
        parts = self.comm.gather(np.ascontiguousarray(mine), root=0)
        return np.concatenate(parts, axis=self.axis) if self.rank == 0 else None

    def sum(self, value: float) -> float:
        return self.comm.allreduce(value) if self.comm else value

    def max(self, values: np.ndarray) -> np.ndarray:
        """The largest of each entry over the ranks (one reduction)."""
        if self.comm is None:
            return values
        from mpi4py import MPI

        out = np.empty_like(values)
        self.comm.Allreduce(np.ascontiguousarray(values), out, op=MPI.MAX)
        return out
