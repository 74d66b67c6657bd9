"""Contact between rough fracture faces: the solid participant of cases/fracture_closure
(generator fracture_specimen, a stress-controlled platen, mortar contact) on coarse
specimens, and the hard cases of the contact issue: near full closure at 20 MPa, a 5:1
mesh size ratio across the face, nearly flat faces (all nodes in contact), very rough faces
(many small patches), initial interpenetration. Each converges without active-set cycling
(``monotone_from`` is None), keeps the faces apart, balances forces, and the loading curve
stiffens."""

import numpy as np
import pytest

pytest.importorskip("dolfinx")

from coupler.plan.plan import make_plan  # noqa: E402
from coupler.scene import load  # noqa: E402
from solid_fenicsx.participant import SolidParticipant  # noqa: E402
from transfer.generators import generate  # noqa: E402
from vc_helpers import CASES  # noqa: E402

SMALL = {"lattice": [8, 8, 3]}


def specimen(stresses, tolerance=5e-3, contact=None, **parameters) -> SolidParticipant:
    """The configured solid of cases/fracture_closure with `parameters` of its specimen, the
    platen's `stresses` (one per load step) and the contact search across the largest gap."""
    config = make_plan(load(CASES / "fracture_closure")).participant("solid").config
    generated = config["generator"]["parameters"] = {**config["generator"]["parameters"], **SMALL, **parameters}
    info = generate("fracture_specimen", generated).info
    search = 2 * info["max_initial_aperture"] + generated["rms"]
    config["contact"] = {**config["contact"], "search_distance": search, **(contact or {})}
    platen = next(ld for ld in config["loads"] if ld["type"] == "platen")
    platen.update(value=list(stresses), tolerance=tolerance)
    if generated["shape"] == "box":
        del platen["area"]  # the top face's own area: size^2
    config["steps"] = len(stresses)
    p = SolidParticipant()
    p.comm, p.rank = None, 0
    p.configure(config)
    return p


def step(p, k):
    """Load step k: (outputs, reports by solver, figures)."""
    out = p.advance(k, 0, float(k), 1.0, {})
    reports, figures = p.take_reports()
    return out, {r.solver: r for r in reports}, figures


def check_state(p, figures, stress):
    """No interpenetration, complementarity, pressure >= 0, force balance, no cycling."""
    state, m = p.static.state, p.contact.mortar
    gap, pressure = state.gap[m.covered], state.pressure[m.covered]
    tol = 1e-9 * 2e-4
    assert gap.min() >= -tol
    assert pressure.min() >= 0 and np.max(np.abs(gap * pressure)) <= tol * pressure.max()
    top = p.solver.boundary_force("top")
    assert abs(state.force[2] - top[2]) <= 1e-6 * abs(top[2])  # the slave's contact force = the platen's load
    assert figures["platen_force"] == pytest.approx(-top[2], rel=1e-12)
    assert abs(figures["stress"] / stress - 1) < 5e-3
    assert state.solution.converged and state.solution.info["monotone_from"] is None


@pytest.mark.parametrize("shape", ["box", "cylinder"])
def test_loading_curve_stiffens(shape):
    stresses = [1e6, 2e6, 5e6, 10e6, 20e6]
    p = specimen(stresses, shape=shape)
    rows = []
    for k, stress in enumerate(stresses):
        _, reports, figures = step(p, k)
        assert reports["platen"].converged and reports["platen"].residual <= 5e-3
        assert reports["platen"].iterations == figures["platen_solves"] >= 1
        check_state(p, figures, stress)
        rows.append(figures)
    stress = np.array([r["stress"] for r in rows])
    closure = np.array([r["closure"] for r in rows])
    area = np.array([r["area_fraction"] for r in rows])
    assert np.all(np.diff(closure) > 0) and np.all(np.diff(area) > 0)
    stiffness = np.diff(stress) / np.diff(closure)
    assert np.all(np.diff(stiffness) > 0)  # the characteristic stiffening
    assert closure[-1] < p.contact.initial_mean_gap
    assert rows[-1]["mean_gap"] == pytest.approx(p.contact.initial_mean_gap - closure[-1], rel=1e-12)
    # the platen's secant search from the last stress's slope: a later stress in a few solves
    assert max(r["platen_solves"] for r in rows[1:]) <= 3


def test_20_mpa_near_full_closure_in_one_step():
    """Straight to 20 MPa from the open fracture (no intermediate load steps)."""
    p = specimen([20e6])
    _, reports, figures = step(p, 0)
    check_state(p, figures, 20e6)
    assert figures["area_fraction"] > 0.3 and reports["contact active_set"].iterations <= 10


def test_mesh_size_ratio_5_to_1():
    p = specimen([10e6], lattice=[15, 15, 2], ratio=5, shape="box")
    assert len(p.contact.mortar.slave.nodes) == 16 * 16 and len(p.contact.mortar.master.nodes) == 4 * 4
    check_state(p, step(p, 0)[2], 10e6)


def test_nearly_flat_faces_close_everywhere():
    """Faces 0.2 um rough, 1 um apart: at 10 MPa every slave node touches."""
    p = specimen([10e6], rms=2e-7, aperture=1e-6, min_aperture=5e-7, shape="box")
    _, _, figures = step(p, 0)
    check_state(p, figures, 10e6)
    assert p.static.state.active[p.contact.mortar.covered].all() and figures["area_fraction"] == pytest.approx(1.0)


def test_very_rough_faces_touch_in_many_patches():
    """RMS 1 mm against a 0.2 mm mean aperture and a short mismatch length: many small
    contact patches (starting interpenetrated where the faces cross)."""
    p = specimen([5e6], lattice=[16, 16, 3], rms=1e-3, aperture=2e-4, mismatch_length=0.005, min_aperture=1e-6,
                 shape="box")
    check_state(p, step(p, 0)[2], 5e6)
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components

    m, on = p.contact.mortar, p.static.state.active
    # patches: connected groups of slave nodes in contact on the slave face's triangle graph
    edges = np.array([(a, b) for t in m.slave.triangles for a, b in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0]))
                      if on[a] and on[b]]).reshape(-1, 2)
    graph = sp.csr_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), (len(on), len(on)))
    _, label = connected_components(graph, directed=False)
    assert len(set(label[on])) >= 5


def test_initial_interpenetration_is_resolved():
    """Faces generated crossing (negative minimum aperture after the coarse upper face
    cuts the fine lower one): the first solve separates them."""
    p = specimen([2e6], rms=5e-4, aperture=1e-4, min_aperture=1e-7, shape="box")
    assert np.nanmin(p.contact.mortar.gap) < 0
    check_state(p, step(p, 0)[2], 2e6)


def test_too_few_iterations_stop_the_search_and_say_so():
    """An active-set limit of 1 iteration: the contact solve is reported unconverged, and the
    platen's search stops there, unconverged, naming the solve that did not converge."""
    p = specimen([10e6], contact={"max_iterations": 1}, shape="box")
    _, reports, _ = step(p, 0)
    contact, platen = reports["contact active_set"], reports["platen"]
    assert not contact.converged and contact.iterations == 1
    assert not platen.converged and "did not converge" in platen.detail


def test_a_step_reports_its_wall_time_split_into_its_phases():
    """The step's ``seconds`` is the wall time of the participant's advance (not its last
    solve's), split into assembly, AMG set-up, solves and the rest; the platen search and
    the counts of all the step's solves beside it."""
    import time

    p = specimen([2e6, 5e6])
    for k in range(2):
        start = time.perf_counter()
        _, reports, figures = step(p, k)
        wall = time.perf_counter() - start
        assert 0.97 * wall - 0.01 <= figures["seconds"] <= wall
        parts = [figures[f"seconds_{k}"] for k in ("assembly", "amg_setup", "solves")]  # "other" is the rest
        assert min(parts) >= 0 and sum(parts) <= figures["seconds"] and figures["seconds_other"] >= 0
        assert figures["seconds_platen_search"] <= figures["seconds"]
        assert figures["contact_solves"] == figures["platen_solves"] == reports["platen"].iterations
        assert figures["step_iterations"] >= figures["iterations"] + figures["contact_solves"] - 1
        assert figures["step_krylov_iterations"] >= figures["krylov_iterations"]


def test_a_long_step_logs_its_progress(monkeypatch, caplog):
    """Progress lines (platen trial, active-set iteration and residual, CG iteration) come
    whenever PROGRESS_SECONDS have passed; here every event, and the step's summary line."""
    import logging

    import solid_fenicsx.load_steps

    monkeypatch.setattr(solid_fenicsx.load_steps, "PROGRESS_SECONDS", 0.0)
    p = specimen([2e6])
    with caplog.at_level(logging.INFO, logger="varcouple.solid_fenicsx"):
        _, _, figures = step(p, 0)
    lines = [r.getMessage() for r in caplog.records if r.name == "varcouple.solid_fenicsx"]
    assert any("platen trial 1, platen displacement" in line for line in lines)
    assert any(f"platen trial {int(figures['platen_solves'])}," in line for line in lines)
    assert any("active set iteration" in line and "residual" in line for line in lines)
    assert any("cg iteration" in line and "cg residual" in line for line in lines)
    assert lines[-1].startswith("load step 0: seconds ") and "seconds amg setup" in lines[-1]


def test_the_amg_set_up_once_per_solve_gives_the_closure_of_the_from_scratch_solves():
    """The contact solves with the AMG set up once per solve (the default) against set up at
    every active-set iteration: the same platen trials, contact set and closure to the
    solver's tolerance, with fewer set-ups."""
    reused, scratch = specimen([1e6, 5e6]), specimen([1e6, 5e6])
    scratch.contact.options["amg_reuse"] = False
    for k in range(2):
        (a, _, fa), (b, _, fb) = step(reused, k), step(scratch, k)
        assert fa["platen_solves"] == fb["platen_solves"]
        assert fa["platen_displacement"] == pytest.approx(fb["platen_displacement"], rel=1e-8)
        assert fa["closure"] == pytest.approx(fb["closure"], rel=1e-8)
        assert np.array_equal(reused.static.state.active, scratch.static.state.active)
        ua, ub = a["displacement"].data, b["displacement"].data
        assert np.max(np.abs(ua - ub)) <= 1e-8 * np.max(np.abs(ub))
        check_state(reused, fa, [1e6, 5e6][k])
        assert reused.static.state.solution.info["amg_setups"] == 1
        assert scratch.static.state.solution.info["amg_setups"] == scratch.static.state.solution.iterations
