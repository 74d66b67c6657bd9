"""Run under ``mpirun -n P`` by test_results_mpi.py with an output directory: a tet mesh of a box
cut in slabs along x (the last rank holds no cells when P > 2), each rank writing its piece of
two steps of a Series; rank 0 also writes the serial series of the whole mesh into
``serial/``. The summary figures of the parts are reduced; rank 0 prints them as JSON with
their serial values and the error of a figure without a rule."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
from mpi4py import MPI

from coupler.errors import CouplerError
from coupler.output.results import Series, reduce_figures, write_summary
from transfer.distributed import Part
from transfer.generate import box_tetrahedra
from transfer.partition import slabs

comm = MPI.COMM_WORLD


def fields(mesh, step):
    x = np.asarray(mesh.points)
    centres = x[mesh.cells].mean(axis=1)
    displacement = np.stack([np.sin(3 * x[:, 0]) + step, x[:, 1] * x[:, 2], x[:, 2] ** 2], axis=1)
    return ({"displacement": displacement, "pressure": np.cos(2 * x[:, 1]) * (1 + step)},
            {"fraction": centres[:, 0] * centres[:, 2], "owner_id": np.full(len(centres), 7, dtype=np.int64)})


def figures(mesh, step):
    points, _ = fields(mesh, step)
    u = points["displacement"]
    return {"max_displacement": float(np.max(np.linalg.norm(u, axis=1))) if len(u) else 0.0,
            "sizes": {"cells": mesh.num_cells, "min_pressure": float(points["pressure"].min(initial=np.inf))},
            "contact": bool(np.any(u[:, 2] > 0.9)) if len(u) else False, "note": "per rank"}


HOW = {"max_displacement": "max", "sizes.cells": "sum", "sizes.min_pressure": "min", "contact": "max"}


def main():
    out = Path(sys.argv[1])
    whole = box_tetrahedra((4, 3, 3), jitter=0.1, seed=2)
    holders = comm.size - 1 if comm.size > 2 else comm.size
    owner = slabs(whole, holders, 0)
    part = Part.of_cells(whole, np.flatnonzero(owner == comm.rank), "P1").mesh
    series = Series(out, "solid", part, comm)
    reduced = []
    for step, t in ((0, 0.5), (3, 1.5)):
        points, cells = fields(part, step)
        series.write(step, t, point_data=points, cell_data=cells)
        reduced.append(reduce_figures(figures(part, step), HOW, comm))
    write_summary(out, {"steps": reduced}, comm=comm)
    try:
        reduce_figures({"mean_aperture": 1.0, "max_displacement": 2.0}, HOW, comm)
        error = None
    except CouplerError as exc:
        error = str(exc)
    if comm.rank == 0:
        (out / "serial").mkdir()
        serial = Series(out / "serial", "solid", whole)
        for step, t in ((0, 0.5), (3, 1.5)):
            points, cells = fields(whole, step)
            serial.write(step, t, point_data=points, cell_data=cells)
        print(json.dumps({"ranks": comm.size, "reduced": reduced, "serial": [figures(whole, s) for s in (0, 3)],
                          "error": error}))


if __name__ == "__main__":
    main()
