"""Make cases/small_fracture/solid.msh once: two rock blocks around a rough fracture.

The fracture: 0.05 x 0.025 m, self-affine faces (Hurst 0.8, RMS 0.15 mm, matched above a
mismatch length of 12.5 mm), mean aperture 1 mm, at least 0.5 mm (generator
rough_fracture of transfer.generators, seed 4). Each block is 5 mm thick, 20 x 10 x 2 lattice cells (2400 tetrahedra per
block). Faces (gmsh physical tags): bottom 1, top 2, fracture_lower 3, fracture_upper 4,
xmin 5, xmax 6, ymin 7, ymax 8. Prints the z-range the fluid grid must cover.

    .venv/bin/python cases/small_fracture/make_mesh.py
"""

from pathlib import Path

from transfer.generators import generate

PARAMETERS = dict(
    shape=(20, 10, 2),
    size=(0.05, 0.025),
    height=0.005,
    aperture=0.001,
    min_aperture=0.0005,
    rms=0.00015,
    hurst=0.8,
    mismatch_length=0.0125,
    seed=4,
)

if __name__ == "__main__":
    solid = generate("rough_fracture", PARAMETERS)
    print(f"{solid.write(Path(__file__).with_name('solid.msh'))}: {solid.describe()}")
