"""Meshes of contact problems made with gmsh (Debian's python3-gmsh).

:func:`hertz_mesh`: a half-sphere of radius R (curved face down, touching the
block at the origin, flat face up at z = R) resting on a block (paper figure 5),
the two bodies meshed separately (non-matching at the contact face) and graded
toward the contact point; :func:`hertz_solution`: Hertz theory.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

#: gmsh physical surface tags of :func:`hertz_mesh`
HERTZ_SURFACES = {"load": 1, "sphere": 2, "block_top": 3, "block_bottom": 4, "block_sides": 5}
#: gmsh physical volume tags (the two bodies)
HERTZ_VOLUMES = {"half_sphere": 1, "block": 2}


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


def hertz_boundaries(radius: float = 1.0, cap: float = 0.3) -> dict:
    """Predicates for :func:`solid_fenicsx.read_mesh`: ``slave`` = the half-sphere's
    curved face below z = cap * radius (where contact can happen)."""
    R = float(radius)

    def slave(x):
        d = np.sqrt(x[0] ** 2 + x[1] ** 2 + (x[2] - R) ** 2)
        return (x[2] > 1e-12 * R) & (x[2] < cap * R) & (np.abs(d - R) < 0.05 * R)

    return {"slave": slave}


def hertz_solution(force: float, radius: float, E: float, nu: float) -> dict:
    """Hertz theory for a sphere on a half-space of the same material:
    E* = E / (2 (1 - nu^2)), a = (3 F R / (4 E*))^(1/3), p0 = 3 F / (2 pi a^2)."""
    E_star = E / (2.0 * (1.0 - nu * nu))
    a = (3.0 * force * radius / (4.0 * E_star)) ** (1.0 / 3.0)
    return {"E_star": E_star, "a": a, "p0": 3.0 * force / (2.0 * np.pi * a * a),
            "approach": a * a / radius}
