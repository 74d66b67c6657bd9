"""The solid cases' numerics: pressurized penny crack against Sneddon (paper 4.2,
second simulation), and the block compression on two MPI ranks."""

from __future__ import annotations

import shutil
import textwrap

import numpy as np
import pytest

pytest.importorskip("dolfinx")

from mpi4py import MPI  # noqa: E402

from solid_fenicsx.cases import block_compression, penny_crack, sneddon_opening  # noqa: E402
from vc_helpers import run_mpi



def test_sneddon_formula():
    w = sneddon_opening([0.0, 0.1, 0.2], a=0.1, E=10e9, nu=0.25, p=1e6)
    assert np.isclose(w[0], 8 * (1 - 0.25 ** 2) * 1e6 * 0.1 / (np.pi * 10e9)) and w[1] == 0 and w[2] == 0


def test_penny_crack_sneddon():
    """P1, h_tip = a/32, L = H = 8a: centre opening within 5 % (measured -2.2 %),
    profile up to r = 0.8 a within 5 % of the centre opening (measured 4.2 %)."""
    r = penny_crack(a=0.1, E=10e9, nu=0.25, p=1e6)
    assert abs(r.center_error) < 0.05, r.center_error
    assert r.profile_error < 0.05, r.profile_error
    assert r.center_opening > 0 and np.all(r.opening > 0)
    assert r.num_cells == 68952


def _mpirun():
    exe = shutil.which("mpirun") or shutil.which("mpiexec")
    return exe


@pytest.mark.skipif(_mpirun() is None, reason="mpirun not found")
@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="already running under MPI")
def test_block_compression_two_ranks(tmp_path):
    script = tmp_path / "block.py"
    script.write_text(textwrap.dedent("""
        import json, sys
        import numpy as np
        from mpi4py import MPI
        from solid_fenicsx.cases import block_compression
        from solid_fenicsx.mesh import box_mesh
        solid = box_mesh(upper=(1.0, 2.0, 1.5), shape=(4, 6, 5))
        r = block_compression(E=1e9, nu=0.3, p=1e6, solid=solid, rtol=1e-12)
        u = r.solver.vertex_values("displacement")
        boundary = r.solver.vertices.boundary_triangles()  # None on rank 1
        if MPI.COMM_WORLD.rank == 0:
            tris, tags = boundary
            np.save(sys.argv[1], u)
            print(json.dumps({"error": r.error, "size": MPI.COMM_WORLD.size, "triangles": len(tris)}))
    """))
    out = tmp_path / "u.npy"
    result = run_mpi(script, 2, out, timeout=120)
    assert result["size"] == 2
    assert result["error"] < 1e-6
    serial = block_compression(E=1e9, nu=0.3, p=1e6, shape=(4, 6, 5), size=(1.0, 2.0, 1.5), rtol=1e-12)
    u_serial = serial.solver.vertex_values("displacement")
    u_mpi = np.load(out)
    assert np.abs(u_mpi - u_serial).max() <= 1e-8 * np.abs(u_serial).max()
    assert result["triangles"] == 2 * 2 * (4 * 6 + 4 * 5 + 6 * 5)
