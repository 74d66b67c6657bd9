"""The obstacle problem of paper section 4.3 as a :class:`BoundConstrainedQP`, assembled
without dolfinx: the nonsmooth package's own test problem (its solvers are tested on it), and
the reference the solid participant's contact with a rigid plane is checked against
(tests/solid_fenicsx/test_obstacle.py: the same matrix to round-off).

Linear elasticity with P1 tetrahedra (assembled here, vectorised, node-major
unknowns ``u[3 * node + component]``), prescribed displacements on some nodes,
and a rigid plane ``z = plane`` the body may not cross: ``z + u_z >= plane`` at
every node (for P1 the nodal condition is the condition everywhere).
Prescribed components are eliminated symmetrically (identity rows and columns,
``lower = upper`` = the value), so A stays symmetric positive definite and every
solver sees the same problem.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from transfer.grid import StructuredGrid
from transfer.mesh import lattice_tetrahedra

from .problem import BoundConstrainedQP


def lame(E: float, nu: float) -> tuple[float, float]:
    """(lambda, mu) from Young's modulus and Poisson's ratio."""
    if not (E > 0 and -1 < nu < 0.5):
        raise ValueError(f"need E > 0 and -1 < nu < 0.5, got E = {E}, nu = {nu}")
    return E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))


def p1_elasticity_stiffness(points: np.ndarray, tets: np.ndarray, E: float, nu: float,
                            chunk: int = 200_000) -> sp.csr_matrix:
    """Stiffness matrix of isotropic linear elasticity, P1 on tetrahedra:
    ``K_e = |T| B^T C B`` with the constant strain-displacement matrix B."""
    lam, mu = lame(E, nu)
    points, tets = np.asarray(points, float), np.asarray(tets, np.int64)
    n = 3 * len(points)
    C = np.zeros((6, 6))
    C[:3, :3] = lam
    C[np.arange(3), np.arange(3)] += 2 * mu
    C[np.arange(3, 6), np.arange(3, 6)] = mu
    K = sp.csr_matrix((n, n))
    for s in range(0, len(tets), chunk):
        cells = tets[s:s + chunk]
        p = points[cells]  # (m, 4, 3)
        J = (p[:, 1:] - p[:, :1]).transpose(0, 2, 1)  # columns: edges from vertex 0
        vol = np.abs(np.linalg.det(J)) / 6.0
        ref = np.array([[-1.0, -1, -1], [1, 0, 0], [0, 1, 0], [0, 0, 1]])  # reference gradients
        G = ref @ np.linalg.inv(J)  # (m, 4, 3) physical gradients
        B = np.zeros((len(cells), 6, 12))
        for a in range(4):
            gx, gy, gz = G[:, a, 0], G[:, a, 1], G[:, a, 2]
            c = 3 * a
            B[:, 0, c], B[:, 1, c + 1], B[:, 2, c + 2] = gx, gy, gz
            B[:, 3, c + 1], B[:, 3, c + 2] = gz, gy  # gamma_yz
            B[:, 4, c], B[:, 4, c + 2] = gz, gx  # gamma_xz
            B[:, 5, c], B[:, 5, c + 1] = gy, gx  # gamma_xy
        Ke = vol[:, None, None] * (B.transpose(0, 2, 1) @ (C @ B))
        dofs = (3 * cells[:, :, None] + np.arange(3)).reshape(len(cells), 12)
        rows = np.repeat(dofs, 12, axis=1).ravel()
        cols = np.tile(dofs, (1, 12)).ravel()
        K = K + sp.csr_matrix((Ke.ravel(), (rows, cols)), shape=(n, n))
    return K.tocsr()


def obstacle_qp(points: np.ndarray, tets: np.ndarray, E: float, nu: float, prescribed: np.ndarray,
                displacement, plane: float = 0.0) -> BoundConstrainedQP:
    """The body pressed onto the plane ``z = plane``: the nodes `prescribed`
    (indices) move by `displacement` (3 components), no body force, and
    ``u_z >= plane - z`` at every node."""
    points = np.asarray(points, float)
    K = p1_elasticity_stiffness(points, tets, E, nu)
    n = K.shape[0]
    fixed = (3 * np.asarray(prescribed, np.int64)[:, None] + np.arange(3)).ravel()
    g = np.zeros(n)
    g[fixed] = np.tile(np.asarray(displacement, float).reshape(3), len(prescribed))
    mask = np.zeros(n, bool)
    mask[fixed] = True
    keep = sp.diags((~mask).astype(float))
    A = (keep @ K @ keep + sp.diags(mask.astype(float))).tocsr()
    A.eliminate_zeros()
    b = np.where(mask, g, -(K @ g))
    lower = np.full(n, -np.inf)
    lower[2::3] = plane - points[:, 2]
    upper = np.full(n, np.inf)
    lower[fixed], upper[fixed] = g[fixed], g[fixed]
    return BoundConstrainedQP(A, b, lower, upper, block_size=3, near_nullspace=rigid_body_modes(points))


def rigid_body_modes(points: np.ndarray) -> np.ndarray:
    """(3 n, 6) translations and rotations of the nodes, node-major."""
    points = np.asarray(points, float)
    n = len(points)
    R = np.zeros((3 * n, 6))
    for c in range(3):
        R[c::3, c] = 1.0
    x, y, z = points.T
    R[0::3, 3], R[1::3, 3] = -y, x
    R[1::3, 4], R[2::3, 4] = -z, y
    R[0::3, 5], R[2::3, 5] = z, -x
    return R


def box_obstacle(cells: int, size: float, E: float, nu: float, displacement, plane: float = 0.0, tilt: float = 0.0):
    """The benchmark of paper figure 13: the cube ``[0, size]^3`` in `cells`^3
    lattice hexahedra split into tetrahedra, its top face moved by
    `displacement`, over the plane ``z = plane + tilt * (x - size / 2)``
    (`tilt` != 0 makes the contact set partial). Returns (points, tets, qp)."""
    grid = StructuredGrid.from_bounds([0.0] * 3, [size] * 3, [cells] * 3)
    points, tets = grid.points, lattice_tetrahedra(grid.shape)
    top = np.flatnonzero(np.isclose(points[:, 2], size, rtol=0, atol=1e-9 * size))
    qp = obstacle_qp(points, tets, E, nu, top, displacement, plane)
    free = ~np.isfinite(qp.upper[2::3])  # not prescribed
    qp.lower[2::3][free] += tilt * (points[free, 0] - size / 2)
    return points, tets, qp
