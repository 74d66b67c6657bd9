"""What a hydro-mechanical fracture's figures cost in accuracy (coupler/fsi/resolution.py): the
warnings' thresholds, the plates study's error in them, and each kind printed once per run."""

import pytest

from types import SimpleNamespace

from coupler.fsi.fracture import FractureFigures, table
from coupler.fsi.resolution import (ASSUMED_ORDER, aperture_error, apertures_warning, cells_across_warning,
                                   coarse_aperture, contact_area_warning, error_warning, plates_error, throat_warning)


def test_the_plates_error_model_gives_the_measured_refinement_figures():
    """cases/parallel_plates/README.md: +12.5 %, +3.1 %, +0.78 %, +0.20 % at 4, 8, 16, 32 across."""
    for n, measured in ((4, 0.125), (8, 0.031), (16, 0.0078), (32, 0.0020)):
        assert plates_error(n) == pytest.approx(measured, rel=0.03)


def test_a_contact_area_above_one_half_warns_and_names_the_in_plane_cell():
    assert contact_area_warning(0.5, (1.25e-3, 1.25e-3)) is None
    text = contact_area_warning(0.62, (1.25e-3, 2.5e-3))
    assert text.startswith("fracture: the contact area is 62 % of the fracture plane (above 50 %)")
    assert "(1.25 x 2.5 mm in the plane)" in text and "[geometry.fluid] shape" in text


def test_an_aperture_under_one_cell_warns_with_the_cells_across_and_the_error():
    assert cells_across_warning(1.0e-5, 1.0e-5) is None  # one cell across
    text = cells_across_warning(5.0e-6, 1.0e-5)
    assert "the mean open aperture 5 um is 0.50 fluid cells across ([geometry.fluid] cells 10 um across" in text
    assert "800 % extrapolated to 0.50" in text and "+12.5 % at 4 cells across" in text
    assert "unbounded" in cells_across_warning(0.0, 1.0e-5)


class Context:
    def __init__(self):
        self.logged = []

    def warn(self, texts):
        self.logged += texts


def test_a_throat_under_four_cells_warns_with_its_cells_and_error():
    assert throat_warning(4e-5, 1e-5) is None  # four cells across
    assert throat_warning(0.0, 1e-5) is None  # no path: the percolation warning says it
    text = throat_warning(2.5e-5, 1e-5)
    assert "the narrowest throat on the widest open path from inlet to outlet is 25 um, 2.50 fluid cells" in text
    assert "12.5 % at 4 cells (32 % at 2.50 (2 / n^2))" in text and "[geometry.fluid] shape" in text
    assert "under one cell it is open or closed by the rounding" in throat_warning(5e-6, 1e-5)


def test_with_an_error_estimate_only_a_throat_under_one_cell_warns():
    """The estimate measures the error the plates' 2 / n^2 guesses (a drag exact on plates makes
    that guess wrong): 2.5 cells say nothing, half a cell still does."""
    assert throat_warning(2.5e-5, 1e-5, estimated=True) is None
    assert "under one cell it is open or closed by the rounding" in throat_warning(5e-6, 1e-5, estimated=True)


def test_a_hydraulic_aperture_above_the_mechanical_warns():
    assert apertures_warning(8e-5, 8e-5) is None
    text = apertures_warning(9.5e-5, 9.0e-5)
    assert text.startswith("fracture: e_h 95 um exceeds e_m 90 um")


class Context:
    def __init__(self):
        self.logged = []

    def warn(self, texts):
        self.logged += texts


def test_each_kind_of_warning_is_logged_once_and_kept_per_step():
    monitor = FractureFigures.__new__(FractureFigures)
    monitor.ctx, monitor.told = Context(), set()
    assert monitor.warnings({"contact area": None, "throat": None}) == []
    first = monitor.warnings({"contact area": "a 1", "throat": "t 1"})
    second = monitor.warnings({"contact area": "a 2", "throat": "t 2", "apertures": None})
    assert first == ["a 1", "t 1"] and second == ["a 2", "t 2"]
    assert [t.split(" (per")[0] for t in monitor.ctx.logged] == ["a 1", "t 1"]
    assert all(t.endswith("(per step: summary.json steps[].fracture.warnings)") for t in monitor.ctx.logged)


def test_the_coarse_aperture_is_the_cubic_law_at_the_same_pressure_drop():
    """e_h is proportional to Q^(1/3): Q_c = 1.331 Q gives 1.1 e_h; no coarse flow: 0."""
    assert coarse_aperture(8e-5, 2e-9, 1.331 * 2e-9) == pytest.approx(8.8e-5, rel=1e-12)
    assert coarse_aperture(8e-5, 2e-9, 0.0) == 0.0 and coarse_aperture(8e-5, 2e-9, -1e-12) == 0.0


def test_richardson_at_the_assumed_order():
    """|e_h - e_h,c| / (2^p - 1): at p = 1 the difference itself, at the assumed 1/2 2.41 times it."""
    assert aperture_error(80e-6, 90e-6, order=1.0) == pytest.approx(10e-6, rel=1e-12)
    assert ASSUMED_ORDER == 0.5
    assert aperture_error(80e-6, 70e-6) == pytest.approx(10e-6 / (2 ** 0.5 - 1), rel=1e-12)


def test_an_estimated_error_above_five_percent_warns():
    assert error_warning(80e-6, 4e-6, 8.0) is None  # 5 %
    text = error_warning(80e-6, 8e-6, 7.5)
    assert text.startswith("fracture: e_h 80 um is uncertain by about +-8 um (10 %, above 5 %)")
    assert "the gap is 7.5 cells across" in text and "[geometry.fluid] shape" in text
    assert error_warning(0.0, 0.0, 0.0) is None  # no flow: nothing to warn about


def monitor(settings: dict, kind: str = "chorin") -> FractureFigures:
    """The figures' estimate part, with a scene whose fluid is `kind` with `settings`."""
    m = FractureFigures.__new__(FractureFigures)
    solver = SimpleNamespace(kind=kind, settings=settings)
    m.ctx = SimpleNamespace(scene=SimpleNamespace(solvers={"fluid": solver}))
    return m


def test_the_estimate_from_the_fluids_coarse_flow_rate_or_the_reason_without_it():
    """With the fluid's coarse flow rate: e_h on the coarse grid, the error absolute and relative;
    without it no number, the reason: a fluid that declares no estimate (named), the setting off,
    a step without the figure (transient), no flow."""
    found = monitor({"error_estimate": True}).error_estimate(80e-6, 2e-9, 1.331 * 2e-9)
    assert found["coarse_hydraulic_aperture"] == pytest.approx(88e-6, rel=1e-12)
    assert found["hydraulic_aperture_error"] == pytest.approx(8e-6 / (2 ** ASSUMED_ORDER - 1), rel=1e-12)
    assert found["hydraulic_aperture_relative_error"] == pytest.approx(0.1 / (2 ** ASSUMED_ORDER - 1), rel=1e-12)
    for settings, kind, reason in (
            ({"steady": "x"}, "openfoam", "the fluid participant 'openfoam' gives no coarse_flow_rate"),
            ({}, "reynolds", "its model has no second grid across the fracture"),
            ({"error_estimate": False}, "chorin", "[solvers.fluid] error_estimate = false"),
            ({"error_estimate": True}, "chorin", "the fluid gave no coarse_flow_rate this step")):
        missing = monitor(settings, kind).error_estimate(80e-6, 2e-9, None)
        assert list(missing) == ["hydraulic_aperture_error_missing"] and reason in missing[
            "hydraulic_aperture_error_missing"]
    assert monitor({}).error_estimate(0.0, 0.0, 0.0) == {
        "hydraulic_aperture_error_missing": "no flow through the fracture (e_h = 0)"}


def test_the_log_table_shows_the_estimate_or_why_there_is_none():
    common = {"mechanical_aperture": 9e-5, "hydraulic_aperture": 8e-5, "contact_area_fraction": 0.1,
              "flow_rate": 2e-9, "mean_face_pressure": 2.5e5, "cells_across": 8.0, "throat_cells_across": 6.0}
    steps = [{"step": 0, "iterations": 3, "fracture": {**common, "hydraulic_aperture_error": 8e-6,
                                                       "hydraulic_aperture_relative_error": 0.1}},
             {"step": 1, "iterations": 2, "fracture": {**common, "hydraulic_aperture_error_missing": "why"}}]
    header, first, second, note = table(steps)
    assert "e_h error [um]" in header and "8.000 (10.0%)" in first and "  -  " in second
    assert note == "fracture  no e_h error estimate: why"

