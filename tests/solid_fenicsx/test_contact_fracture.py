"""Contact between rough fracture faces (solid_fenicsx.contact_fracture) and the hard
cases of the contact issue: near full closure at 20 MPa, a 5:1 mesh size ratio across
the face, nearly flat faces (all nodes in contact), very rough faces (many small
patches), initial interpenetration. Each converges without active-set cycling
(``monotone_from`` is None), keeps the faces apart, balances forces, and the
loading curve stiffens."""

import numpy as np
import pytest

from nonsmooth import NonsmoothSolveError
from solid_fenicsx.contact_fracture import ClosureTest, Specimen, bandis_fit, specimen_mesh, square_to_disc

SMALL = dict(lattice=(8, 8, 3))


def check_state(test, state, stress):
    """No interpenetration, complementarity, pressure >= 0, force balance, no cycling."""
    m = test.contact.mortar
    gap, p = state.gap[m.covered], state.pressure[m.covered]
    tol = 1e-9 * test.spec.aperture
    assert gap.min() >= -tol
    assert p.min() >= 0 and np.max(np.abs(gap * p)) <= tol * p.max()
    top = test.contact.reaction("top")
    assert abs(state.force[2] - top[2]) <= 1e-6 * abs(top[2])  # the slave's contact force = platen load
    assert abs(-top[2] / test.area / stress - 1) < 5e-3
    assert state.solution.converged and state.solution.info["monotone_from"] is None


@pytest.mark.parametrize("shape", ["box", "cylinder"])
def test_loading_curve_stiffens(shape):
    test = ClosureTest(Specimen(**SMALL, shape=shape))
    rows = []
    for mpa in (1, 2, 5, 10, 20):
        state, row = test.load_to(mpa * 1e6, rtol=5e-3)
        check_state(test, state, mpa * 1e6)
        rows.append(row)
    stress = np.array([r["stress"] for r in rows])
    closure = np.array([r["closure"] for r in rows])
    area = np.array([r["area_fraction"] for r in rows])
    assert np.all(np.diff(closure) > 0) and np.all(np.diff(area) > 0)
    stiffness = np.diff(stress) / np.diff(closure)
    assert np.all(np.diff(stiffness) > 0)  # the characteristic stiffening
    assert closure[-1] < test.initial_aperture
    fit = bandis_fit(stress, closure)
    assert fit["k_ni"] > 0 and closure[-1] < fit["d_max"] < test.initial_aperture


def test_square_to_disc_is_equal_area_onto_the_disc():
    """The square's boundary lands on the unit circle, uniformly in angle along each
    side; the Jacobian (finite differences, off the diagonals) is pi/4 everywhere."""
    t = np.linspace(-1, 1, 9)
    for x, y in ((t, np.ones(9)), (t, -np.ones(9)), (np.ones(9), t), (-np.ones(9), t)):
        X, Y = square_to_disc(x, y)
        assert np.allclose(np.hypot(X, Y), 1.0)
        assert np.allclose(np.diff(np.unwrap(np.arctan2(Y, X))), np.diff(np.unwrap(np.arctan2(Y, X)))[0])
    rng = np.random.default_rng(0)
    x, y = rng.uniform(-1, 1, (2, 200))
    x, y = x[np.abs(np.abs(x) - np.abs(y)) > 1e-3], y[np.abs(np.abs(x) - np.abs(y)) > 1e-3]
    h = 1e-6
    dxx, dyx = (np.subtract(square_to_disc(x + h, y), square_to_disc(x - h, y))) / (2 * h)
    dxy, dyy = (np.subtract(square_to_disc(x, y + h), square_to_disc(x, y - h))) / (2 * h)
    assert np.allclose(dxx * dyy - dxy * dyx, np.pi / 4, rtol=1e-6)
    assert np.allclose(square_to_disc(0.0, 0.0), 0.0)


def test_cylinder_specimen_mesh_is_valid():
    """Positive tet volumes, a circular outline of the specimen's radius, the volume of
    the cylinder, the contact faces still non-matching; mean stress over pi r^2."""
    spec = Specimen(lattice=(8, 8, 3), shape="cylinder", size=0.122)
    solid, _ = specimen_mesh(spec)
    x = solid.mesh.geometry.x
    p = x[solid.mesh.geometry.dofmap.array.reshape(-1, 4)]
    a, b, c = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]
    volume = np.abs(np.einsum("ij,ij->i", a, np.cross(b, c))) / 6
    assert volume.min() > 0.05 * volume.mean()  # measured 0.097 (box: 0.62)
    edges = [np.linalg.norm(p[:, i] - p[:, j], axis=1) for i in range(4) for j in range(i)]
    quality = 6 * np.sqrt(2) * volume / np.max(edges, axis=0) ** 3  # 1 for the regular tet
    assert quality.min() > 0.02  # measured 0.026 (box: 0.19): the flattened cells on a diagonal
    radius = np.hypot(x[:, 0] - 0.061, x[:, 1] - 0.061)
    assert radius.max() == pytest.approx(0.061, rel=1e-12)
    height = x[:, 2].max() - x[:, 2].min()
    # the polygonal outline (32 chords) holds a little less than the cylinder
    assert volume.sum() == pytest.approx(np.pi * 0.061 ** 2 * height, rel=0.02)
    assert spec.area == pytest.approx(np.pi * 0.061 ** 2)
    test = ClosureTest(spec)
    m = test.contact.mortar
    assert len(m.slave.nodes) == 81 and len(m.master.nodes) == 25
    assert test.area == spec.area


def test_unknown_shape_is_a_clear_error():
    with pytest.raises(ValueError, match="specimen shape 'sphere': use one of box, cylinder"):
        Specimen(shape="sphere")


def test_bandis_fit_recovers_its_own_law():
    k, d_max = 3e9, 1e-4
    stress = np.array([1, 2, 5, 10, 20]) * 1e6
    closure = stress * d_max / (k * d_max + stress)
    fit = bandis_fit(stress, closure)
    assert fit["k_ni"] == pytest.approx(k, rel=1e-9) and fit["d_max"] == pytest.approx(d_max, rel=1e-9)
    assert fit["rms_deviation"] < 1e-12


def test_20_mpa_near_full_closure_in_one_step():
    """Straight to 20 MPa from the open fracture (no intermediate load steps)."""
    test = ClosureTest(Specimen(**SMALL))
    state, row = test.load_to(20e6, rtol=5e-3)
    check_state(test, state, 20e6)
    assert row["area_fraction"] > 0.3
    assert max(row["iterations"]) <= 10


def test_mesh_size_ratio_5_to_1():
    test = ClosureTest(Specimen(lattice=(15, 15, 2), ratio=5))
    assert len(test.contact.mortar.slave.nodes) == 16 * 16 and len(test.contact.mortar.master.nodes) == 4 * 4
    state, _ = test.load_to(10e6, rtol=5e-3)
    check_state(test, state, 10e6)


def test_nearly_flat_faces_close_everywhere():
    """Faces 0.2 um rough, 1 um apart: at 10 MPa every slave node touches."""
    test = ClosureTest(Specimen(**SMALL, rms=2e-7, aperture=1e-6, min_aperture=5e-7))
    state, row = test.load_to(10e6, rtol=5e-3)
    check_state(test, state, 10e6)
    assert state.active[test.contact.mortar.covered].all() and row["area_fraction"] == pytest.approx(1.0)


def test_very_rough_faces_touch_in_many_patches():
    """RMS 1 mm against a 0.2 mm mean aperture and a short mismatch length: many small
    contact patches (starting interpenetrated where the faces cross)."""
    spec = Specimen(lattice=(16, 16, 3), rms=1e-3, aperture=2e-4, mismatch_length=0.005, min_aperture=1e-6)
    test = ClosureTest(spec)
    state, _ = test.load_to(5e6, rtol=5e-3)
    check_state(test, state, 5e6)
    m = test.contact.mortar
    # patches: connected groups of slave nodes in contact on the slave face's triangle graph
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components

    tri = m.slave.triangles
    on = state.active
    edges = [(a, b) for t in tri for a, b in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0])) if on[a] and on[b]]
    n = len(on)
    rows, cols = (np.array([e[0] for e in edges], int), np.array([e[1] for e in edges], int)) if edges else ([], [])
    graph = sp.csr_matrix((np.ones(len(rows)), (rows, cols)), (n, n))
    count, label = connected_components(graph, directed=False)
    patches = len(set(label[on]))
    assert patches >= 5


def test_initial_interpenetration_is_resolved():
    """Faces generated crossing (negative minimum aperture after the coarse upper face
    cuts the fine lower one): the first solve separates them."""
    test = ClosureTest(Specimen(**SMALL, rms=5e-4, aperture=1e-4, min_aperture=1e-7))
    assert np.nanmin(test.contact.mortar.gap) < 0
    state, _ = test.load_to(2e6, rtol=5e-3)
    check_state(test, state, 2e6)


def test_too_few_iterations_is_a_clear_error():
    test = ClosureTest(Specimen(**SMALL), max_iter=1)
    with pytest.raises(NonsmoothSolveError, match="active_set did not converge"):
        test.load_to(10e6)
