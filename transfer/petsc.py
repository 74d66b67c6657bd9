"""The distributed transfer on PETSc (petsc4py): ``B`` and ``D`` as parallel AIJ matrices, rows
owned by blocks of global dof ids as PETSc splits them; pseudo-L2's ``T = D^-1 B`` applied as
``B`` and the inverse diagonal (its matrix made only on request), and the l2 solve (CG on the
overlap mass matrix, Jacobi) run distributed (paper eq. 3-4).

Fields enter and leave as each rank's values at its local dofs (:class:`transfer.distributed.Part`);
scatters carry them to and from the global vectors.
"""

from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp
from mpi4py import MPI
from petsc4py import PETSc

from .errors import FieldError, TransferError
from .assembly import COVERED_RTOL


def destroy_dropped(comm) -> None:
    """Destroy the PETSc objects Python has dropped on `comm` and on PETSc's COMM_SELF (the
    sequential vectors, index sets and scatters of :class:`_Local`). petsc4py (PETSc >= 3.18)
    does not destroy them when their last reference goes: it queues them per communicator until
    a cleanup of that communicator; without it every transfer rebuilt (the coupler's, each time
    the solid deforms) would keep its predecessors' matrices and scatters. Collective on `comm`."""
    PETSc.garbage_cleanup(comm)
    PETSc.garbage_cleanup(PETSc.COMM_SELF)


def ownership(n: int, size: int) -> np.ndarray:
    """First global id of every rank's block, and n (PETSc's split: sizes differ by at most one)."""
    counts = n // size + (np.arange(size) < n % size)
    return np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)


def _to_owners(comm, row_ranges, indptr, rows, cols, vals):
    """The CSR rows given here whose global ids `rows` another rank owns, sent to it as CSR blocks
    (row ids, row lengths, columns, values); returns the rows this rank received (the same four)."""
    owner = np.searchsorted(row_ranges, rows, side="right") - 1
    foreign = np.flatnonzero(owner != comm.rank)
    order = foreign[np.argsort(owner[foreign], kind="stable")]
    lengths = (indptr[order + 1] - indptr[order]).astype(PETSc.IntType)
    entries = np.repeat(indptr[order] - (np.cumsum(lengths) - lengths), lengths) + np.arange(int(lengths.sum()))
    counts = np.stack([np.bincount(owner[order], minlength=comm.size),
                       np.bincount(owner[order], lengths, minlength=comm.size)]).astype(np.int64)
    incoming = np.empty_like(counts)
    for k in (0, 1):
        comm.Alltoall(counts[k], incoming[k])
    out = []
    for a, k in ((rows[order], 0), (lengths, 0), (cols[entries], 1), (vals[entries], 1)):
        r = np.empty(int(incoming[k].sum()), a.dtype)
        comm.Alltoallv([a, counts[k]], [r, incoming[k]])
        out.append(r)
    return out


def _indices(ids) -> np.ndarray:
    ids = np.asarray(ids)
    if len(ids) and ids.max() > np.iinfo(PETSc.IntType).max:
        raise TransferError(f"global dof id {int(ids.max())} does not fit PETSc's {np.dtype(PETSc.IntType)} indices")
    return ids.astype(PETSc.IntType)


def _nonzeros(indptr, rows, diagonal, r0, r1) -> np.ndarray:
    """(2, r1 - r0): the nonzeros of every row r0..r1 in the diagonal block and off it, counted from
    CSR rows at global ids `rows` (others ignored; a row given several times counts each time);
    `diagonal` marks the entries whose column is owned here."""
    inside = np.concatenate([[0], np.cumsum(diagonal, dtype=np.int64)])
    d = inside[indptr[1:]] - inside[indptr[:-1]]
    here = (rows >= r0) & (rows < r1)
    at = np.where(here, rows - r0, 0)
    return np.stack([np.bincount(at, n * here, minlength=r1 - r0)[:r1 - r0] for n in (d, np.diff(indptr) - d)])


def aij(comm, csr, row_ids, col_ids, shape, row_ranges, col_ranges) -> PETSc.Mat:
    """A parallel AIJ matrix from CSR rows given on any rank: `csr` (indptr, indices, data) in local
    numbers, `row_ids` and `col_ids` their global ids (a row given by several ranks is summed). The
    rows this rank owns go straight into its preallocated block; only those owned elsewhere travel,
    as CSR blocks (:func:`_to_owners`); nothing is converted to triplets."""
    indptr, indices, data = csr
    r0, r1, c0, c1 = (ranges[comm.rank + k] for ranges in (row_ranges, col_ranges) for k in (0, 1))
    rows, cols = _indices(row_ids), _indices(col_ids)[indices]
    got_rows, got_lengths, got_cols, got_vals = _to_owners(comm, row_ranges, indptr, rows, cols, data)
    got_indptr = np.concatenate([[0], np.cumsum(got_lengths)])
    nnz = (_nonzeros(indptr, rows, (cols >= c0) & (cols < c1), r0, r1)
           + _nonzeros(got_indptr, got_rows, (got_cols >= c0) & (got_cols < c1), r0, r1))
    width = np.array([[c1 - c0], [shape[1] - (c1 - c0)]])  # a row summed from several ranks: at most its columns
    nnz = np.minimum(nnz, width).astype(PETSc.IntType)
    A = PETSc.Mat().createAIJ(size=((r1 - r0, shape[0]), (c1 - c0, shape[1])), nnz=(nnz[0], nnz[1]), comm=comm)
    A.setOption(PETSc.Mat.Option.NO_OFF_PROC_ENTRIES, True)
    add = PETSc.InsertMode.ADD_VALUES
    owned = np.where((rows >= r0) & (rows < r1), rows, -1).astype(PETSc.IntType)  # PETSc skips rows < 0
    A.setValuesIJV(_indices(indptr), cols, data, addv=add, rowmap=owned)
    A.setValuesIJV(_indices(got_indptr), got_cols, got_vals, addv=add, rowmap=got_rows)
    A.assemble()
    return A


def gather_matrix(A: PETSc.Mat, comm, root: int = 0) -> sp.csr_matrix | None:
    """The whole matrix as scipy CSR on `root` (None elsewhere)."""
    indptr, indices, data = A.getValuesCSR()
    r0, _ = A.getOwnershipRange()
    rows = np.repeat(np.arange(r0, r0 + len(indptr) - 1), np.diff(indptr))
    pieces = comm.gather((rows, indices, data), root=root)
    if comm.rank != root:
        return None
    rows, cols, vals = (np.concatenate(p) for p in zip(*pieces))
    return sp.csr_matrix((vals, (rows, cols)), shape=A.getSize())


class _Local:
    """Scatters between a distributed vector and the values at one part's local dofs."""

    def __init__(self, vec: PETSc.Vec, global_dofs):
        self.vec = vec
        self.local = PETSc.Vec().createSeq(len(global_dofs), comm=PETSc.COMM_SELF)
        index = PETSc.IS().createGeneral(_indices(global_dofs), comm=PETSc.COMM_SELF)
        self.scatter = PETSc.Scatter().create(self.local, None, vec, index)

    def put(self, values, addv=PETSc.InsertMode.INSERT_VALUES) -> PETSc.Vec:
        """The distributed vector from local values (shared dofs: equal values, or summed with ADD)."""
        if addv == PETSc.InsertMode.ADD_VALUES:
            self.vec.zeroEntries()
        self.local.array[:] = values
        self.scatter.scatter(self.local, self.vec, addv=addv, mode=PETSc.ScatterMode.FORWARD)
        return self.vec

    def get(self, vec: PETSc.Vec | None = None) -> np.ndarray:
        """Values of the distributed vector at the local dofs."""
        self.scatter.scatter(self.vec if vec is None else vec, self.local, addv=PETSc.InsertMode.INSERT_VALUES,
                             mode=PETSc.ScatterMode.REVERSE)
        return self.local.array.copy()


def _columns(u: np.ndarray) -> np.ndarray:
    """(n,) or (n, k) values as (n, k) columns (also for n = 0)."""
    return u.reshape(len(u), u.shape[1] if u.ndim > 1 else 1)


class DistributedTransfer:
    """``T = D^{-1} B`` between distributed spaces (:func:`transfer.distributed.assemble`).

    ``B`` (target x source dofs) and ``D`` are PETSc matrices in global dof ids. :meth:`apply`
    takes this rank's values at its source dofs and returns those at its target dofs; ``covered`` marks the local target dofs the source reaches."""

    #: CG stops at this ratio of the Jacobi-scaled residual to that of the right-hand side
    #: (the serial solver's criterion); where it stalls, a direct solve on one rank takes over
    RTOL, MAXITER = 4e-15, 200

    def __init__(self, source, target, method: str, comm, rows: dict, per_dof: dict, stats: dict):
        start = time.perf_counter()
        self.source, self.target, self.method, self.comm = source, target, method, comm
        n_src, n_tgt = (comm.allreduce(int(p.global_dofs.max()) + 1 if len(p.global_dofs) else 0, op=MPI.MAX)
                        for p in (source, target))
        rows_t, rows_s = ownership(n_tgt, comm.size), ownership(n_src, comm.size)
        # each matrix's kernel rows are let go as soon as it is made (popped: nothing else holds them)
        self.B = aij(comm, *rows.pop("B"), (n_tgt, n_src), rows_t, rows_s)
        self.D = aij(comm, *rows.pop("D"), (n_tgt, n_tgt), rows_t, rows_t)
        x, y = self.B.createVecs()
        self._source, self._target = _Local(x, source.global_dofs), _Local(y, target.global_dofs)
        measure, overlap = (self._target.put(per_dof[name], PETSc.InsertMode.ADD_VALUES).array.copy()
                            for name in ("measure", "overlap"))
        nb = target.space.basis_per_cell
        self._mass = self.D.getRowSum()  # int_overlap phi_j: the weight of each dof over the overlap
        diagonal = self.D.getDiagonal().array
        weight = self._mass.array / np.maximum(measure / nb, np.finfo(float).tiny)
        owned_covered = (weight > COVERED_RTOL) & (diagonal > 0)
        self._owned_covered = owned_covered
        flags = y.duplicate()
        flags.array[:] = owned_covered
        self.covered = self._target.get(flags) > 0.5
        coverage = np.divide(overlap, measure, out=np.zeros_like(measure), where=measure > 0)
        flags.array[:] = coverage
        #: fraction of the support of each local target dof that the source covers
        self.coverage = self._target.get(flags)
        self.num_covered = comm.allreduce(int(owned_covered.sum()))
        self.num_target_dofs = n_tgt
        r0 = rows_t[comm.rank]
        uncovered = _indices(r0 + np.flatnonzero(~owned_covered))
        self._inverse, self._ksp, self._direct = None, None, None
        if method == "pseudo_l2":  # T = D^-1 B applied as B, then the inverse diagonal (no copy of B)
            self._inverse = y.duplicate()
            self._inverse.array[:] = np.where(owned_covered, 1.0 / np.where(owned_covered, diagonal, 1.0), 0.0)
        else:
            self._Dc = self.D.duplicate(copy=True)
            self._Dc.zeroRowsColumns(uncovered, diag=1.0)
            self._ksp = ksp = PETSc.KSP().create(comm)
            ksp.setOperators(self._Dc)
            ksp.setType("cg")
            ksp.getPC().setType("jacobi")
            ksp.setNormType(PETSc.KSP.NormType.NATURAL)
            ksp.setTolerances(rtol=self.RTOL, atol=0.0, max_it=self.MAXITER)
        self._b = y.duplicate()
        #: iterations of the last l2 solve (-1: direct)
        self.iterations = 0
        stats["matrix_seconds"] = time.perf_counter() - start
        self.stats = stats

    # -- queries ----------------------------------------------------------------------
    @property
    def warnings(self) -> list[str]:
        return self.stats["warnings"]

    @property
    def covered_fraction(self) -> float:
        return self.num_covered / max(self.num_target_dofs, 1)

    def diagonal(self) -> np.ndarray:
        """The diagonal of D at this rank's target dofs (the overlap volumes of a P0/Q0 target)."""
        return self._target.get(self.D.getDiagonal())

    def row_sums(self) -> np.ndarray:
        """The row sums of D (the lumped mass over the overlap) of the dofs this rank owns in
        PETSc's block split."""
        return self._mass.array.copy()

    def matrix(self) -> PETSc.Mat:
        """T = D^{-1} B (pseudo-L2 only, as in the serial :meth:`transfer.Transfer.matrix`): a new
        matrix (:meth:`apply` does not keep one). Collective."""
        if self._inverse is None:
            raise TransferError("T of the l2 method is dense; use apply, or method='pseudo_l2'")
        T = self.B.duplicate(copy=True)
        T.diagonalScale(L=self._inverse)
        return T

    # -- apply ----------------------------------------------------------------------------
    def _check(self, u) -> np.ndarray:
        """The local source values as (n, k); FieldError on every rank if any rank's are wrong."""
        u = np.asarray(u, dtype=np.float64)
        n = len(self.source.global_dofs)
        problem = ""
        if u.shape[:1] != (n,) or u.ndim > 2:
            problem = f"field has shape {u.shape} on rank {self.comm.rank}; expected ({n},) or ({n}, k)"
        elif not np.all(np.isfinite(u)):
            problem = (f"field has {np.count_nonzero(~np.isfinite(u))} NaN/inf value(s) on rank {self.comm.rank} "
                       f"(first at local dof {int(np.argwhere(~np.isfinite(u))[0, 0])})")
        problems = [p for p in self.comm.allgather(problem) if p]
        if problems:
            raise FieldError(problems[0])
        return _columns(u)

    def _solve(self, b: PETSc.Vec, y: PETSc.Vec) -> None:
        self._ksp.solve(b, y)
        if self._ksp.getConvergedReason() > 0:
            self.iterations = self._ksp.getIterationNumber()
            return
        if self._direct is None:  # a dof covered by a sliver makes D ill-conditioned: LU
            self._direct = PETSc.KSP().create(self.comm)
            self._direct.setOperators(self._Dc)
            self._direct.setType("preonly")
            self._direct.getPC().setType("redundant")
        self._direct.solve(b, y)
        self.iterations = -1

    def apply(self, u, fill: float = np.nan) -> np.ndarray:
        """T u at this rank's target dofs; `fill` (NaN by default) where not covered. Collective."""
        shape = np.shape(u)
        columns = self._check(u)
        out = np.empty((len(self.target.global_dofs), columns.shape[1]))
        x, y = self._source.vec, self._target.vec
        for c in range(columns.shape[1]):
            self._source.put(columns[:, c])
            if self._inverse is not None:
                self.B.mult(x, y)
                y.pointwiseMult(y, self._inverse)
            else:
                self.B.mult(x, self._b)
                self._b.array[~self._owned_covered] = 0.0
                self._solve(self._b, y)
            out[:, c] = self._target.get()
        out[~self.covered] = fill
        return out.reshape((len(out),) + shape[1:])

    __call__ = apply

    def product(self, u) -> np.ndarray:
        """B u at this rank's target dofs: the coupling matrix of eq. 3 alone, a scalar field `u`
        at the source dofs (the serial ``Transfer.B @ u``). Collective."""
        self._source.put(self._check(u)[:, 0])
        self.B.mult(self._source.vec, self._target.vec)
        return self._target.get()

    def integral_source(self, u) -> np.ndarray:
        """Integral of the source field over the overlap (1^T B u), on every rank."""
        ones, colsum = self.B.createVecLeft(), self.B.createVecRight()
        ones.set(1.0)
        self.B.multTranspose(ones, colsum)
        columns = self._check(u)
        values = [colsum.dot(self._source.put(columns[:, c])) for c in range(columns.shape[1])]
        return np.asarray(values) if np.ndim(u) > 1 else np.float64(values[0])

    def integral_target(self, v) -> np.ndarray:
        """Integral over the overlap of a target field given at the covered local dofs."""
        vector = np.ndim(v) > 1
        v = _columns(np.asarray(v, dtype=np.float64))
        mass = self._mass.copy()
        mass.array[~self._owned_covered] = 0.0
        values = [mass.dot(self._target.put(np.where(self.covered, v[:, c], 0.0))) for c in range(v.shape[1])]
        return np.asarray(values) if vector else np.float64(values[0])

    def conservation_error(self, u, v=None) -> float:
        """Relative difference of the integrals of u and T u over the overlap; `v`: T u when
        already at hand (not applied again)."""
        a = np.atleast_1d(self.integral_source(u))
        b = np.atleast_1d(self.integral_target(self.apply(u) if v is None else v))
        return float(np.max(np.abs(a - b)) / max(np.max(np.abs(a)), np.finfo(float).tiny))
