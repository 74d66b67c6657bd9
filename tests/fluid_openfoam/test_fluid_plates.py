"""Immersed parallel plates (fluid_openfoam.plates, cases/parallel_plates): flow rate per unit
width through a gap between two solid blocks that do not align with the grid, against the
cubic law Q = w^3 dp / (12 mu L).

Measured (``varcouple run cases/parallel_plates`` with ``[study] methods = ["binary", "linear",
"wall"]`` and ``offsets = [0.0, 0.25, 0.3, 0.5, 0.75]`` of a cell), error of Q:

    cells across        4        8        16       32
    binary mask      +87.5%   +40.6%   +19.5%   +9.6%   (any offset: the aperture grows by ~1 cell)
    fractions, linear -6.2%    -1.5%    -0.4%   -0.1%   at offset 0.3, but +87.5% ... +9.6% at
                                                         offset 0 (fractions 0/1: as the mask)
    fractions, wall  +5.8%    +1.4%    +0.36%  +0.09%  at offset 0.3
      worst offset   +12.5%   +3.1%    +0.78%  +0.20%  (offset 0 = 2 (h/w)^2, the real-wall error)

about 0.3 s per run (2D grids of 4 x (n+5) cells: simpleFoam start-up dominates).
"""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from fluid_openfoam import plates
from transfer.penalization import drag_fraction

needs_foam = pytest.mark.skipif(shutil.which("simpleFoam") is None, reason="OpenFOAM (simpleFoam) not installed")


def test_exact_fractions_are_intersection_volumes():
    grid, lower, upper = plates.geometry(4, offset=0.3)
    f = plates.exact_fractions(grid, (lower, upper)).reshape(grid["shape"][1], plates.NX)
    np.testing.assert_allclose(f[:, 0], [1, 1, 0.3, 0, 0, 0, 0.7, 1, 1], atol=1e-12)
    np.testing.assert_allclose(f, f[:, :1] * np.ones((1, plates.NX)), atol=1e-12)


def test_wall_drag_in_one_dimension():
    """Fluid-centred cell next to a solid-centred one: D = nu/h^2 (h/d - 1), d = h (3/2 - f_c - f_s);
    solid-centred cells get the maximum (T = 1)."""
    nu, h, dmax = 1e-6, 0.1, 1.0
    f = np.array([1.0, 1.0, 0.3, 0.0, 0.0, 0.7, 1.0])
    T = drag_fraction(f, (1, 7, 1), (1.0, h, 1.0), nu, dmax, "wall")
    d = np.array([h * (1.5 - 0.3 - 1.0), h * (1.5 - 0.0 - 0.7)])
    np.testing.assert_allclose(T[[2, 4]], nu / h ** 2 * (h / d - 1) / dmax, rtol=1e-12)
    np.testing.assert_array_equal(T[[0, 1, 5, 6]], 1.0)
    assert T[3] == 0.0
    np.testing.assert_array_equal(drag_fraction(f, (1, 7, 1), (1, h, 1), nu, dmax, "linear"), f)


@needs_foam
def test_smallest_resolution(tmp_path):
    """4 cells across, offset 0.3: +5.77% with the wall drag (binary mask +87.5%); walls on
    grid faces (offset 0): +12.5% = 2 (h/w)^2, exactly the error with real walls."""
    r = plates.run(4, "wall", 0.3, tmp_path / "a")
    print(r)
    assert r["converged"] and r["Q_spread"] < 1e-8
    assert 0.05 < r["error"] < 0.065
    r0 = plates.run(4, "wall", 0.0, tmp_path / "b")
    assert abs(r0["error"] - 2 / 4 ** 2) < 2e-3
    rb = plates.run(4, "binary", 0.3, tmp_path / "c")
    assert rb["error"] > 0.8


@needs_foam
def test_goal_eight_cells_across(tmp_path):
    """The issue's goal: under 5% at 8 cells across, for every offset (measured worst +3.13%,
    at offset 0); about 1.5 s."""
    errs = [plates.run(8, "wall", off, tmp_path / str(off))["error"] for off in (0.0, 0.25, 0.5, 0.75)]
    print(errs)
    assert max(abs(e) for e in errs) < 0.035
