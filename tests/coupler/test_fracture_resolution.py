"""What a hydro-mechanical fracture's figures cost in accuracy (coupler/fsi/resolution.py): the
warnings' thresholds, the plates study's error in them, and each kind printed once per run."""

import pytest

from coupler.fsi.fracture import FractureFigures
from coupler.fsi.resolution import cells_across_warning, contact_area_warning, plates_error


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


def test_each_kind_of_warning_is_logged_once_and_kept_per_step():
    monitor = FractureFigures.__new__(FractureFigures)
    monitor.ctx, monitor.h, monitor.cell, monitor.told = Context(), 1e-5, (1e-3, 1e-3), set()
    assert monitor.warnings(0.3, 2e-5) == []
    first = monitor.warnings(0.6, 5e-6)
    second = monitor.warnings(0.7, 4e-6)
    assert len(first) == 2 and len(second) == 2 and first != second
    assert len(monitor.ctx.logged) == 2
    assert all(t.endswith("(per step: summary.json steps[].fracture.warnings)") for t in monitor.ctx.logged)
