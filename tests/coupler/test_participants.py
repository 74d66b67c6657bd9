"""Participants declare their settings (coupler/scene/participants.py): they are found through
the entry points of pyproject.toml, reading a declaration imports no solver, a scene's
[solvers.X] is validated through the chosen participant's declaration, and the participant is
configured with exactly those validated settings, whose defaults it takes from the same
declaration."""

import subprocess
import sys
import textwrap
import tomllib

import pytest

from coupler.errors import SceneError
from coupler.plan.plan import make_plan
from coupler.protocol.settings import ParticipantSpec, Setting, Settings
from coupler.scene import load, participants
from fluid_openfoam.settings import PARTICIPANT as OPENFOAM
from vc_helpers import CASES, ROOT

SOLID = """
[physics]
effects = {effects}

[geometry.solid]
lower = [0, 0, 0]
upper = [1, 1, 0.5]
shape = [2, 2, 1]

[materials.solid]
E = 1e9
nu = 0.25

[[loads]]
type = "dirichlet"
boundary = "zmin"
"""
FLOW = """
[geometry.fluid]
lower = [0, 0, 0]
upper = [1, 1, 1]
shape = [4, 4, 4]

[time]
dt = 1.0
steps = 1

[coupling]
interface = "zmax"

[flow]
inlet_pressure = 1.0
"""


def scene(tmp_path, solvers="", effects='["elasticity", "flow"]'):
    text = SOLID.format(effects=effects) + (FLOW if "flow" in effects else "") + textwrap.dedent(solvers)
    (tmp_path / "scene.toml").write_text(text)
    return load(tmp_path)


def test_the_entry_points_declare_every_participant_in_its_settings_module():
    entries = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["entry-points"][participants.GROUP]
    assert sorted(participants.registered()) == sorted(entries) == [
        "chorin", "echo", "openfoam", "replay_fluid", "reynolds", "solid_fenicsx", "spring_solid"]
    for kind, target in entries.items():
        module = target.split(":")[0]
        assert module.endswith(".settings") or module == "coupler.standins", target
    assert {k: s.role for k, s in participants.registered().items()} == {
        "chorin": "fluid", "echo": None, "openfoam": "fluid", "replay_fluid": "fluid", "reynolds": "fluid",
        "solid_fenicsx": "solid", "spring_solid": "solid"}


def test_reading_the_declarations_and_a_scene_imports_no_solver():
    """In a fresh interpreter: the registry, a coupled scene with flow and its plan load no dolfinx,
    PETSc or OpenFOAM driver; ``from solid_fenicsx import Elasticity`` still works (lazily)."""
    code = textwrap.dedent(f"""
        import sys
        from coupler.plan.plan import make_plan
        from coupler.scene import load, participants
        participants.registered()
        make_plan(load({str(CASES / "small_fracture")!r}))
        heavy = sorted(m for m in sys.modules if m.split(".")[0] in ("dolfinx", "petsc4py", "ufl", "basix")
                       or m.startswith(("solid_fenicsx.", "fluid_openfoam.")) and not m.endswith(".settings"))
        print("heavy", heavy)
        import solid_fenicsx
        print("lazy", "dolfinx" in sys.modules)
        from solid_fenicsx import Elasticity, box_mesh
        print("imported", Elasticity.__module__, "dolfinx" in sys.modules, "Elasticity" in dir(solid_fenicsx))
    """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split("\n")[:3] == ["heavy []", "lazy False", "imported solid_fenicsx.elasticity True True"]
    with pytest.raises(AttributeError, match="has no attribute 'Elastic'"):
        import solid_fenicsx

        solid_fenicsx.Elastic


def test_a_key_no_participant_of_the_role_declares_is_refused(tmp_path):
    with pytest.raises(SceneError) as info:
        scene(tmp_path, '[solvers.fluid]\nparticipant = "replay_fluid"\ntolerence = 1e-6\n')
    assert str(info.value) == (f"{tmp_path / 'scene.toml'}: [solvers.fluid] tolerence: unknown key (participant "
                               f"'replay_fluid'); known keys: participant, ranks, allow_unconverged, pressure, "
                               f"feedback, unconverged")


def test_a_key_of_another_participant_of_the_role_is_ignored_with_a_note(tmp_path):
    """Swapping a participant stays one line: openfoam's tolerance does not stop a replay_fluid scene."""
    plan = make_plan(scene(tmp_path, '[solvers.fluid]\nparticipant = "replay_fluid"\ntolerance = 1e-6\n'))
    assert "tolerance" not in plan.participant("fluid").config
    assert "[solvers.fluid] tolerance: a key of openfoam, ignored by replay_fluid" in plan.notes
    with pytest.raises(SceneError, match=r"\[solvers.fluid\] tolerance: must be positive"):
        scene(tmp_path, "[solvers.fluid]\ntolerance = -1.0\n")  # the chosen participant's key: checked


def test_a_required_key_of_the_participant_is_asked_for(tmp_path):
    with pytest.raises(SceneError, match=r"\[solvers.solid\] stiffness: missing \(spring stiffness\)$"):
        scene(tmp_path, '[solvers.solid]\nparticipant = "spring_solid"\n', effects='["elasticity"]')


def test_an_unknown_participant_names_those_of_the_role(tmp_path):
    with pytest.raises(SceneError, match=r"\[solvers.fluid\] participant: unknown value 'spring_solid'; use one of "
                                         r"'chorin', 'openfoam', 'replay_fluid', 'reynolds'$"):
        scene(tmp_path, '[solvers.fluid]\nparticipant = "spring_solid"\n')


def test_openfoam_runs_one_process_per_processor(tmp_path):
    """openfoam on ranks = 2 is started on 2 MPI ranks, one per processor of the decomposed case
    (it declares no ranks of its own); so is the solid on its ranks."""
    plan = make_plan(scene(tmp_path, "[solvers.fluid]\nranks = 2\n[solvers.solid]\nranks = 3\n"))
    fluid, solid = plan.participant("fluid"), plan.participant("solid")
    assert (fluid.ranks, fluid.config["decomposition"]) == (2, "simple") and "ranks" not in fluid.config
    assert solid.ranks == 3 and "ranks" not in solid.config
    assert any("openfoam on 2 MPI ranks (simple decomposition by decomposePar once; one participant process per "
               "processor" in task for task in plan.tasks)
    with pytest.raises(SceneError, match=r"\[solvers.fluid\] decomposition: applies to ranks > 1 only"):
        make_plan(scene(tmp_path, '[solvers.fluid]\ndecomposition = "simple"\n'))


def test_the_participants_are_configured_with_their_validated_settings(tmp_path):
    """Nothing picked key by key: each configuration holds all of its participant's settings, the
    defaults those of the declaration, and the OpenFOAM case takes them as they come."""
    from fluid_openfoam.case import CaseSpec
    from solid_fenicsx.settings import PARTICIPANT as SOLID_FENICSX

    plan = make_plan(scene(tmp_path, "[solvers.solid]\nrtol = 1e-8\n"))
    fluid, solid = plan.participant("fluid").config, plan.participant("solid").config
    assert {k: fluid[k] for k in OPENFOAM.settings.names} == OPENFOAM.settings.defaults()
    assert {k: solid[k] for k in SOLID_FENICSX.settings.names} == {**SOLID_FENICSX.settings.defaults(), "rtol": 1e-8}
    spec = CaseSpec.from_config(fluid)
    assert {k: getattr(spec, k) for k in OPENFOAM.settings.names if k != "keep_case"} == \
        {k: v for k, v in OPENFOAM.settings.defaults().items() if k != "keep_case"}
    assert spec.penalization_exponent == 2.0  # one default (it was 3.0 in the plates study)


def test_keep_case_puts_the_case_in_the_output_logs(tmp_path):
    config = make_plan(scene(tmp_path, "[solvers.fluid]\nkeep_case = true\n")).participant("fluid").config
    assert config["keep_case"] is True and config["case_dir"].endswith("results/logs/fluid_case")


def test_a_new_participant_is_its_declaration(tmp_path, monkeypatch):
    """A plug-in participant (here declared in the test alone, as its entry point would give it):
    the scene validates its keys, the plan starts its module with its arguments and configures it
    with its settings; nothing of the coupler names it."""
    spec = ParticipantSpec("lbm", "lbm_fluid", "fluid", "a lattice-Boltzmann fluid", Settings(
        Setting("relaxation_time", "number", "BGK relaxation time", positive=True, unit="s"),
        Setting("lattice", "string", "velocity set", default="D3Q19", choices=("D3Q19", "D3Q27"))),
        arguments=("--lattice-boltzmann",), memory=(10 * 2**20, 500))
    monkeypatch.setattr(participants, "_registered", {**participants.registered(), "lbm": spec})
    with pytest.raises(SceneError, match=r"\[solvers.fluid\] lattice: unknown value 'D2Q9'; use one of 'D3Q19', "
                                         r"'D3Q27'$"):
        scene(tmp_path, '[solvers.fluid]\nparticipant = "lbm"\nrelaxation_time = 0.6\nlattice = "D2Q9"\n')
    plan = make_plan(scene(tmp_path, '[solvers.fluid]\nparticipant = "lbm"\nrelaxation_time = 0.6\n'))
    fluid = plan.participant("fluid")
    assert (fluid.kind, fluid.module, fluid.arguments) == ("lbm", "lbm_fluid", ["--lattice-boltzmann"])
    assert (fluid.config["relaxation_time"], fluid.config["lattice"]) == (0.6, "D3Q19")
    assert "python -m lbm_fluid --lattice-boltzmann" in fluid.describe()
    from coupler.run.preflight import COSTS, estimate

    fluid_estimate = [e for e in estimate(load(tmp_path)) if e.name == "fluid"][0]
    assert fluid_estimate.bytes == 10 * 2**20 + 500 * 64  # its declared memory, 4^3 cells
    coupler = {p: [e for e in estimate(load(tmp_path), p) if e.name == "coupler"][0].bytes for p in (1, 3)}
    assert coupler[3] - coupler[1] == 2 * COSTS["coupler_solid"][0]  # the fixed part once per coupler rank
    scene(tmp_path, '[solvers.fluid]\nparticipant = "lbm"\nrelaxation_time = 0.6\nranks = 3\n')
    fluid_estimate = [e for e in estimate(load(tmp_path)) if e.name == "fluid"][0]
    assert fluid_estimate.bytes == 3 * 10 * 2**20 + 500 * 64  # the fixed part once per rank


def test_a_broken_entry_point_is_named(monkeypatch):
    from importlib import metadata

    from coupler.errors import CouplerError

    broken = metadata.EntryPoint("broken", "no_such_package.settings:PARTICIPANT", participants.GROUP)
    wrong = metadata.EntryPoint("wrong", "fluid_openfoam.settings:PARTICIPANT", participants.GROUP)
    for entry, reason in ((broken, "cannot load it: No module named 'no_such_package'"),
                          (wrong, "not the ParticipantSpec of kind 'wrong'")):
        monkeypatch.setattr(participants, "_registered", None)
        monkeypatch.setattr(participants, "entry_points", lambda group, entry=entry: [entry])
        with pytest.raises(CouplerError, match=f"entry point varcouple.participants {entry.name} = "
                                               f"{entry.value}: {reason}"):
            participants.registered()
