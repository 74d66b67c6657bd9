"""Run under ``mpirun -n N`` by test_contact_mpi.py: one contact problem solved on the N ranks,
its results written by rank 0 to an npz file (vertex values in input numbering, slave-node
values in the faces' numbering) and its figures printed as JSON.

    mpi_contact_cases.py hertz OUT.npz     the Hertz case's mesh (cases/hertz), push 0.02 m, then
                                           the same solve again at a push 2 % larger (warm start)
    mpi_contact_cases.py blocks OUT.npz    two blocks of the fracture_specimen generator (box,
                                           rough faces), the top pushed down 0.3 mm
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np
from mpi4py import MPI

from solid_fenicsx import Elasticity, read_mesh
from solid_fenicsx.contact import Contact
from solid_fenicsx.contact_hertz import hertz_boundaries
from solid_fenicsx.mesh import generated_mesh

ROOT = Path(__file__).resolve().parents[2]
PUSH = {"hertz": 0.02, "blocks": 3.0e-4}


def hertz():
    solid = read_mesh(ROOT / "cases" / "hertz" / "hertz.msh", boundaries=hertz_boundaries(1.0))
    s = Elasticity(solid, E=1.0e9, nu=0.3)
    s.add_dirichlet("block_bottom", 0.0)
    load = s.add_dirichlet("load", [0.0, 0.0, -PUSH["hertz"]])
    return Contact(s, "slave", "block_top", search_distance=0.1), load


def blocks():
    parameters = {"shape": "box", "size": 0.05, "height": 0.02, "lattice": [8, 8, 3], "ratio": 2, "aperture": 2.0e-4,
                  "rms": 1.0e-4, "seed": 3}
    s = Elasticity(generated_mesh("fracture_specimen", parameters), E=1.0e10, nu=0.25)
    s.add_dirichlet("bottom", 0.0)
    load = s.add_dirichlet("top", [0.0, 0.0, -PUSH["blocks"]])
    return Contact(s, "fracture_lower", "fracture_upper", search_distance=1.0e-3), load


def main(case: str, out: str) -> None:
    comm = MPI.COMM_WORLD
    contact, load = {"hertz": hertz, "blocks": blocks}[case]()
    start = time.perf_counter()
    state = contact.solve()
    seconds = time.perf_counter() - start
    u = contact.elasticity.vertex_values("displacement")
    load.value[:] = [0.0, 0.0, -1.02 * PUSH[case]]
    warm = contact.solve()
    warm_u = contact.elasticity.vertex_values("displacement")
    if comm.rank == 0:
        np.savez(out, u=u, pressure=state.pressure, gap=state.gap, active=state.active, force=state.force,
                 warm_u=warm_u, warm_active=warm.active)
        print(json.dumps({"ranks": comm.size, "iterations": state.solution.iterations,
                          "converged": state.solution.converged, "krylov": state.solution.krylov_iterations,
                          "seconds": seconds, "warm_iterations": warm.solution.iterations,
                          "warm_converged": warm.solution.converged, "dofs": contact.num_dofs,
                          "mean_gap": state.mean_gap, "area_fraction": state.area_fraction}))


if __name__ == "__main__":
    main(*sys.argv[1:])
