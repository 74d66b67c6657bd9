"""The dual (biorthogonal) basis of paper eq. 4: int psi_a phi_c = delta_ac int phi_c.

The dual basis is computed inside the kernels (since 0980f76; `transfer.dual` is
gone). It is recovered here from the public operators of a one-cell target: with
the standard coupling B (method "l2") and the dual one B' (method "pseudo_l2"),
B' = A B where psi_a = sum_c A[a, c] phi_c. Biorthogonality is then checked with
quadrature written in the tests (collapsed Gauss on tets, 4^3 tensor Gauss on
hexahedra), not with the library's integration.
"""

import numpy as np
import pytest

from transfer import FunctionSpace, Mesh, Transfer
from transfer.generate import box_hexahedra, box_tetrahedra

from vc_helpers import HEX_SIX_TETS, q1_inverse, q1_jacobians, q1_values, tensor_rule, tet_rule

CUBE = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], float)


def dual_of_cell(vertices, cell_type, family, source=None, **kwargs):
    """Dual coefficients A (nb, nb) the kernels use on a one-cell target mesh,
    from B' = A B (B from "l2", B' from "pseudo_l2"); the source defaults to the cell itself."""
    cell = Mesh(vertices, np.arange(len(vertices))[None], cell_type, name="cell")
    V = FunctionSpace(cell, family)
    S = V if source is None else source
    B = Transfer.assemble(S, V, "l2", **kwargs).B.toarray()
    Bd = Transfer.assemble(S, V, "pseudo_l2", **kwargs).B.toarray()
    A = np.linalg.lstsq(B.T, Bd.T, rcond=None)[0].T  # A B = Bd, B has full row rank
    assert np.max(np.abs(A @ B - Bd)) <= 1e-12 * np.max(np.abs(Bd))
    return A


def biorthogonality_defect(A, phi, weights):
    """max |int psi_a phi_c - delta_ac int phi_c| / max int phi_c, with phi (q, nb)
    the basis at the quadrature points and weights (q,) including the Jacobian."""
    mass = np.einsum("q,qa,qc->ac", weights, phi, phi)
    integral_phi = weights @ phi
    return np.max(np.abs(A @ mass - np.diag(integral_phi))) / np.max(integral_phi)


def hex_defect(A, vertices):
    """Biorthogonality defect on the trilinear cell, by 4^3-point tensor Gauss."""
    xi, w = tensor_rule(3, 4)
    det = np.abs(np.linalg.det(q1_jacobians(vertices, xi)))
    return biorthogonality_defect(A, q1_values(xi), w * det)


# -- tetrahedra --------------------------------------------------------------
@pytest.fixture(scope="module")
def covering_source():
    """A jittered mesh that covers every cell of `cells_of_a_mesh` (non-matching)."""
    return FunctionSpace(box_tetrahedra((4, 4, 4), jitter=0.2, seed=21), "P1")


def cells_of_a_mesh():
    m = box_tetrahedra((2, 2, 2), jitter=0.2, seed=22)
    return [m.points[m.cells[c]] for c in (0, 7, 20, 33, 47)]


@pytest.mark.parametrize("vertices", cells_of_a_mesh())
def test_tet_dual_coefficients_analytic(vertices, covering_source):
    """On affine simplices A = (d + 2) I - 1 1^T, whatever the cell and the source."""
    A = dual_of_cell(vertices, "tetra", "P1", source=covering_source)
    np.testing.assert_allclose(A, 5 * np.eye(4) - np.ones((4, 4)), rtol=0, atol=1e-11)


@pytest.mark.parametrize("vertices", cells_of_a_mesh())
def test_tet_dual_biorthogonal_by_quadrature(vertices):
    A = dual_of_cell(vertices, "tetra", "P1")
    x, w = tet_rule(5)  # reference tet, exact to degree 7
    phi = np.column_stack([1 - x.sum(axis=1), x])  # P1 basis in VTK order
    det = abs(np.linalg.det(vertices[1:] - vertices[0]))
    assert biorthogonality_defect(A, phi, w * det) < 1e-13


def test_tet_dual_with_quadrature_path(covering_source):
    """The same dual basis when B is integrated by a quadrature rule instead of moments."""
    vertices = cells_of_a_mesh()[2]
    A = dual_of_cell(vertices, "tetra", "P1", source=covering_source, quadrature_degree=2)
    np.testing.assert_allclose(A, 5 * np.eye(4) - np.ones((4, 4)), rtol=0, atol=1e-11)


# -- hexahedra ---------------------------------------------------------------
def parallelepipeds():
    rng = np.random.default_rng(23)
    out = []
    for k in range(3):
        M = np.eye(3) + 0.3 * rng.normal(size=(3, 3))
        if np.linalg.det(M) < 0:
            M[:, 0] *= -1  # keep the orientation positive
        out.append(CUBE @ M.T + rng.uniform(-2, 2, 3))
    out.append(CUBE * [0.5, 2.0, 0.1])  # a box
    return out


@pytest.mark.parametrize("vertices", parallelepipeds())
def test_parallelepiped_dual_biorthogonal_by_quadrature(vertices):
    """Affine hexahedra: the Q1 basis is polynomial, integration is exact."""
    A = dual_of_cell(vertices, "hexahedron", "Q1")
    assert hex_defect(A, vertices) < 1e-12


def frustum(scale):
    """Planar faces, not a parallelepiped: the top face is the bottom one scaled."""
    p = CUBE.copy()
    top = p[:, 2] == 1
    p[top, :2] = 0.5 + scale * (p[top, :2] - 0.5)
    return p


def test_frustum_dual_biorthogonal_by_quadrature():
    """Planar-faced but non-affine hexahedron: the basis is not a polynomial in x,
    so biorthogonality holds up to the quadrature error, which must shrink as the
    rule is refined."""
    vertices = frustum(0.7)
    defects = [hex_defect(dual_of_cell(vertices, "hexahedron", "Q1", quadrature_degree=q), vertices)
               for q in (6, 9, 12)]
    assert defects[0] > defects[1] > defects[2]
    assert defects[2] < 1e-4


def jittered_hex_cells():
    m = box_hexahedra((2, 2, 2), jitter=0.24, seed=5)
    return [m.points[m.cells[c]] for c in range(3)]


def six_tet_defect(A, vertices):
    """Biorthogonality defect over the six-tet polyhedron of the cell (the geometry the
    kernels and Mesh.cell_measures use, README), with the Q1 basis evaluated through
    the inverse trilinear map: collapsed Gauss on each tet, Newton in the test."""
    x, w = tet_rule(8)
    phis, weights = [], []
    for tet in HEX_SIX_TETS:
        p = vertices[tet]
        det = abs(np.linalg.det(p[1:] - p[0]))
        phys = p[0] + x @ (p[1:] - p[0])
        phis.append(q1_values(q1_inverse(vertices, phys)))
        weights.append(w * det)
    return biorthogonality_defect(A, np.vstack(phis), np.concatenate(weights))


@pytest.mark.parametrize("vertices", jittered_hex_cells())
def test_distorted_hex_dual_biorthogonal_on_six_tets(vertices):
    """Warped hexahedra: the kernels' dual basis is biorthogonal over the cell as the
    kernels define it (six tets), up to the quadrature error on the non-polynomial Q1
    basis, which a high-degree rule makes small."""
    assert np.linalg.norm(vertices[0] + vertices[2] - vertices[1] - vertices[3]) > 1e-2  # warped
    defects = [six_tet_defect(dual_of_cell(vertices, "hexahedron", "Q1", quadrature_degree=q), vertices)
               for q in (8, 11, 14)]
    assert defects[0] > defects[1] > defects[2]
    assert defects[2] < 1e-6


@pytest.mark.xfail(strict=True, reason=(
    "documented approximation (README: hexahedra are the union of six tetrahedra, an "
    "approximation of warped ones): on the trilinear Q1 cell, the kernels' dual basis is "
    "biorthogonal only to 1.5e-2..8e-2 for jitter 0.24, and the element mass differs from "
    "FunctionSpace.mass_matrix by 2-12%"))
@pytest.mark.parametrize("vertices", jittered_hex_cells())
def test_distorted_hex_dual_biorthogonal_on_trilinear_cell(vertices):
    A = dual_of_cell(vertices, "hexahedron", "Q1")
    assert hex_defect(A, vertices) < 1e-8


def test_distorted_hex_dual_is_biorthogonal_for_the_kernel_integration():
    """Whatever the geometry the kernels integrate on, their B' is diagonal (int psi_a phi_c
    = delta_ac int phi_c with their own integration) and the dual basis sums to one."""
    m = box_hexahedra((2, 2, 2), jitter=0.24, seed=5)
    V = FunctionSpace(m, "Q1")
    Tp = Transfer.assemble(V, V, "pseudo_l2")
    Bd = Tp.B.toarray()
    assert np.max(np.abs(Bd - np.diag(np.diag(Bd)))) <= 1e-13 * np.max(np.abs(Bd))
    np.testing.assert_allclose(np.diag(Bd), Tp.D.diagonal(), rtol=1e-13)
    for vertices in jittered_hex_cells():
        A = dual_of_cell(vertices, "hexahedron", "Q1")
        np.testing.assert_allclose(A.sum(axis=0), 1.0, rtol=0, atol=1e-12)


# -- the pseudo-L2 mass matrix -----------------------------------------------
def test_pseudo_l2_mass_is_the_lumped_mass(src_tets):
    """With the source covering the target (here: the same mesh), pseudo-L2's D is
    diagonal and equals the row sums of the target mass matrix, int phi_a; so are the
    row sums of B' (int psi_a = int phi_a)."""
    V = FunctionSpace(src_tets, "P1")
    T = Transfer.assemble(V, V, "pseudo_l2")
    assert T.D.nnz == V.num_dofs
    lumped = np.asarray(V.mass_matrix().sum(axis=1)).ravel()
    np.testing.assert_allclose(T.D.diagonal(), lumped, rtol=1e-12)
    np.testing.assert_allclose(np.asarray(T.B.sum(axis=1)).ravel(), lumped, rtol=1e-12)
