"""Transfer operators between non-matching meshes (paper section 2.1).

``coupling_operator`` assembles, over the exact intersection of the two meshes,
the coupling matrix ``B`` (eq. 3: B[k, j] = int lambda_j^V lambda_k^W) and the
target mass matrix ``D`` restricted to the overlap. :class:`Transfer` applies
``T = D^{-1} B``:

* ``method="l2"``: the full overlap mass matrix, factorised once (never
  inverted densely);
* ``method="pseudo_l2"``: the dual basis of eq. 4 on the target, so ``D`` is
  diagonal. Target elements cut by the boundary of the overlap, where the dual
  basis is not biorthogonal, use the standard basis with a lumped mass.

Both are conservative over the overlap: the integral of ``T u`` over the
overlap equals that of ``u``. Target dofs the source does not reach are
reported in ``Transfer.covered`` and filled with NaN by default, never zero.
Meshes that look like different length units or places get an
:class:`OverlapWarning` (:func:`overlap_warnings`), kept in ``Transfer.warnings``.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .assembly import (COVERED_RTOL, METHODS, assemble_rows, boxes_overlap, default_search_distance,
                       integration_rule, no_overlap_message, overlap_warnings, pairing)
from .errors import FieldError, NoOverlapError, OverlapWarning, TransferError
from .heap import give_back
from .spaces import FunctionSpace

@dataclass
class Coupling:
    """The matrices of eq. 3 assembled over the overlap of two meshes."""

    B: sp.csr_matrix  # target dofs x source dofs
    D: sp.csr_matrix  # target dofs x target dofs (diagonal for pseudo_l2)
    overlap: np.ndarray  # per target cell: measure covered by the source
    measure: np.ndarray  # per target cell: its measure
    stats: dict = field(default_factory=dict)


def coupling_operator(source: FunctionSpace, target: FunctionSpace, method: str = "l2", *,
                      quadrature_degree: int | None = None, search_distance: float | None = None,
                      max_normal_angle: float = 45.0, nthreads: int = 1) -> Coupling:
    """Assemble ``B`` and ``D`` of eq. 3 (``method="pseudo_l2"``: with the dual basis of eq. 4).

    Products of affine bases (P0, P1 on tets) are integrated exactly from the
    moments of the intersection unless `quadrature_degree` is given; other
    pairs use a simplex rule of that degree (default: exact for the bases) on
    the intersection pieces; degrees above :data:`transfer.quadrature.MAX_DEGREE`
    raise :class:`QuadratureError`.

    Volume meshes (tetra, hexahedron, structured grid) are intersected exactly;
    a surface target inside a volume source gets the trace of the volume field
    (its surface elements clipped by the source cells); surface meshes (triangle,
    quad in 3D) are paired by mortar segmentation: elements within
    `search_distance` along the target normal and with normals within
    `max_normal_angle` degrees (either orientation) are projected on the target
    element's plane, clipped and integrated.
    """
    if method not in METHODS:
        raise TransferError(f"unknown method {method!r}; use one of {METHODS}")
    rule = integration_rule(source, target, quadrature_degree)
    smesh, tmesh = source.mesh, target.mesh
    surface = pairing(smesh, tmesh) == "surface"
    if search_distance is None:
        search_distance = default_search_distance(tmesh) if surface else 0.0
    if not boxes_overlap(smesh, tmesh) and not surface:
        raise NoOverlapError(no_overlap_message(smesh, tmesh))
    start = time.perf_counter()
    raw = assemble_rows(source, target, method, rule, search_distance=search_distance,
                        max_normal_angle=max_normal_angle, nthreads=nthreads)
    seconds = time.perf_counter() - start
    shape_b = (target.num_dofs, source.num_dofs)
    B = sp.csr_matrix((raw["B"][2], raw["B"][1], raw["B"][0]), shape=shape_b)
    D = sp.csr_matrix((raw["D"][2], raw["D"][1], raw["D"][0]), shape=(target.num_dofs,) * 2)
    if not np.any(raw["overlap"] > 0):
        raise NoOverlapError(no_overlap_message(smesh, tmesh))
    found = overlap_warnings(smesh, tmesh, proximity=surface)
    for text in found:
        warnings.warn(text, OverlapWarning, stacklevel=3)
    stats = {"pairs_tested": int(raw["pairs_tested"]), "pairs_intersected": int(raw["pairs_intersected"]),
             "assembly_seconds": seconds, "quadrature_degree": rule.degree, "quadrature_points": len(rule.weights),
             "nthreads": nthreads, "warnings": found}
    return Coupling(B, D, raw["overlap"], raw["measure"], stats)


class Transfer:
    """``T = D^{-1} B`` from `source` to `target` (paper eq. 3, eq. 4 for pseudo-L2).

    Use :meth:`assemble` to build one; call it (or :meth:`apply`) on source dof
    values, shape (n,) or (n, k) for vector fields.
    """

    def __init__(self, source: FunctionSpace, target: FunctionSpace, method: str, coupling: Coupling):
        self.source, self.target, self.method = source, target, method
        self.B, self.D = coupling.B, coupling.D
        self.coupling = coupling
        cells, nb = target.cell_dofs, target.basis_per_cell
        per_dof = lambda per_cell: np.bincount(cells.ravel(), np.repeat(per_cell, nb), target.num_dofs)
        measure, overlap = per_dof(coupling.measure), per_dof(coupling.overlap)
        #: fraction of the support of each target dof that the source covers
        self.coverage = np.divide(overlap, measure, out=np.zeros_like(measure), where=measure > 0)
        # A dof is covered when its basis function has weight over the overlap
        # (int_overlap phi_j, the row sum of D, against about int phi_j).
        weight = np.asarray(self.D.sum(axis=1)).ravel() / np.maximum(measure / nb, np.finfo(float).tiny)
        self.covered = (weight > COVERED_RTOL) & (self.D.diagonal() > 0)
        self._index = np.flatnonzero(self.covered)
        Dc = self.D[self._index][:, self._index]
        self._solve = _DiagonalSolve(Dc.diagonal()) if method == "pseudo_l2" else _MassSolve(Dc)

    @classmethod
    def assemble(cls, source, target, method: str = "l2", comm=None, **kwargs):
        """Assemble the transfer; keyword arguments go to :func:`coupling_operator`.

        With an MPI communicator `comm`, `source` and `target` are this rank's
        :class:`transfer.distributed.Part` of each space (any partition) and the
        result is a :class:`transfer.petsc.DistributedTransfer` (distributed PETSc
        matrices, equal to the serial operator)."""
        if comm is not None:
            from .distributed import assemble

            return assemble(source, target, method, comm, **kwargs)
        give_back()  # what the caller freed leaves the resident memory before the kernel's large arrays come
        transfer = cls(source, target, method, coupling_operator(source, target, method, **kwargs))
        give_back()  # and so do the kernel's intermediates
        return transfer

    @property
    def stats(self) -> dict:
        return self.coupling.stats

    @property
    def warnings(self) -> list[str]:
        """The :class:`OverlapWarning` texts of this pair of meshes (:func:`overlap_warnings`)."""
        return self.coupling.stats["warnings"]

    @property
    def covered_fraction(self) -> float:
        return float(self.covered.mean())

    @property
    def num_covered(self) -> int:
        return int(np.count_nonzero(self.covered))

    @property
    def num_target_dofs(self) -> int:
        return self.target.num_dofs

    @property
    def uncovered(self) -> np.ndarray:
        """Indices of target dofs the source does not reach."""
        return np.flatnonzero(~self.covered)

    def matrix(self) -> sp.csr_matrix:
        """T = D^{-1} B as a sparse matrix (pseudo-L2 only: with the full mass
        matrix of the L2 method T is dense, use :meth:`apply`). Rows of
        uncovered target dofs are empty."""
        if self.method != "pseudo_l2":
            raise TransferError("T of the l2 method is dense; use Transfer.apply, or method='pseudo_l2'")
        scale = np.zeros(self.target.num_dofs)
        scale[self._index] = self._solve.inverse
        return (sp.diags(scale) @ self.B).tocsr()

    def apply(self, u, fill: float = np.nan) -> np.ndarray:
        """T u on the covered target dofs; `fill` (NaN by default) elsewhere."""
        u = np.asarray(u, dtype=np.float64)
        if u.shape[0] != self.source.num_dofs or u.ndim > 2:
            raise FieldError(f"field has shape {u.shape}; expected ({self.source.num_dofs},) or "
                             f"({self.source.num_dofs}, k) for {self.source}")
        if not np.all(np.isfinite(u)):
            raise FieldError(f"field has {np.count_nonzero(~np.isfinite(u))} NaN/inf value(s) "
                             f"(first at dof {int(np.argwhere(~np.isfinite(u))[0, 0])})")
        rhs = (self.B @ u)[self._index]
        out = np.full((self.target.num_dofs,) + u.shape[1:], fill, dtype=np.float64)
        out[self._index] = self._solve(rhs)
        return out

    __call__ = apply

    def integral_source(self, u) -> np.ndarray:
        """Integral of the source field over the overlap (1^T B u)."""
        return np.asarray(self.B.sum(axis=0)).ravel() @ np.asarray(u, dtype=np.float64)

    def integral_target(self, v) -> np.ndarray:
        """Integral over the overlap of a target field given on the covered dofs."""
        mass = np.asarray(self.D.sum(axis=1)).ravel()[self._index]
        return mass @ np.asarray(v, dtype=np.float64)[self._index]

    def conservation_error(self, u, v=None) -> float:
        """Relative difference of the integrals of u and T u over the overlap; `v`: T u when
        already at hand (not applied again)."""
        v = self.apply(u) if v is None else v
        a, b = np.atleast_1d(self.integral_source(u)), np.atleast_1d(self.integral_target(v))
        return float(np.max(np.abs(a - b)) / max(np.max(np.abs(a)), np.finfo(float).tiny))


class _MassSolve:
    """Solve with the (overlap) mass matrix: conjugate gradients with a Jacobi
    preconditioner, which needs a handful of iterations on mass matrices of
    shape-regular meshes whatever their size; a sparse LU where CG stalls (a
    dof covered only by a sliver of overlap makes D ill-conditioned)."""

    def __init__(self, D: sp.csr_matrix, rtol: float = 1e-15, maxiter: int = 200):
        self.D, self.rtol, self.maxiter = D, rtol, maxiter
        self.inv_diag = 1.0 / D.diagonal()
        self._lu = None
        #: iterations of the last solve (-1: direct)
        self.iterations = 0

    def __call__(self, rhs: np.ndarray) -> np.ndarray:
        x = self._pcg(rhs)
        if x is None:
            if self._lu is None:
                self._lu = spla.splu(self.D.tocsc())
            self.iterations = -1
            x = self._lu.solve(rhs)
        return x

    def _pcg(self, b):
        """Preconditioned CG on all columns of b at once."""
        d = self.inv_diag.reshape((-1,) + (1,) * (b.ndim - 1))
        x = b * d
        r = b - self.D @ x
        z = r * d
        p = z.copy()
        rz = np.sum(r * z, axis=0)
        # Stop on the Jacobi-scaled residual: the unscaled one would accept large
        # errors at dofs whose mass over the overlap is small.
        target = self.rtol * np.sqrt(np.sum(b * b * d, axis=0)) + np.finfo(float).tiny
        for it in range(self.maxiter):
            if np.all(np.sqrt(np.abs(rz)) <= 4 * target):
                self.iterations = it
                return x
            q = self.D @ p
            alpha = rz / np.where(rz == 0, 1.0, np.sum(p * q, axis=0))
            x += alpha * p
            r -= alpha * q
            z = r * d
            rz_new = np.sum(r * z, axis=0)
            p = z + (rz_new / np.where(rz == 0, 1.0, rz)) * p
            rz = rz_new
        return None


class _DiagonalSolve:
    def __init__(self, diagonal):
        self.inverse = 1.0 / diagonal

    def __call__(self, rhs):
        return rhs * self.inverse.reshape((-1,) + (1,) * (rhs.ndim - 1))
