"""solid_fenicsx.elasticity: static linear elasticity (paper eq. 5, 7): exact
solutions, loads as constants and as vertex fields, stress, locking."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

pytest.importorskip("dolfinx")

from mpi4py import MPI  # noqa: E402

from solid_fenicsx import Elasticity, LockingWarning, box_mesh  # noqa: E402
from solid_fenicsx.cases import block_compression, block_exact, cantilever  # noqa: E402

E, NU, P = 1e9, 0.3, 1e6


@pytest.fixture(scope="module")
def cube():
    return box_mesh(upper=(1.0, 1.0, 1.0), shape=(4, 4, 4))


def _rollers(s):
    s.add_dirichlet("zmin", 0.0, components="z")
    s.add_dirichlet("xmin", 0.0, components="x")
    s.add_dirichlet("ymin", 0.0, components="y")


@pytest.mark.parametrize("solver,degree", [("cg", 1), ("lu", 1), ("cg", 2)])
def test_block_compression_exact(cube, solver, degree):
    result = block_compression(E, NU, P, solid=cube, degree=degree, solver=solver, rtol=1e-12)
    assert result.error < 1e-6, result.error
    # the gathered vertex field agrees too (input numbering)
    s = result.solver
    pts, u = s.vertices.points(), s.vertex_values("displacement")
    if MPI.COMM_WORLD.rank == 0:
        exact = block_exact(pts, E, NU, P)
        assert np.abs(u - exact).max() <= 1e-6 * np.abs(exact).max()


def test_von_mises_uniaxial(cube):
    s = block_compression(E, NU, P, solid=cube).solver
    for kind in ("DG0", "P1"):
        vm = s.von_mises(kind).x.array
        assert np.allclose(vm, P, rtol=1e-8), kind
    sig = s.evaluate([[0.3, 0.6, 0.2]], s.von_mises("DG0"))
    assert np.isclose(sig[0, 0], P, rtol=1e-8)


def test_von_mises_p1_never_undershoots():
    """A pressure on a corner patch: the consistent L2 projection of von Mises goes negative
    beside the patch; the vertex field (lumped projection) is a weighted mean of the cell
    values around each vertex, within their range, and keeps the integral."""
    import dolfinx.fem
    import dolfinx.fem.petsc
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla
    import ufl

    solid = box_mesh(upper=(1.0, 1.0, 1.0), shape=(6, 6, 6),
                     boundaries={"patch": lambda x: (x[2] > 1 - 1e-9) & (x[0] < 0.2) & (x[1] < 0.2)})
    s = Elasticity(solid, E=E, nu=NU, solver="lu")
    s.add_dirichlet("zmin", 0.0)
    s.add_pressure("patch", P)
    s.solve_static()
    vm, cells = s.von_mises("P1"), s.von_mises("DG0").x.array
    W = vm.function_space
    p, q = ufl.TrialFunction(W), ufl.TestFunction(W)
    dx = ufl.dx(domain=s.mesh)
    M = dolfinx.fem.petsc.assemble_matrix(dolfinx.fem.form(p * q * dx))
    M.assemble()
    indptr, indices, data = M.getValuesCSR()
    b = dolfinx.fem.petsc.assemble_vector(dolfinx.fem.form(s.von_mises("DG0") * q * dx)).array
    consistent = spla.spsolve(sp.csr_matrix((data, indices, indptr)).tocsc(), b)
    assert consistent.min() < -1e-4 * consistent.max()  # -1.2 kPa against 1.3 MPa
    assert cells.min() <= vm.x.array.min() and vm.x.array.max() <= cells.max() and cells.min() >= 0.0
    lumped = dolfinx.fem.petsc.assemble_vector(dolfinx.fem.form(q * dx)).array
    assert lumped @ vm.x.array == pytest.approx(b.sum(), rel=1e-12)


def test_vertex_fields_equal_constant_loads(cube):
    """A pressure field, a traction field and the constant pressure give one solution."""
    ref = block_compression(E, NU, P, solid=cube).solver.u.x.array
    n = cube.num_points
    root = MPI.COMM_WORLD.rank == 0
    for kind in ("pressure", "traction"):
        s = Elasticity(cube, E=E, nu=NU, rtol=1e-12)
        _rollers(s)
        if kind == "pressure":
            s.add_pressure_field("zmax", name="p")
            s.set_vertex_field("p", np.full(n, P) if root else None)
        else:
            s.add_traction_field("zmax", name="p")
            s.set_vertex_field("p", np.tile([0.0, 0.0, -P], (n, 1)) if root else None)
        s.solve_static()
        assert np.allclose(s.u.x.array, ref, rtol=0, atol=1e-9 * np.abs(ref).max()), kind


def test_body_force_and_prescribed_component_p2():
    """Column under gravity: quadratic exact solution, reproduced by P2; the
    bottom carries the exact u_z as a callable Dirichlet value on one component."""
    rho_g, H = 2e4, 1.0

    def exact(x):
        return np.stack([NU * rho_g * (H - x[2]) * x[0] / E, NU * rho_g * (H - x[2]) * x[1] / E,
                         -rho_g / E * (H * x[2] - x[2] ** 2 / 2) + NU * rho_g * (x[0] ** 2 + x[1] ** 2) / (2 * E)])

    solid = box_mesh(upper=(1.0, 1.0, H), shape=(2, 2, 3))
    s = Elasticity(solid, E=E, nu=NU, degree=2, solver="lu")
    s.add_dirichlet("zmin", exact, components="z")
    s.add_dirichlet("xmin", 0.0, components="x")
    s.add_dirichlet("ymin", 0.0, components="y")
    s.add_body_force((0.0, 0.0, -rho_g))
    s.solve_static()
    x = s.V.tabulate_dof_coordinates()
    ref = exact(x.T).T
    err = MPI.COMM_WORLD.allreduce(np.abs(s.u.x.array.reshape(-1, 3) - ref).max(), op=MPI.MAX)
    assert err < 1e-9 * np.abs(ref).max()


def test_prescribed_vector_displacement_and_constant_update(cube):
    s = Elasticity(cube, E=E, nu=NU, rtol=1e-12)
    g = s.add_dirichlet(["xmin", "xmax", "ymin", "ymax", "zmin", "zmax"], (1e-3, 2e-3, 0.0))
    s.solve_static()
    assert np.allclose(s.u.x.array.reshape(-1, 3), [1e-3, 2e-3, 0.0], atol=1e-14)
    g.value[:] = (0.0, 0.0, -5e-4)  # a new value, same matrix
    s.solve_static()
    assert np.allclose(s.u.x.array.reshape(-1, 3), [0.0, 0.0, -5e-4], atol=1e-14)
    assert np.allclose(s.von_mises("DG0").x.array, 0.0, atol=1e-3)


def test_a_capped_krylov_solve_is_reported_not_raised(cube):
    """rtol 1e-20 in 3 CG iterations cannot be met: the solve returns and tells so."""
    s = Elasticity(cube, E=E, nu=NU, rtol=1e-20, max_it=3)
    _rollers(s)
    s.add_pressure("zmax", P)
    s.solve_static()
    (r,) = s.info.solves
    assert (r.solver, r.what, r.converged, r.iterations, r.reason) == ("CG+GAMG", "static", False, 3, "DIVERGED_MAX_IT")
    assert r.tolerance == 1e-20 and 1e-20 < r.residual < 1.0
    assert np.all(np.isfinite(s.u.x.array)) and s.info.iterations == 3


@pytest.mark.parametrize("solver", ["cg", "lu"])
def test_a_solve_records_its_residual(cube, solver):
    """CG: converged with the residual relative to the initial one below rtol; LU: one
    iteration and the true relative residual ||K u - F|| / ||F||."""
    s = block_compression(E, NU, P, solid=cube, solver=solver, rtol=1e-10).solver
    (r,) = s.info.solves
    K, F = s.static_system()
    Ku = F.duplicate()
    K.mult(s.u.vector, Ku)
    Ku.axpy(-1.0, F)
    true = Ku.norm() / F.norm()
    assert r.converged and r.residual <= r.tolerance == 1e-10 and true < 1e-8
    if solver == "lu":
        assert (r.solver, r.iterations, r.reason) == ("LU", 1, "CONVERGED_ITS")
        assert r.residual == pytest.approx(true, rel=1e-6) and r.residual < 1e-13
    else:
        assert r.solver == "CG+GAMG" and r.iterations > 1 and r.reason == "CONVERGED_RTOL"


def test_a_warm_started_solve_is_measured_against_the_right_side(cube):
    """From the last solution PETSc divides by ||B b||, not by the (small) initial residual:
    the reported residual is below rtol exactly when PETSc says converged."""
    s = Elasticity(cube, E=E, nu=NU, rtol=1e-8)
    _rollers(s)
    p = s.add_pressure("zmax", P)
    s.solve_static()
    p.value = 1.01 * P
    s.solve_static()
    (r,) = s.info.solves
    assert r.reason == "CONVERGED_RTOL" and 1e-10 < r.residual <= r.tolerance == 1e-8


def test_evaluate_outside_is_nan(cube):
    s = block_compression(E, NU, P, solid=cube).solver
    values = s.evaluate([[0.5, 0.5, 0.5], [2.0, 0.0, 0.0]])
    assert np.allclose(values[0], block_exact([0.5, 0.5, 0.5], E, NU, P)[0])
    assert np.isnan(values[1]).all()


def test_locking_warning_and_p2_locking_free(cube):
    with pytest.warns(LockingWarning, match="nearly incompressible"):
        Elasticity(cube, E=E, nu=0.499)
    with warnings.catch_warnings():
        warnings.simplefilter("error", LockingWarning)
        s = Elasticity(cube, E=E, nu=0.499, locking_free=True)
    assert s.degree == 2
    # cantilever, 20x2x2 lattice: P1 locks at nu = 0.499, P2 does not
    p1_free, beam_free = cantilever(0.3, degree=1)
    p1, beam = cantilever(0.499, degree=1)
    p2, _ = cantilever(0.499, locking_free=True)
    assert p1 / beam < 0.1 < 0.4 < p1_free / beam_free  # locked: 2 % of the beam deflection
    assert p2 / beam > 0.9


def test_bad_parameters():
    solid = box_mesh(shape=(1, 1, 1))
    with pytest.raises(ValueError, match="Poisson"):
        Elasticity(solid, E=E, nu=0.5)
    with pytest.raises(ValueError, match="rho_s - rho_f"):
        Elasticity(solid, E=E, nu=NU, density=1000.0, fluid_density=1000.0, scheme="newmark", dt=1.0)
    with pytest.raises(RuntimeError, match="static"):
        Elasticity(solid, E=E, nu=NU).step(1.0)
    with pytest.raises(ValueError, match="components"):
        Elasticity(solid, E=E, nu=NU).add_dirichlet("zmin", 0.0, components=[3])
