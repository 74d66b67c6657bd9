"""Make cases/fracture_flow/solid.msh once: two rock blocks around a rough fracture.

The fracture: 0.1 x 0.05 m, self-affine faces (Hurst 0.8, RMS 0.3 mm, matched above a
mismatch length of 25 mm, independent below it), mean aperture 2 mm, at least 1 mm
(transfer.fracture, seed 7). Each block is 10 mm thick, 40 x 20 x 2 lattice cells
(9600 tetrahedra per block). Faces (gmsh physical tags): bottom 1, top 2, fracture_lower 3, fracture_upper 4,
xmin 5, xmax 6, ymin 7, ymax 8. Prints the z-range the fluid grid must cover.

    .venv/bin/python cases/fracture_flow/make_mesh.py [--shape NX NY NZ] [--out FILE]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent.parent))

from transfer.fracture import fracture_blocks, fracture_pair, surface_mean  # noqa: E402

SIZE = (0.1, 0.05)
APERTURE, MIN_APERTURE, RMS, HURST, SEED = 2.0e-3, 1.0e-3, 0.3e-3, 0.8, 7
HEIGHT = 10.0e-3
MISMATCH = 0.025


def make(shape=(40, 20, 2), seed=SEED):
    lower, upper = fracture_pair(shape[:2], SIZE, aperture=APERTURE, hurst=HURST, rms=RMS, seed=seed,
                                 min_aperture=MIN_APERTURE, periodic=False,
                                 mismatch_length=MISMATCH)
    return fracture_blocks(shape, SIZE, HEIGHT, (lower, upper))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--shape", type=int, nargs=3, default=(40, 20, 2))
    ap.add_argument("--out", default=str(HERE / "solid.msh"))
    a = ap.parse_args(argv)
    blocks = make(a.shape)
    path = blocks.solid.write(a.out)
    lower, upper = blocks.heights
    w = blocks.aperture
    print(f"{path}: {len(blocks.solid.points)} points, {len(blocks.solid.cells)} tetrahedra")
    print(f"aperture mean {surface_mean(w, SIZE) * 1e3:.4f} mm, min {w.min() * 1e3:.4f} mm, max {w.max() * 1e3:.4f} mm")
    print(f"lower face z in [{lower.min():.6g}, {lower.max():.6g}], upper face z in [{upper.min():.6g}, {upper.max():.6g}]")
    print(f"top z = {blocks.solid.points[:, 2].max():.6g}, bottom z = {blocks.solid.points[:, 2].min():.6g}")


if __name__ == "__main__":
    main()
