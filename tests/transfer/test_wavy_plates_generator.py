"""The wavy_plates generator (transfer/generators/wavy_plates.py): two blocks whose gap is
e0 (1 + a sin(2 pi s / lambda)) along the flow (s = x) or across it (s = y), and the grid made
for them."""

from __future__ import annotations

import numpy as np
import pytest

from transfer.generators import GENERATORS, generate, parameters

WAVY = {"aperture": 1e-3, "amplitude": 0.3, "wavelength": 0.05, "cells_across": 8}


def face_heights(block, name) -> dict:
    """{(x, y) rounded: z} of the vertices of a named face."""
    p = block.points[np.unique(block.faces[name])]
    return {(round(x, 12), round(y, 12)): z for x, y, z in p}


@pytest.mark.parametrize("direction, axis", [("along", 0), ("across", 1)])
def test_the_gap_is_the_sinusoid_at_every_face_vertex(direction, axis):
    values = {**WAVY, "direction": direction}
    block = generate("wavy_plates", values)
    lower, upper = face_heights(block, "fracture_lower"), face_heights(block, "fracture_upper")
    assert lower.keys() == upper.keys() and len(lower) == (2 * 65 if direction == "along" else 5 * 65)
    s = np.array([key[axis] for key in upper])
    gap = np.array([upper[k] - lower[k] for k in upper])
    np.testing.assert_allclose(gap, 1e-3 * (1 + 0.3 * np.sin(2 * np.pi * s / 0.05)), rtol=0, atol=1e-15)
    assert np.ptp(list(lower.values())) == 0.0  # the lower face is flat
    assert block.volume() == pytest.approx(block.mesh.cell_measures().sum())


def test_the_grid_has_cells_across_cells_across_the_smallest_aperture_and_covers_the_blocks():
    p = parameters("wavy_plates", {**WAVY, "offset": 0.25})
    module = GENERATORS["wavy_plates"]
    g = module.grid(p)
    h = g["spacing"][2]
    assert 0.7e-3 / h == pytest.approx(8, rel=1e-14) and g["spacing"][1] == h
    assert g["shape"] == [32, 1, 20] and g["spacing"][0] * 32 == pytest.approx(0.05, rel=1e-15)
    block = module.mesh(p)
    top = g["spacing"][2] * g["shape"][2]
    assert block.points[:, 2].min() == 0.0 and block.points[:, 2].max() == pytest.approx(top, rel=1e-15)
    assert face_heights(block, "fracture_lower").popitem()[1] == pytest.approx(2.25 * h, rel=1e-14)
    # two cells of the upper block above the largest aperture
    assert top - (2.25 * h + 1.3e-3) >= 2 * h - 1e-15 and module.cells(p) == len(block.cells)
    across = module.grid(parameters("wavy_plates", {**WAVY, "direction": "across", "wavelengths": 2}))
    assert across["shape"][:2] == [4, 64] and across["spacing"][1] * 64 == pytest.approx(0.1, rel=1e-15)


@pytest.mark.parametrize("key, value, reason", [
    ("amplitude", 1.0, "amplitude: must lie in [0.0, 1.0), got 1.0"),
    ("direction", "diagonal", "direction: must be one of 'along', 'across', got 'diagonal'"),
    ("cells_per_wavelength", 1, "cells_per_wavelength: must lie in [2, inf), got 1"),
    ("wavelength", 0.0, "wavelength: must be positive, got 0.0")])
def test_bad_parameters_are_refused_by_name(key, value, reason):
    with pytest.raises(ValueError) as error:
        parameters("wavy_plates", {**WAVY, key: value})
    assert str(error.value) == reason
