"""Make cases/fracture_flow/solid.msh once: two rock blocks around a rough fracture.

The fracture: 0.1 x 0.05 m, self-affine faces (Hurst 0.8, RMS 0.3 mm, matched above a
mismatch length of 25 mm, independent below it), mean aperture 2 mm, at least 1 mm
(generator rough_fracture of transfer.generators, seed 7). Each block is 10 mm thick,
40 x 20 x 2 lattice cells (9600 tetrahedra per block). Faces (gmsh physical tags): bottom 1, top 2, fracture_lower 3, fracture_upper 4,
xmin 5, xmax 6, ymin 7, ymax 8. Prints the z-range the fluid grid must cover.

    .venv/bin/python cases/fracture_flow/make_mesh.py
"""

from pathlib import Path

from transfer.generators import generate

PARAMETERS = dict(
    shape=(40, 20, 2),
    size=(0.1, 0.05),
    height=0.01,
    aperture=0.002,
    min_aperture=0.001,
    rms=0.0003,
    hurst=0.8,
    mismatch_length=0.025,
    seed=7,
)

if __name__ == "__main__":
    solid = generate("rough_fracture", PARAMETERS)
    print(f"{solid.write(Path(__file__).with_name('solid.msh'))}: {solid.describe()}")
