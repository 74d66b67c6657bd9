"""The OpenFOAM fluid coupled to the dolfinx solid (paper 2.3, Steps 1-6): the [flow] keys
of a scene, the fluid pressure sampled on the solid's wetted boundary half a fluid cell
into the fluid (Steps 2-3), and cases/plates_fsi end to end (real processes, zenoh)."""

from __future__ import annotations

import json
import shutil
import textwrap

import meshio
import numpy as np
import pytest

from coupler.cli import main
from coupler.plan.plan import make_plan
from coupler.fsi.interface import WettedInterface
from coupler.errors import CouplerError, SceneError
from coupler.scene import load
from transfer import Mesh, StructuredGrid
from transfer.generate import box_tetrahedra
from vc_helpers import CASES

CASE = CASES / "plates_fsi"
needs_foam = pytest.mark.skipif(shutil.which("simpleFoam") is None, reason="OpenFOAM (simpleFoam) not installed")


# ----------------------------------------------------------------------------- scene keys
SCENE = """
[physics]
effects = ["elasticity", "flow"]

[geometry.solid]
lower = [0, 0, 0]
upper = [1, 1, 0.5]
shape = [2, 2, 1]

[geometry.fluid]
lower = [0, 0, 0]
upper = [1, 1, 1]
shape = [4, 4, 4]

[materials.solid]
E = 1e9
nu = 0.25

[materials.fluid]
viscosity = 0.5

[[loads]]
type = "dirichlet"
boundary = "zmin"

[time]
dt = 1.0
steps = 1

[coupling]
interface = "zmax"
"""
FLOW = """
[flow]
inlet_velocity = [0.1, 0, 0]
outlet_pressure = 5.0
walls = "slip"
faces = { zmax = "wall" }

[solvers.fluid]
penalization = "linear"
max_iterations = 300
tolerance = 1e-5
drag = 1e6
"""


def scene_in(tmp_path, text):
    (tmp_path / "scene.toml").write_text(textwrap.dedent(text))
    return tmp_path


def test_flow_keys_reach_the_openfoam_participant(tmp_path):
    config = make_plan(load(scene_in(tmp_path, SCENE + FLOW))).participant("fluid").config
    assert config["inlet"] == {"velocity": [0.1, 0.0, 0.0]} and config["outlet"] == {"pressure": 5.0}
    assert config["walls"] == "slip" and config["boundaries"] == {"zmax": "wall"}
    assert (config["penalization"], config["max_iterations"], config["tolerance"], config["drag"]) == \
        ("linear", 300, 1e-5, 1e6)
    assert (config["rho"], config["mu"]) == (1000.0, 0.5)
    # the participant's own parser accepts what the scene gives
    from fluid_openfoam.case import CaseSpec

    spec = CaseSpec.from_config(config)
    assert spec.faces["xmin"]["kind"] == "velocity" and spec.faces["ymin"]["kind"] == "slip"
    assert spec.faces["zmax"]["kind"] == "wall" and spec.faces["xmax"]["value"] == 5.0
    assert spec.nu == 0.5 / 1000.0 and spec.drag_value() == 1e6 and spec.penalization == "linear"


def test_pressure_inlet_and_defaults(tmp_path):
    config = make_plan(load(scene_in(tmp_path, SCENE + '\n[flow]\ninlet_pressure = 100.0\n'))).participant("fluid").config
    assert config["inlet"] == {"pressure": 100.0} and config["outlet"] == {"pressure": 0.0}
    assert config["walls"] == "wall" and config["boundaries"] == {}
    assert (config["penalization"], config["max_iterations"], config["tolerance"], config["drag"]) == \
        ("wall", 2000, 1e-7, None)


BAD_FLOW = [
    ("", "[flow] inlet_velocity", "missing"),
    ("\n[flow]\noutlet_pressure = 1.0\n", "[flow] inlet_velocity", "exactly one"),
    ("\n[flow]\ninlet_velocity = [1, 0, 0]\ninlet_pressure = 1.0\n", "[flow] inlet_velocity", "exactly one"),
    ("\n[flow]\ninlet_velocity = [1, 0]\n", "[flow] inlet_velocity", "list of 3 finite numbers"),
    ("\n[flow]\ninlet_pressure = 1.0\nwalls = \"sticky\"\n", "[flow] walls", "unknown value 'sticky'"),
    ("\n[flow]\ninlet_pressure = 1.0\nfaces = { xmin = \"wall\" }\n", "[flow.faces] xmin", "xmin is the inlet"),
    ("\n[flow]\ninlet_pressure = 1.0\nfaces = { top = \"wall\" }\n", "[flow.faces] top", "unknown face"),
    ("\n[flow]\ninlet_pressure = 1.0\nfaces = { ymin = \"porous\" }\n", "[flow.faces] ymin", "unknown condition"),
    ("\n[flow]\ninlet_pressure = 1.0\nfaces = { zmin = \"empty\" }\n", "[flow] faces", "needs both zmin and zmax"),
    ("\n[flow]\ninlet_pressure = 1.0\nfaces = { zmin = \"empty\", zmax = \"empty\" }\n", "[flow] faces",
     "one cell along z"),
    ("\n[flow]\ninlet_pressure = 1.0\nspeed = 3\n", "[flow] speed", "unknown key"),
    ("\n[flow]\ninlet_pressure = 1.0\n[solvers.fluid]\npenalization = \"soft\"\n", "[solvers.fluid] penalization",
     "unknown value 'soft'"),
    ("\n[flow]\ninlet_pressure = 1.0\n[solvers.fluid]\nmax_iterations = 0\n", "[solvers.fluid] max_iterations",
     "integer >= 1"),
    ("\n[flow]\ninlet_pressure = 1.0\n[solvers.fluid]\ntolerance = -1.0\n", "[solvers.fluid] tolerance",
     "must be positive"),
    ("\n[flow]\ninlet_pressure = 1.0\n[solvers.fluid]\nranks = 2\ndecomposition = \"scotch\"\n",
     "[solvers.fluid] decomposition", "unknown value 'scotch'"),
    ("\n[flow]\ninlet_pressure = 1.0\n[solvers.fluid]\ndecomposition = \"simple\"\n",
     "[solvers.fluid] decomposition", "ranks > 1"),
    ("\n[flow]\ninlet_pressure = 1.0\n[solvers.fluid]\npenalization_exponent = 3.0\n",
     "[solvers.fluid] penalization_exponent", '"power" only'),
]


@pytest.mark.parametrize("extra, where, reason", BAD_FLOW)
def test_bad_flow_keys_name_file_table_and_key(tmp_path, extra, where, reason):
    case = scene_in(tmp_path, SCENE + extra)
    with pytest.raises(SceneError) as info:
        load(case)
    message = str(info.value)
    assert str(case / "scene.toml") in message and where in message and reason in message, message


def test_flow_table_needs_the_flow_effect(tmp_path):
    text = SCENE.replace('effects = ["elasticity", "flow"]', 'effects = ["elasticity"]') + \
        "\n[flow]\ninlet_pressure = 1.0\n"
    with pytest.raises(SceneError, match=r"\[flow\]: needs the effect 'flow'"):
        load(scene_in(tmp_path, text))


def test_stand_in_fluid_needs_no_flow_table(tmp_path):
    text = SCENE + '\n[solvers.fluid]\nparticipant = "replay_fluid"\n'
    assert make_plan(load(scene_in(tmp_path, text))).participant("fluid").config.get("inlet") is None


# ---------------------------------------------------------------- Steps 2-3 on the interface
def top_triangles(mesh, z):
    """Boundary triangles of a tet mesh on the plane z, oriented with the normal +z."""
    faces = np.sort(np.concatenate([mesh.cells[:, [0, 1, 2]], mesh.cells[:, [0, 1, 3]], mesh.cells[:, [0, 2, 3]],
                                    mesh.cells[:, [1, 2, 3]]]), axis=1)
    faces = faces[np.all(np.isclose(mesh.points[faces, 2], z), axis=1)]
    faces = np.unique(faces, axis=0)
    p = mesh.points
    n = np.cross(p[faces[:, 1]] - p[faces[:, 0]], p[faces[:, 2]] - p[faces[:, 0]])
    flip = n[:, 2] < 0
    faces[flip] = faces[flip][:, [0, 2, 1]]
    return faces


def test_pressure_is_sampled_on_the_fluid_side_of_the_wetted_boundary():
    """The block's top (z = 0.37) lies in a grid cell whose centre (0.35) is in the solid:
    the trace on the top face itself would read that penalized cell; the interface moved up
    by half a cell diagonal reads the fluid cell above."""
    grid = StructuredGrid.from_bounds((0, 0, 0), (1, 1, 1), (10, 10, 10))
    m = box_tetrahedra((4, 4, 2), (0.1, 0.1, 0.0), (0.9, 0.9, 0.37))
    solid = Mesh(m.points, m.cells, "tetra")
    k, j, i = np.meshgrid(*(np.arange(n) for n in grid.shape[::-1]), indexing="ij")  # x fastest
    centres = np.asarray(grid.origin) + (np.column_stack([i.ravel(), j.ravel(), k.ravel()]) + 0.5) * grid.spacing
    pressure = np.where(centres[:, 2] < 0.37, 1.0, 2.0) + 0.1 * centres[:, 0]
    tris = top_triangles(solid, 0.37)
    interface = WettedInterface(solid, tris, grid)
    assert interface.offset == pytest.approx(0.5 * np.sqrt(3) * 0.1)
    np.testing.assert_allclose(interface.normals, [[0, 0, 1]] * interface.size, atol=1e-12)
    np.testing.assert_allclose(interface.surface.points[:, 2], 0.37 + interface.offset)
    sampled = interface.from_fluid(pressure)
    assert sampled.min() > 1.9  # the fluid cells above, never the solid-centred ones
    # the exact integral of the Q0 field (2 + 0.1 x per column, cells of 0.1) over the top face
    area = 0.8 * 0.8
    integral = interface.transfer.integral_target(sampled)
    assert integral == pytest.approx(interface.transfer.integral_source(pressure), rel=1e-12)
    assert integral / area == pytest.approx(2.05, abs=0.01)
    full = interface.to_solid_vertices(sampled)
    assert full.shape == (len(solid.points),) and np.all(full[np.setdiff1d(np.arange(len(full)),
                                                                          interface.vertices)] == 0)
    np.testing.assert_allclose(interface.weights.sum(), area, rtol=1e-12)


def test_an_interface_sampled_outside_the_grid_is_a_clear_error():
    grid = StructuredGrid.from_bounds((0, 0, 0), (1, 1, 0.4), (10, 10, 4))
    m = box_tetrahedra((2, 2, 1), (0.1, 0.1, 0.0), (0.9, 0.9, 0.37))
    solid = Mesh(m.points, m.cells, "tetra")
    with pytest.raises(CouplerError, match="does not cover the interface sampled"):
        WettedInterface(solid, top_triangles(solid, 0.37), grid)


# ------------------------------------------------------------------------ end to end
@needs_foam
def test_plates_fsi_runs_end_to_end(tmp_path, capsys):
    """cases/plates_fsi with real processes: OpenFOAM's pressure on the block's top face,
    sampled in the fluid, compresses the block by about p H / E (uniaxial stress: rollers
    below and on two sides)."""
    out = tmp_path / "out"
    assert main(["run", str(CASE), "--output", str(out)]) == 0, capsys.readouterr().err
    s = json.loads((out / "summary.json").read_text())
    assert s["status"] == "completed"
    assert s["participants_announced"]["fluid"]["kind"] == "openfoam_fluid"
    assert s["participants_announced"]["solid"]["kind"] == "solid_fenicsx"
    assert s["interface"]["method"] == "surface trace" and s["interface"]["vertices"] == 33
    assert s["interface"]["sampled_area"] == pytest.approx(0.1 * 0.02, rel=1e-12)
    assert len(s["steps"]) == 3
    for step in s["steps"]:
        assert step["converged"] and step["iterations"] == len(step["residuals"]) >= 1
        assert step["residuals"][-1] <= 1e-6
    for phase in ("fluid", "solid", "transfer", "messaging"):
        assert s["phases_seconds"][phase] > 0

    last = meshio.read(out / "solid_0002.vtu")
    x, p, u = last.points, last.point_data["pressure"], last.point_data["displacement"]
    H, L, E = 0.0185, 0.1, 1e8
    top = np.isclose(x[:, 2], H)
    assert top.sum() == 33 and np.all(p[~top] == 0)
    # Poiseuille-type channel flow: the pressure falls linearly from inlet to outlet
    np.testing.assert_allclose(p[top], 1.1e4 - 1e3 * x[top, 0] / L, rtol=2e-3)
    # compressed, not pulled: u_z < 0 on top, about -p H / E
    assert np.all(u[top, 2] < 0)
    estimate = -p[top].mean() * H / E
    assert u[top, 2].mean() / estimate == pytest.approx(1.0, abs=0.05)
    assert u[top, 2][np.argmin(x[top, 0])] < u[top, 2][np.argmax(x[top, 0])]  # more at the inlet
    # the channel carries a laminar flow of the scene's viscosity (1 Pa s):
    # u_max = a^2 dp / (8 mu L) = 0.165 m/s for a = 0.0115 m
    fluid = meshio.read(out / "fluid_0002.vtu")
    ux = fluid.cell_data["velocity"][0][:, 0]
    assert 0.1 < ux.max() < 0.25
    frac = fluid.cell_data["solid_fraction"][0]
    assert np.abs(ux[frac > 0.99]).max() < 1e-3 * ux.max()
