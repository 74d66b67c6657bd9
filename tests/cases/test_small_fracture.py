"""cases/small_fracture: flow through a rough fracture between two rock blocks, coupled two
ways (the fluid sees the deformed blocks in every coupling iteration), and the acceleration
on a soft rock."""

from __future__ import annotations

import json
import shutil

import meshio
import numpy as np
import pytest

from coupler.cli import main
from vc_helpers import CASES, copy_case
from coupler.fsi.interface import SolidOnGrid, WettedInterface
from coupler.errors import SceneError
from coupler.scene import load
from transfer import Mesh, StructuredGrid
from transfer.generators.blocks import FACE_TAGS

CASE = CASES / "small_fracture"
needs_foam = pytest.mark.skipif(shutil.which("simpleFoam") is None, reason="OpenFOAM (simpleFoam) not installed")


def fracture_solid():
    m = meshio.read(CASE / "solid.msh")
    S = Mesh(m.points, m.cells_dict["tetra"], "tetra")
    tags = [FACE_TAGS["fracture_lower"], FACE_TAGS["fracture_upper"]]
    tris = np.concatenate([c.data[np.isin(m.cell_data["gmsh:physical"][i], tags)]
                           for i, c in enumerate(m.cells) if c.type == "triangle"])
    return S, tris


# ------------------------------------------------------------------------------ fast
def test_interface_may_be_a_list_of_boundaries(tmp_path):
    scene = load(CASE)
    assert scene.coupling["interface"] == ["fracture_lower", "fracture_upper"]
    assert scene.coupling["deformation"] is True
    bad = copy_case(CASE, tmp_path, {'interface = ["fracture_lower", "fracture_upper"]':
                               'interface = ["fracture_lower", "nope"]'})
    with pytest.raises(SceneError, match=r"\[coupling\] interface: unknown boundary 'nope'"):
        load(bad)
    (bad / "scene.toml").write_text((bad / "scene.toml").read_text().replace(
        'interface = ["fracture_lower", "nope"]', "interface = []"))
    with pytest.raises(SceneError, match="empty list"):
        load(bad)


def test_solid_on_grid_rebuilds_from_the_deformed_solid_only_when_it_moves():
    S, tris = fracture_solid()
    G = StructuredGrid([0.0, 0.0, -0.0006], [0.0025, 0.0025, 0.0002], [20, 10, 11])
    on_grid = SolidOnGrid(S, G, tris, "test")
    f0, z0 = on_grid.fraction.copy(), on_grid.interface.surface.points[:, 2].copy()
    assert isinstance(on_grid.interface, WettedInterface)
    # thin cells across the fracture: the sampling offset follows the cell's extent along the normal
    assert on_grid.interface.offset < 0.25e-3
    assert on_grid.outside > 0.5  # the grid covers the gap region only, not the blocks
    assert not on_grid.update(np.zeros((len(S.points), 3))) and on_grid.builds == 0  # zero: no rebuild
    # open the fracture by 0.1 mm on each side (the blocks moved apart rigidly): the blocks
    # fill less of the grid, by exactly 2 x 0.1 mm x the fracture's projected area
    u = np.zeros((len(S.points), 3))
    lower = np.arange(len(S.points)) < len(S.points) // 2  # the lower block's points come first
    assert S.points[lower, 2].max() < S.points[~lower, 2].min()
    u[lower, 2], u[~lower, 2] = -0.1e-3, 0.1e-3
    assert on_grid.update(u) and on_grid.builds == 1
    assert not on_grid.update(u.copy()) and on_grid.builds == 1  # unchanged: no rebuild
    removed = (f0 - on_grid.fraction) @ G.cell_measures()
    assert removed == pytest.approx(2 * 0.1e-3 * 0.05 * 0.025, rel=0.02)
    # the sampling surface moved with the faces
    np.testing.assert_allclose(np.abs(on_grid.interface.surface.points[:, 2] - z0), 0.1e-3, rtol=1e-9)
    assert on_grid.describe()["seconds_per_rebuild"] > 0


@needs_foam
def test_small_fracture_runs_end_to_end(tmp_path, capsys):
    """The README's demo: two quasi-static steps, IQN-ILS, the fluid sees the deformed blocks."""
    out = tmp_path / "out"
    assert main(["run", str(CASE), "--output", str(out)]) == 0, capsys.readouterr().err
    s = json.loads((out / "summary.json").read_text())
    assert s["status"] == "completed" and s["wall_seconds"] < 60
    assert s["interface"]["method"] == "surface trace"
    assert s["interface"]["sampled_area"] == pytest.approx(2 * 0.05 * 0.025, rel=0.01)  # both faces, rough
    assert len(s["steps"]) == 2
    for step in s["steps"]:
        assert step["converged"] and step["iterations"] == len(step["residuals"]) <= 10
        assert step["residuals"][-1] <= 1e-6
    assert s["steps"][1]["iterations"] <= 2  # quasi-static: the second step starts at the fixed point
    g = s["geometry_update"]
    assert g["deformed"] and g["rebuilds"] >= 2 and g["solid_volume_outside_grid"] > 0.5
    for phase in ("fluid", "solid", "transfer", "geometry update", "messaging"):
        assert s["phases_seconds"][phase] > 0
    solid = meshio.read(out / "solid_0001.vtu")
    x, p, u = solid.points, solid.point_data["pressure"], solid.point_data["displacement"]
    wet = p != 0
    assert wet.sum() == 462
    # the pressure falls from the inlet to the outlet (a few hundred Pa)
    inlet, outlet = wet & (x[:, 0] < 1e-9), wet & (x[:, 0] > 0.05 - 1e-9)
    assert p[inlet].mean() > 300 and abs(p[outlet].mean()) < 0.2 * p[inlet].mean()
    # the pressure opens the fracture: the lower face moves down, the upper one up
    lower_face = wet & (x[:, 2] < 0.5e-3)
    assert u[lower_face, 2].mean() < 0 < u[wet & ~lower_face, 2].mean()
    fluid = meshio.read(out / "fluid_0001.vtu")
    ux = fluid.cell_data["velocity"][0][:, 0]
    frac = fluid.cell_data["solid_fraction"][0]
    assert ux[frac < 0.01].mean() > 0.005 and np.abs(ux[frac > 0.99]).max() < 1e-2 * ux.max()


SOFT = {"E = 2.0e5": "E = 5.0e3", "steps = 2": "steps = 1",
        "lower = [0.0, 0.0, -0.0006]": "lower = [0.0, 0.0, -0.0016]",
        "upper = [0.05, 0.025, 0.0016]": "upper = [0.05, 0.025, 0.0026]",
        "shape = [21, 11, 11]": "shape = [21, 11, 21]", "max_iterations = 30": "max_iterations = 25"}


@needs_foam
@pytest.mark.slow
def test_soft_rock_needs_acceleration(tmp_path, capsys):
    """E = 5 kPa: the fracture opens by about half its aperture and the pressure (about w^-3 at a
    fixed inlet velocity) reacts strongly: the plain iteration (constant relaxation 1.0) takes
    many more coupling iterations than IQN-ILS (measured: 17 against 10)."""
    iterations = {}
    for acc in ("constant", "iqn-ils"):
        case = copy_case(CASE, tmp_path / acc, {**SOFT, 'acceleration = "iqn-ils"':
                                          f'acceleration = "{acc}"\nrelaxation = 1.0'})
        out = tmp_path / acc / "out"
        assert main(["run", str(case), "--output", str(out)]) == 0, capsys.readouterr().err
        s = json.loads((out / "summary.json").read_text())
        assert s["steps"][0]["converged"]
        assert s["steps"][0]["max_displacement"] > 2e-4
        iterations[acc] = s["steps"][0]["iterations"]
    assert iterations["iqn-ils"] <= 12
    assert iterations["constant"] >= iterations["iqn-ils"] + 4, iterations


def test_a_folded_interface_is_named():
    """Two triangles on the same three vertices, opposite orientations: the vertex normals sum to
    zero, and the interface refuses to move its vertices into the fluid (one line, the key)."""
    from coupler.errors import CouplerError

    S = Mesh(np.array([[0.2, 0.2, 0.5], [0.8, 0.2, 0.5], [0.2, 0.8, 0.5], [0.2, 0.2, 0.8]]), np.array([[0, 1, 2, 3]]),
             "tetra")
    G = StructuredGrid((0, 0, 0), (0.1, 0.1, 0.1), (10, 10, 10))
    with pytest.raises(CouplerError, match=r"^\[geometry.fluid\]: the interface has a vertex whose triangle normals "
                                           r"cancel \(a folded surface\)$"):
        WettedInterface(S, [[0, 1, 2], [0, 2, 1]], G)
