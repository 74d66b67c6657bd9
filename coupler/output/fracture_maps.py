"""Per load step of a hydro-mechanical fracture (effects contact and flow; paper 1, 4.2): the
aperture map on the fracture plane beside the fluid speed in the fracture's mid-surface (the
flow channels), both seen along the normal of the fracture plane, the contacts outlined.

The mid-surface is found per column of fluid cells across the fracture (the grid's thinnest
extent): the solid fractions of the cells below the most open cell are the lower block's
height in the column, those above it the upper block's, the open aperture the rest; the speed is
interpolated between the cell centres at half that aperture.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .drawing import Picture, colour_bar, plane_normal, read, step_files, surface_where, view

MICRO = 1e6


def grid_arrays(fluid) -> tuple[np.ndarray, np.ndarray, dict]:
    """The cells of a structured fluid grid read from VTU as arrays indexed [i, j, k] along x,
    y, z: the grid's lower corner, its spacing and ``{field: array}`` of its cell fields."""
    centres = np.asarray(fluid.cell_centers().points)
    b = np.asarray(fluid.bounds, float)
    lower, extent = b[::2], b[1::2] - b[::2]
    shape = np.array([len(np.unique(np.round((centres[:, d] - lower[d]) / extent[d], 9))) for d in range(3)])
    spacing = extent / shape
    index = np.clip(np.floor((centres - lower) / spacing).astype(int), 0, shape - 1)
    fields = {}
    for name in fluid.cell_data:
        values = np.asarray(fluid.cell_data[name], float)
        array = np.zeros((*shape, *values.shape[1:]))
        array[index[:, 0], index[:, 1], index[:, 2]] = values
        fields[name] = array
    return lower, spacing, fields


def mid_surface(fraction: np.ndarray, velocity: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per column along the last axis (cells of size `h` across the fracture): the open aperture
    ``(n - sum of fractions) h``, the mid-surface's height above the grid's lower side and the
    fluid speed there (zero where the column is closed)."""
    n = fraction.shape[-1]
    most_open = np.argmin(fraction, axis=-1)
    lower_block = np.take_along_axis(np.cumsum(fraction, axis=-1), most_open[..., None], -1)[..., 0] * h
    aperture = np.maximum(n - fraction.sum(axis=-1), 0.0) * h
    height = lower_block + aperture / 2
    s = np.clip(height / h - 0.5, 0.0, n - 1.0)  # in cell-centre units
    k = np.clip(np.floor(s).astype(int), 0, max(n - 2, 0))
    t = np.clip(s - k, 0.0, 1.0)
    speed = np.linalg.norm(velocity, axis=-1)
    below = np.take_along_axis(speed, k[..., None], -1)[..., 0]
    above = np.take_along_axis(speed, np.minimum(k + 1, n - 1)[..., None], -1)[..., 0]
    return aperture, height, np.where(aperture > 0, (1 - t) * below + t * above, 0.0)


def speed_plane(fluid):
    """The fluid speed in the fracture's mid-surface as a plane of the grid's columns (cell data
    ``speed``, the surface drawn flat at the mean mid-surface height), and the axis across."""
    import pyvista as pv

    lower, spacing, fields = grid_arrays(fluid)
    across = int(np.argmin(np.asarray(fluid.bounds)[1::2] - np.asarray(fluid.bounds)[::2]))
    fraction = np.moveaxis(fields.get("solid_fraction", np.zeros(fields["velocity"].shape[:3])), across, -1)
    velocity = np.moveaxis(fields["velocity"], across, -2)
    aperture, height, speed = mid_surface(fraction, velocity, spacing[across])
    plane_axes = [d for d in range(3) if d != across]
    shape = fraction.shape[:2]
    edges = [lower[d] + spacing[d] * np.arange(shape[i] + 1) for i, d in enumerate(plane_axes)]
    coords = [None, None, None]
    coords[plane_axes[0]], coords[plane_axes[1]] = np.meshgrid(*edges, indexing="ij")
    open_columns = aperture > 0
    level = lower[across] + (float(height[open_columns].mean()) if open_columns.any() else 0.0)
    coords[across] = np.full(coords[plane_axes[0]].shape, level)
    plane = pv.StructuredGrid(*(c[..., None] for c in coords))
    plane.cell_data["speed"] = speed.ravel(order="F")
    return plane, across


def aperture_face(solid):
    """The slave face with its aperture in micrometres (the gap, contacts as zero)."""
    face = surface_where(solid, "slave")
    if face is None:
        return None
    gap = np.maximum(np.asarray(face.point_data["gap"], float), 0.0)
    touching = np.asarray(face.point_data["in_contact"], float) > 0.5
    face.point_data["aperture [um]"] = MICRO * np.where(touching, 0.0, gap)
    return face


def fracture_map(solid, fluid, out: Path, name: str, label: str) -> Picture | None:
    """Two panels: the aperture map (cividis) and the speed in the mid-surface (viridis), each
    seen along the normal of the fracture plane, the contacts outlined in black on both."""
    import pyvista as pv

    face = aperture_face(solid)
    if face is None:
        return None
    plane, across = speed_plane(fluid)
    normal = np.eye(3)[across] * np.sign(plane_normal(face.points)[across] or 1.0)
    contacts = face.contour([0.5], scalars="in_contact") if np.any(face.point_data["in_contact"] > 0.5) else None
    p = pv.Plotter(off_screen=True, shape=(1, 2), window_size=(1600, 800))
    p.set_background("white")
    panels = ((face, "aperture [um]", "cividis", "mechanical aperture (contacts as zero)"),
              (plane, "speed [m/s]", "viridis", "fluid speed in the fracture's mid-surface"))
    for i, (mesh, title, cmap, text) in enumerate(panels):
        p.subplot(0, i)
        scalars = "speed" if mesh is plane else title
        p.add_mesh(mesh, scalars=scalars, cmap=cmap, scalar_bar_args=colour_bar(title))
        if contacts is not None and contacts.n_points:
            p.add_mesh(contacts.translate(normal * 1e-3 * plane.length, inplace=False), color="black", line_width=3)
        p.add_text(f"{label}: {text}", position="upper_left", font_size=11, color="black")
        view(p, face.bounds, normal)
    p.screenshot(str(out / name))
    p.close()
    aperture, speed = face.point_data["aperture [um]"], plane.cell_data["speed"]
    figures = {"mean_aperture_um": float(np.mean(aperture)), "largest_aperture_um": float(np.max(aperture)),
               "largest_speed": float(np.max(speed))}
    return Picture(name, f"Fracture, {label}",
                   f"{label}: the aperture on the fracture plane (mean {figures['mean_aperture_um']:.3g} um over the "
                   f"face's vertices, largest {figures['largest_aperture_um']:.3g} um; contacts outlined black) and "
                   f"the fluid speed in the mid-surface between the faces (largest {figures['largest_speed']:.3g} "
                   f"m/s): the flow channels.", figures)


def _stress_labels(out: Path) -> dict[int, str]:
    """Step index -> "step k, X MPa" from the run's summary.json (the platen's stress)."""
    path = out / "summary.json"
    steps = json.loads(path.read_text()).get("steps", []) if path.is_file() else []
    labels = {}
    for s in steps:
        stress = s.get("figures", {}).get("solid", {}).get("stress")
        labels[s["step"]] = f"step {s['step']}, {stress / 1e6:.3g} MPa" if stress is not None else f"step {s['step']}"
    return labels


def fracture_maps(out: Path) -> list[Picture]:
    """One :func:`fracture_map` per written step of the solid and fluid series in `out`
    (``fracture_step_NNNN.png``), when the solid carries the contact faces' gap."""
    labels = _stress_labels(out)
    pictures = []
    for solid_file, fluid_file in zip(step_files(out, "solid"), step_files(out, "fluid")):
        solid = read(solid_file)
        if not {"gap", "slave", "in_contact"} <= set(solid.point_data):
            return []
        step = int(solid_file.stem.rsplit("_", 1)[1])
        pictures.append(fracture_map(solid, read(fluid_file), out, f"fracture_step_{step:04d}.png",
                                     labels.get(step, f"step {step}")))
    return [p for p in pictures if p is not None]
