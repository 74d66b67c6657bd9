"""Stress-controlled load steps (solid_fenicsx.platen, solid_fenicsx.load_steps): a rigid
platen finds the uniform displacement that gives each step's mean normal stress, reported as
an inner solve with its figures; loads given per step; the platen's errors."""

import numpy as np
import pytest

pytest.importorskip("dolfinx")

from coupler.plan.plan import make_plan  # noqa: E402
from coupler.scene import load  # noqa: E402
from solid_fenicsx.participant import SolidParticipant  # noqa: E402
from solid_fenicsx.platen import Platen  # noqa: E402

#: a unit-height block, nu = 0: under a platen on top and rollers below and on two sides the
#: stress is uniaxial whatever the platen holds laterally: sigma = E d / H exactly (P1 too)
BLOCK = """
[physics]
effects = ["elasticity"]
[geometry.solid]
lower = [0.0, 0.0, 0.0]
upper = [0.5, 0.4, 1.0]
shape = [2, 2, 4]
[materials.solid]
E = 2.0e9
nu = 0.0
[[loads]]
type = "dirichlet"
boundary = "zmin"
components = ["z"]
[[loads]]
type = "dirichlet"
boundary = "xmin"
components = ["x"]
[[loads]]
type = "dirichlet"
boundary = "ymin"
components = ["y"]
"""


def participant(tmp_path, loads: str):
    case = tmp_path / "case"
    case.mkdir(exist_ok=True)
    (case / "scene.toml").write_text(BLOCK + loads)
    scene = load(case)
    p = SolidParticipant()
    p.comm, p.rank = None, 0
    p.configure(make_plan(scene).participant("solid").config)
    return scene, p


def advance(p, k):
    out = p.advance(k, 0, float(k), 1.0, {})
    reports, figures = p.take_reports()
    return out, {r.solver: r for r in reports}, figures


def test_the_platen_finds_the_exact_displacement_of_a_linear_block(tmp_path):
    """sigma = E d / H: the first trial of the search (the elastic column of the block's height)
    is already exact, so each step takes one solve beyond the start; the mean stress is the
    platen's force over the top's area (0.2 m^2)."""
    scene, p = participant(tmp_path, '[[loads]]\ntype = "platen"\nboundary = "zmax"\nstress = [1.0e6, 3.0e6]\n')
    assert scene.time["steps"] == 2  # one step per stress
    for k, stress in enumerate((1e6, 3e6)):
        out, reports, figures = advance(p, k)
        platen = reports["platen"]
        assert platen.converged and platen.residual < 1e-9 and platen.tolerance == 1e-3
        assert platen.iterations == figures["platen_solves"] == (2 if k == 0 else 1)  # the start and one
        assert figures["stress"] == pytest.approx(stress, rel=1e-9)
        assert figures["platen_displacement"] == pytest.approx(stress * 1.0 / 2e9, rel=1e-9)
        assert figures["platen_force"] == pytest.approx(stress * 0.2, rel=1e-9)
        u = out["displacement"].data
        assert u[:, 2].min() == pytest.approx(-stress / 2e9, rel=1e-9)
        assert reports["CG+GAMG static"].converged  # the linear solve of the last trial


def test_loads_given_per_step(tmp_path):
    """A pressure of 1, then 2, then 0.5 MPa: the displacement follows it step by step (no ramp
    without contact)."""
    _, p = participant(tmp_path, '[[loads]]\ntype = "pressure"\nboundary = "zmax"\nvalue = [1.0e6, 2.0e6, 0.5e6]\n')
    tops = [advance(p, k)[0]["displacement"].data[:, 2].min() for k in range(3)]
    assert np.allclose(tops, [-1e6 / 2e9, -2e6 / 2e9, -0.5e6 / 2e9], rtol=1e-8)


def test_a_search_that_runs_out_of_solves_is_reported_unconverged(tmp_path):
    _, p = participant(tmp_path, '[[loads]]\ntype = "platen"\nboundary = "zmax"\nstress = [1.0e6]\n'
                                 'max_iterations = 1\n')
    _, reports, figures = advance(p, 0)
    platen = reports["platen"]
    assert not platen.converged and platen.iterations == 1 and "target not bracketed in 1 solves" in platen.detail
    assert figures["stress"] == 0.0  # the one solve it had was the start, at zero displacement


def test_a_platen_must_be_flat(tmp_path):
    """A boundary over two faces of the block (top and a side) is not a platen."""
    from solid_fenicsx.elasticity import Elasticity
    from solid_fenicsx.mesh import box_mesh
    from solid_fenicsx.platen import Platen, PlatenError

    corner = {"corner": lambda x: np.isclose(x[2], 1.0) | np.isclose(x[0], 1.0)}
    s = Elasticity(box_mesh(shape=(2, 2, 2), boundaries=corner), E=1e9, nu=0.3)
    with pytest.raises(PlatenError, match="platen boundary 'corner' is not flat: its facets' normals are on average"):
        Platen(s, "corner")
    with pytest.raises(PlatenError, match="platen boundary 'zmax' has no facets"):  # taken by 'corner'
        Platen(s, "zmax")
    platen = Platen(Elasticity(box_mesh(shape=(2, 2, 2)), E=1e9, nu=0.3), "zmax")
    assert np.array_equal(platen.normal, [0.0, 0.0, 1.0]) and platen.area == pytest.approx(1.0, rel=1e-12)


class CurvePlaten(Platen):
    """The platen's search on a stress curve sigma(d) in place of the solid's solves."""

    def __init__(self, curve, compliance: float):
        self.curve, self.compliance, self.tolerance, self.max_solves = curve, compliance, 1e-3, 40
        self.history, self.d, self.area = [], 0.0, 1.0

    def set(self, displacement: float) -> None:
        self.d = displacement

    def stress(self) -> float:
        return self.curve(self.d)


def test_a_stiffening_contact_is_found_by_secant_steps_in_few_solves():
    """The usual curve (contact stiffening exponentially with closure): found in a handful of
    solves; the search steps towards the target from every trial (a trial above it is followed by
    one at a smaller displacement), so the bracket's ends never come inverted."""
    found = CurvePlaten(lambda d: 1e5 * np.expm1(d / 1e-5), compliance=1e-11).load_to(2e6, solve=lambda: True)
    assert found.converged and found.stress == pytest.approx(2e6, rel=1e-3) and found.solves <= 8


def measured_fracture(method: str, tolerance: float) -> list[dict]:
    """cases/measured_fracture on every fourth map node (an 8 x 8 lattice), its three stresses
    with the platen's `method` and `tolerance`: each step's figures and platen report."""
    from vc_helpers import CASES

    config = make_plan(load(CASES / "measured_fracture")).participant("solid").config
    config["generator"]["parameters"]["coarsen"] = 4
    platen = next(ld for ld in config["loads"] if ld["type"] == "platen")
    platen.update(method=method, tolerance=tolerance)
    p = SolidParticipant()
    p.comm, p.rank = None, 0
    p.configure(config)
    out = []
    for k in range(config["steps"]):
        _, reports, figures = advance(p, k)
        out.append({**figures, "platen": reports["platen"], "contact": reports["contact active_set"]})
    return out


def test_the_platen_as_an_unknown_closes_the_fracture_in_one_contact_solve_per_stress():
    """method = "constraint": each stress (1, 5, 20 MPa) in one contact solve, the stress exact
    to the solver's tolerance; the closure and the platen displacement those of the search of
    full solves (today's path, here to a 1e-7 stress tolerance) within 1e-5: the same problem.
    The search took 5 to 8 solves a stress at this tolerance."""
    one, search = measured_fracture("constraint", 1e-3), measured_fracture("search", 1e-7)
    for a, b in zip(one, search):
        assert a["contact_solves"] == 1 and a["platen"].converged and a["contact"].converged
        assert a["stress"] == pytest.approx(a["target_stress"], rel=1e-8)
        assert b["contact_solves"] >= 3
        assert a["closure"] == pytest.approx(b["closure"], rel=1e-5)
        assert a["platen_displacement"] == pytest.approx(b["platen_displacement"], rel=1e-5)
        assert a["area_fraction"] == pytest.approx(b["area_fraction"], abs=1e-9)


def test_the_platen_as_an_unknown_needs_contact(tmp_path):
    from coupler.scene import SceneError

    with pytest.raises(SceneError, match="method: 'constraint' makes the displacement an unknown of the contact"):
        participant(tmp_path, '[[loads]]\ntype = "platen"\nboundary = "zmax"\nstress = [1.0e6]\nmethod = "constraint"\n')
