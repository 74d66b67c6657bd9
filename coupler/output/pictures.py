"""Pictures of what a run simulated, and only that, rendered offscreen (pyvista over VTK's
EGL render window: no X server) from the run's last VTU files (on a coupler of several ranks
the ``.pvtu`` of its ranks' pieces, joined: :func:`coupler.output.drawing.read`). Each picture
also gives the figures its caption prints, unrounded (summary.json ``picture_figures``).

- elasticity: the deformed solid coloured by the displacement magnitude (the warp factor
  printed on the image), and the von Mises stress on a cut through the solid;
- flow: the fluid speed on the grid's mid-plane across its thinnest extent (through a
  fracture's gap), with the solid's outline and streamlines, and the fluid pressure on the
  wetted faces of the solid;
- contact: the contact pressure and the in-contact map on the slave face;
- contact and flow (a hydro-mechanical fracture): per load step the aperture map beside the
  speed in the fracture's mid-surface (coupler/output/fracture_maps.py);
- transfer: the source field and each transferred one on the same slice, with one colour range.

Colour maps are perceptually uniform (viridis, cividis, inferno), every colour bar names
its quantity and unit, and the camera frames the part that matters (the wetted faces, the
contact face, the slice), not the bounding box.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .drawing import (Picture, colour_bar, last_step, magnitude, plane_normal, plotter, read, save, surface_where,
                      view)
from .fracture_maps import fracture_maps


def deformed_solid(solid, out: Path) -> Picture:
    """The solid warped by its displacement (scaled so that the largest shows at 5 % of the
    body's size) and coloured by the displacement magnitude."""
    u = np.asarray(solid.point_data["displacement"], float)
    size = float(np.linalg.norm(np.ptp(solid.points, axis=0)))
    largest = float(magnitude(u).max())
    factor = 0.05 * size / largest if largest > 0 else 1.0
    factor = float(f"{factor:.1g}")
    shown = solid.copy()
    title = "displacement magnitude [m]"
    shown.point_data[title] = magnitude(u)
    warped = shown.warp_by_vector("displacement", factor=factor)
    p = plotter()
    p.add_mesh(warped, scalars=title, cmap="viridis", show_edges=False, scalar_bar_args=colour_bar(title))
    p.add_mesh(solid.extract_feature_edges(), color="gray", line_width=1, opacity=0.5)
    p.view_isometric()
    p.reset_camera()
    save(p, out, "solid_displacement.png", f"deformed solid, displacement scaled x {factor:g}; largest {largest:.3g} m")
    return Picture("solid_displacement.png", "Deformed solid",
                   f"Displacement magnitude on the solid warped by {factor:g} (largest {largest:.3g} m).",
                   {"largest_displacement": largest, "warp_factor": factor})


def _cut_normal(bounds) -> int:
    """The axis of the middle extent: the cut contains the longest and the shortest extent
    (for a fracture between two blocks: along the flow and across the fracture)."""
    extents = [bounds[1] - bounds[0], bounds[3] - bounds[2], bounds[5] - bounds[4]]
    return int(np.argsort(extents)[1])


def von_mises_cut(solid, out: Path) -> Picture | None:
    if "von_mises" not in solid.point_data:
        return None
    axis = _cut_normal(solid.bounds)
    normal = np.eye(3)[axis]
    cut = solid.slice(normal=normal, origin=solid.center)
    if cut.n_points == 0:
        return None
    p = plotter()
    p.add_mesh(cut, scalars="von_mises", cmap="inferno", scalar_bar_args=colour_bar("von Mises stress [Pa]"))
    p.add_mesh(cut.extract_feature_edges(boundary_edges=True, feature_edges=False, manifold_edges=False,
                                         non_manifold_edges=False), color="black", line_width=1.5)
    view(p, cut.bounds, normal)
    where = f"{'xyz'[axis]} = {solid.center[axis]:.3g} m"
    save(p, out, "solid_von_mises.png", f"von Mises stress on the cut {where}")
    largest = float(np.max(cut.point_data["von_mises"]))
    return Picture("solid_von_mises.png", "Von Mises stress",
                   f"Von Mises stress on the cut {where} through the solid (largest {largest:.3g} Pa).",
                   {"largest_von_mises": largest, "cut": float(solid.center[axis])})


def flow_slice(fluid, solid, out: Path) -> Picture:
    """Speed on the grid's mid-plane across its thinnest extent, the solid's outline on it
    (solid fraction 1/2) and streamlines seeded along the inlet."""
    grid = fluid.cell_data_to_point_data()
    grid.point_data["speed"] = magnitude(grid.point_data["velocity"])
    b = grid.bounds
    extents = [b[1] - b[0], b[3] - b[2], b[5] - b[4]]
    axis = int(np.argmin(extents))
    normal = np.eye(3)[axis]
    plane = grid.slice(normal=normal, origin=grid.center)
    p = plotter()
    p.add_mesh(plane, scalars="speed", cmap="viridis", scalar_bar_args=colour_bar("speed [m/s]"))
    if "solid_fraction" in plane.point_data:
        outline = plane.contour([0.5], scalars="solid_fraction")
        if outline.n_points:
            p.add_mesh(outline, color="black", line_width=2)
    inlet = np.array(grid.center)
    inlet[0] = b[0] + 1e-3 * extents[0]
    across = [d for d in range(3) if d not in (0, axis)]
    seeds = np.tile(inlet, (24, 1))
    if across:
        d = across[0]
        seeds[:, d] = np.linspace(b[2 * d], b[2 * d + 1], 26)[1:-1][:24]
    import pyvista as pv

    tangential = np.asarray(plane.point_data["velocity"], float).copy()
    tangential[:, axis] = 0.0  # the flow within the plane
    plane.point_data["in-plane velocity"] = tangential
    lines = plane.streamlines_from_source(pv.PolyData(seeds), vectors="in-plane velocity", surface_streamlines=True,
                                          max_steps=20000, max_length=4 * max(extents), initial_step_length=0.2,
                                          step_unit="cl", integration_direction="forward")
    if lines.n_points:
        p.add_mesh(lines, color="white", line_width=1.5, opacity=0.8)
    view(p, plane.bounds, normal)
    where = f"{'xyz'[axis]} = {grid.center[axis]:.3g} m"
    save(p, out, "flow_speed.png", f"fluid speed on the grid's mid-plane {where}, solid outline, streamlines")
    largest = float(np.max(plane.point_data["speed"]))
    return Picture("flow_speed.png", "Flow", f"Fluid speed on the plane {where} (largest {largest:.3g} m/s), the "
                   f"solid's outline (black) and streamlines from the inlet (white).",
                   {"largest_speed": largest, "plane": float(grid.center[axis])})


def wetted_pressure(solid, out: Path) -> Picture | None:
    field = "pressure" if "pressure" in solid.point_data else "traction" if "traction" in solid.point_data else None
    if field is None:
        return None
    faces = surface_where(solid, field)
    if faces is None:
        return None
    title = "fluid pressure [Pa]" if field == "pressure" else "|fluid traction| [Pa]"
    faces.point_data[title] = magnitude(faces.point_data[field]) if field == "traction" else \
        np.asarray(faces.point_data[field], float)
    p = plotter()
    p.add_mesh(faces, scalars=title, cmap="cividis", scalar_bar_args=colour_bar(title))
    view(p, faces.bounds, plane_normal(faces.points))
    save(p, out, "fluid_pressure_on_faces.png", f"{title.split(' [')[0]} on the wetted faces of the solid")
    values = faces.point_data[title]
    smallest, largest = float(values.min()), float(values.max())
    return Picture("fluid_pressure_on_faces.png", "Fluid load on the rock",
                   f"The {title} on the wetted faces, from {smallest:.3g} to {largest:.3g} Pa.",
                   {"smallest": smallest, "largest": largest, "wetted_vertices": int(faces.n_points)})


def contact_face(solid, out: Path) -> list[Picture]:
    """The contact pressure and the in-contact map on the slave face."""
    if "slave" not in solid.point_data or "contact_pressure" not in solid.point_data:
        return []
    face = surface_where(solid, "slave")
    if face is None:
        return []
    normal = plane_normal(face.points)
    pictures = []
    p = plotter()
    p.add_mesh(face, scalars="contact_pressure", cmap="inferno", scalar_bar_args=colour_bar("contact pressure [Pa]"))
    view(p, face.bounds, normal)
    save(p, out, "contact_pressure.png", "contact pressure on the slave face")
    largest = float(np.max(face.point_data["contact_pressure"]))
    pictures.append(Picture("contact_pressure.png", "Contact pressure",
                            f"Contact pressure on the slave face (largest {largest:.3g} Pa).",
                            {"largest_contact_pressure": largest}))
    p = plotter()
    in_contact = np.asarray(face.point_data["in_contact"], float)
    p.add_mesh(face, scalars=in_contact, cmap=["#d9d9d9", "#b2182b"], clim=(0, 1), n_colors=2,
               scalar_bar_args={**colour_bar("in contact"), "n_labels": 2})
    view(p, face.bounds, normal)
    fraction = float(np.mean(in_contact))
    save(p, out, "contact_map.png", f"slave face in contact (red): {100 * fraction:.1f} % of its vertices")
    pictures.append(Picture("contact_map.png", "In contact", f"Slave face vertices in contact (red): "
                            f"{100 * fraction:.1f} % of them.", {"fraction_in_contact": fraction,
                                                                 "slave_vertices": int(face.n_points)}))
    return pictures


def transferred_fields(out: Path, files: list[Path]) -> Picture | None:
    """The field of the first file (the source) and the same field of the others (its transfers)
    on the mid-plane of the source across its thinnest extent, side by side, one colour range;
    white where a transfer did not reach (NaN)."""
    import pyvista as pv

    meshes = [read(f) for f in files]
    source = meshes[0]
    names = [n for n in (*source.point_data, *source.cell_data) if n != "covered"]
    if not names:
        return None
    field = names[0]
    b = source.bounds
    axis = int(np.argmin([b[1] - b[0], b[3] - b[2], b[5] - b[4]]))
    normal, origin = np.eye(3)[axis], source.center
    cuts = [m.slice(normal=normal, origin=origin) for m in meshes]
    values = [magnitude(c[field]) for c in cuts if c.n_points and field in c.array_names]
    if len(values) < len(cuts) or not all(np.isfinite(v).any() for v in values):
        return None
    clim = (min(float(np.nanmin(v)) for v in values), max(float(np.nanmax(v)) for v in values))
    p = pv.Plotter(off_screen=True, shape=(1, len(cuts)), window_size=(600 * len(cuts), 600))
    p.set_background("white")
    for i, (cut, file) in enumerate(zip(cuts, files)):
        p.subplot(0, i)
        p.add_mesh(cut, scalars=magnitude(cut[field]), clim=clim, cmap="viridis", nan_color="white",
                   scalar_bar_args=colour_bar(field) if i == len(cuts) - 1 else None, show_scalar_bar=i == len(cuts) - 1)
        p.add_text(file.stem.rsplit("_", 1)[0], position="upper_left", font_size=12, color="black")
        view(p, cut.bounds, normal)
    where = f"{'xyz'[axis]} = {origin[axis]:.3g}"
    path = out / "transfer.png"
    p.screenshot(str(path))
    p.close()
    return Picture(path.name, "Transfer", f"'{field}' on the source and on each target (" +
                   ", ".join(f.stem.rsplit("_", 1)[0] for f in files[1:]) + f") on the plane {where}.",
                   {"smallest": clim[0], "largest": clim[1]})


def render(out: Path, effects: list[str], timeout: float = 600.0) -> list[Picture]:
    """The pictures of a run's effects from its last VTU files in `out`, rendered in a child
    process: VTK's wheel and dolfinx's Debian libraries must not meet in one process (a
    render after ``import dolfinx`` aborts with std::bad_alloc), and a crash in the renderer
    must not take the coupler with it. Raises RuntimeError with the child's last words."""
    import json
    import subprocess
    import sys

    done = subprocess.run([sys.executable, "-m", __name__, str(out), *effects], capture_output=True, text=True,
                          timeout=timeout)
    if done.returncode != 0:
        last = " | ".join(done.stderr.strip().splitlines()[-3:])
        raise RuntimeError(f"the renderer exited with code {done.returncode}: {last}")
    return [Picture(**p) for p in json.loads(done.stdout.strip().splitlines()[-1])]


def render_here(out: Path, effects: list[str]) -> list[Picture]:
    """:func:`render` in this process (the child's work)."""
    pictures: list[Picture] = []
    solid_file, fluid_file = last_step(out, "solid"), last_step(out, "fluid")
    solid = read(solid_file) if solid_file else None
    if "elasticity" in effects and solid is not None and "displacement" in solid.point_data:
        pictures.append(deformed_solid(solid, out))
        pictures.append(von_mises_cut(solid, out))
    if "flow" in effects and fluid_file is not None:
        pictures.append(flow_slice(read(fluid_file), solid, out))
        if solid is not None:
            pictures.append(wetted_pressure(solid, out))
    if "contact" in effects and solid is not None:
        pictures += contact_face(solid, out)
    if "contact" in effects and "flow" in effects and fluid_file is not None:
        pictures += fracture_maps(out)
    if "transfer" in effects and last_step(out, "source") is not None:
        targets = sorted(out.glob("target_*.pvd"))
        pictures.append(transferred_fields(out, [last_step(out, "source")] + [last_step(out, t.stem) for t in targets]))
    return [p for p in pictures if p is not None]


if __name__ == "__main__":
    import json
    import sys
    from dataclasses import asdict

    made = render_here(Path(sys.argv[1]), sys.argv[2:])
    print(json.dumps([asdict(p) for p in made]))

