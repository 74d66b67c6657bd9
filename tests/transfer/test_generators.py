"""transfer.generators: the registry of case geometry generators (one module each: parameters
checked, defaults filled in, the faces it names, its cell count without building), the closure
specimen (box and cylinder, the concentric map) and the rock obstacle's block."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from transfer.generators import GENERATORS, cells, generate, parameters
from transfer.generators.fracture_specimen import square_to_disc
from vc_helpers import CASES


ROUGH = {"shape": [6, 4, 2], "size": [0.03, 0.02], "height": 0.005, "aperture": 1e-3, "min_aperture": 5e-4,
         "rms": 1.5e-4, "mismatch_length": 0.01}


@pytest.mark.parametrize("name, values", [
    ("rough_fracture", ROUGH),
    ("fracture_specimen", {"lattice": [8, 8, 3], "shape": "box"}),
    ("fracture_specimen", {"lattice": [8, 8, 3], "shape": "cylinder", "size": 0.122}),
    ("rough_block", {"cells": [8, 8, 3], "size": [0.05, 0.05, 0.02], "rms": 5e-4}),
    ("measured_fracture", {"surfaces": str(CASES / "measured_fracture" / "surfaces.npz"), "height": 0.04,
                           "coarsen": 4, "ratio": 2, "layers": 2}),
    ("measured_fracture", {"surfaces": str(CASES / "measured_fracture" / "surfaces.npz"), "height": 0.04,
                           "coarsen": 2, "ratio": 2, "grading": 1.5}),
    ("penny_crack", {"extent": 2.0, "h_tip": 0.02}),
])
def test_a_generator_makes_its_faces_and_the_cells_it_counts(name, values):
    module = GENERATORS[name]
    block = generate(name, values)
    assert block.mesh.num_cells == block.num_cells == cells(name, values)  # valid, positively oriented tets
    assert set(block.named_faces()) == set(module.FACES)
    for face, tag in module.FACES.items():
        assert block.face_tags[face] == tag and len(block.faces[face]) > 0
    triangles, tags = block.tagged_triangles()
    assert len(triangles) == len(tags) == sum(len(block.faces[f]) for f in module.FACES)
    assert set(module.DEFAULTS) <= set(module.PARAMETERS) and module.DESCRIPTION


@pytest.mark.parametrize("values, message", [
    ({"colour": 1}, "colour: unknown parameter of generator 'fracture_specimen'; known: shape, size"),
    ({"lattice": [8, 8]}, "lattice: must be a list of 3 integers, got [8, 8]"),
    ({"lattice": [8.0, 8, 3]}, "lattice: must be an integer, got 8.0"),
    ({"size": "big"}, "size: must be a finite number, got 'big'"),
    ({"ratio": 2.5}, "ratio: must be an integer, got 2.5"),
    ({"seed": True}, "seed: must be an integer, got True"),
    ({"shape": "sphere"}, "shape: must be one of 'box', 'cylinder', got 'sphere'"),
    ({"lattice": [9, 9, 3]}, "ratio: 2 does not divide the lattice's nx, ny [9, 9]"),
    ({"min_aperture": 1e-3}, "min_aperture: 0.001 m must be below the mean aperture 0.0002 m"),
])
def test_parameters_are_checked_naming_the_key(values, message):
    with pytest.raises(ValueError) as err:
        parameters("fracture_specimen", values)
    assert str(err.value).startswith(message), str(err.value)


def test_a_required_parameter():
    with pytest.raises(ValueError, match=r"^rms: missing \(RMS height of the bottom face \[m\]\)"):
        parameters("rough_block", {"cells": [2, 2, 2], "size": [1.0, 1.0, 1.0]})


def test_square_to_disc_is_equal_area_onto_the_disc():
    """The square's boundary lands on the unit circle, uniformly in angle along each
    side; the Jacobian (finite differences, off the diagonals) is pi/4 everywhere."""
    t = np.linspace(-1, 1, 9)
    for x, y in ((t, np.ones(9)), (t, -np.ones(9)), (np.ones(9), t), (-np.ones(9), t)):
        X, Y = square_to_disc(x, y)
        assert np.allclose(np.hypot(X, Y), 1.0)
        assert np.allclose(np.diff(np.unwrap(np.arctan2(Y, X))), np.diff(np.unwrap(np.arctan2(Y, X)))[0])
    rng = np.random.default_rng(0)
    x, y = rng.uniform(-1, 1, (2, 200))
    x, y = x[np.abs(np.abs(x) - np.abs(y)) > 1e-3], y[np.abs(np.abs(x) - np.abs(y)) > 1e-3]
    h = 1e-6
    dxx, dyx = (np.subtract(square_to_disc(x + h, y), square_to_disc(x - h, y))) / (2 * h)
    dxy, dyy = (np.subtract(square_to_disc(x, y + h), square_to_disc(x, y - h))) / (2 * h)
    assert np.allclose(dxx * dyy - dxy * dyx, np.pi / 4, rtol=1e-6)
    assert np.allclose(square_to_disc(0.0, 0.0), 0.0)


def test_cylinder_specimen_mesh_is_valid():
    """Positive tet volumes, a circular outline of the specimen's radius, the volume of the
    cylinder, the lower face twice as fine as the upper (non-matching)."""
    block = generate("fracture_specimen", {"lattice": [8, 8, 3], "shape": "cylinder", "size": 0.122})
    p = block.points[block.cells]
    a, b, c = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]
    volume = np.einsum("ij,ij->i", a, np.cross(b, c)) / 6
    assert volume.min() > 0.05 * volume.mean()  # measured 0.097 (box: 0.62)
    edges = [np.linalg.norm(p[:, i] - p[:, j], axis=1) for i in range(4) for j in range(i)]
    quality = 6 * np.sqrt(2) * volume / np.max(edges, axis=0) ** 3  # 1 for the regular tet
    assert quality.min() > 0.02  # measured 0.026 (box: 0.19): the flattened cells on a diagonal
    radius = np.hypot(block.points[:, 0] - 0.061, block.points[:, 1] - 0.061)
    assert radius.max() == pytest.approx(0.061, rel=1e-12)
    height = np.ptp(block.points[:, 2])
    # the polygonal outline (32 chords) holds a little less than the cylinder
    assert volume.sum() == pytest.approx(np.pi * 0.061 ** 2 * height, rel=0.02)
    assert block.info["cross_section"] == pytest.approx(np.pi * 0.061 ** 2)
    lower, upper = (np.unique(block.faces[f]) for f in ("fracture_lower", "fracture_upper"))
    assert (len(lower), len(upper)) == (81, 25)


def test_rough_block_has_a_flat_top_and_a_rough_bottom():
    block = generate("rough_block", {"cells": [8, 8, 3], "size": [0.05, 0.05, 0.02], "rms": 5e-4, "seed": 7})
    top, bottom = (block.points[np.unique(block.faces[f]), 2] for f in ("top", "bottom"))
    assert np.ptp(top) == 0 and top[0] == pytest.approx(0.02, rel=1e-12)
    assert np.std(bottom) == pytest.approx(5e-4, rel=0.2) and bottom.min() == block.info["lowest_point"]


def test_the_hertz_radius_is_a_parameter(tmp_path):
    """R = 0.5 m: the curved face lies on the sphere of that radius about (0, 0, R), the flat
    face at z = R. In a child process: gmsh loaded here disturbs VTK's rendering in later tests."""
    pytest.importorskip("gmsh")
    code = ("import numpy as np; from transfer.generators import generate\n"
            "b = generate('hertz', {'radius': 0.5, 'h_contact': 0.08, 'h_far': 0.3})\n"
            "s = b.points[np.unique(b.faces['sphere'])]; l = b.points[np.unique(b.faces['load'])]\n"
            "print(np.abs(np.linalg.norm(s - [0, 0, 0.5], axis=1) - 0.5).max(), np.ptp(l[:, 2]), l[0, 2])")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    sphere_error, flatness, z = (float(v) for v in out[-3:])
    assert sphere_error < 1e-3 * 0.5 and flatness < 1e-12 and z == pytest.approx(0.5)


def test_every_generator_is_listed_in_the_package_docstring():
    import transfer.generators as package

    assert set(GENERATORS) >= {"rough_fracture", "fracture_specimen", "rough_block", "hertz", "penny_crack"}
    for name in GENERATORS:
        assert f"``{name}``" in package.__doc__, name
