"""Run under ``mpirun -n 2`` by test_fracture_ranks.py: the fracture monitor's figures on rows and
grid slabs split over the ranks against the serial functions on the whole arrays (every rank
computes both). Rank 0 prints JSON: the largest relative difference of each figure, and each
percolation case's (serial, ranks) answers."""

from __future__ import annotations

import json

import numpy as np
from mpi4py import MPI

from coupler.fsi.apertures import contact_area_fraction, mean_open_aperture, mechanical_aperture
from coupler.fsi.flow_rate import column_open_lengths, percolates, section_flow_rates
from coupler.fsi.open_gap import contact_share
from coupler.fsi.ranks import GridSlab
from transfer import StructuredGrid
from transfer.rows import Rows
from test_fracture_figures import patch_in_contact  # this script's directory is on sys.path

comm = MPI.COMM_WORLD


def relative(a, b) -> float:
    a, b = np.asarray(a, float), np.asarray(b, float)
    return float(np.max(np.abs(a - b)) / max(np.max(np.abs(a)), 1e-300))


def paths(grid: StructuredGrid, steps) -> np.ndarray:
    """A solid grid (fraction 1) with the open cells (fraction 0.1) of the polylines `steps`
    (lists of (i, j, k) corners joined along one axis at a time)."""
    nx, ny, nz = grid.shape
    fraction = np.ones((nz, ny, nx))
    for corners in steps:
        for a, b in zip(corners, corners[1:]):
            lo, hi = np.minimum(a, b), np.maximum(a, b)
            fraction[lo[2]:hi[2] + 1, lo[1]:hi[1] + 1, lo[0]:hi[0] + 1] = 0.1
    return fraction.ravel()


def percolation_cases() -> dict:
    """Slabs along z (rank 0: z < 4, rank 1: z >= 4) and along x (the inlet on rank 0 only, the
    outlet on rank 1 only)."""
    along_z = StructuredGrid((0, 0, 0), (1, 1, 1), (6, 4, 8))
    along_x = StructuredGrid((0, 0, 0), (1, 1, 1), (8, 4, 3))
    up = [(0, 1, 1), (2, 1, 1), (2, 1, 6), (5, 1, 6)]  # inlet and outlet on either side of the cut at z = 4
    blocked = [(0, 1, 1), (2, 1, 1), (2, 1, 3)], [(2, 1, 5), (2, 1, 6), (5, 1, 6)]  # no cell at z = 4
    # the inlet's and the outlet's open cells both below the cut, joined only through the slab above it
    twice = [(0, 1, 1), (1, 1, 1), (1, 1, 5), (4, 1, 5), (4, 1, 1), (5, 1, 1)]
    # open cells facing across the cut only diagonally (no shared face)
    diagonal = [(0, 1, 1), (2, 1, 1), (2, 1, 3)], [(3, 1, 4), (3, 1, 6), (5, 1, 6)]
    channel = [(0, 2, 1), (7, 2, 1)]
    cases = {"across the cut": (along_z, [up]), "blocked at the cut": (along_z, list(blocked)),
             "down and up again": (along_z, [twice]), "diagonal at the cut": (along_z, list(diagonal)),
             "along x across the cut": (along_x, [channel]),
             "along x blocked": (along_x, [[(0, 2, 1), (3, 2, 1)], [(5, 2, 1), (7, 2, 1)]])}
    out = {}
    for name, (grid, steps) in cases.items():
        fraction = paths(grid, steps)
        slab = GridSlab(comm, grid, name)
        out[name] = [percolates(grid, fraction), percolates(grid, fraction[slab.ids], block=slab.block, comm=comm),
                     slab.block[0], slab.block[1]]
    return out


def flow_rates() -> float:
    grid = StructuredGrid((0, 0, 0), (0.1, 0.2, 0.3), (5, 3, 9))
    velocity = np.random.default_rng(3).normal(size=(grid.num_cells, 3))
    slab = GridSlab(comm, grid, "flow")
    return relative(section_flow_rates(grid, velocity), section_flow_rates(grid, velocity[slab.ids], slab.block, comm))


def open_lengths() -> dict:
    """Each column's open length across z with the slabs along z (every rank a part of each
    column) and along x (each column whole on one rank)."""
    out = {}
    for name, grid in {"across the cut": StructuredGrid((0, 0, 0), (1, 1, 1), (3, 2, 6)),
                       "along the cut": StructuredGrid((0, 0, 0), (1, 1, 1), (6, 2, 3))}.items():
        fraction = np.random.default_rng(5).uniform(size=grid.num_cells)
        slab = GridSlab(comm, grid, name)
        out[name] = relative(column_open_lengths(grid, fraction, 2),
                             column_open_lengths(grid, fraction[slab.ids], 2, slab.block, comm))
    return out


def apertures() -> dict:
    rng = np.random.default_rng(4)
    n = 41
    gap, weights = rng.uniform(-1e-6, 1e-4, n), rng.uniform(0.5, 2.0, n)
    touching = rng.uniform(size=n) < 0.3
    mine = np.arange(comm.rank, n, comm.size)  # rows dealt out
    return {"mechanical_aperture": relative(mechanical_aperture(gap, touching, weights),
                                            mechanical_aperture(gap[mine], touching[mine], weights[mine], comm)),
            "mean_open_aperture": relative(mean_open_aperture(gap, touching, weights),
                                           mean_open_aperture(gap[mine], touching[mine], weights[mine], comm)),
            "contact_area_fraction": relative(contact_area_fraction(touching, weights),
                                              contact_area_fraction(touching[mine], weights[mine], comm))}


def contact_shares() -> dict:
    """The fine slave face (7 x 6) in contact on a patch under the coarse face (3 x 2): the
    triangles dealt out one by one, or each face whole on one rank (every mortar pair across the
    ranks); each rank's shares at its vertices against the serial ones."""
    points, triangles, on_slave, in_contact = patch_in_contact()
    serial = contact_share(points, triangles, on_slave, in_contact)
    rows = Rows(comm, len(points))
    splits = {"dealt out": np.arange(len(triangles)) % comm.size == comm.rank,
              "a face per rank": np.all(on_slave[triangles], axis=1) == (comm.rank == 0)}
    out = {}
    for name, mine in splits.items():
        vertices, local = np.unique(triangles[mine], return_inverse=True)
        chi = contact_share(points[vertices], local.reshape(-1, 3), on_slave[vertices], in_contact[vertices],
                            rows, vertices)
        out[name] = comm.allreduce(float(np.max(np.abs(chi - serial[vertices]), initial=0.0)), op=MPI.MAX)
    out["other face touches"] = bool(0 < serial[~on_slave].max() < 1)
    return out


def main():
    result = {"ranks": comm.size, "percolation": percolation_cases(), "flow_rates": flow_rates(),
              "open_lengths": open_lengths(),
              "apertures": apertures(), "contact_share": contact_shares()}
    if comm.rank == 0:
        print(json.dumps(result, default=lambda a: np.asarray(a).tolist()))


if __name__ == "__main__":
    main()
