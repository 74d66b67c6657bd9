"""Make hertz.msh: the half-sphere (R = 1 m) on a block (2 x 2 x 1 m), meshed separately
with gmsh, 0.04 m cells near the contact point growing to 0.3 m (about 2k points, 10k tets).

    .venv/bin/python cases/hertz/make_mesh.py [h_contact]
"""

import sys
from pathlib import Path

from solid_fenicsx.contact_meshes import hertz_mesh

if __name__ == "__main__":
    h = float(sys.argv[1]) if len(sys.argv) > 1 else 0.04
    info = hertz_mesh(Path(__file__).with_name("hertz.msh"), radius=1.0, half_width=1.0, depth=1.0,
                      h_contact=h, h_far=0.3, refine_radius=0.25, grading_radius=1.0)
    print(f"{info['path']}: {info['points']} points, {info['tetrahedra']} tetrahedra")
