"""[check] kind = "cubic_law" (coupler/checks/cubic_law.py): the flow rate per unit width through
every cross-section of the grid against Q = w^3 dp / (12 mu L), its parameters from the scene."""

from __future__ import annotations

import numpy as np
import pytest

from coupler import checks
from coupler.checks.cubic_law import flow_rates
from coupler.errors import SceneError
from coupler.scene import load
from transfer import StructuredGrid
from vc_helpers import CASES, copy_case

CASE = CASES / "parallel_plates"


def cell_index(G: StructuredGrid) -> np.ndarray:
    """(i, j, k) of every cell, x fastest."""
    ijk = np.stack(np.meshgrid(*[np.arange(n) for n in G.shape], indexing="ij"), axis=-1)
    return ijk.transpose(2, 1, 0, 3).reshape(-1, 3)


def plug_flow(G: StructuredGrid, across: int, rows, speed: float) -> np.ndarray:
    """x velocity `speed` in the cells whose index along `across` is in `rows`, zero elsewhere."""
    u = np.zeros((G.num_cells, 3))
    u[np.isin(cell_index(G)[:, across], rows), 0] = speed
    return u


@pytest.mark.parametrize("across", [1, 2])
def test_flow_rate_per_unit_width_through_each_section(across):
    """A plug of speed U over 3 cells of height h across the gap carries 3 h U per unit width,
    whatever the width's resolution; a faster layer along the width counts by its share."""
    G = StructuredGrid([0, 0, 0], [0.5, 0.1, 0.2], [4, 6, 5])
    u = plug_flow(G, across, [1, 2, 3], 2.0)
    q = 3 * G.spacing[across] * 2.0
    np.testing.assert_allclose(flow_rates(G, u, across), q, rtol=1e-14)
    width = 3 - across  # the other axis: z across y, y across z
    u[cell_index(G)[:, width] == 2, 0] *= 2
    np.testing.assert_allclose(flow_rates(G, u, across), q * (1 + 1 / G.shape[width]), rtol=1e-14)


def test_the_scene_gives_the_parameters_and_the_result_the_flow_rate():
    scene = load(CASE)
    assert scene.check == {"kind": "cubic_law", "aperture": 1e-3, "across": "y", "tolerance": 0.05,
                           "pressure_drop": 1e-2, "viscosity": 1e-3, "length": 2e-3}
    G = StructuredGrid(scene.fluid.origin, scene.fluid.spacing, scene.fluid.shape)
    q_cubic = 1e-9 * 1e-2 / (12 * 1e-3 * 2e-3)
    h = scene.fluid.spacing[1]
    for speed, passed in ((q_cubic / (8 * h) * 1.04, True), (q_cubic / (8 * h) * 0.9, False)):
        u = plug_flow(G, 1, range(2, 10), speed)  # 8 cells of the gap
        report = checks.evaluate(scene, checks.Result({"fluid": G}, {"fluid": {"velocity": u}}))
        assert report["Q_cubic"] == pytest.approx(q_cubic, rel=1e-15)
        assert report["relative_difference"] == pytest.approx(speed * 8 * h / q_cubic - 1, rel=1e-12)
        assert report["error"] == abs(report["relative_difference"]) and report["passed"] is passed
        assert report["Q_spread"] < 1e-15
    assert "against the cubic law's 4.1667e-07: -10.000% (tolerance 0.05): FAIL" in checks.describe(report)


@pytest.mark.parametrize("old, new, message", [
    ("inlet_pressure = 1.0e-2 ", "inlet_velocity = [1.0e-3, 0, 0] ",
     "[check] kind: 'cubic_law' needs the pressure drop: give [flow] inlet_pressure"),
    ("outlet_pressure = 0.0", "outlet_pressure = 0.02", "[check] kind: 'cubic_law' needs a pressure drop: [flow] "
                                                        "inlet_pressure - outlet_pressure is -0.01 Pa"),
    ("tolerance = 0.05", "tolerance = 0.05\nacross = \"x\"", "[check] across: unknown value 'x'"),
    ("tolerance = 0.05", "tolerance = 0.05\naperture = -1.0", "[check] aperture: must be positive"),
    ("tolerance = 0.05", "tolerance = 0.05\nlength = 1.0", "[check] length: unknown key"),
])
def test_bad_cubic_law_checks_name_the_key(tmp_path, old, new, message):
    with pytest.raises(SceneError) as info:
        load(copy_case(CASE, tmp_path, {old: new}))
    assert "scene.toml: " + message in str(info.value)


BOX = """
[physics]
effects = ["flow"]
[geometry.solid]
lower = [0, 0, 0]
upper = [2e-3, 2.5e-4, 1.25e-4]
shape = [3, 2, 1]
[geometry.fluid]
origin = [0, 0, 0]
spacing = [5e-4, 1.25e-4, 1.25e-4]
shape = [4, 13, 1]
[flow]
inlet_pressure = 1e-2
faces = { zmin = "empty", zmax = "empty" }
[time]
dt = 1.0
steps = 1
[check]
kind = "cubic_law"
tolerance = 0.05
"""


def test_without_a_generator_the_aperture_is_a_key(tmp_path):
    """A box solid (the lower plate alone) gives no aperture: [check] names it."""
    (tmp_path / "scene.toml").write_text(BOX)
    with pytest.raises(SceneError, match=r"scene.toml: \[check\] aperture: missing: the gap w \[m\] \(no generator"):
        load(tmp_path)
    (tmp_path / "scene.toml").write_text(BOX + "aperture = 1e-3\n")
    assert load(tmp_path).check["aperture"] == 1e-3
