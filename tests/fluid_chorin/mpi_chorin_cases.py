"""Flows of the Chorin fluid solved on the ranks of MPI.COMM_WORLD (tests/fluid_chorin/test_chorin_mpi.py):
``mpirun -n N python tests/fluid_chorin/mpi_chorin_cases.py CASE POISSON SLAB_AXIS OUT.npz [progress|coarsened]``
writes rank 0's gathered pressure and velocity to OUT.npz and prints the run's figures as JSON
(with ``progress``: a progress line due at every pseudo-time step, and the lines each rank
logged; with ``coarsened``: the flow rate on the grid coarsened across, :func:`coarse_rate`).
:func:`solve` with ``comm=None`` is the serial reference."""

from __future__ import annotations

import json
import sys

import numpy as np

from fluid_chorin.solver import ChorinSolver
from fluid_chorin.spec import ChorinSpec
from fluid_chorin.staggered import along


def cavity(n: int = 16, re: float = 100.0) -> tuple[dict, tuple]:
    """The lid-driven unit cavity (closed: a singular Poisson matrix), steady."""
    return ({"grid": {"origin": [0, 0, 0], "spacing": [1 / n] * 3, "shape": [n, n, 1]}, "inlet": "wall",
             "outlet": "wall", "walls": "wall", "rho": 1.0, "mu": 1.0 / re, "tolerance": 1e-6,
             "boundaries": {"zmin": "empty", "zmax": "empty", "ymax": {"velocity": [1.0, 0.0, 0.0]}}}, ())


def plates(cells_across: int = 8, offset: float = 0.3) -> tuple[dict, tuple]:
    """The immersed plates of cases/parallel_plates (w = 1 mm, L = 2 mm, dp = 0.01 Pa, mu = 1e-3 Pa s;
    8 cells across, 'wall' penalization: the drag of a cell from its neighbours' fractions),
    pressure driven."""
    from transfer import FunctionSpace, StructuredGrid, Transfer
    from transfer.generators import GENERATORS, parameters

    p = parameters("plates", {"aperture": 1e-3, "length": 2e-3, "cells_across": cells_across, "offset": offset})
    grid = GENERATORS["plates"].grid(p)
    G = StructuredGrid(grid["origin"], grid["spacing"], grid["shape"])
    mesh = GENERATORS["plates"].mesh(p).mesh
    volumes = Transfer.assemble(FunctionSpace(mesh, "P0"), FunctionSpace(G, "Q0"), "l2").D
    return ({"grid": grid, "inlet": {"pressure": 1e-2}, "outlet": {"pressure": 0.0}, "rho": 1000.0, "mu": 1e-3,
             "boundaries": {"zmin": "empty", "zmax": "empty"}, "tolerance": 1e-9},
            (np.asarray(volumes.diagonal()) / G.cell_measures(),))


def box(n: int = 12) -> tuple[dict, tuple]:
    """A 3D box n x (n-2) x (n+2) with an inlet velocity on xmin, a pressure outlet on xmax, a
    block in its lower half that moves up and turns (per-cell solid velocity), transient."""
    shape = [n, n - 2, n + 2]
    h = 1.0 / n
    cells = np.stack(np.meshgrid(*[(np.arange(s) + 0.5) * h for s in shape], indexing="ij"), -1)
    cells = cells.transpose(2, 1, 0, 3).reshape(-1, 3)  # x fastest
    inside = (np.abs(cells[:, 0] - 0.5) < 0.2) & (cells[:, 2] < 0.45)
    fraction = np.where(inside, 1.0, 0.0)
    velocity = np.zeros_like(cells)
    velocity[inside, 0] = -0.2 * (cells[inside, 1] - 0.4)
    velocity[inside, 1] = 0.2 * (cells[inside, 0] - 0.5)
    velocity[inside, 2] = 0.05
    return ({"grid": {"origin": [0, 0, 0], "spacing": [h] * 3, "shape": shape}, "inlet": {"velocity": [0.1, 0, 0]},
             "outlet": {"pressure": 0.0}, "walls": "wall", "rho": 1.0, "mu": 0.01, "transient": True, "dt": 0.05,
             "substeps": 4, "tolerance": 1e-10}, (fraction, velocity))


def bodies() -> tuple[dict, tuple]:
    """The box with its block moving as a rigid body (``solid_velocity = "bodies"``: the mean of
    its wetted layer's velocity, the block across the slabs)."""
    config, solid = box()
    return {**config, "solid_velocity": "bodies"}, solid


def plates_power() -> tuple[dict, tuple]:
    """The plates under the "power" penalization (a cell's drag from its own fraction alone)."""
    config, solid = plates()
    return {**config, "penalization": "power", "penalization_exponent": 2.0}, solid


def rough_gap() -> tuple[dict, tuple]:
    """A gap across z whose walls step from column to column (3 to 5 cells open, walls at random
    sub-cell positions), pressure driven along x, "lubrication" penalization: the in-plane faces'
    drag from the overlap of their two columns' openings."""
    shape, h = (8, 6, 12), 1e-4
    rng = np.random.default_rng(4)
    lower = rng.uniform(2.2, 3.8, shape[1::-1])  # [j, i] in cells
    upper = lower + rng.uniform(3.0, 5.0, shape[1::-1])
    k = np.arange(shape[2], dtype=float)[:, None, None]
    open_ = np.clip(np.minimum(k + 1, upper) - np.maximum(k, lower), 0.0, 1.0)  # [k, j, i]
    return ({"grid": {"origin": [0, 0, 0], "spacing": [h] * 3, "shape": list(shape)}, "inlet": {"pressure": 1e-2},
             "outlet": {"pressure": 0.0}, "walls": "wall", "rho": 1000.0, "mu": 1e-3, "tolerance": 1e-9,
             "penalization": "lubrication"}, ((1.0 - open_).ravel(),))


CASES = {"cavity": cavity, "plates": plates, "plates_power": plates_power, "box": box, "bodies": bodies,
         "rough_gap": rough_gap}


def solve(case: str, poisson: str, slab_axis: str, comm=None) -> tuple[ChorinSolver, object]:
    """The case solved on the ranks of ``comm``, each given the rows of its input cells only."""
    config, solid = CASES[case]()
    solver = ChorinSolver(ChorinSpec.from_config({**config, "poisson": poisson, "slab_axis": slab_axis}), comm)
    if solid:
        rows = solver.slabs.input_ids()
        solver.set_solid(*(a[rows] for a in solid))
    run = solver.transient(0.0, config["dt"]) if config.get("transient") else solver.steady()
    return solver, run


def coarse_rate(solver: ChorinSolver, case: str) -> tuple[float, list[int]]:
    """The steady flow of ``case`` on ``solver``'s grid coarsened across (fluid_chorin/coarsened.py),
    each rank given the rows of its input cells only: its flow rate (NaN: not converged) and the
    coarse slabs' bounds."""
    from fluid_chorin.coarsened import CoarsenedFlow, across_direction

    _, solid = CASES[case]()
    coarse = CoarsenedFlow(solver, across_direction(solver.spec))
    rows = solver.slabs.input_ids()
    coarse.set_solid(*(a[rows] for a in solid))
    return coarse.flow_rate() if coarse.steady().converged else float("nan"), coarse.solver.slabs.bounds


def same_solid(solver: ChorinSolver, case: str) -> bool:
    """Whether this rank's drag, solid velocity (on the faces of its own cells) and dilatation
    (its own cells) equal, bit for bit, those of one process given the whole grid; with rigid
    bodies (their means summed over the ranks in another order) the solid velocity to 1e-14 of
    its largest value and the dilatation to 1e-14 of that over the smallest cell."""
    config, solid = CASES[case]()
    whole = ChorinSolver(solver.spec)
    if solid:
        whole.set_solid(*solid)
    slabs = solver.slabs
    g0, m, axis = slabs.ghost[0], slabs.hi - slabs.lo, slabs.axis
    rigid = solver.spec.solid_velocity == "bodies"
    speed = max(np.abs(t).max() for t in whole.target)

    def equal(local, serial, faces, scale=0.0):
        extra = int(faces)  # the faces of the own cells along the slab direction: one more than the cells
        a, b = local[along(axis, slice(g0, g0 + m + extra))], serial[along(axis, slice(slabs.lo, slabs.hi + extra))]
        return np.array_equal(a, b) if scale == 0 else bool(np.abs(a - b).max() <= 1e-14 * scale)

    return (all(equal(a, b, c == slabs.d) for c, (a, b) in enumerate(zip(solver.drag, whole.drag)))
            and all(equal(a, b, c == slabs.d, rigid * speed) for c, (a, b) in enumerate(zip(solver.target, whole.target)))
            and equal(solver.source, whole.source, False, rigid * speed / solver.grid.h.min())
            and equal(solver.fraction, whole.fraction, False))


def main(case: str, poisson: str, slab_axis: str, out: str, mode: str = "") -> None:
    import logging

    from mpi4py import MPI

    import fluid_chorin.solver

    comm = MPI.COMM_WORLD
    lines = []
    if mode == "progress":
        fluid_chorin.solver.PROGRESS_SECONDS = 0.0
        handler = logging.Handler()
        handler.emit = lambda record: lines.append(record.getMessage())
        logging.getLogger("varcouple.fluid_chorin").addHandler(handler)
        logging.getLogger("varcouple.fluid_chorin").setLevel(logging.INFO)
    solver, run = solve(case, poisson, slab_axis, comm)
    logged = comm.gather(sum("pseudo-time step" in line for line in lines), root=0)
    planes = comm.gather(list(solver.slabs.input_planes), root=0)
    same = comm.gather(same_solid(solver, case), root=0)
    coarse = coarse_rate(solver, case) if mode == "coarsened" else None
    pressure, velocity = solver.cell_pressure(), solver.cell_velocity()
    if comm.rank == 0:
        np.savez(out, pressure=pressure, velocity=velocity)
        print(json.dumps({"ranks": comm.size, "converged": run.converged, "iterations": run.report.iterations,
                          "poisson": run.poisson[-1].method, "poisson_converged": all(p.converged for p in run.poisson),
                          "slabs": solver.slabs.bounds, "direction": solver.slabs.d, "progress_lines": logged,
                          "input_planes": planes, "same_solid": same,
                          **({"coarse_rate": coarse[0], "coarse_slabs": coarse[1]} if coarse else {})}))


if __name__ == "__main__":
    main(*sys.argv[1:])
