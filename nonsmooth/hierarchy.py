"""Semi-geometric multilevel hierarchies from L2 projections (paper section 2.4, eq. 17).

A fine tet mesh that cannot be coarsened is covered by simple structured grids:
the coarsest encloses the mesh's bounding box (optionally with a margin), each
finer grid halves its spacing. Consecutive levels are linked by the pseudo-L2
projection of :mod:`transfer` from the coarser Q1 space onto the finer space
(eq. 17 with the dual basis of eq. 4, so the projection is a sparse matrix; with
the full mass matrix of the L2 method it would be dense).
Coarse basis functions whose support misses the fine mesh (the whole chain of
projections gives them zero weight) are dropped, so the coarse spaces are the
images of the projections restricted to what the fine mesh sees.

Vector fields (displacements, ``block_size`` components per node, node-major:
``x[block_size * node + component]``) use the block prolongation
``kron(P, I_block_size)``.

A mesh of several bodies (connected components of the tet graph, e.g. the two
bodies of a contact problem) gets one set of grids per body
(:func:`per_body_hierarchy`, block-diagonal prolongations), as in Krause's and
Dickopf's contact multigrid: a grid enclosing both bodies has coarse functions
spanning the gap, which tie the bodies together in the coarse spaces.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from transfer import FunctionSpace, Mesh, StructuredGrid, Transfer

#: a coarse basis function is dropped when the sum of its prolongation column is
#: below this fraction of the largest column sum
DROP_RTOL = 1e-10


class HierarchyError(ValueError):
    """A hierarchy that cannot be built: bad levels, shape or mesh."""


@dataclass
class Hierarchy:
    """Prolongations from the coarsest level (0) to the fine mesh (``levels - 1``).

    ``prolongations[l]`` maps level ``l`` to level ``l + 1`` (rows: dofs of the
    finer level, columns: kept dofs of the coarser); ``grids[l]`` is the grid of
    coarse level ``l`` and ``kept[l]`` its nodes that survive the dropping.
    A hierarchy of several bodies (:func:`per_body_hierarchy`) has no grids of
    its own: ``bodies`` holds each body's hierarchy and ``body_nodes`` its fine nodes.
    """

    prolongations: list[sp.csr_matrix]
    grids: list[StructuredGrid]
    kept: list[np.ndarray]
    block_size: int
    seconds: float = 0.0
    bodies: list["Hierarchy"] = field(default_factory=list)
    body_nodes: list[np.ndarray] = field(default_factory=list)

    @property
    def levels(self) -> int:
        return len(self.prolongations) + 1

    @property
    def sizes(self) -> list[int]:
        """Unknowns per level, coarsest first (the last is the fine mesh)."""
        return [p.shape[1] for p in self.prolongations] + [self.prolongations[-1].shape[0]]

    def in_basis(self, Q: sp.spmatrix) -> "Hierarchy":
        """The hierarchy for fine unknowns ``y`` with ``x = Q y`` (Q orthogonal, e.g. the
        rotation of contact nodes to normal/tangential coordinates, paper eq. 10): the
        finest prolongation becomes ``Q^T P``."""
        fine = sp.csr_matrix(Q.T @ self.prolongations[-1])
        return replace(self, prolongations=self.prolongations[:-1] + [fine])

    def galerkin(self, A: sp.spmatrix) -> list[sp.csr_matrix]:
        """Coarse operators ``A_{l} = P_l^T A_{l+1} P_l``, coarsest first, ending with A."""
        ops = [sp.csr_matrix(A)]
        for P in reversed(self.prolongations):
            ops.append((P.T @ ops[-1] @ P).tocsr())
        return ops[::-1]


def enclosing_grids(points: np.ndarray, coarse_shape, count: int, margin: float = 0.0) -> list[StructuredGrid]:
    """`count` grids over the bounding box of `points` enlarged by `margin` (a
    fraction of its size per side), the coarsest with `coarse_shape` cells and
    each next one refined uniformly (spacing halved); coarsest first."""
    points = np.asarray(points, dtype=float)
    shape = np.asarray(coarse_shape, dtype=int).reshape(-1)
    if shape.size == 1:
        shape = np.repeat(shape, 3)
    if shape.size != 3 or np.any(shape < 1):
        raise HierarchyError(f"coarse_shape must be 1 or 3 positive cell counts, got {list(coarse_shape)!r}")
    if count < 1:
        raise HierarchyError(f"a hierarchy needs at least one coarse grid, got {count}")
    if not margin >= 0:
        raise HierarchyError(f"margin must be >= 0, got {margin}")
    lo, hi = points.min(axis=0), points.max(axis=0)
    pad = margin * (hi - lo)
    lo, hi = lo - pad, hi + pad
    return [StructuredGrid.from_bounds(lo, hi, shape * 2**k, name=f"coarse grid {k}") for k in range(count)]


def _projection(coarse: FunctionSpace, fine: FunctionSpace, nthreads: int) -> sp.csr_matrix:
    """The pseudo-L2 projection (eq. 17, dual basis) of the coarse space onto the fine one."""
    T = Transfer.assemble(coarse, fine, "pseudo_l2", nthreads=nthreads)
    if not np.all(T.covered):
        raise HierarchyError(f"{coarse.mesh.name} does not cover {T.uncovered.size} dofs of {fine.mesh.name}")
    return T.matrix()


def semi_geometric_hierarchy(points: np.ndarray, tets: np.ndarray, levels: int, coarse_shape=(2, 2, 2), *,
                             margin: float = 0.0, block_size: int = 3, nthreads: int = 1) -> Hierarchy:
    """The hierarchy of `levels` levels over the P1 space of the fine tet mesh:
    ``levels - 1`` enclosing grids (:func:`enclosing_grids`) and the projections
    between them (eq. 17), coarse dofs without support on the fine mesh dropped."""

    if levels < 2:
        raise HierarchyError(f"levels must be >= 2 (the fine mesh and at least one grid), got {levels}")
    start = time.perf_counter()
    fine = FunctionSpace(Mesh(points, tets, "tetra", name="fine mesh"), "P1")
    grids = enclosing_grids(fine.mesh.points, coarse_shape, levels - 1, margin)
    scalar, kept = [], []
    finer, rows = fine, np.arange(fine.num_dofs)
    for grid in reversed(grids):
        coarse = FunctionSpace(grid, "Q1")
        P = _projection(coarse, finer, nthreads)[rows]
        weight = np.asarray(abs(P).sum(axis=0)).ravel()
        cols = np.flatnonzero(weight > DROP_RTOL * weight.max())
        scalar.append(P[:, cols].tocsr())
        kept.append(cols)
        finer, rows = coarse, cols
    eye = sp.identity(block_size, format="csr")
    prolongations = [sp.kron(P, eye, format="csr") for P in reversed(scalar)]
    return Hierarchy(prolongations, grids, kept[::-1], block_size, time.perf_counter() - start)


def connected_bodies(num_points: int, tets: np.ndarray) -> np.ndarray:
    """The body (connected component of the tet mesh) of each of `num_points` nodes."""
    tets = np.asarray(tets, dtype=np.int64)
    rows = np.repeat(tets, 4, axis=1).ravel()
    cols = np.tile(tets, (1, 4)).ravel()
    graph = sp.csr_matrix((np.ones(rows.size), (rows, cols)), (num_points, num_points))
    return connected_components(graph, directed=False)[1]


def per_body_hierarchy(points: np.ndarray, tets: np.ndarray, levels: int, coarse_shape=(2, 2, 2), *,
                       margin: float = 0.0, block_size: int = 3, nthreads: int = 1) -> Hierarchy:
    """:func:`semi_geometric_hierarchy` built separately for every connected body of
    the mesh (its own enclosing grids), joined with block-diagonal prolongations, so
    no coarse function couples two bodies; one body gives the plain hierarchy."""
    points, tets = np.asarray(points, dtype=float), np.asarray(tets, dtype=np.int64)
    body = connected_bodies(len(points), tets)
    if body.max() == 0:
        return semi_geometric_hierarchy(points, tets, levels, coarse_shape, margin=margin, block_size=block_size,
                                        nthreads=nthreads)
    start = time.perf_counter()
    parts, nodes = [], []
    local = np.empty(len(points), dtype=np.int64)
    for b in range(body.max() + 1):
        on = np.flatnonzero(body == b)
        local[on] = np.arange(on.size)
        parts.append(semi_geometric_hierarchy(points[on], local[tets[body[tets[:, 0]] == b]], levels, coarse_shape,
                                              margin=margin, block_size=block_size, nthreads=nthreads))
        nodes.append(on)
    prolongations = [sp.block_diag([h.prolongations[l] for h in parts], format="csr") for l in range(levels - 1)]
    dofs = (block_size * np.concatenate(nodes)[:, None] + np.arange(block_size)).ravel()
    row_of = np.empty(dofs.size, dtype=np.int64)
    row_of[dofs] = np.arange(dofs.size)  # global fine dof -> row of the body-ordered block
    prolongations[-1] = prolongations[-1][row_of]
    return Hierarchy(prolongations, [], [], block_size, time.perf_counter() - start, parts, nodes)
