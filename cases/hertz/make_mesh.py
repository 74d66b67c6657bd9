"""Make hertz.msh: the half-sphere (R = 1 m) on a block (2 x 2 x 1 m), meshed separately
with gmsh (generator hertz of transfer.generators), 0.04 m cells near the contact point
growing to 0.3 m (about 2.5k points, 12k tets).

    .venv/bin/python cases/hertz/make_mesh.py [--h 0.04] [--radius 1.0] [-o hertz.msh]
"""

import argparse
from pathlib import Path

from transfer.generators.hertz import hertz_mesh

if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--h", type=float, default=0.04, help="cell size at the contact [m]")
    parser.add_argument("--radius", type=float, default=1.0, help="radius of the half-sphere [m]")
    parser.add_argument("-o", "--output", default=str(Path(__file__).with_name("hertz.msh")))
    args = parser.parse_args()
    info = hertz_mesh(args.output, radius=args.radius, half_width=1.0, depth=1.0, h_contact=args.h, h_far=0.3,
                      refine_radius=0.25, grading_radius=1.0)
    print(f"{info['path']}: {info['points']} points, {info['tetrahedra']} tetrahedra")
