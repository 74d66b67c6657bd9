"""Drawing helpers the pictures of a run share (pyvista offscreen): the series' VTU files
(read as one mesh, the pieces of a coupler on several ranks joined), a white plotter, colour bars naming quantity and unit, a camera framing a box along a
normal, the faces of a solid that carry a field, and the plane a face fits."""

from __future__ import annotations

import os
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from transfer.atomic import atomic_path

os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")  # offscreen, no X server

WINDOW = (1200, 800)


@dataclass
class Picture:
    """A rendered picture: its file (in the output directory), what it shows and the figures its
    caption prints, unrounded (summary.json ``picture_figures``)."""

    file: str
    title: str
    caption: str
    figures: dict = field(default_factory=dict)


def step_files(out: Path, series: str) -> list[Path]:
    """The VTU files of ``<series>.pvd`` in `out`, in time order ([] when the series was not written)."""
    pvd = out / f"{series}.pvd"
    return [out / f for f in re.findall(r'file="([^"]+)"', pvd.read_text())] if pvd.is_file() else []


def last_step(out: Path, series: str) -> Path | None:
    """The last VTU file of ``<series>.pvd`` in `out` (None when the series was not written)."""
    files = step_files(out, series)
    return files[-1] if files else None


def read(path: Path):
    """A step's file as one mesh: a ``.vtu`` as it is; the pieces a ``.pvtu`` names (a coupler on
    several ranks, docs/scaling.md step 5) joined, the points a cut puts in several pieces merged
    into one (their coordinates and values are the same row's), so that slices, surfaces, outlines,
    point averages and streamlines see one connected mesh."""
    import pyvista as pv

    mesh = pv.read(path)
    return mesh.clean(tolerance=0.0, average_point_data=False) if Path(path).suffix == ".pvtu" else mesh


def plotter():
    """An offscreen pyvista plotter on a white background."""
    import pyvista as pv

    pv.OFF_SCREEN = True
    p = pv.Plotter(off_screen=True, window_size=WINDOW)
    p.set_background("white")
    return p


def colour_bar(title: str) -> dict:
    """A horizontal colour bar under the picture, naming the quantity and its unit."""
    return {"title": title, "color": "black", "fmt": "%.3g", "vertical": False, "position_x": 0.2,
            "position_y": 0.03, "height": 0.07, "width": 0.6, "title_font_size": 20, "label_font_size": 16}


def save(p, out: Path, name: str, text: str) -> Path:
    """Write `text` on the picture and save it as `name` in `out`."""
    p.add_text(text, position="upper_left", font_size=12, color="black")
    path = out / name
    try:
        with atomic_path(path) as tmp:
            p.screenshot(str(tmp))
    finally:
        p.close()
    return path


def view(p, bounds, normal) -> None:
    """Look along `normal` at the box `bounds` (xmin, xmax, ymin, ymax, zmin, zmax), framed."""
    normal = np.asarray(normal, float) / np.linalg.norm(normal)
    centre = np.array([(bounds[0] + bounds[1]) / 2, (bounds[2] + bounds[3]) / 2, (bounds[4] + bounds[5]) / 2])
    size = np.linalg.norm([bounds[1] - bounds[0], bounds[3] - bounds[2], bounds[5] - bounds[4]])
    up = np.array([0.0, 0.0, 1.0]) if abs(normal[2]) < 0.9 else np.array([0.0, 1.0, 0.0])
    p.camera_position = [tuple(centre + normal * 3 * size), tuple(centre), tuple(up)]
    p.reset_camera(bounds=bounds)
    p.camera.zoom(1.0)


def magnitude(values) -> np.ndarray:
    """|v| of a vector field (one row per point), |v| of a scalar one."""
    values = np.asarray(values, float)
    return np.linalg.norm(values, axis=1) if values.ndim == 2 else np.abs(values)


def surface_where(solid, field: str):
    """The boundary faces of the solid whose vertices all carry a non-zero `field`."""
    surface = solid.extract_surface(algorithm="dataset_surface")
    values = magnitude(surface.point_data[field])
    faces = surface.faces.reshape(-1, 4)[:, 1:] if surface.is_all_triangles else None
    if faces is None:
        surface = surface.triangulate()
        values = magnitude(surface.point_data[field])
        faces = surface.faces.reshape(-1, 4)[:, 1:]
    keep = np.all(values[faces] != 0, axis=1)
    return surface.extract_cells(np.flatnonzero(keep)).extract_surface(algorithm="dataset_surface") \
        if keep.any() else None


def plane_normal(points) -> np.ndarray:
    """The normal of the plane that fits `points` best (their covariance's smallest direction)."""
    centred = np.asarray(points) - np.mean(points, axis=0)
    normal = np.linalg.eigh(centred.T @ centred)[1][:, 0]
    return normal if normal[np.argmax(np.abs(normal))] > 0 else -normal
