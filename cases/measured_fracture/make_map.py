"""The example height map of this case, `surfaces.npz`, made reproducibly from the synthetic
generator (transfer.generators.surfaces.fracture_pair: the faces of the fracture_closure
specimen's kind on 32 x 32 cells of 0.1 x 0.1 m, Hurst 0.8, RMS 0.2 mm per face, mean aperture
0.2 mm, touching where the aperture would be negative), written as a profilometer's map would
be: arrays lower and upper of shape (ny, nx), row j at y = j dy, and spacing [dx, dy].

    .venv/bin/python cases/measured_fracture/make_map.py          # surfaces.npz
    .venv/bin/python cases/measured_fracture/make_map.py --xyz    # also lower.xyz, upper.xyz
"""

from __future__ import annotations

import sys
from pathlib import Path

from transfer.generators.height_maps import write_npz, write_xyz
from transfer.generators.surfaces import fracture_pair

HERE = Path(__file__).resolve().parent
CELLS, SIZE = 32, 0.1


def faces():
    """(lower, upper) heights (ny, nx) [m] and the spacing (dx, dy) [m]."""
    lower, upper = fracture_pair((CELLS, CELLS), (SIZE, SIZE), aperture=2.0e-4, hurst=0.8, rms=2.0e-4,
                                 mismatch_length=0.02, seed=5, min_aperture=0.0, periodic=False)
    return lower.T, upper.T, (SIZE / CELLS, SIZE / CELLS)


def main(argv) -> None:
    lower, upper, spacing = faces()
    print(write_npz(HERE / "surfaces.npz", lower, upper, spacing))
    if "--xyz" in argv:
        for name, heights in (("lower", lower), ("upper", upper)):
            print(write_xyz(HERE / f"{name}.xyz", heights, spacing))


if __name__ == "__main__":
    main(sys.argv[1:])
