"""What a hydro-mechanical fracture's figures cost in accuracy (coupler/fsi/resolution.py): the
warnings' thresholds, the plates study's error in them, and each kind printed once per run."""

import pytest

from coupler.fsi.fracture import FractureFigures
from coupler.fsi.resolution import (apertures_warning, cells_across_warning, contact_area_warning, plates_error,
                                   throat_warning)


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
