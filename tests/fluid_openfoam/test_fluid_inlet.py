"""Inlet masking of the OpenFOAM fluid: a fixed-velocity inlet (xmin) gets per-face values
u_in (1 - f), f the solid fraction of the cell behind the face, so no fluid is pushed into
a solid that touches the inlet."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from fluid_openfoam.case import CaseSpec
from fluid_openfoam.solver import OpenFOAMSolver

pytestmark = pytest.mark.skipif(shutil.which("simpleFoam") is None, reason="OpenFOAM (simpleFoam) not installed")


def test_xmin_face_order_is_the_i0_column(tmp_path):
    """blockMesh's xmin faces are ordered like the cells of the i = 0 column, j fastest then k
    (read from constant/polyMesh/owner, binary); the other box faces likewise."""
    nx, ny, nz = 3, 4, 5
    spec = CaseSpec.from_config({"grid": {"origin": [0, 0, 0], "spacing": [1, 1, 1], "shape": [nx, ny, nz]}})
    s = OpenFOAMSolver(tmp_path / "c", spec)
    s.setup()
    k, j, i = np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx), indexing="ij")
    cell = (i + nx * j + nx * ny * k)
    np.testing.assert_array_equal(s.patch_cells["xmin"], cell[:, :, 0].ravel())   # j fastest, then k
    np.testing.assert_array_equal(s.patch_cells["xmax"], cell[:, :, -1].ravel())
    assert sorted(s.patch_cells["ymin"]) == sorted(cell[:, 0, :].ravel())
    # the per-face values written are u_in (1 - f) of the cell behind each face
    frac = np.zeros(s.n)
    frac[cell[:, :, 0].ravel()] = np.linspace(0, 1, ny * nz)
    s.write_solid(frac)
    text = (s.case / "0" / "U").read_bytes()
    assert b"nonuniform List<vector>" in text.split(b"xmin")[1][:200]


def test_slab_blocking_half_the_inlet(tmp_path):
    """2D channel, inlet velocity 1e-3 m/s, a solid slab over the lower half of the inlet
    (first quarter of the length): ~0 inflow into the slab, the outflow equals u_in * W/2.
    Without masking the fixed value would push u_in * W through the domain (measured: the
    outflow doubles)."""
    W, L, nx, ny, u_in = 1e-3, 4e-3, 16, 8, 1e-3
    cfg = {"grid": {"origin": [0, 0, 0], "spacing": [L / nx, W / ny, W / ny], "shape": [nx, ny, 1]},
           "inlet": {"velocity": [u_in, 0, 0]}, "outlet": {"pressure": 0.0},
           "boundaries": {"zmin": "empty", "zmax": "empty"}, "max_iterations": 3000, "tolerance": 1e-8}
    s = OpenFOAMSolver(tmp_path / "c", CaseSpec.from_config(cfg))
    s.setup()
    c = s.spec.grid.cell_centres()
    frac = ((c[:, 1] < W / 2) & (c[:, 0] < L / 4)).astype(float)
    U, _ = s.solve(frac)
    assert s.last_run["converged"]
    Ux = U[:, 0].reshape(ny, nx)
    out = Ux[:, -1].sum() * W / ny
    print(f"outflow / (u_in W/2) = {out / (u_in * W / 2):.5f}, max |U| in slab / u_in = "
          f"{np.abs(U[frac == 1]).max() / u_in:.2e}")
    assert abs(out / (u_in * W / 2) - 1) < 0.01
    assert np.abs(U[frac == 1]).max() < 1e-3 * u_in
    # the inlet values in the result directory: 0 in front of the slab, u_in above it
    inlet = s.patch_cells["xmin"]
    assert np.all(frac[inlet][: ny // 2] == 1) and np.all(frac[inlet][ny // 2:] == 0)
