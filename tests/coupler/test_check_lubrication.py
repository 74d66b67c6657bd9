"""[check] kind = "lubrication" (coupler/checks/lubrication.py): the hydraulic aperture of a run
through a sinusoidal aperture against its lubrication limits, series (along the flow) and
parallel (across), its parameters from the wavy_plates generator or its own keys."""

from __future__ import annotations

import numpy as np
import pytest

from coupler import checks
from coupler.checks.lubrication import parallel_limit, series_limit
from coupler.errors import SceneError
from coupler.scene import load
from transfer import StructuredGrid
from transfer.generators import GENERATORS, parameters
from vc_helpers import CASES, copy_case

CASE = CASES / "lubrication"
#: the scene with the aperture varying across the flow
ACROSS = {'direction = "along" ': 'direction = "across" ',
          'faces = { ymin = "empty", ymax = "empty" }': 'faces = { ymin = "symmetry", ymax = "symmetry" }'}


@pytest.mark.parametrize("a", [0.0, 0.1, 0.3, 0.6])
def test_the_limits_are_the_means_of_the_generator_s_aperture_over_a_period(a):
    """1 / mean(1/e^3) and mean(e^3) by the trapezoidal rule over one period (exponentially exact
    for a periodic smooth function) against the closed forms."""
    p = parameters("wavy_plates", {"aperture": 2e-4, "amplitude": a, "wavelength": 0.01, "cells_across": 4})
    e = GENERATORS["wavy_plates"].aperture(p, np.linspace(0.0, 0.01, 4096, endpoint=False))
    assert series_limit(2e-4, a) ** 3 == pytest.approx(1 / np.mean(1 / e ** 3), rel=1e-13)
    assert parallel_limit(2e-4, a) ** 3 == pytest.approx(np.mean(e ** 3), rel=1e-13)
    assert series_limit(2e-4, a) <= 2e-4 <= parallel_limit(2e-4, a)


def test_the_scene_gives_the_parameters_and_the_flow_rate_the_hydraulic_aperture():
    scene = load(CASE)
    assert scene.check == {"kind": "lubrication", "aperture": 1e-3, "amplitude": 0.3, "direction": "along",
                           "tolerance": 0.03, "pressure_drop": 1e-2, "viscosity": 1e-3, "length": 0.05,
                           "width": scene.fluid.spacing[1]}
    G = StructuredGrid(scene.fluid.origin, scene.fluid.spacing, scene.fluid.shape)
    e_s = series_limit(1e-3, 0.3)
    q = e_s ** 3 * 1e-2 / (12 * 1e-3 * 0.05)  # the series limit's flow rate per unit width
    for factor, passed in ((1.025, True), (1.035, False)):
        u = np.zeros((G.num_cells, 3))
        u[:, 0] = q * factor ** 3 / (G.shape[2] * G.spacing[2])  # a plug over the whole section
        report = checks.evaluate(scene, checks.Result({"fluid": G}, {"fluid": {"velocity": u}}))
        assert report["hydraulic_aperture"] == pytest.approx(e_s * factor, rel=1e-12)
        assert report["relative_difference"] == pytest.approx(factor - 1, rel=1e-9)
        assert report["flow_rate_difference"] == pytest.approx(factor ** 3 - 1, rel=1e-9)
        assert report["passed"] is passed and report["limit"] == report["series_limit"] == e_s
    assert checks.describe(report) == ("check: hydraulic aperture 942.8 um against the series lubrication limit's 911 um: "
                                       "+3.500% (flow rate +10.872%) (tolerance 0.03): FAIL")


def test_across_the_flow_the_parallel_limit(tmp_path):
    scene = load(copy_case(CASE, tmp_path, ACROSS))
    assert scene.check["direction"] == "across" and scene.fluid.shape[:2] == [4, 32]
    G = StructuredGrid(scene.fluid.origin, scene.fluid.spacing, scene.fluid.shape)
    u = np.zeros((G.num_cells, 3))
    e_p = parallel_limit(1e-3, 0.3)
    width = G.spacing[1] * G.shape[1]
    u[:, 0] = e_p ** 3 * 1e-2 / (12 * 1e-3 * 0.05) * width / (G.shape[1] * G.spacing[1] * G.shape[2] * G.spacing[2])
    report = checks.evaluate(scene, checks.Result({"fluid": G}, {"fluid": {"velocity": u}}))
    assert report["limit"] == e_p and report["hydraulic_aperture"] == pytest.approx(e_p, rel=1e-12)


@pytest.mark.parametrize("case, replace, message", [
    ("parallel_plates", {'kind = "cubic_law"': 'kind = "lubrication"'},
     "[check] aperture: missing: e0, the mean aperture [m] (the solid is not made by the generator 'wavy_plates')"),
    ("lubrication", {"tolerance = 0.03": "tolerance = 0.03\namplitude = 1.0"},
     "[check] amplitude: must be below 1 (the aperture would close), got 1.0"),
    ("lubrication", {"inlet_pressure = 1.0e-2": "inlet_pressure = 0.0"},
     "[check] kind: 'lubrication' needs a pressure drop: [flow] inlet_pressure - outlet_pressure is 0 Pa")])
def test_bad_settings_are_one_line_naming_the_key(tmp_path, case, replace, message):
    case = copy_case(CASES / case, tmp_path, replace)
    with pytest.raises(SceneError) as error:
        load(case)
    assert str(error.value) == f"{case / 'scene.toml'}: {message}"
