"""Write crack_quarter.vtu, the mesh of this case (run once; the file is in the repo).

A quarter model [0, 0.8]^2 x [0, 0.8] m of a penny-shaped crack of radius a = 0.1 m in
the plane z = 0 (symmetry planes x = 0, y = 0, z = 0): a lattice graded toward the crack
front (spacing a/32 there) and bent so that the front r = a is a row of mesh edges
(generator penny_crack of transfer.generators). Run with
``.venv/bin/python cases/pressurized_fracture/make_mesh.py``.
"""

from pathlib import Path

import meshio

from transfer.generators import generate

if __name__ == "__main__":
    crack = generate("penny_crack", {"a": 0.1, "extent": 8.0})
    points, cells = crack.points, crack.cells
    out = Path(__file__).with_name("crack_quarter.vtu")
    meshio.write(out, meshio.Mesh(points, [("tetra", cells)]), compression="zlib")
    print(f"wrote {out}: {len(points)} points, {len(cells)} tetrahedra")
