"""The Hertz contact geometry (paper figure 5), meshed with gmsh (Debian's python3-gmsh): a
half-sphere of radius R (curved face down, touching the block at the origin, flat face up
at z = R) resting on a block, the two bodies meshed separately (non-matching at the contact
face) and graded toward the contact point. :func:`hertz_mesh` writes gmsh's file
(cases/hertz/make_mesh.py); :func:`mesh` is the generator's (the same mesh as a
:class:`~transfer.generators.blocks.Block`).
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from . import number
from .blocks import Block

#: gmsh physical surface tags of :func:`hertz_mesh`
HERTZ_SURFACES = {"load": 1, "sphere": 2, "block_top": 3, "block_bottom": 4, "block_sides": 5}
#: gmsh physical volume tags (the two bodies)
HERTZ_VOLUMES = {"half_sphere": 1, "block": 2}

NAME = "hertz"
DESCRIPTION = "a half-sphere on a block, meshed separately with gmsh (non-matching contact faces)"
PARAMETERS = {"radius": "R, the half-sphere's radius [m] (default 1)",
              "half_width": "the block is [-half_width, half_width]^2 x [-depth, 0] [m] (default 1)",
              "depth": "the block's depth [m] (default 1)",
              "h_contact": "cell size within refine_radius of the contact point [m] (default 0.04)",
              "h_far": "cell size from grading_radius on [m] (default 0.3)",
              "refine_radius": "radius of the finest cells about the contact point [m] (default 0.25)",
              "grading_radius": "where the cells reach h_far [m] (default 1)",
              "master_ratio": "the block's cells at the contact are this times the sphere's (default 1)"}
DEFAULTS = {"radius": 1.0, "half_width": 1.0, "depth": 1.0, "h_contact": 0.04, "h_far": 0.3, "refine_radius": 0.25,
            "grading_radius": 1.0, "master_ratio": 1.0}
FACES = dict(HERTZ_SURFACES)


def hertz_mesh(path, radius: float = 1.0, half_width: float = 1.0, depth: float = 1.0,
               h_contact: float = 0.02, h_far: float = 0.25, refine_radius: float = 0.25,
               grading_radius: float = 1.0, master_ratio: float = 1.0) -> dict:
    """Write a half-sphere on a block as a gmsh ``.msh`` file; return its counts.

    The half-sphere is the lower half of the ball of radius ``radius`` centred at
    (0, 0, radius): its curved face touches the block's top (z = 0) at the
    origin, its flat face (``load``) is at z = radius. The block is
    [-half_width, half_width]^2 x [-depth, 0]. Element size ``h_contact``
    within ``refine_radius`` of the origin on the half-sphere (``h_contact *
    master_ratio`` on the block), growing linearly to ``h_far`` at
    ``grading_radius``. Physical names: :data:`HERTZ_SURFACES`, :data:`HERTZ_VOLUMES`.
    """
    import gmsh

    R, W, D = float(radius), float(half_width), float(depth)
    gmsh.initialize(["-noenv"], readConfigFiles=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setNumber("General.NumThreads", 1)
        gmsh.model.add("hertz")
        occ = gmsh.model.occ
        ball = occ.addSphere(0, 0, R, R)
        lower_half = occ.addBox(-R, -R, 0, 2 * R, 2 * R, R)
        (sphere_vol,), _ = occ.intersect([(3, ball)], [(3, lower_half)])
        block = occ.addBox(-W, -W, -D, 2 * W, 2 * W, D)
        occ.synchronize()

        def classify(volume):
            out = {}
            for dim, tag in gmsh.model.getBoundary([volume], oriented=False):
                box = gmsh.model.getBoundingBox(dim, tag)
                out[tag] = box
            return out

        surfaces = {name: [] for name in HERTZ_SURFACES}
        for tag, (x0, y0, z0, x1, y1, z1) in classify(sphere_vol).items():
            surfaces["load" if abs(z0 - R) < 1e-6 * R and abs(z1 - R) < 1e-6 * R else "sphere"].append(tag)
        for tag, (x0, y0, z0, x1, y1, z1) in classify((3, block)).items():
            if abs(z0) < 1e-6 * R and abs(z1) < 1e-6 * R:
                surfaces["block_top"].append(tag)
            elif abs(z0 + D) < 1e-6 * R and abs(z1 + D) < 1e-6 * R:
                surfaces["block_bottom"].append(tag)
            else:
                surfaces["block_sides"].append(tag)
        for name, tags in surfaces.items():
            gmsh.model.addPhysicalGroup(2, tags, HERTZ_SURFACES[name])
            gmsh.model.setPhysicalName(2, HERTZ_SURFACES[name], name)
        for (name, tag), vol in zip(HERTZ_VOLUMES.items(), (sphere_vol[1], block)):
            gmsh.model.addPhysicalGroup(3, [vol], tag)
            gmsh.model.setPhysicalName(3, tag, name)

        # one size field for both bodies (gmsh 4.8's Restrict field ignores volumes): the
        # block (z <= 0, its top included) is scaled by master_ratio
        on_block = f"min(1, max(0, ({1e-9 * R} - z) * {1e12 / R}))"
        scale = f"(1 + {master_ratio - 1.0} * {on_block})"
        ramp = f"min(1, max(0, (sqrt(x*x + y*y + z*z) - {refine_radius}) / {grading_radius - refine_radius}))"
        size = gmsh.model.mesh.field.add("MathEval")
        gmsh.model.mesh.field.setString(size, "F", f"max({scale} * {h_contact}, {h_contact} + ({h_far} - {h_contact}) * {ramp})")
        gmsh.model.mesh.field.setAsBackgroundMesh(size)
        for key in ("Mesh.MeshSizeExtendFromBoundary", "Mesh.MeshSizeFromPoints", "Mesh.MeshSizeFromCurvature"):
            gmsh.option.setNumber(key, 0)
        gmsh.option.setNumber("Mesh.Algorithm3D", 1)  # Delaunay (HXT gave different meshes run to run)
        gmsh.model.mesh.generate(3)
        gmsh.option.setNumber("Mesh.Binary", 1)
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        gmsh.write(str(path))
        nodes, _, _ = gmsh.model.mesh.getNodes()
        types, tags, _ = gmsh.model.mesh.getElements(3)
        return {"path": str(path), "points": int(len(nodes)), "tetrahedra": int(sum(len(t) for t in tags))}
    finally:
        gmsh.finalize()



def check(p: dict) -> dict:
    out = {k: number(p, k, positive=True) for k in PARAMETERS}
    if not out["h_contact"] <= out["h_far"]:
        raise ValueError(f"h_contact: {out['h_contact']:g} m must not exceed h_far ({out['h_far']:g} m)")
    return out


def mesh(p: dict) -> Block:
    """:func:`hertz_mesh` with the parameters, read back as a Block with the faces of
    :data:`HERTZ_SURFACES` and the bodies of :data:`HERTZ_VOLUMES`."""
    import meshio

    with tempfile.TemporaryDirectory(prefix="varcouple-hertz-") as tmp:
        path = Path(tmp) / "hertz.msh"
        hertz_mesh(path, **p)
        m = meshio.read(path)
    tags = {kind: [(b.data, np.asarray(m.cell_data["gmsh:physical"][i])) for i, b in enumerate(m.cells)
                   if b.type == kind] for kind in ("tetra", "triangle")}
    tets = np.concatenate([data for data, _ in tags["tetra"]])
    triangles = np.concatenate([data for data, _ in tags["triangle"]])
    face_tag = np.concatenate([t for _, t in tags["triangle"]])
    faces = {name: triangles[face_tag == tag] for name, tag in HERTZ_SURFACES.items()}
    return Block(m.points, tets, faces, np.concatenate([t for _, t in tags["tetra"]]).astype(np.int32),
                 f"hertz R = {p['radius']:g} m", face_tags=dict(HERTZ_SURFACES), cell_names=dict(HERTZ_VOLUMES))
