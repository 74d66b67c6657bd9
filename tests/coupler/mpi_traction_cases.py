"""Run under ``mpirun -n P`` by test_traction_ranks.py: the traction ``(-p I + tau) n`` with the
wall shear from three samples (coupler/fsi/viscous.py) on P coupler ranks (coupler/fsi/ranks.py:
the solid's cells and wetted triangles dealt out round-robin, its vertex rows too, or the cells
placed on the slabs, the fluid in grid slabs) against the serial :class:`SolidOnGrid` on the whole arrays (every rank computes
both). Rank 0 prints JSON per case: the largest difference of each part at the interface rows
relative to its largest value, the fits and the figures of both, the slab cuts and where the walls and
the samples lie along the slab axis (the cuts pass through the sampled region), which deeper
surfaces are None and how many vertices of each lie outside the grid (serially), and the error
of the grid-stress method, which the ranks refuse."""

from __future__ import annotations

import json
import sys
import warnings
from pathlib import Path

import numpy as np
from mpi4py import MPI

from coupler.errors import CouplerError
from coupler.fsi.held import Held
from coupler.fsi.interface import SolidOnGrid
from coupler.fsi.ranks import GridSlab, SolidOnSlabs, SolidPart
from coupler.fsi.viscous import FluidTraction, traction_figures
from transfer import Mesh, OverlapWarning, StructuredGrid
from transfer.generate import box_tetrahedra
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # tests/: vc_helpers, which test_viscous_traction uses
from test_viscous_traction import PLATES, channel_fields, face_triangles, plates_on_grid, poiseuille

comm = MPI.COMM_WORLD
warnings.simplefilter("ignore", OverlapWarning)  # the deeper surfaces reach beyond the grid on purpose


def dealt(S: Mesh, triangles: np.ndarray, slab: GridSlab | None = None, shift: int = 0) -> SolidPart:
    """This rank's share of the solid `S`: cells and vertex rows round-robin, each wetted triangle
    with the cell it bounds (`shift` ranks further on); with a `slab`, the coupler's ranks then work
    on the cells over their slabs (SolidPart's placement)."""
    size, rank = comm.size, comm.rank
    cell_of = {}
    for c, cell in enumerate(S.cells):
        for face in ((0, 1, 2), (0, 1, 3), (0, 2, 3), (1, 2, 3)):
            cell_of[tuple(sorted(cell[list(face)]))] = c
    owner = np.array([(cell_of[tuple(sorted(t))] + shift) % size for t in triangles])
    rows = np.flatnonzero(np.arange(S.num_points) % size == rank)
    part = {"points": S.points[rows], "cells": S.cells[np.arange(len(S.cells)) % size == rank],
            "interface_triangles": triangles[owner == rank]}
    return SolidPart(comm, Held(comm, "solid", [rank], [rows], [rows]), [part], slab)


def compare(serial: SolidOnGrid, pressure, velocity, wall, deform=None, on_slabs: bool = False) -> dict:
    """The traction of `serial` and of its solid on the ranks (deformed by `deform` when given; the
    cells placed on the slabs with `on_slabs`)."""
    G, S = serial.G, serial.S
    slab = GridSlab(comm, G, "test")
    solid = dealt(S, serial.triangles, slab if on_slabs else None)
    ranks = SolidOnSlabs(comm, solid, slab, "test", deform=deform is not None, traction="full")
    if deform is not None:
        serial.update(deform)
        ranks.update(deform[solid.vertices])
    traction = FluidTraction(PLATES.mu)
    t_serial = traction.parts(serial, pressure, velocity, wall[serial.interface.vertices])
    fits = traction.fits
    figures = traction_figures(serial.interface.weights, *t_serial)
    held = solid.held
    held.fields = {"velocity": wall[held.out_ids]}
    interface = ranks.interface
    t_ranks = traction.parts(ranks, pressure[slab.ids], velocity[slab.ids], interface.from_solid(held, "velocity"))
    block = interface.block
    axis = int(np.flatnonzero(np.subtract(slab.block[1], slab.block[0]) < G.shape)[0])
    out = {"fits": [fits, traction.fits],
           "figures": [figures, traction_figures(interface.weights, *t_ranks, comm)],
           "rows": comm.allreduce(len(block)), "vertices": serial.interface.size,
           "deeper_none": [[d is None for d in on.deeper] for on in (serial, ranks)],
           "outside": [0 if d is None else int(d.transfer.uncovered.size) for d in serial.deeper],
           "cuts": sorted({int(lower[axis]) for lower, _ in comm.allgather(slab.block)} - {0}),
           "cells": comm.allgather(solid.mesh.num_cells), "solid_cells": S.num_cells,
           "off_slab": comm.allreduce(off_slab(solid.mesh, slab, axis)),
           "misplaced": misplaced(S, serial.triangles, slab) if on_slabs else ""}
    for name, a, b in (("pressure", t_serial[0], t_ranks[0]), ("viscous", t_serial[1], t_ranks[1])):
        local = float(np.max(np.abs(a[block] - b), initial=0.0))
        out[name] = comm.allreduce(local, op=MPI.MAX) / float(np.max(np.abs(a)))
    out["stress"] = refused(ranks, pressure[slab.ids], velocity[slab.ids])
    # where the walls are and the surfaces sample along the slab axis, in cells (the cuts fall among them)
    points = [serial.interface.points] + [s.surface.points for s in (serial.interface, *serial.deeper) if s]
    out["sampled"] = sorted({round(float(x) / G.spacing[axis], 6) for p in points for x in p[:, axis]})
    return out


def off_slab(mesh: Mesh, slab: GridSlab, axis: int) -> int:
    """The cells of `mesh` whose centroid lies off this rank's slab along `axis` (the first slab
    reaching back to -inf, the last on to +inf)."""
    G, (lower, upper) = slab.G, slab.block
    lo = G.origin[axis] + G.spacing[axis] * lower[axis] if lower[axis] > 0 else -np.inf
    hi = G.origin[axis] + G.spacing[axis] * upper[axis] if upper[axis] < G.shape[axis] else np.inf
    x = mesh.points[mesh.cells].mean(axis=1)[:, axis] if mesh.num_cells else np.zeros(0)
    return int(np.count_nonzero((x < lo) | (x >= hi)))


def misplaced(S: Mesh, triangles: np.ndarray, slab: GridSlab) -> str:
    """The error of placing on the slabs a solid whose parts' wetted triangles lie one rank off the
    cells they bound ('' if none)."""
    try:
        dealt(S, triangles, slab, shift=1)
    except CouplerError as exc:
        return str(exc)
    return ""


def refused(ranks: SolidOnSlabs, pressure, velocity) -> str:
    """The error of the grid-stress method on the ranks ('' if it ran)."""
    try:
        FluidTraction(PLATES.mu, "stress").parts(ranks, pressure, velocity)
    except CouplerError as exc:
        return str(exc)
    return ""


def plates(n: int, columns: int | None = None) -> dict:
    """Plane Poiseuille flow between the plates at n cells across (test_viscous_traction.py), its
    grid of `columns` cells along x (None: the plates' own 4), the walls' vertices moving along the
    plates at random velocities."""
    serial, y0, y1 = plates_on_grid(n)
    if columns is not None:
        G = serial.G
        G = StructuredGrid(G.origin, [PLATES.length / columns, *G.spacing[1:]], [columns, *G.shape[1:]])
        serial = SolidOnGrid(serial.S, G, serial.triangles, "test", deform=False, traction="full")
    p, u = channel_fields(serial, y0, y1, poiseuille(y0, y1))
    wall = np.zeros((serial.S.num_points, 3))
    wall[:, 0] = np.random.default_rng(n).uniform(-1, 1, serial.S.num_points) * 1e-3
    return compare(serial, p, u, wall)


def thin(tilt: float, deform: bool = False, on_slabs: bool = False) -> dict:
    """test_viscous_traction.py's block under a thin channel (top at z = 0.37, the grid to 0.6) with
    its top tilted by `tilt` over x (the deepest samples partly outside the grid: NaN there), and
    deformed (rebuilt on the ranks) when `deform`, its cells placed on the slabs with `on_slabs`: a
    shear flow u_x = 2 z, u_y = z^2."""
    G = StructuredGrid.from_bounds((0, 0, 0), (1, 1, 0.6), (10, 10, 6))
    m = box_tetrahedra((4, 4, 2), (0.0, 0.0, 0.0), (1.0, 1.0, 0.37))
    points = m.points.copy()
    points[:, 2] *= 1 + tilt * (points[:, 0] - 0.5)
    S = Mesh(points, m.cells, "tetra")
    top = face_triangles(S, 2, 0.37, +1) if tilt == 0 else top_triangles(S)
    serial = SolidOnGrid(S, G, top, "test", deform=deform, traction="full")
    c = G.cell_centers()
    u = np.zeros((len(c), 3))
    u[:, 0], u[:, 1] = 2 * c[:, 2], c[:, 2] ** 2
    wall = np.zeros((S.num_points, 3))
    u_solid = None
    if deform:
        u_solid = np.zeros((S.num_points, 3))
        u_solid[:, 2] = 0.02 * np.sin(3 * S.points[:, 0]) * S.points[:, 2]
    return compare(serial, c[:, 0] * 10.0, u, wall, u_solid, on_slabs)


def top_triangles(S: Mesh) -> np.ndarray:
    """The boundary triangles of `S` on its top (the faces whose vertices are all at the largest z
    of their x), oriented upwards."""
    c = S.cells
    faces = np.sort(np.concatenate([c[:, [0, 1, 2]], c[:, [0, 1, 3]], c[:, [0, 2, 3]], c[:, [1, 2, 3]]]), axis=1)
    faces, count = np.unique(faces, axis=0, return_counts=True)
    p = S.points
    highest = {}
    for x, z in zip(np.round(p[:, 0], 12), p[:, 2]):
        highest[x] = max(highest.get(x, -np.inf), z)
    on_top = np.array([np.isclose(p[v, 2], highest[np.round(p[v, 0], 12)]) for v in range(len(p))])
    faces = faces[(count == 1) & np.all(on_top[faces], axis=1)]
    normal = np.cross(p[faces[:, 1]] - p[faces[:, 0]], p[faces[:, 2]] - p[faces[:, 0]])
    flip = normal[:, 2] < 0
    faces[flip] = faces[flip][:, [0, 2, 1]]
    return faces


def main():
    cases = {"plates, cuts across the gap": plates(4), "plates, cuts along the flow": plates(4, columns=12),
             "thin channel": thin(0.0), "tilted thin channel": thin(0.4), "deformed tilted channel": thin(0.4, True),
             "deformed tilted channel on slabs": thin(0.4, True, on_slabs=True)}
    if comm.rank == 0:
        print(json.dumps({"ranks": comm.size, "cases": cases}, default=lambda a: np.asarray(a).tolist()))


if __name__ == "__main__":
    main()
