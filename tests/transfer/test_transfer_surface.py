"""Surface-to-surface (mortar) transfer: paper sections 2.1-2.2.

Surfaces are triangle or quad meshes embedded in 3D; the kernel pairs source
and target elements by proximity along the target normal, projects them on the
target element's plane, clips and integrates (mortar segmentation). These tests
check the properties the mortar projection T = D^-1 B must have whatever the
meshes: exactness for fields the target space contains, the biorthogonality of
the dual basis (eq. 4), scale invariance, robustness to tiny gaps, facing
(contact) surfaces, convergence on curved surfaces, partial overlap with
conservation, and the normal-angle filter.

Reference values are computed here independently of the library (analytic
integrals, polygon clipping written from scratch).
"""

from __future__ import annotations

import numpy as np
import pytest

from transfer import FunctionSpace, Mesh, NoOverlapError, Transfer, coupling_operator
from transfer.generate import box_hexahedra, box_tetrahedra, rectangle

METHODS = ("l2", "pseudo_l2")
CELL_PAIRS = [("triangle", "triangle"), ("triangle", "quad"), ("quad", "triangle"), ("quad", "quad")]


# -- helpers -------------------------------------------------------------------
def rotation(seed: int = 7) -> np.ndarray:
    """A proper rotation in general position (no axis-aligned plane)."""
    q, r = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return q


ROT = rotation()
SHIFT3 = np.array([0.3, -1.2, 2.5])
#: unit normal of the rotated plane z = 0
NORMAL = ROT @ np.array([0.0, 0.0, 1.0])


def moved(mesh: Mesh, scale: float = 1.0, offset=(0.0, 0.0, 0.0), name=None) -> Mesh:
    """The mesh rotated by ROT, translated by SHIFT3 (+ offset), all scaled."""
    pts = (mesh.points @ ROT.T + SHIFT3 + np.asarray(offset, float)) * scale
    return Mesh(pts, mesh.cells, mesh.cell_type, name=name or mesh.name)


def flipped(mesh: Mesh) -> Mesh:
    """Same surface, opposite orientation (vertex order of every cell reversed)."""
    return Mesh(mesh.points, mesh.cells[:, ::-1], mesh.cell_type, name=mesh.name + "-flipped")


def space(mesh: Mesh, degree: int = 1) -> FunctionSpace:
    return FunctionSpace(mesh, ("P" if mesh.is_simplex else "Q") + str(degree))


def rel_err(value, exact) -> float:
    value, exact = np.asarray(value, float), np.asarray(exact, float)
    return float(np.max(np.abs(value - exact)) / np.max(np.abs(exact)))


def linear_field(seed: int, normal=None):
    """u(x) = c + g.x with random c, g (g made orthogonal to `normal` if given)."""
    rng = np.random.default_rng(seed)
    g = rng.uniform(-2.0, 2.0, 3)
    if normal is not None:
        g = g - (g @ normal) * normal
    c = rng.uniform(2.0, 4.0)
    return lambda x: c + np.asarray(x, float) @ g


def dense_T(transfer: Transfer) -> np.ndarray:
    """T as a dense matrix (columns: T applied to the source unit vectors)."""
    return transfer(np.eye(transfer.source.num_dofs))


def clip_to_unit_square(poly: np.ndarray) -> np.ndarray:
    """Sutherland-Hodgman clip of a 2D polygon (k, 2) by [0, 1]^2."""
    out = list(map(tuple, poly))
    for axis, bound, keep_below in ((0, 0.0, False), (0, 1.0, True), (1, 0.0, False), (1, 1.0, True)):
        src, out = out, []
        if not src:
            break
        inside = (lambda p: p[axis] <= bound) if keep_below else (lambda p: p[axis] >= bound)
        for i, p in enumerate(src):
            q = src[(i + 1) % len(src)]
            if inside(p):
                out.append(p)
            if inside(p) != inside(q):
                t = (bound - p[axis]) / (q[axis] - p[axis])
                out.append((p[0] + t * (q[0] - p[0]), p[1] + t * (q[1] - p[1])))
    return np.array(out).reshape(-1, 2)


def polygon_area(poly: np.ndarray) -> float:
    if len(poly) < 3:
        return 0.0
    x, y = poly[:, 0], poly[:, 1]
    return 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


# -- 1. exactness on a planar surface in general position ----------------------
@pytest.mark.parametrize("src_type,dst_type", CELL_PAIRS)
@pytest.mark.parametrize("method", METHODS)
def test_planar_linear_fields_exact(src_type, dst_type, method):
    src = moved(rectangle((7, 6), cell_type=src_type, jitter=0.2, seed=1, name="src"))
    dst = moved(rectangle((5, 9), cell_type=dst_type, jitter=0.2, seed=2, name="dst"))
    S, D = space(src), space(dst)
    transfer = Transfer.assemble(S, D, method)
    assert transfer.covered_fraction == 1.0
    for seed in range(3):
        u = linear_field(seed)
        v = transfer(S.interpolate(u))
        assert rel_err(v, D.interpolate(u)) < 1e-12, (seed, rel_err(v, D.interpolate(u)))
    # vector field (n, 3): the coordinates themselves
    X = transfer(src.points)
    assert rel_err(X, dst.points) < 1e-12


@pytest.mark.parametrize("src_type,dst_type", CELL_PAIRS)
def test_planar_p0_coupling_sums_to_area(src_type, dst_type):
    src = moved(rectangle((7, 6), cell_type=src_type, jitter=0.2, seed=1))
    dst = moved(rectangle((5, 9), cell_type=dst_type, jitter=0.2, seed=2))
    c = coupling_operator(space(src, 0), space(dst, 0), "l2")
    # rotated unit square: area 1; rows = target cell areas, columns = source cell areas
    assert abs(c.B.sum() - 1.0) < 1e-13
    np.testing.assert_allclose(np.asarray(c.B.sum(axis=1)).ravel(), dst.cell_measures(), rtol=1e-12)
    np.testing.assert_allclose(np.asarray(c.B.sum(axis=0)).ravel(), src.cell_measures(), rtol=1e-12)
    np.testing.assert_allclose(c.D.diagonal(), dst.cell_measures(), rtol=1e-12)


# -- 2. biorthogonality of the dual basis (eq. 4) --------------------------------
SELF_MESHES = {
    "triangle": lambda: moved(rectangle((6, 5), cell_type="triangle", jitter=0.2, seed=3)),
    "quad": lambda: moved(rectangle((6, 5), cell_type="quad", jitter=0.2, seed=3)),
    "tetra": lambda: box_tetrahedra((3, 3, 3), jitter=0.2, seed=4),
    "hexahedron": lambda: box_hexahedra((3, 3, 3), jitter=0.2, seed=4),
}


@pytest.mark.parametrize("kind", list(SELF_MESHES))
def test_dual_basis_biorthogonal_on_self_transfer(kind):
    mesh = SELF_MESHES[kind]()
    V = space(mesh)
    c = coupling_operator(V, V, "pseudo_l2")
    B = c.B.toarray()
    scale = np.abs(B).max()
    off = B - np.diag(np.diag(B))
    assert np.abs(off).max() < 1e-14 * scale, np.abs(off).max() / scale
    # D is diagonal and equal to diag(B): int psi_a phi_b = delta_ab int phi_b
    Dd = c.D.toarray()
    assert np.abs(Dd - np.diag(np.diag(Dd))).max() == 0.0
    np.testing.assert_allclose(np.diag(B), c.D.diagonal(), rtol=1e-13, atol=0)
    # and the self transfer is the identity
    T = Transfer(V, V, "pseudo_l2", c)
    assert np.abs(dense_T(T) - np.eye(V.num_dofs)).max() < 1e-13


def _lumped_mass_error(mesh, **kwargs) -> float:
    V = space(mesh)
    c = coupling_operator(V, V, "pseudo_l2", **kwargs)
    lumped = np.asarray(V.mass_matrix().sum(axis=1)).ravel()
    return rel_err(c.B.diagonal(), lumped)


@pytest.mark.parametrize("kind", ["triangle", "tetra"])
def test_dual_basis_diagonal_is_lumped_mass_simplices(kind):
    assert _lumped_mass_error(SELF_MESHES[kind]()) < 1e-13


@pytest.mark.xfail(strict=True, reason=(
    "library bug: on distorted (non-parallelogram) quads the default surface quadrature is not exact "
    "for Q1 x Q1 (the projected bilinear basis is not polynomial in physical coordinates), so diag(B) of "
    "the self transfer differs from the lumped FunctionSpace.mass_matrix() by ~1.6e-7 relative "
    "(README: 'quadrature_degree, default exact for the bases'; spaces.py: the mass matrix is the D of "
    "eq. 3 when the source covers the target)"))
def test_dual_basis_diagonal_is_lumped_mass_distorted_quads():
    assert _lumped_mass_error(SELF_MESHES["quad"]()) < 1e-13


def test_dual_basis_diagonal_distorted_quads_converges_with_quadrature_degree():
    """The quad discrepancy above is quadrature error only: it vanishes as the degree grows."""
    mesh = SELF_MESHES["quad"]()
    errs = [_lumped_mass_error(mesh, quadrature_degree=q) for q in (4, 8, 14)]
    assert errs[0] > errs[1] > errs[2]
    assert errs[2] < 1e-10


@pytest.mark.xfail(strict=True, reason=(
    "library bug: the volume kernel integrates a hexahedron over its six-tet decomposition (HEX_TETS) "
    "while FunctionSpace.mass_matrix() integrates the trilinear element; on hexes with jitter 0.2 the "
    "cell volumes differ by up to ~9% and diag(B) of the self transfer differs from the lumped mass by "
    "~2.3e-3 relative, whatever quadrature_degree (spaces.py claims the mass matrix is the D of eq. 3)"))
def test_dual_basis_diagonal_is_lumped_mass_distorted_hexes():
    assert _lumped_mass_error(SELF_MESHES["hexahedron"]()) < 1e-13


def test_dual_basis_diagonal_is_lumped_mass_undistorted_quads_and_hexes():
    """Parallelogram quads and boxes: the bases are polynomial, everything is exact."""
    assert _lumped_mass_error(moved(rectangle((6, 5), cell_type="quad"))) < 1e-13
    assert _lumped_mass_error(box_hexahedra((3, 3, 3))) < 1e-13


# -- 3. unit-scale invariance ----------------------------------------------------
@pytest.mark.parametrize("src_type,dst_type", [("triangle", "quad"), ("quad", "triangle")])
@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("geometry", ["planar", "curved", "facing"])
def test_unit_scale_invariance(src_type, dst_type, method, geometry):
    kwargs = {}
    if geometry == "planar":
        src = moved(rectangle((6, 5), cell_type=src_type, jitter=0.2, seed=5))
        dst = moved(rectangle((4, 7), cell_type=dst_type, jitter=0.2, seed=6))
    elif geometry == "curved":
        bump = lambda x, y: 0.1 * np.sin(2 * np.pi * x) * np.cos(np.pi * y)  # noqa: E731
        src = rectangle((6, 5), cell_type=src_type, jitter=0.2, seed=5, height=bump)
        dst = rectangle((4, 7), cell_type=dst_type, jitter=0.2, seed=6, height=bump)
    else:
        src = flipped(rectangle((6, 5), cell_type=src_type, jitter=0.2, seed=5))
        dst = rectangle((4, 7), cell_type=dst_type, jitter=0.2, seed=6)
        dst = Mesh(dst.points + [0, 0, 0.01], dst.cells, dst.cell_type)
        kwargs = {"search_distance": 0.05}

    def mm(m):
        return Mesh(m.points * 1000.0, m.cells, m.cell_type)

    S, D = space(src), space(dst)
    Smm, Dmm = space(mm(src)), space(mm(dst))
    t_m = Transfer.assemble(S, D, method, **kwargs)
    t_mm = Transfer.assemble(Smm, Dmm, method, **{k: v * 1000.0 for k, v in kwargs.items()})
    np.testing.assert_array_equal(t_m.covered, t_mm.covered)
    Bm, Bmm = t_m.B.toarray(), t_mm.B.toarray()
    assert np.abs(Bmm - 1e6 * Bm).max() < 1e-12 * 1e6 * np.abs(Bm).max()
    Dm, Dmm_ = t_m.D.toarray(), t_mm.D.toarray()
    assert np.abs(Dmm_ - 1e6 * Dm).max() < 1e-12 * 1e6 * np.abs(Dm).max()
    Tm, Tmm = dense_T(t_m), dense_T(t_mm)
    assert np.array_equal(np.isnan(Tm), np.isnan(Tmm))
    ok = ~np.isnan(Tm)
    assert np.abs(Tmm[ok] - Tm[ok]).max() < 1e-12 * np.abs(Tm[ok]).max()
    if method == "pseudo_l2":  # the sparse T agrees with the applied one, in both units
        rows = t_m.covered
        for t, dense in ((t_m, Tm), (t_mm, Tmm)):
            assert np.abs(t.matrix().toarray()[rows] - dense[rows]).max() < 1e-14 * np.abs(Tm[ok]).max()


# -- 4. offset along the normal --------------------------------------------------
@pytest.mark.parametrize("src_type,dst_type", CELL_PAIRS)
@pytest.mark.parametrize("method", METHODS)
def test_tiny_normal_offset_fully_covered_and_exact(src_type, dst_type, method):
    src = moved(rectangle((7, 6), cell_type=src_type, jitter=0.2, seed=1), offset=1e-12 * NORMAL)
    dst = moved(rectangle((5, 9), cell_type=dst_type, jitter=0.2, seed=2))
    S, D = space(src), space(dst)
    transfer = Transfer.assemble(S, D, method)
    assert transfer.covered_fraction == 1.0
    assert np.all(transfer.coverage > 1 - 1e-10)
    ones = transfer(np.ones(S.num_dofs))
    assert np.abs(ones - 1).max() < 1e-13
    for seed in range(2):
        # a linear field constant along the normal: the exact values do not see the offset
        u = linear_field(seed, normal=NORMAL)
        assert rel_err(transfer(S.interpolate(u)), D.interpolate(u)) < 1e-12


@pytest.mark.parametrize("cell_type", ["triangle", "quad"])
def test_offset_beyond_search_distance_raises(cell_type):
    dst = moved(rectangle((5, 9), cell_type=cell_type, jitter=0.2, seed=2))
    base = rectangle((7, 6), cell_type=cell_type, jitter=0.2, seed=1)
    S_near = space(moved(base, offset=0.04 * NORMAL))
    S_far = space(moved(base, offset=0.06 * NORMAL))
    D = space(dst)
    # within the search distance: couples fully
    assert Transfer.assemble(S_near, D, "l2", search_distance=0.05).covered_fraction == 1.0
    for method in METHODS:
        with pytest.raises(NoOverlapError, match="do not overlap"):
            Transfer.assemble(S_far, D, method, search_distance=0.05)
    # default search distance: half the mean longest edge of the target
    h = dst.longest_edges().mean()
    S_default_far = space(moved(base, offset=0.6 * h * NORMAL))
    with pytest.raises(NoOverlapError, match="do not overlap"):
        coupling_operator(S_default_far, D, "pseudo_l2")


# -- 5. contact-like facing surfaces ---------------------------------------------
@pytest.mark.parametrize("src_type,dst_type", CELL_PAIRS)
@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("which", ["source", "target"])
def test_facing_surfaces(src_type, dst_type, method, which):
    src = rectangle((7, 6), cell_type=src_type, jitter=0.2, seed=11, name="slave")
    dst = rectangle((5, 8), cell_type=dst_type, jitter=0.2, seed=12, name="master")
    if which == "source":
        src = flipped(src)
    else:
        dst = flipped(dst)
    src = Mesh(src.points + [0.0, 0.0, 0.01], src.cells, src.cell_type)
    S, D = space(src), space(dst)
    transfer = Transfer.assemble(S, D, method, search_distance=0.05)
    assert transfer.covered_fraction == 1.0
    assert np.all(transfer.coverage > 1 - 1e-10)
    assert np.abs(transfer(np.full(S.num_dofs, 2.5)) - 2.5).max() < 1e-13
    u = lambda x: 1.5 + 2.0 * x[:, 0] - 3.0 * x[:, 1]  # noqa: E731  (linear in x, y)
    assert rel_err(transfer(S.interpolate(u)), D.interpolate(u)) < 1e-12
    # conservation over the (complete) overlap
    assert transfer.conservation_error(S.interpolate(u)) < 1e-12


# -- 6. curved surface: convergence and constants ----------------------------------
def _wave(x, y):
    return 0.1 * np.sin(2 * np.pi * x)


def _smooth(x):
    return np.sin(2.0 * x[:, 0] + 0.5) * np.cos(3.0 * x[:, 1]) + 2.0 * x[:, 2]


def _curved_errors(src_type, dst_type, method):
    """Max nodal errors of T(f) on refined meshes of z = 0.1 sin(2 pi x), and h.

    For pseudo_l2 the error is taken on the dofs whose support lies in fully
    covered target cells: on the curved edges y = 0, 1 the source and target
    boundary polylines differ, the projected source leaves slivers (~1e-3 of
    the cell) uncovered, and those cells use the lumped standard basis, which
    is only first order (by design, see transfer.operators)."""
    errors, hs = [], []
    levels = (4, 8, 16, 32) if method == "l2" else (8, 16, 32, 64)  # inner dofs need n >= 8
    for n in levels:
        src = rectangle((n + n // 2 + 1, n + 1), cell_type=src_type, jitter=0.2, seed=n, height=_wave)
        dst = rectangle((n, n), cell_type=dst_type, jitter=0.2, seed=n + 1, height=_wave)
        S, D = space(src), space(dst)
        transfer = Transfer.assemble(S, D, method)
        assert transfer.covered_fraction == 1.0
        err = np.abs(transfer(S.interpolate(_smooth)) - D.interpolate(_smooth))
        if method == "pseudo_l2":
            c = transfer.coupling
            inner = np.ones(D.num_dofs, bool)
            inner[dst.cells[c.overlap < (1 - 1e-10) * c.measure].ravel()] = False
            assert inner.mean() > (0.5 if n < 32 else 0.8)
            err = err[inner]
        errors.append(err.max())
        hs.append(dst.longest_edges().mean())
    return np.array(errors), np.array(hs)


@pytest.mark.parametrize("src_type,dst_type", CELL_PAIRS)
@pytest.mark.parametrize("method", METHODS)
def test_curved_surface_projection_converges(src_type, dst_type, method):
    errors, hs = _curved_errors(src_type, dst_type, method)
    rates = np.log(errors[:-1] / errors[1:]) / np.log(hs[:-1] / hs[1:])
    overall = np.log(errors[0] / errors[-1]) / np.log(hs[0] / hs[-1])
    assert overall >= 1.5, (errors, rates)
    assert np.all(rates >= 1.2), (errors, rates)


@pytest.mark.parametrize("src_type,dst_type", CELL_PAIRS)
@pytest.mark.parametrize("method", METHODS)
def test_curved_surface_constants_reproduced(src_type, dst_type, method):
    bump = lambda x, y: 0.1 * np.sin(2 * np.pi * x) + 0.05 * np.cos(np.pi * y)  # noqa: E731
    src = rectangle((9, 7), cell_type=src_type, jitter=0.2, seed=21, height=bump)
    dst = rectangle((6, 8), cell_type=dst_type, jitter=0.2, seed=22, height=bump)
    S, D = space(src), space(dst)
    transfer = Transfer.assemble(S, D, method)
    assert transfer.covered_fraction == 1.0
    v = transfer(np.full(S.num_dofs, -3.25))
    assert np.abs(v + 3.25).max() < 1e-13 * 3.25


# -- 7. partial overlap -------------------------------------------------------------
@pytest.mark.parametrize("src_type,dst_type", CELL_PAIRS)
@pytest.mark.parametrize("method", METHODS)
def test_partial_overlap_coverage_and_conservation(src_type, dst_type, method):
    offset = np.array([0.5, 0.3])
    src2 = rectangle((7, 6), cell_type=src_type, jitter=0.2, seed=31)
    dst2 = rectangle((6, 5), lower=offset, upper=offset + 1, cell_type=dst_type, jitter=0.2, seed=32)
    src, dst = moved(src2), moved(dst2)
    S, D = space(src), space(dst)
    transfer = Transfer.assemble(S, D, method)

    # expected coverage from the in-plane geometry (independent clipping)
    cells2 = dst2.points[dst2.cells][:, :, :2]
    cut = np.array([polygon_area(clip_to_unit_square(c)) for c in cells2])
    area = dst2.cell_measures()
    frac = cut / area
    assert np.all((frac == 0) | (frac > 1e-6)), "ambiguous cell (test geometry)"
    np.testing.assert_allclose(transfer.coupling.overlap, cut, rtol=1e-12, atol=1e-15)
    touched = np.zeros(D.num_dofs, bool)
    touched[dst2.cells[cut > 0].ravel()] = True
    np.testing.assert_array_equal(transfer.covered, touched)
    assert 0 < transfer.covered_fraction < 1

    u = linear_field(3)
    v = transfer(S.interpolate(u))
    assert np.all(np.isfinite(v[touched])) and np.all(np.isnan(v[~touched]))
    np.testing.assert_array_equal(transfer.uncovered, np.flatnonzero(~touched))

    # conservation: integral over the overlap [0.5, 1] x [0.3, 1] (rotated) of u, analytically
    lo, hi = np.array([0.5, 0.3]), np.array([1.0, 1.0])
    centre = np.append(0.5 * (lo + hi), 0.0) @ ROT.T + SHIFT3
    exact = np.prod(hi - lo) * u(centre[None])[0]
    assert abs(transfer.integral_target(v) - exact) < 1e-12 * abs(exact)
    assert abs(transfer.integral_source(S.interpolate(u)) - exact) < 1e-12 * abs(exact)

    # linear fields are reproduced on the dofs whose whole support is covered (both methods;
    # pseudo_l2 uses the lumped standard basis on cut elements) and, by l2, also on the cut
    # dofs with a reasonable share of their support covered (dofs covered by a sliver of
    # ~3e-4 of their support make the overlap mass matrix ill-conditioned, cond ~1e10,
    # so their values are only as accurate as the solve)
    full_cell = frac > 1 - 1e-10
    inner = np.ones(D.num_dofs, bool)
    inner[dst2.cells[~full_cell].ravel()] = False
    exact_dofs = inner | (transfer.coverage > 0.01) if method == "l2" else inner
    assert inner.sum() > 3 and (exact_dofs & ~inner).sum() > (3 if method == "l2" else -1)
    ex = D.interpolate(u)
    assert np.abs(v[exact_dofs] - ex[exact_dofs]).max() < 1e-12 * np.abs(ex).max()


# -- 8. normal-angle filter --------------------------------------------------------
@pytest.mark.parametrize("cell_type", ["triangle", "quad"])
@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_normal_angle_filter(cell_type, sign):
    dst = moved(rectangle((6, 6), cell_type=cell_type, jitter=0.1, seed=41))
    # source: a square tilted by 60 degrees about the in-plane line y = 0.5, crossing the target
    base = rectangle((5, 5), lower=(-0.5, -0.5), upper=(0.5, 0.5), cell_type=cell_type, jitter=0.1, seed=42)
    a = np.radians(60.0) * sign
    tilt = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    pts = base.points @ tilt.T + [0.5, 0.5, 0.0]
    src = moved(Mesh(pts, base.cells, base.cell_type))
    S, D = space(src), space(dst)
    for method in METHODS:
        with pytest.raises(NoOverlapError, match="do not overlap"):
            Transfer.assemble(S, D, method, max_normal_angle=45.0)
        t = Transfer.assemble(S, D, method, max_normal_angle=75.0)
        assert t.stats["pairs_intersected"] > 0
        assert 0 < t.covered_fraction < 1
        # constants are reproduced on the covered dofs; with l2, dofs covered by a sliver
        # (~1e-3 of their support) make D ill-conditioned and are only as good as the solve
        err = np.abs(t(np.ones(S.num_dofs)) - 1)
        if method == "pseudo_l2":
            assert err[t.covered].max() < 1e-13
        else:
            assert err[t.coverage > 0.01].max() < 1e-12
            assert err[t.covered].max() < 1e-9
