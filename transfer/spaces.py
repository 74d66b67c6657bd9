"""Function spaces: P0/P1 on simplices, Q0/Q1 on hexahedra, quadrilaterals and grids.

Degree-0 spaces have one dof per cell (the cell index); degree-1 spaces one dof
per mesh vertex (the vertex index), with the VTK vertex order as local order.
Element mass matrices and the global mass matrix live here too: they are the
``D`` of paper eq. 3 when the source covers the whole target (for hexahedra
with planar faces: the kernels integrate a warped hexahedron over its six
tetrahedra, :data:`transfer.mesh.HEX_TETS`).
"""

from __future__ import annotations

from functools import cached_property

import numpy as np
import scipy.sparse as sp

from .errors import SpaceError
from .grid import StructuredGrid
from .mesh import Mesh
from .quadrature import gauss_tensor, simplex_rule

FAMILIES = {"P0": 0, "P1": 1, "Q0": 0, "Q1": 1}


def _q1_basis(dim: int, xi: np.ndarray):
    """Q1 basis (VTK order) and reference gradients at points xi (q, dim) of [0,1]^dim."""
    x, y = xi[:, 0], xi[:, 1]
    phi2 = np.stack([(1 - x) * (1 - y), x * (1 - y), x * y, (1 - x) * y], axis=1)
    dphi2 = np.stack([np.stack([-(1 - y), (1 - y), y, -y], axis=1),
                      np.stack([-(1 - x), -x, x, (1 - x)], axis=1)], axis=2)  # (q, 4, 2)
    if dim == 2:
        return phi2, dphi2
    z = xi[:, 2][:, None]
    phi = np.concatenate([phi2 * (1 - z), phi2 * z], axis=1)
    grad_xy = np.concatenate([dphi2 * (1 - z)[..., None], dphi2 * z[..., None]], axis=1)
    grad_z = np.concatenate([-phi2, phi2], axis=1)[..., None]
    return phi, np.concatenate([grad_xy, grad_z], axis=2)  # (q, 8), (q, 8, 3)


class FunctionSpace:
    """A Lagrange space on a :class:`Mesh` or :class:`StructuredGrid`.

    ``family`` is ``"P0"``/``"P1"`` on tetrahedra and triangles, ``"Q0"``/``"Q1"``
    on hexahedra, quadrilaterals and structured grids."""

    def __init__(self, mesh: Mesh | StructuredGrid, family: str):
        if family not in FAMILIES:
            raise SpaceError(f"unknown family {family!r}; use one of {sorted(FAMILIES)}")
        wants_simplex = family.startswith("P")
        if wants_simplex != mesh.is_simplex:
            kind = "simplices (tetra, triangle)" if wants_simplex else "hexahedra, quads and grids"
            raise SpaceError(f"{mesh.name}: {family} is defined on {kind}, not on {mesh.cell_type} cells")
        self.mesh = mesh
        self.family = family
        self.degree = FAMILIES[family]

    @property
    def num_dofs(self) -> int:
        return self.mesh.num_cells if self.degree == 0 else self.mesh.num_points

    @property
    def basis_per_cell(self) -> int:
        return 1 if self.degree == 0 else self.mesh.cells.shape[1]

    @cached_property
    def cell_dofs(self) -> np.ndarray:
        if self.degree == 0:
            return np.arange(self.mesh.num_cells, dtype=np.int64)[:, None]
        return self.mesh.cells

    @cached_property
    def dof_coordinates(self) -> np.ndarray:
        if self.degree == 0:
            return self.mesh.points[self.mesh.cells].mean(axis=1)
        return self.mesh.points

    def interpolate(self, f) -> np.ndarray:
        """Values of f (callable on (n, 3) points) at the dofs: nodal for degree 1,
        cell centroids for degree 0."""
        return np.asarray(f(self.dof_coordinates), dtype=np.float64)

    # -- quadrature over the cells ----------------------------------------------
    def cell_quadrature(self, degree: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """A rule on every cell, exact to `degree` on affine simplices and boxes:
        points x (m, q, 3), weights w (m, q) (with |det J| of the reference map;
        sum_q w[K, q] = |K|) and the basis at the reference points phi (q, nb), so
        that a field with dof values u is u_h(x[K, q]) = phi[q] @ u[cell_dofs[K]].
        Simplices: :func:`simplex_rule`; quadrilaterals and hexahedra: Gauss on [0,1]^d."""
        mesh = self.mesh
        p = mesh.points[mesh.cells]  # (m, k, 3)
        if mesh.is_simplex:
            bary, weights = simplex_rule(mesh.tdim, degree)
            shape, w = bary, mesh.cell_measures()[:, None] * weights[None, :]
        else:
            xi, weights = gauss_tensor(mesh.tdim, degree // 2 + 1)
            shape, dshape = _q1_basis(mesh.tdim, xi)
            jac = np.einsum("mkd,qke->mqde", p, dshape)  # dx_d / dxi_e
            if mesh.tdim == 3:
                det = np.abs(np.linalg.det(jac))
            else:
                det = np.linalg.norm(np.cross(jac[..., 0], jac[..., 1]), axis=-1)
            w = weights[None, :] * det
        phi = shape if self.degree == 1 else np.ones((len(shape), 1))
        return np.einsum("qk,mkd->mqd", shape, p), w, phi

    def l2_squares(self, values, f, cells=None, degree: int = 4) -> tuple[float, float]:
        """||u_h - f||^2 and ||f||^2 in L2 over `cells` (a mask or indices; default all; squares, so
        that the sums over the parts of a mesh add up), u_h the field with dof `values` (n,), f a
        callable on (n, 3) points, by
        :meth:`cell_quadrature` of `degree` (Keast's 11 points on tetrahedra, 3^d
        Gauss points on hexahedra and quadrilaterals): exact for a polynomial f of
        degree 2 against P1 / Q1 on affine cells, within 1e-4 of the converged
        value for the smooth field of the transfer demo."""
        x, w, phi = self.cell_quadrature(degree)
        dofs = self.cell_dofs
        if cells is not None:
            x, w, dofs = x[cells], w[cells], dofs[cells]
        u_h = np.einsum("qi,mi->mq", phi, np.asarray(values, dtype=np.float64)[dofs])
        exact = np.asarray(f(x.reshape(-1, 3)), dtype=np.float64).reshape(u_h.shape)
        return float(np.sum(w * (u_h - exact) ** 2)), float(np.sum(w * exact**2))

    # -- mass matrices ----------------------------------------------------
    def element_mass_matrices(self) -> np.ndarray:
        """(m, nb, nb) local mass matrices, exact for affine simplices and
        boxes, 3^d-point Gauss on general quadrilaterals and hexahedra."""
        mesh, nb = self.mesh, self.basis_per_cell
        if self.degree == 0:
            return mesh.cell_measures()[:, None, None]
        if mesh.is_simplex:  # int phi_i phi_j = |K| (1 + delta_ij) / ((d+1)(d+2))
            d = mesh.tdim
            ref = (np.ones((nb, nb)) + np.eye(nb)) / ((d + 1) * (d + 2))
            return mesh.cell_measures()[:, None, None] * ref[None]
        _, w, phi = self.cell_quadrature(5)
        return np.einsum("mq,qi,qj->mij", w, phi, phi)

    def mass_matrix(self) -> sp.csr_matrix:
        """Global mass matrix (sparse)."""
        local = self.element_mass_matrices()
        dofs = self.cell_dofs
        nb = dofs.shape[1]
        rows = np.repeat(dofs, nb, axis=1).ravel()
        cols = np.tile(dofs, (1, nb)).ravel()
        return sp.csr_matrix((local.ravel(), (rows, cols)), shape=(self.num_dofs, self.num_dofs))

    def __repr__(self):
        return f"FunctionSpace({self.mesh.name}, {self.family}, {self.num_dofs} dofs)"
