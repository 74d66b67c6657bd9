"""Role contracts (coupler/protocol/roles.py, docs/protocol.md "Roles"): every participant passes
the conformance kit (announce, geometry and one advance checked against its role), faulty
stand-ins (a required field left out, a wrong shape, a grid fluid without its grid) are refused
with one line naming participant, role, field and fault, the runner refuses such a reply, and the
documentation's table is the module's."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys

import numpy as np
import pytest

from coupler.plan.plan import make_plan
from coupler.protocol import roles
from coupler.protocol.mpi import mpi_environment
from coupler.protocol.roles import DISPLACEMENT, PRESSURE, VELOCITY, ContractError, conformance
from coupler.protocol.wire import Field
from coupler.scene import load
from coupler.standins import ReplayFluid, RigidSolid, SpringSolid
from vc_helpers import CASES, ROOT, copy_case

BOX = {"lower": [0.0, 0.0, 0.0], "upper": [1.0, 1.0, 1.0], "shape": [2, 1, 1]}
GRID = {"origin": [0.0, 0.0, 0.0], "spacing": [0.5, 0.5, 0.5], "shape": [3, 2, 2]}


def chorin():
    from fluid_chorin.participant import ChorinParticipant

    return ChorinParticipant(), {"grid": {"origin": [0, 0, 0], "spacing": [1e-3] * 3, "shape": [4, 3, 1]},
                                 "inlet": {"pressure": 1.0}, "outlet": {"pressure": 0.0},
                                 "boundaries": {"zmin": "empty", "zmax": "empty"}, "rho": 1000.0, "mu": 0.1}


def reynolds():
    from fluid_reynolds.participant import ReynoldsParticipant

    return ReynoldsParticipant(), {"grid": {"origin": [0, 0, 0], "spacing": [2e-3, 2.5e-3, 5e-5], "shape": [4, 3, 6]},
                                   "location": "cells", "mu": 1e-3, "inlet": {"pressure": 10.0},
                                   "outlet": {"pressure": 0.0}, "walls": "wall"}


def solid_fenicsx(tmp_path):
    """The dolfinx solid as a scene configures it: a block of 2 x 1 x 2 cells, loaded by the fluid's
    pressure on zmax."""
    from solid_fenicsx.participant import SolidParticipant

    (tmp_path / "scene.toml").write_text(
        '[physics]\neffects = ["elasticity"]\n[geometry.solid]\nlower = [0, 0, 0]\nupper = [1, 1, 1]\n'
        'shape = [2, 1, 2]\n[materials.solid]\nE = 1.0e9\nnu = 0.25\n[[loads]]\ntype = "dirichlet"\n'
        'boundary = "zmin"\n')
    config = dict(make_plan(load(tmp_path)).participant("solid").config, wetted="zmax", traction="pressure")
    return SolidParticipant(), config


def openfoam(tmp_path):
    from fluid_openfoam.participant import FluidParticipant

    return FluidParticipant(), {"grid": {"origin": [0, 0, 0], "spacing": [5e-4, 5e-4, 5e-4], "shape": [2, 2, 1]},
                                "location": "cells", "inlet": {"pressure": 1e-2}, "outlet": {"pressure": 0.0},
                                "boundaries": {"zmin": "empty", "zmax": "empty"}, "mu": 1e-3, "rho": 1000.0,
                                "max_iterations": 200, "tolerance": 1e-6, "case_dir": str(tmp_path / "case")}


PARTICIPANTS = {
    "replay_fluid": ("fluid", lambda tmp: (ReplayFluid(), {"grid": GRID, "pressure": 5.0})),
    "replay_fluid on cells": ("fluid", lambda tmp: (ReplayFluid(), {"grid": GRID, "location": "cells"})),
    "spring_solid": ("solid", lambda tmp: (SpringSolid(), {"box": BOX, "stiffness": 1e6})),
    "rigid_solid": ("solid", lambda tmp: (RigidSolid(), {"box": BOX})),
    "chorin": ("fluid", lambda tmp: chorin()),
    "reynolds": ("fluid", lambda tmp: reynolds()),
    "solid_fenicsx": ("solid", solid_fenicsx),
    "openfoam": ("fluid", openfoam),
}
SLOW = {"openfoam"}


@pytest.mark.parametrize("kind", [pytest.param(k, marks=pytest.mark.slow) if k in SLOW else k for k in PARTICIPANTS])
def test_every_participant_keeps_its_role_contract(kind, tmp_path):
    if kind == "openfoam" and shutil.which("simpleFoam") is None:
        pytest.skip("OpenFOAM (simpleFoam) not installed")
    role, make = PARTICIPANTS[kind]
    participant, config = make(tmp_path)
    participant.bind("conformance", role)
    given = [PRESSURE] if kind == "solid_fenicsx" else None  # loaded by pressure: it takes no traction
    try:
        outputs = conformance(role, participant, config, given)
    finally:
        participant.finish()
    for field in roles.ROLES[role].outputs:
        if field.required:
            assert np.all(np.isfinite(np.asarray(getattr(outputs[field.name], "data", outputs[field.name]))))


class WithoutVelocity(ReplayFluid):
    def advance(self, *args):
        out = dict(super().advance(*args))
        del out[VELOCITY]
        return out


class ScalarVelocity(ReplayFluid):
    def advance(self, *args):
        out = dict(super().advance(*args))
        out[VELOCITY] = Field(VELOCITY, out[VELOCITY].data[:, 0])
        return out


class ShortPressure(ReplayFluid):
    def advance(self, *args):
        out = dict(super().advance(*args))
        out[PRESSURE] = Field(PRESSURE, out[PRESSURE].data[:-1])
        return out


class Gridless(ReplayFluid):
    def geometry(self):
        header, ids = super().geometry()
        return {k: v for k, v in header.items() if k != "grid"}, ids


class ExtraOutput(ReplayFluid):
    def advance(self, *args):
        return {**super().advance(*args), "vorticity": Field("vorticity", np.zeros(self.n))}


class Unannounced(ReplayFluid):
    def announce(self):
        return {**super().announce(), "provides": [PRESSURE]}


class FlatDisplacement(SpringSolid):
    def advance(self, *args):
        out = dict(super().advance(*args))
        out[DISPLACEMENT] = Field(DISPLACEMENT, out[DISPLACEMENT].data.ravel())
        return out


@pytest.mark.parametrize("cls, config, message", [
    (WithoutVelocity, {"grid": GRID}, "participant 'fluid' (role fluid): advance output 'velocity': missing "
                                      "(required, vector (3))"),
    (ScalarVelocity, {"grid": GRID}, "participant 'fluid' (role fluid): advance output 'velocity': wrong shape (36,), "
                                     "expected (36, 3) (vector (3) per row of 36)"),
    (ShortPressure, {"grid": GRID}, "participant 'fluid' (role fluid): advance output 'pressure': wrong shape (35,), "
                                    "expected (36,) (scalar per row of 36)"),
    (Gridless, {"grid": GRID}, "participant 'fluid' (role fluid): geometry: missing 'grid'"),
    (ExtraOutput, {"grid": GRID},
     "participant 'fluid' (role fluid): advance output 'vorticity': not a field of its role"),
    (Unannounced, {"grid": GRID}, "participant 'fluid' (role fluid): announce 'provides': missing velocity"),
    (FlatDisplacement, {"box": BOX, "stiffness": 1e6},
     "participant 'solid' (role solid): advance output 'displacement': wrong shape (36,), expected (12, 3)"),
])
def test_a_participant_that_breaks_its_contract_is_refused_naming_the_field(cls, config, message):
    role = "solid" if issubclass(cls, SpringSolid) else "fluid"
    participant = cls()
    participant.bind("conformance", role)
    with pytest.raises(ContractError) as info:
        conformance(role, participant, config)
    assert str(info.value).startswith(message) and "\n" not in str(info.value)


def test_a_solid_of_wrong_cells_and_a_fluid_of_unknown_location_are_refused():
    with pytest.raises(ContractError, match=r"geometry 'cells': wrong shape \(5, 1\), expected \(n, 4\)"):
        roles.check_geometry("solid", {"cell_type": "tetra"}, {"points": np.zeros((5, 3)), "cells": np.zeros((5, 1))})
    with pytest.raises(ContractError, match=r"geometry: cell_type 'vertex', expected 'tetra'"):
        roles.check_geometry("solid", {"cell_type": "vertex"}, {"points": np.zeros((5, 3)), "cells": np.zeros((5, 4))})
    with pytest.raises(ContractError, match=r"geometry 'cell_ids': wrong shape \(12, 1\), expected ids \(n,\)"):
        roles.check_geometry("fluid", {"grid": GRID}, {"cell_ids": np.zeros((12, 1))})
    with pytest.raises(ContractError, match=r"geometry 'location' 'faces' is not one of \['cells', 'points'\]"):
        roles.check_geometry("fluid", {"grid": GRID, "location": "faces"}, {})
    with pytest.raises(ContractError, match=r"shape must be at least 1 cell per axis"):
        roles.check_geometry("fluid", {"grid": {**GRID, "shape": [3, 0, 2]}}, {})
    assert roles.check_geometry("fluid", {"grid": GRID, "location": "cells"}, {}) == 12
    assert roles.check_geometry("mesh", {}, {}) is None  # no role (a mesh file): no contract


def test_the_runner_refuses_a_reply_that_breaks_the_contract(tmp_path, monkeypatch, capsys):
    """A one-way flow scene (a fixed solid served in process, the Chorin fluid): a solid whose
    displacement has the wrong shape stops the run, exit 4 (failed), with the contract's line."""
    from coupler.cli import main

    case = copy_case(CASES / "parallel_plates", tmp_path, {'participant = "openfoam"': 'participant = "chorin"',
                                                           "max_iterations = 5000\n": ""})
    original = RigidSolid.advance

    def flat(self, *args):
        out = original(self, *args)
        return {**out, DISPLACEMENT: Field(DISPLACEMENT, out[DISPLACEMENT].data[:, :2])}

    monkeypatch.setattr(RigidSolid, "advance", flat)
    assert main(["run", str(case), "-o", str(tmp_path / "out")]) == 4
    line = re.compile(r"participant 'solid' \(role solid\): advance output 'displacement': wrong shape \(\d+, 2\), "
                      r"expected \(\d+, 3\)")
    assert line.search(capsys.readouterr().err)
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["status"] == "failed" and line.search(summary["error"])


BREAKING_SOLID = """
import sys

from coupler.cli import main
from coupler.protocol.roles import DISPLACEMENT
from coupler.protocol.wire import Field
from coupler.standins import RigidSolid

original = RigidSolid.advance


def flat(self, *args):
    out = original(self, *args)
    return {**out, DISPLACEMENT: Field(DISPLACEMENT, out[DISPLACEMENT].data[:, :2])}


RigidSolid.advance = flat
sys.exit(main(["run", sys.argv[1], "-o", sys.argv[2]]))
"""


@pytest.mark.skipif(shutil.which("mpirun") is None, reason="mpirun not installed")
def test_two_coupler_ranks_refuse_a_reply_that_breaks_the_contract(tmp_path):
    """The same broken solid with the coupler on 2 ranks (each rank checks the parts it holds,
    their rows their ids): exit 4 on the job, the contract's line (before: the ranks' runner did
    not check, and the run went on with a displacement of 2 columns)."""
    case = copy_case(CASES / "parallel_plates", tmp_path, {'participant = "openfoam"': 'participant = "chorin"',
                                                           "max_iterations = 5000\n": ""})
    (tmp_path / "broken.py").write_text(BREAKING_SOLID)
    out = tmp_path / "out"
    run = subprocess.run(["mpirun", "-q", "-n", "2", "--oversubscribe", sys.executable, str(tmp_path / "broken.py"),
                          str(case), str(out)], capture_output=True, text=True, timeout=300,
                         env=mpi_environment())  # (not this process's C environment: its MPI singleton's)
    line = re.compile(r"participant 'solid' \(role solid\): advance output 'displacement': wrong shape \(\d+, 2\), "
                      r"expected \(\d+, 3\)")
    assert run.returncode == 4 and line.search(run.stderr), run.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "failed" and line.search(summary["error"])


def test_the_documented_roles_are_the_module_s():
    doc = (ROOT / "docs" / "protocol.md").read_text()
    rows = re.search(r"\| role \| geometry \|.*?\n\n", doc, re.S)
    assert rows is not None and rows.group(0).rstrip("\n") + "\n" == roles.table()


def test_every_registered_participant_declares_a_role_with_a_contract_and_inputs_of_it():
    from coupler.scene.participants import registered

    specs = registered()
    assert {"openfoam", "chorin", "reynolds", "solid_fenicsx", "spring_solid", "replay_fluid"} <= set(specs)
    for kind, spec in specs.items():
        if spec.role is None:  # a test participant (echo)
            continue
        assert spec.role in roles.ROLES, kind
        assert set(spec.accepts) <= {f.name for f in roles.ROLES[spec.role].inputs}, kind
