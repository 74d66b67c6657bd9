"""The Reynolds fluid as a participant: the aperture of the fluid grid's columns from the solid
fraction, its flow given back as the 3D fluids' pressure and velocity (so the coupler's flow rate
through the sections x = const is the plane's), a plane grid of another resolution, the inlet
pressure input and the checkpoints, and the scenes it refuses at check."""

from __future__ import annotations

import re

import numpy as np
import pytest

from coupler.errors import SceneError
from coupler.fsi.flow_rate import section_flow_rates
from coupler.protocol.wire import Field
from coupler.scene import load
from fluid_reynolds.participant import ReynoldsParticipant
from transfer import StructuredGrid
from vc_helpers import CASES, copy_case

MU, DP = 1.0e-3, 10.0
SHAPE, SPACING = (6, 4, 10), (2.0e-3, 2.5e-3, 5.0e-5)  # 12 x 10 mm in the plane, 0.5 mm across
LOW, HIGH = 1.3e-4, 3.55e-4  # the gap's faces: they cut cells


def gap_fraction(low=LOW, high=HIGH) -> np.ndarray:
    """The solid fraction of the cells of the grid between the rock below `low` and above `high`."""
    z = np.arange(SHAPE[2] + 1) * SPACING[2]
    open_ = np.clip(np.minimum(z[1:], high) - np.maximum(z[:-1], low), 0, None) / SPACING[2]
    return np.broadcast_to((1 - open_)[:, None, None], SHAPE[::-1]).ravel()


def participant(**settings) -> ReynoldsParticipant:
    p = ReynoldsParticipant()
    p.configure({"grid": {"origin": [0, 0, 0], "spacing": list(SPACING), "shape": list(SHAPE)}, "location": "cells",
                 "mu": MU, "inlet": {"pressure": DP}, "outlet": {"pressure": 0.0}, "walls": "wall", **settings})
    return p


def cubic_law(e: float) -> float:
    return SHAPE[1] * SPACING[1] * e**3 * DP / (12 * MU * SHAPE[0] * SPACING[0])


@pytest.mark.parametrize("resolution", [None, [6, 4], [13, 7]])
def test_a_gap_between_faces_that_cut_cells_passes_the_cubic_law(resolution):
    p = participant(resolution=resolution)
    assert p.announce()["provides"] == ["pressure", "velocity"]
    header, ids = p.geometry()
    assert header["grid"]["shape"] == list(SHAPE) and ids is None
    out = p.advance(0, 0, 0.0, 1.0, {"solid_fraction": Field("solid_fraction", gap_fraction())})
    grid = StructuredGrid([0, 0, 0], SPACING, SHAPE)
    sections = section_flow_rates(grid, out["velocity"].data)
    if resolution is None or resolution == [6, 4]:
        assert np.allclose(sections, cubic_law(HIGH - LOW), rtol=1e-10)  # every section x = const
    assert sections.mean() == pytest.approx(cubic_law(HIGH - LOW), rel=1e-10)  # conserved from the plane
    p_cells = out["pressure"].data.reshape(SHAPE[::-1])
    assert np.ptp(p_cells, axis=0).max() == 0  # one pressure per column
    x = (np.arange(SHAPE[0]) + 0.5) * SPACING[0]
    linear = DP * (1 - x / (SHAPE[0] * SPACING[0]))
    same = resolution is None or resolution == [6, 4]  # else: the mean of the plane's steps over a column
    assert np.allclose(p_cells[0, 0], linear, rtol=1e-9) if same else np.allclose(p_cells[0, 0], linear, atol=0.02 * DP)
    u = out["velocity"].data[:, 0].reshape(SHAPE[::-1])
    assert np.all(u[(gap_fraction().reshape(SHAPE[::-1]) == 1)] == 0)  # nothing moves in the rock
    solves, _ = p.take_reports()
    assert [s.solver for s in solves] == ["Reynolds (SuperLU)"] and solves[0].converged


def test_the_inlet_pressure_input_and_the_checkpoints():
    p = participant()
    fraction = {"solid_fraction": Field("solid_fraction", gap_fraction())}
    first = p.advance(0, 0, 0.0, 1.0, fraction)["velocity"].data.copy()
    p.save_state(1)
    doubled = p.advance(1, 0, 0.0, 1.0, {"inlet_pressure": Field("inlet_pressure", np.array([2 * DP]))})
    assert np.allclose(doubled["velocity"].data, 2 * first, rtol=1e-12)  # Stokes: linear in dp
    p.advance(1, 1, 0.0, 1.0, {"solid_fraction": Field("solid_fraction", gap_fraction(LOW, LOW + 1e-5))})
    p.restore_state(1)
    again = p.advance(1, 2, 0.0, 1.0, {})["velocity"].data
    assert np.array_equal(again, first)
    with pytest.raises(ValueError, match="solid_fraction"):
        p.advance(1, 3, 0.0, 1.0, {"solid_fraction": Field("solid_fraction", np.zeros(7))})


def test_a_closed_gap_passes_nothing():
    p = participant()
    out = p.advance(0, 0, 0.0, 1.0, {"solid_fraction": Field("solid_fraction", np.ones(int(np.prod(SHAPE))))})
    assert not out["velocity"].data.any() and np.all(out["pressure"].data == 0.0)
    # a gap below `closed` (a share of the grid's height, 0.5 mm) is closed; above it, it passes the cubic law
    thin = {"solid_fraction": Field("solid_fraction", gap_fraction(LOW, LOW + 4e-10))}  # 0.8e-6 of the height
    assert not participant().advance(0, 0, 0.0, 1.0, thin)["velocity"].data.any()
    sections = section_flow_rates(StructuredGrid([0, 0, 0], SPACING, SHAPE),
                                  participant(closed=1e-7).advance(0, 0, 0.0, 1.0, thin)["velocity"].data)
    assert sections.mean() == pytest.approx(cubic_law(4e-10), rel=1e-6)


@pytest.mark.parametrize("case, edit, reason", [
    ("added_mass_light", {}, "effect 'dynamics'"),
    ("plates_fsi", {'interface = ': 'traction = "full"\ninterface = '}, 'traction = "full"'),
    ("lubrication", {'participant = "chorin"': 'participant = "chorin"\nranks = 2'}, "ranks = 1"),
    ("lubrication", {'participant = "chorin"': 'participant = "chorin"\nresolution = [4]'}, "two numbers of cells")])
def test_a_scene_it_cannot_run_is_refused_at_check(tmp_path, case, edit, reason):
    path = copy_case(CASES / case, tmp_path, edit) / "scene.toml"
    text = path.read_text()
    path.write_text(text.replace('participant = "openfoam"', 'participant = "reynolds"')
                    .replace('participant = "chorin"', 'participant = "reynolds"'))
    with pytest.raises(SceneError, match=r"\[solvers.fluid\] participant = 'reynolds': .*" + re.escape(reason)):
        load(path)
