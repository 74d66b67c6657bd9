"""Paper figure 12 (cases/fracture_open_by_pressure): effects elasticity, contact and
fluid_pressure together. A rough fracture closed by the platen at 2 MPa, then 1 MPa of
fluid in it, the confining stress held: the force balance platen = contact + fluid on the
faces at every step, the contact force dropping and the faces opening where the fluid acts,
and the formulation (the fluid on the whole faces, the contact stress beyond it) being
exactly the fluid on the open parts of the faces only."""

from __future__ import annotations

import json

import meshio
import numpy as np
import pytest

from coupler.cli import main
from vc_helpers import CASES, copy_case

CASE = CASES / "fracture_open_by_pressure"
COARSE = {"lattice = [16, 16, 5]": "lattice = [8, 8, 3]"}


@pytest.fixture(scope="module")
def coarse(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("figure12")
    out = tmp / "out"
    with pytest.MonkeyPatch.context() as mp:  # before the tests' own fixtures: no pictures here either
        mp.setenv("VARCOUPLE_PICTURES", "0")
        assert main(["run", str(copy_case(CASE, tmp, COARSE)), "-o", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    return summary, [meshio.read(out / f"solid_{k:04d}.vtu") for k in range(2)]


def test_platen_force_is_contact_plus_fluid_at_every_step(coarse):
    """The upper block (under the platen): the platen's force (its reaction) = the contact
    force the lower block exerts on it + the fluid's force on its open face, to 1e-6."""
    summary, _ = coarse
    for step in summary["steps"]:
        f = step["figures"]["solid"]
        assert step["converged"]
        contact_on_upper = -f["force_z"]  # the slave's contact force is the lower block's
        balance = contact_on_upper + f["fluid_force_fracture_upper_z"]
        assert balance == pytest.approx(f["platen_force"], rel=1e-6)
        assert f["stress"] == pytest.approx(2e6, rel=1e-3)
    first, second = (s["figures"]["solid"] for s in summary["steps"])
    assert first["fluid_force_fracture_upper_z"] == first["fluid_force_fracture_lower_z"] == 0.0
    # the fluid's force is that of 1 MPa on the open part of the disc (projected), up on the upper face
    assert 0.8 * 1e6 * np.pi * 0.061**2 < second["fluid_force_fracture_upper_z"] < 1e6 * np.pi * 0.061**2


def test_the_contact_force_drops_and_the_faces_open_where_the_fluid_acts(coarse):
    summary, (closed, opened) = coarse
    first, second = (s["figures"]["solid"] for s in summary["steps"])
    assert -second["force_z"] < 0.7 * -first["force_z"]  # the fluid carries part of the 2 MPa
    assert second["active_nodes"] < first["active_nodes"] and second["closure"] < first["closure"]
    slave = opened.point_data["slave"] == 1
    wet = slave & (opened.point_data["in_contact"] == 0)  # the open part, where the fluid acts
    opening = opened.point_data["gap"] - closed.point_data["gap"]
    assert opening[wet].min() > 0
    # next to the contacts too: open nodes sharing a slave triangle with a node in contact
    touching = slave & (opened.point_data["in_contact"] == 1)
    triangles = opened.cells_dict["tetra"]
    near = np.zeros(len(slave), bool)
    for tet in triangles[touching[triangles].any(axis=1)]:
        near[tet] = True
    assert (near & wet).sum() > 5 and opening[near & wet].min() > 0
    # where they touch, the contact stress carries at least the fluid's pressure
    assert opened.point_data["contact_pressure"][touching].min() >= 1e6


def test_the_formulation_is_the_fluid_on_the_open_parts_only(tmp_path):
    """Remove the fluid's load from the contact set (slave nodes: -p D_kk n_k; master: its
    mortar image) and solve again: the same displacement, the contact multiplier larger by
    p D_kk. So the fluid on the whole faces is exactly the fluid on the open parts."""
    pytest.importorskip("dolfinx")
    from coupler.plan.plan import make_plan
    from coupler.scene import load
    from nonsmooth.solvers import solve
    from solid_fenicsx.participant import SolidParticipant

    config = make_plan(load(copy_case(CASE, tmp_path, COARSE))).participant("solid").config
    p = SolidParticipant()
    p.comm, p.rank = None, 0
    p.configure(config)
    for k in range(2):
        p.advance(k, 0, float(k), 1.0, {})
        p.take_reports()
    contact, state = p.contact, p.static.state
    m, active, pressure = contact.mortar, state.active, 1e6
    qp = contact.problem()
    # the fluid's load on the contact set, in the displacement space (dof numbering)
    on_slave = -pressure * (m.weights * active)[:, None] * m.normals
    f = np.zeros((contact.num_dofs // 3, 3))
    f[contact.dofs[m.slave.nodes]] = on_slave
    np.add.at(f, contact.dofs[m.master.nodes], -(m.T.T @ on_slave))  # the master: its mortar image
    open_only = type(qp)(qp.A, qp.b - contact.P.T @ f.ravel(), qp.lower, qp.upper, block_size=3)
    solution = solve(open_only, "active_set", x0=contact.x)
    assert solution.converged
    assert np.abs(solution.x - contact.x).max() <= 1e-9 * np.abs(contact.x).max()
    normal = contact.normal_of_node[active]
    gained = open_only.multiplier(solution.x)[normal] - qp.multiplier(contact.x)[normal]
    assert gained == pytest.approx(pressure * m.weights[active], rel=1e-6)
