"""The rows 0..count-1 of a field spread over the ranks of a communicator, nothing gathered: a
PETSc vector split in blocks (:func:`transfer.petsc.ownership`) through which any rank puts the
values of the rows it holds and gets those of the rows it needs (the halo of a part, the inputs
of another process's part); :func:`to_ranks` sends rows of integers (cells) to the ranks chosen
for them. Used by the coupler on several ranks (docs/scaling.md, step 3)."""

from __future__ import annotations

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from .petsc import _Local, ownership


class Rows:
    """Rows 0..`count`-1 over the ranks of `comm`; :meth:`move` carries values from the rows a
    rank holds to the rows it asks for (collective)."""

    def __init__(self, comm, count: int):
        self.comm, self.count = comm, int(count)
        self.ranges = ownership(self.count, comm.size)
        self.vec = PETSc.Vec().createMPI((int(self.ranges[comm.rank + 1] - self.ranges[comm.rank]), self.count),
                                         comm=comm)
        self._scatters: dict = {}
        #: the rows of this rank's block
        self.own = np.arange(self.ranges[comm.rank], self.ranges[comm.rank + 1], dtype=np.int64)

    def _local(self, ids: np.ndarray, keep: bool = True) -> _Local:
        """The scatter of `ids`, kept with the array (callers pass the same arrays every iteration)
        unless not `keep`."""
        found = self._scatters.get(id(ids))
        if found is not None and found[0] is ids:
            return found[1]
        local = _Local(self.vec, ids)
        if keep:
            self._scatters[id(ids)] = (ids, local)
        return local

    def move(self, held: np.ndarray, values, wanted: np.ndarray, add: bool = False, keep: bool = True) -> np.ndarray:
        """The values at the rows `wanted` from every rank's `values` at its rows `held` ((n,) or
        (n, k)); with `add` the values given for one row by several ranks are summed, else they
        must be equal. Rows nobody holds read zero; a rank that holds none gets (k,) columns
        of the others' width k (scalars when k is 1, or when no rank holds any). The scatter of
        `wanted` is kept for the next call with the same array, but for a move made once (not
        `keep`). Collective."""
        values = np.asarray(values, dtype=np.float64)
        columns = values.reshape(len(held), -1) if len(held) else np.zeros((0, 0))
        width = self.comm.allreduce(columns.shape[1] if len(held) else 0, op=MPI.MAX)
        out = np.zeros((len(wanted), max(width, 1)))
        source, target = self._local(held), self._local(wanted, keep)
        for c in range(width):
            self.vec.zeroEntries()
            source.put(columns[:, c] if columns.shape[1] else np.zeros(len(held)),
                       PETSc.InsertMode.ADD_VALUES if add else PETSc.InsertMode.INSERT_VALUES)
            out[:, c] = target.get()
        shape = values.shape[1:] if len(held) else (width,) * (width > 1)
        return out.reshape((len(wanted),) + shape)

    def block(self, held: np.ndarray, values, add: bool = False) -> np.ndarray:
        """This rank's block of the rows (``ranges[rank]`` to ``ranges[rank + 1]``) from every
        rank's `values` at its rows `held` ((n,) only). Collective."""
        self.vec.zeroEntries()
        self._local(held).put(np.asarray(values, np.float64),
                                                    PETSc.InsertMode.ADD_VALUES if add else
                                                    PETSc.InsertMode.INSERT_VALUES)
        return self.vec.array.copy()


    def numbering(self, held: np.ndarray) -> tuple[np.ndarray, int]:
        """(index, m): the rows that some rank holds (`held`) numbered 0..m-1 in row order, nothing
        gathered; ``index`` at this rank's block :attr:`own`, -1 for rows nobody holds. Collective."""
        flags = self.block(held, np.ones(len(held))) > 0.5
        first = self.comm.exscan(int(flags.sum())) or 0
        index = np.where(flags, first + np.cumsum(flags) - 1, -1).astype(float)
        return index, self.comm.allreduce(int(flags.sum()))


def to_ranks(comm, arrays: list[np.ndarray], ranks: list[np.ndarray]) -> list[np.ndarray]:
    """Each row of every 2-d integer array of `arrays` sent to the rank given for it (`ranks`, one
    array of ranks per array), all in one alltoallv; per array the rows received, by sending
    rank, each rank's in its order. Collective."""
    arrays = [np.asarray(a, np.int64) for a in arrays]
    widths = np.array([a.shape[1] for a in arrays])
    counts = np.stack([np.bincount(r, minlength=comm.size) for r in ranks], axis=1).astype(np.int64)
    incoming = np.empty_like(counts)
    comm.Alltoall(counts, incoming)
    rows = [a[np.argsort(r, kind="stable")] for a, r in zip(arrays, ranks)]
    starts = [np.concatenate([[0], np.cumsum(c)]) for c in counts.T]
    sent = np.concatenate([np.zeros(0, np.int64)] + [a[s[q]:s[q + 1]].ravel() for q in range(comm.size)
                                                     for a, s in zip(rows, starts)])
    received = np.empty(int((incoming * widths).sum()), np.int64)
    comm.Alltoallv([sent, (counts * widths).sum(axis=1)], [received, (incoming * widths).sum(axis=1)])
    pieces, at = [[] for _ in arrays], 0
    for q in range(comm.size):
        for i, (n, k) in enumerate(zip(incoming[q], widths)):
            pieces[i].append(received[at:at + n * k].reshape(n, k))
            at += n * k
    return [np.concatenate(p) for p in pieces]
