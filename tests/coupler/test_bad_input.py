"""Bad input is exit 2 and one line naming the scene file and key, wherever it is found: a
scene's paths stay in its case directory (inputs read there, outputs written there unless
``--output`` says otherwise, links followed), a scene file that is not text, expressions too
large or with constants beyond floats, and the input errors a participant finds at set-up (a
tag its mesh lacks, a generator that cannot mesh its parameters). No message quotes a file's
content."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from cli_helpers import assert_clean_error, run_cli, transfer_case, write_mesh
from coupler.errors import SceneError
from coupler.protocol.errors import (InputError, ParticipantDied, ParticipantError, ParticipantInputError,
                                     ParticipantStopped, ParticipantTimeout)
from coupler.protocol.roles import ContractError
from coupler.protocol.expressions import MAX_NODES, check_expression, evaluate_expression
from coupler.run.local import LocalClient
from transfer.generate import box_hexahedra
from transfer.generators.height_maps import read_npz, write_xyz
from vc_helpers import CASES, copy_case

BLOCK = CASES / "block_compression"
#: a first line a file outside any case could hold: never in a message
SECRET = "root:x:0:0:secret-content:/root:/bin/bash"


def commands(case, out):
    """Every command that reads a scene, as argv."""
    return [["check", "--quick", case], ["check", case], ["run", case, "--output", out],
            ["study", case, "--vary", "output.every=[1]", "--output", out]]


# -- outputs stay in the case ----------------------------------------------------------
@pytest.mark.parametrize("directory", ["/etc", "../../escaped", "../escaped", "link"])
def test_the_output_directory_of_a_scene_stays_in_its_case(tmp_path, capsys, directory):
    """Before: "/etc" accepted and "../../x" written outside the case."""
    case = tmp_path / "deep" / "case"
    case.mkdir(parents=True)
    transfer_case(case)
    (tmp_path / "elsewhere").mkdir()
    (case / "link").symlink_to(tmp_path / "elsewhere")  # a link inside the case to a directory outside
    with open(case / "scene.toml", "a") as scene:
        scene.write(f'[output]\ndirectory = "{directory}"\n')
    for command in (["check", "--quick", case], ["run", case]):
        code, _, err = run_cli(capsys, *command)
        assert_clean_error(code, err, str(case / "scene.toml"), "[output] directory", repr(directory),
                           "outside the case directory", "--output DIR")
    assert not (tmp_path / "escaped").exists() and not (tmp_path / "deep" / "escaped").exists()
    assert not any((tmp_path / "elsewhere").iterdir())
    code, _, err = run_cli(capsys, "run", case, "--output", tmp_path / "chosen")  # --output: anywhere
    assert code == 0, err
    assert (tmp_path / "chosen" / "summary.json").is_file()


def test_an_output_directory_inside_the_case_is_written(tmp_path, capsys):
    transfer_case(tmp_path)
    with open(tmp_path / "scene.toml", "a") as scene:
        scene.write('[output]\ndirectory = "runs/../runs/first"\n')
    code, _, err = run_cli(capsys, "run", tmp_path)
    assert code == 0, err
    assert (tmp_path / "runs" / "first" / "summary.json").is_file()


# -- inputs are read in the case -------------------------------------------------------
@pytest.mark.parametrize("name", ["/etc/passwd", "../outside.vtu", "../missing.vtu", "link.vtu", "/"])
def test_an_input_file_outside_the_case_is_refused_unread(tmp_path, capsys, name):
    """Before: any file was read (and a missing one said so: outside files could be probed)."""
    case = tmp_path / "case"
    case.mkdir()
    transfer_case(case)
    (case / "src.vtu").rename(tmp_path / "outside.vtu")
    (case / "link.vtu").symlink_to(tmp_path / "outside.vtu")
    text = (case / "scene.toml").read_text().replace('source = "src.vtu"', f'source = "{name}"')
    (case / "scene.toml").write_text(text)
    for argv in commands(case, tmp_path / "out"):
        code, _, err = run_cli(capsys, *argv)
        assert_clean_error(code, err, str(case / "scene.toml"), "[transfer] source", repr(name),
                           f"outside the case directory {case}", "copy the file into it")
        assert "not found" not in err
    assert not (tmp_path / "out").exists()


def test_the_hdf5_file_of_an_xdmf_mesh_is_read_in_the_case(tmp_path, capsys):
    """dolfinx reads solid.h5 beside solid.xdmf: a link from there out of the case is refused."""
    case = copy_case(BLOCK, tmp_path, {"lower = [0.0, 0.0, 0.0]\nupper = [1.0, 1.0, 1.0]\nshape = [4, 4, 4]\n"
                                       "jitter = 0.2": 'mesh = "solid.xdmf"'})
    (case / "solid.xdmf").write_text("<Xdmf><Domain/></Xdmf>")
    (tmp_path / "outside.h5").write_bytes(b"\x89HDF\r\n\x1a\n")
    (case / "solid.h5").symlink_to(tmp_path / "outside.h5")
    code, _, err = run_cli(capsys, "check", "--quick", case)
    assert_clean_error(code, err, "[geometry.solid] mesh", "'solid.h5' is outside the case directory")


@pytest.mark.parametrize("key", ["lower", "upper"])
def test_a_generator_reads_its_files_in_the_case(tmp_path, capsys, key):
    case = xyz_case(tmp_path)
    (tmp_path / "face.xyz").write_text((case / "faces" / f"{key}.xyz").read_text())
    text = (case / "scene.toml").read_text().replace(f'{key} = "faces/{key}.xyz"', f'{key} = "../face.xyz"')
    (case / "scene.toml").write_text(text)
    code, _, err = run_cli(capsys, "check", "--quick", case)
    assert_clean_error(code, err, f"[geometry.solid.parameters] {key}", "'../face.xyz'", "outside the case")


def xyz_case(tmp_path):
    """cases/measured_fracture with its map as the XYZ files faces/lower.xyz and faces/upper.xyz."""
    case = copy_case(CASES / "measured_fracture", tmp_path,
                     {'surfaces = "surfaces.npz"': 'lower = "faces/lower.xyz"\nupper = "faces/upper.xyz"'})
    (lower, upper), spacing = read_npz(case / "surfaces.npz")
    (case / "faces").mkdir()
    write_xyz(case / "faces" / "lower.xyz", lower, spacing)
    write_xyz(case / "faces" / "upper.xyz", upper, spacing)
    return case


@pytest.mark.parametrize("content, words", [
    (f"{SECRET}\n", ["lower.xyz is not a text file of x y z lines (line 1 is not numbers)"]),
    (f"0 0 0\n1 0 0\n{SECRET} 1 2\n", ["(line 3 is not numbers)"]),
    ("0 0 0\n1 0 0\n0 1\n", ["(line 3 has 2 numbers, the lines before it 3)"]),
    (b"0 0 0\n\xff\xfe" + SECRET.encode(), ["is not a text file of x y z lines (byte 6 is not UTF-8)"]),
])
def test_an_xyz_read_error_quotes_no_content(tmp_path, capsys, content, words):
    """Before: numpy's message quoted the offending line ('could not convert string 'root:x:...'')."""
    case = xyz_case(tmp_path)
    lower = case / "faces" / "lower.xyz"
    lower.write_bytes(content if isinstance(content, bytes) else content.encode())
    code, _, err = run_cli(capsys, "check", "--quick", case)
    assert_clean_error(code, err, "[geometry.solid.parameters] lower", *words)
    assert "secret-content" not in err and "bin/bash" not in err


@pytest.mark.parametrize("name", ["src.stl", "src.vtk", "src.off", "src.msh"])
def test_a_mesh_read_error_quotes_no_content(tmp_path, capsys, name):
    """Before: meshio's STL reader said 'could not convert string to float: '<the line>''."""
    transfer_case(tmp_path)
    (tmp_path / name).write_text(f"{SECRET}\n{SECRET}\n")
    (tmp_path / "scene.toml").write_text((tmp_path / "scene.toml").read_text().replace("src.vtu", name))
    code, _, err = run_cli(capsys, "check", "--quick", tmp_path)
    assert_clean_error(code, err, "[transfer] source", f"{name}: cannot read the mesh with meshio")
    assert "secret-content" not in err and "bin/bash" not in err


def test_an_npz_read_error_quotes_no_content(tmp_path):
    """numpy's .npy header error quotes the header (before: in the message)."""
    from transfer.generators.height_maps import read_npz

    path = tmp_path / "faces.npz"
    path.write_bytes(b"\x93NUMPY\x01\x00\x20\x00{'secret-content': (1 2 3)}     \n")
    with pytest.raises(ValueError) as info:
        read_npz(path)
    assert "is not a readable .npz file" in str(info.value) and "secret-content" not in str(info.value)


# -- scene files that are not text ---------------------------------------------------------
@pytest.mark.parametrize("content", [b'[physics]\neffects = ["tr\xc3\x28nsfer"]\n', bytes(range(256)) * 4,
                                     b"\x89PNG\r\n\x1a\n" + b"\x00" * 64])
def test_a_scene_file_that_is_not_utf8_text_is_one_line(tmp_path, capsys, content):
    """Before: a UnicodeDecodeError traceback and exit 1 from run, check and study."""
    transfer_case(tmp_path)
    (tmp_path / "scene.toml").write_bytes(content)
    for argv in commands(tmp_path, tmp_path / "out"):
        code, _, err = run_cli(capsys, *argv)
        assert_clean_error(code, err, str(tmp_path / "scene.toml"))
        assert "not a TOML text file: byte" in err or "invalid TOML" in err, err


# -- expressions: bounded in size and in the numbers they make -----------------------------
@pytest.mark.parametrize("expression, words", [
    (" + ".join(["x"] * 3000), ["characters", "at most 2000"]),
    ("-" * 1500 + "x", ["expression of 3003 terms and operators", f"at most {MAX_NODES}"]),
    (" + ".join(["x * y"] * 130), ["terms and operators", f"at most {MAX_NODES}"]),
    ("(" * 60 + "x" + " + 1)" * 60 + " > 0", ["nested 64 deep", "at most 50"]),
    ("sin(" * 60 + "x" + ")" * 60 + " > 0", ["nested 64 deep", "at most 50"]),
    ("(" * 250 + "x" + ")" * 250, ["too many nested parentheses"]),
    ("x < 10**10**10", ["'10**10**10' is not a finite number"]),
    ("x < 1e308 * 10", ["'1e308 * 10' is not a finite number"]),
    ("clip(x, a_min=0, a_max=9**9**9) > 0", ["'9**9**9' is not a finite number"]),
    ("x > 1 / (2 - 2)", ["divides by zero"]),
    ("(x > 0) & 1", ["& | ^ ~ combine conditions"]),
    ("(x > 0) and (y > 0)", ["BoolOp is not allowed", "not and, or, not"]),
    ("[x][0] > 0", ["is not allowed"]),
    ("x < 1 << 1000", ["LShift is not allowed"]),
    ("x < 'a'", ["'a' is not a number"]),
    ("x(1) > 0", ["only the functions", "may be called"]),  # a variable called (before: a TypeError in the solid)
    ("pi(2) > 0", ["only the functions", "may be called"]),
])
def test_a_boundary_expression_too_large_or_beyond_floats_is_refused(tmp_path, capsys, expression, words):
    """Before: 3000 terms a RecursionError traceback (exit 1); 10**10**10 accepted, and the solid
    hung computing it until the messaging timeout."""
    case = copy_case(BLOCK, tmp_path, {"jitter = 0.2": f'jitter = 0.2\nboundaries = {{ lid = "{expression}" }}'})
    code, _, err = run_cli(capsys, "check", "--quick", case)
    assert_clean_error(code, err, str(case / "scene.toml"), "[geometry.solid.boundaries] lid", *words)
    assert len(err) < 600  # a long expression is cut in the message


def test_a_bounded_expression_is_evaluated_in_floats():
    """Integers are floats: x ** 10**100 is numpy's power (0, 1, inf), not an OverflowError."""
    text = "x ** 10**100 + 0 * (10**300 // 7)"
    check_expression(text, "here")
    values = evaluate_expression(text, np.array([[0.5, 0, 0], [1.0, 0, 0], [2.0, 0, 0]]))
    np.testing.assert_array_equal(values, [0.0, 1.0, np.inf])
    exact = "1 - z + 0.2 * sin(4 * x) * cos(3 * y) + exp(-((x - 0.35)**2 + (y - 0.6)**2 + (z - 0.25)**2) / 0.05)"
    check_expression(exact, "here")  # the shipped expressions stay accepted
    check_expression("(z > 1e-12) & (z < 0.3) & (abs(sqrt(x**2 + y**2 + (z - 1)**2) - 1) < 0.05)", "here")
    check_expression("~(x < 1e-9) | where(y > 0, 1, 0) > clip(z, 0, 1) ^ (y > -1)", "here")


# -- input errors a participant finds: exit 2, run and check alike ---------------------------
ROUGH = ("shape = [4, 4, 2], size = [0.05, 0.025], height = {height}, aperture = 0.001, min_aperture = 0.0005, "
         "rms = 0.00015, hurst = 0.8, mismatch_length = 0.0125, seed = 4")
GENERATED = """[physics]
effects = ["elasticity"]

[geometry.solid]
generator = "rough_fracture"
parameters = {{ {parameters} }}
boundaries = {{ {boundaries} }}

[materials.solid]
E = 1.0e10
nu = 0.25

[[loads]]
type = "dirichlet"
boundary = "bottom"

[[loads]]
type = "pressure"
boundary = "{load}"
value = 1.0e6

[solvers.solid]
participant = "solid_fenicsx"

[output]
pictures = false
"""


@pytest.mark.parametrize("height, rms, boundaries, load, words", [
    (0.005, 0.00015, "lid = 9", "lid", ["boundary 'lid': no facet tag 9"]),
    (0.0001, 0.0015, "", "top", ["generator 'rough_fracture'", "the lower surface reaches below the bottom",
                                 "increase height"]),
], ids=["unknown_tag", "generator_cannot_mesh"])
def test_input_errors_the_solid_finds_are_exit_2(tmp_path, capsys, height, rms, boundaries, load, words):
    """Before: `check` exit 2 but `run` exit 4, status failed."""
    parameters = ROUGH.format(height=height).replace("rms = 0.00015", f"rms = {rms}")
    tmp_path.joinpath("scene.toml").write_text(GENERATED.format(parameters=parameters, boundaries=boundaries,
                                                                load=load))
    out = tmp_path / "out"
    for argv in (["check", tmp_path], ["run", tmp_path, "--output", out]):
        code, _, err = run_cli(capsys, *argv)
        assert code == 2, err
        line = [line for line in err.splitlines() if line.startswith("varcouple: error: ")]
        assert len(line) == 1 and "Traceback" not in err, err
        assert line[0].startswith(f"varcouple: error: {tmp_path / 'scene.toml'}: participant 'solid' refused its "
                                  f"input: SolidMeshError: "), line
        for word in words:
            assert word in line[0], (word, line[0])
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "invalid" and words[0] in summary["error"]


class _Refusing:
    """A participant object whose configure refuses its input."""

    def configure(self, config):
        raise InputError("[geometry.solid] mesh: no tetrahedra")


def test_an_in_process_participant_refusing_its_input_is_bad_input():
    with pytest.raises(ParticipantInputError) as info:
        LocalClient("solid", _Refusing()).configure({})
    assert isinstance(info.value, SceneError)  # status invalid, exit 2
    assert str(info.value) == "participant 'solid' refused its input: InputError: [geometry.solid] mesh: no tetrahedra"


@pytest.mark.parametrize("config, words", [
    (lambda d: {"mesh": str(write_mesh(d / "hex.vtu", box_hexahedra((2, 2, 2))))},
     "rigid_solid needs a tetrahedral mesh, got hexahedron cells from "),
    (lambda d: {"generator": {"name": "rough_fracture", "parameters": dict(
        shape=[4, 4, 2], size=[0.05, 0.025], height=0.0001, aperture=0.001, min_aperture=0.0005, rms=0.0015,
        hurst=0.8, mismatch_length=0.0125, seed=4)}},
     "rigid_solid: generator 'rough_fracture': the lower surface reaches below the bottom"),
    (lambda d: {"mesh": str(d / "none.vtu")}, "rigid_solid: {d}/none.vtu: file not found"),
], ids=["hexahedra", "generator_cannot_mesh", "no_file"])
def test_a_fixed_solid_that_cannot_be_made_is_bad_input(tmp_path, config, words):
    """The fixed solid (served in the coupler's process): before, a ParticipantError (exit 4)."""
    from coupler.standins import RigidSolid

    with pytest.raises(ParticipantInputError, match="^participant 'solid' refused its input: InputError: "
                                                    + re.escape(words.format(d=tmp_path))):
        LocalClient("solid", RigidSolid()).configure(config(tmp_path))


@pytest.mark.parametrize("error", [
    lambda: ParticipantInputError("solid", "SolidMeshError: x"),
    lambda: ParticipantError("fluid", "FloatingPointError: overflow"),
    lambda: ParticipantDied("solid", "process exited with code 1"),
    lambda: ParticipantStopped("fluid", "pid 7 stopped by SIGSTOP"),
    lambda: ParticipantTimeout("solid", "advance", 300.0, progressed=True),
    lambda: ContractError("fluid", "fluid", "advance output 'velocity': missing"),
], ids=["input", "error", "died", "stopped", "timeout", "contract"])
def test_a_participant_failure_travels_between_coupler_ranks_as_raised(error):
    """Each participant failure (pickled by the coupler ranks' vote): its type, its text with
    where it happened (``at``) and its notes kept (before: only the input error unpickled; the
    others became a plain CouplerError on the other ranks, and the ``at`` prefix was lost)."""
    import pickle

    raised = error().at("time step 3, iteration 2")
    raised.add_note("seen on coupler rank 1")
    again = pickle.loads(pickle.dumps(raised))
    assert type(again) is type(raised) and str(again) == str(raised) and str(again).startswith("time step 3")
    assert again.name == raised.name and again.__notes__ == ["seen on coupler rank 1"]
    assert isinstance(again, SceneError) == isinstance(raised, SceneError)


def test_a_refusal_is_named_by_the_scene_file_and_keeps_its_notes(tmp_path):
    """runner.scene_input prefixes the scene file and keeps the refusal as it was (before: a plain
    SceneError of its text, the notes, such as which scene key feeds the refused input, lost)."""
    from types import SimpleNamespace

    from coupler.run.runner import scene_input

    refused = ParticipantInputError("fluid", "InputError: [flow] inlet: selects no face")
    refused.add_note("its inlet pressure comes from [flow] flow_rate")
    with pytest.raises(ParticipantInputError) as info, scene_input(SimpleNamespace(path=tmp_path / "scene.toml")):
        raise refused
    assert str(info.value).startswith(f"{tmp_path / 'scene.toml'}: participant 'fluid' refused its input")
    assert info.value.__notes__ == ["its inlet pressure comes from [flow] flow_rate"]
    assert isinstance(info.value, SceneError)
