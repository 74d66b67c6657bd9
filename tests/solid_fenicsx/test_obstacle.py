"""Contact with a rigid plane (solid_fenicsx.obstacle: eq. 11 with T = 0) through the solid
participant: the plane from the scene, dolfinx's stiffness against the obstacle problem of
nonsmooth.obstacle (to round-off), the cube of cases/cube_obstacle on a small lattice solved
by the multilevel, active-set and SNES VI solvers, and the [contact] obstacle keys' errors."""

import numpy as np
import pytest

pytest.importorskip("dolfinx")

from coupler.errors import SceneError  # noqa: E402
from coupler.plan.plan import make_plan  # noqa: E402
from coupler.scene import load  # noqa: E402
from solid_fenicsx.mortar import ContactSetupError, Face  # noqa: E402
from solid_fenicsx.obstacle import Plane  # noqa: E402
from solid_fenicsx.participant import SolidParticipant  # noqa: E402
from vc_helpers import CASES, copy_case  # noqa: E402

CUBE = CASES / "cube_obstacle"


def cube(cells=6, levels=2, **contact) -> SolidParticipant:
    """The solid of cases/cube_obstacle on a cells^3 lattice."""
    config = make_plan(load(CUBE)).participant("solid").config
    config["box"]["shape"] = [cells] * 3
    config["contact"].update(levels=levels, **contact)
    p = SolidParticipant()
    p.comm, p.rank = None, 0
    p.configure(config)
    return p


def test_the_plane_from_the_scene():
    face = Face("bottom", np.arange(3), np.array([[0, 1, 2]]), np.array([[0.0, 0, 1], [1, 0, 2], [0, 1, 3]]))
    plane = Plane.from_config({"plane": [0.0, 0.0, 2.0, -1.0]}, face)  # 2 z - 1 = 0
    assert np.allclose(plane.normal, [0, 0, 1]) and plane.offset == -0.5
    assert np.allclose(plane.distance(face.points), [0.5, 1.5, 2.5])
    touching = Plane.from_config({"normal": [0.0, 0.0, 1.0], "gap": 0.25}, face)  # 0.25 below the lowest point
    assert np.allclose(touching.distance(face.points), [0.25, 1.25, 2.25])
    with pytest.raises(ContactSetupError, match=r"the whole slave face 'bottom' is behind it"):
        Plane.from_config({"plane": [0.0, 0.0, 1.0, -5.0]}, face)
    m = plane.coupling(face)
    assert m.master is None and m.T.shape == (3, 0) and m.covered.all()
    assert np.allclose(m.normals, [0, 0, -1]) and m.weights == pytest.approx(np.full(3, np.sqrt(6) / 2 / 3))  # a third of the area each


def test_dolfinx_stiffness_is_the_obstacle_problem_of_nonsmooth():
    """The transformed QP of the participant (input numbering; the bottom's normal unknown is
    -u_z) is nonsmooth.obstacle's problem of the same cube to round-off: matrix, right side,
    and the bound at the plane."""
    from nonsmooth.obstacle import obstacle_qp
    from transfer.grid import StructuredGrid
    from transfer.mesh import lattice_tetrahedra

    p = cube(6)
    qp = p.contact.problem()
    grid = StructuredGrid.from_bounds([0.0] * 3, [0.01] * 3, [6] * 3)
    top = np.flatnonzero(np.isclose(grid.points[:, 2], 0.01, rtol=0, atol=1e-12))
    reference = obstacle_qp(grid.points, lattice_tetrahedra(grid.shape), 1e10, 0.25, top, [0, 0, -3e-4], 0.0)
    sign = np.ones(qp.size)
    sign[p.contact.normal_dofs] = -1.0
    A = qp.A.multiply(sign[:, None]).multiply(sign[None, :])
    assert abs(A - reference.A).max() <= 1e-14 * abs(reference.A).max()
    assert np.abs(sign * qp.b - reference.b).max() <= 1e-14 * np.abs(reference.b).max()
    bottom = np.flatnonzero(grid.points[:, 2] == 0.0)
    assert np.array_equal(-qp.upper[3 * bottom + 2], reference.lower[3 * bottom + 2])  # exactly 0: z on the plane


def test_the_cube_on_the_plane():
    """Two levels on 6 cells: the whole bottom pressed onto the plane (no penetration, no gap),
    the plane's push balancing the top face's load, the step length reported as the history;
    active set and SNES VI solve the same QP to the same solution."""
    from nonsmooth.solvers import solve

    p = cube(6)
    out = p.advance(0, 0, 0.0, 1.0, {})
    (report,), figures = p.take_reports()
    assert report.solver == "contact multilevel" and report.converged and report.residual < 1e-12
    assert report.iterations == figures["iterations"] == len(report.history) == 11  # cases/cube_obstacle/README.md
    assert figures["asymptotic_rate"] == pytest.approx(0.1511, abs=1e-4)
    assert [figures["dofs_level_0"], figures["dofs_level_1"]] == [192, 1029]
    u, points = out["displacement"].data, p.solver.vertices.points()
    bottom = points[:, 2] == 0.0
    assert np.array_equal(out["in_contact"].data == 1, bottom) and figures["active_nodes"] == 49
    assert np.abs(u[bottom, 2]).max() <= 1e-15 and figures["min_gap"] >= -1e-15
    top = p.solver.boundary_force("zmax")
    assert figures["force_z"] == pytest.approx(-top[2], rel=1e-9) == pytest.approx(30840.739402825, rel=1e-9)
    qp, x = p.contact.problem(), p.contact.x
    for method in ("active_set", "snes_vi"):
        other = solve(qp, method)
        assert other.converged and np.abs(other.x - x).max() <= 1e-8 * np.abs(x).max(), method


@pytest.mark.parametrize("replace, message", [
    ({"obstacle = { plane = [0.0, 0.0, 1.0, 0.0] }": 'obstacle = { plane = [0.0, 0.0, 1.0, 0.0] }\nmaster = "zmax"'},
     r"\[contact\] master: give either master .* or obstacle"),
    ({"obstacle = { plane = [0.0, 0.0, 1.0, 0.0] }": "obstacle = { plane = [0.0, 0.0, 1.0] }"},
     r"\[contact\] obstacle: plane must be a list of 4 finite numbers"),
    ({"obstacle = { plane = [0.0, 0.0, 1.0, 0.0] }": "obstacle = { plane = [0.0, 0.0, 0.0, 1.0] }"},
     r"\[contact\] obstacle: plane: the plane's normal \(a, b, c\) is zero"),
    ({"obstacle = { plane = [0.0, 0.0, 1.0, 0.0] }": "obstacle = { normal = [0.0, 0.0, 1.0], gap = -1.0 }"},
     r"\[contact\] obstacle: gap must be a number >= 0"),
    ({"obstacle = { plane = [0.0, 0.0, 1.0, 0.0] }": "obstacle = { point = [0.0, 0.0, 0.0] }"},
     r"\[contact\] obstacle: give \{ plane = \[a, b, c, d\] \} or"),
    ({"solver = \"multilevel\"": "solver = \"active_set\""}, r"\[contact\] levels: only the multilevel solver has it"),
    ({"smoothing = 3": "smoothing = 3\nsearch_distance = 0.1"},
     r"\[contact\] search_distance: a rigid obstacle needs no search"),
    ({"levels = 4": "levels = 1"}, r"\[contact\] levels: must be an integer >= 2"),
])
def test_bad_obstacle_tables_name_the_key(tmp_path, replace, message):
    with pytest.raises(SceneError, match=message):
        load(copy_case(CUBE, tmp_path, replace))
