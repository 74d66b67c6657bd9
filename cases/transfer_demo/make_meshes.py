"""Make the two meshes of the transfer demo. Run once; the .vtu files are kept in the repo.

    .venv/bin/python cases/transfer_demo/make_meshes.py

Writes, next to this script:

- ``rock_block.vtu``: the source, a tetrahedral "rock block" over
  [0, 1] x [0, 1] x [0, 0.5]: an 8 x 8 x 4 lattice of boxes, interior vertices
  jittered by 0.2 of the spacing (seed 1), each box split into 6 tetrahedra
  (1536 cells, 405 points). It carries the point field ``pressure`` =
  :data:`PRESSURE` (a smooth, non-polynomial pore pressure: a background
  gradient, a mild wave and a pressurised pocket) at its vertices.
- ``target_block.vtu``: the target, the same block meshed independently: an
  11 x 11 x 5 lattice, jitter 0.2, seed 2 (3630 cells, 864 points), no field.

The two meshes share only the outer boundary of the block: no vertex of the
interior matches. ``scene.toml`` repeats :data:`PRESSURE` as its ``exact`` key,
so ``varcouple run`` measures the error of each transfer against it (and
warns if the two ever disagree).
"""

from pathlib import Path

import meshio

from coupler.protocol.expressions import evaluate_expression
from transfer.generate import box_tetrahedra

HERE = Path(__file__).resolve().parent
UPPER = (1.0, 1.0, 0.5)
#: the source field, an expression in x, y, z (same as [transfer] exact in scene.toml)
PRESSURE = "1 - z + 0.2 * sin(4 * x) * cos(3 * y) + exp(-((x - 0.35)**2 + (y - 0.6)**2 + (z - 0.25)**2) / 0.05)"


def main():
    source = box_tetrahedra((8, 8, 4), upper=UPPER, jitter=0.2, seed=1, name="rock_block")
    target = box_tetrahedra((11, 11, 5), upper=UPPER, jitter=0.2, seed=2, name="target_block")
    pressure = evaluate_expression(PRESSURE, source.points)
    meshio.write(HERE / "rock_block.vtu", meshio.Mesh(source.points, [("tetra", source.cells)],
                                                      point_data={"pressure": pressure}))
    meshio.write(HERE / "target_block.vtu", meshio.Mesh(target.points, [("tetra", target.cells)]))
    for mesh in (source, target):
        print(f"wrote {HERE / (mesh.name + '.vtu')}: {mesh.num_cells} tetra cells, {mesh.num_points} points")


if __name__ == "__main__":
    main()
