"""Make cases/small_fracture/solid.msh once: two rock blocks around a rough fracture.

The fracture: 0.05 x 0.025 m, self-affine faces (Hurst 0.8, RMS 0.15 mm, matched above a
mismatch length of 12.5 mm), mean aperture 1 mm, at least 0.5 mm (transfer.fracture,
seed 4). Each block is 5 mm thick, 20 x 10 x 2 lattice cells (2400 tetrahedra per
block). Faces (gmsh physical tags): bottom 1, top 2, fracture_lower 3, fracture_upper 4,
xmin 5, xmax 6, ymin 7, ymax 8. Prints the z-range the fluid grid must cover.

    .venv/bin/python cases/small_fracture/make_mesh.py [--shape NX NY NZ] [--out FILE]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent.parent))

from transfer.fracture import fracture_blocks, fracture_pair, surface_mean  # noqa: E402

SIZE = (0.05, 0.025)
APERTURE, MIN_APERTURE, RMS, HURST, SEED = 1.0e-3, 0.5e-3, 0.15e-3, 0.8, 4
HEIGHT = 5.0e-3
MISMATCH = 0.0125


def make(shape=(20, 10, 2), seed=SEED):
    lower, upper = fracture_pair(shape[:2], SIZE, aperture=APERTURE, hurst=HURST, rms=RMS, seed=seed,
                                 min_aperture=MIN_APERTURE, periodic=False,
                                 mismatch_length=MISMATCH)
    return fracture_blocks(shape, SIZE, HEIGHT, (lower, upper))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--shape", type=int, nargs=3, default=(20, 10, 2))
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
