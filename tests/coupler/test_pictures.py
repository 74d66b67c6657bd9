"""Pictures and the report page of a run (coupler/output): rendered offscreen, not blank,
showing a known field's extremes where they are, and a page a real browser loads without
errors with every image resolved."""

import json
import warnings
import shutil
from pathlib import Path

import numpy as np
import pytest

from coupler.cli import main
from coupler.output import pictures
from coupler.output.report import write_page
from transfer.generate import box_tetrahedra
from vc_helpers import CASES, copy_case

VIRIDIS_MAX, VIRIDIS_MIN = np.array([253, 231, 37]), np.array([68, 1, 84])


def image(path: Path) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.open(path).convert("RGB"), dtype=float)


def not_blank(path: Path) -> None:
    """More than 5 % of the pixels differ from the (white) background, in more than one colour."""
    pixels = image(path).reshape(-1, 3)
    drawn = pixels[np.any(pixels < 250, axis=1)]
    assert len(drawn) > 0.05 * len(pixels), path
    assert np.std(drawn, axis=0).max() > 20, path


def nearest(path: Path, colour) -> np.ndarray:
    """(row, column) of the pixels closest to `colour`, averaged, above the colour bar."""
    img = image(path)
    img = img[: int(0.85 * len(img))]
    distance = np.linalg.norm(img - np.asarray(colour, float), axis=2)
    rows, cols = np.nonzero(distance <= distance.min() + 10)
    return np.array([rows.mean(), cols.mean()])


def series(out: Path, name: str, mesh) -> None:
    """`mesh` as the only step of the series `name` (as a run writes it)."""
    mesh.save(out / f"{name}_0000.vtu")
    (out / f"{name}.pvd").write_text(f'<VTKFile type="Collection"><Collection><DataSet timestep="1" '
                                     f'file="{name}_0000.vtu"/></Collection></VTKFile>')


def grid_with_speed():
    """A fluid grid (unit square, thin in z) whose speed x + y is largest at (1, 1)."""
    import pyvista as pv

    grid = pv.ImageData(dimensions=(21, 21, 3), spacing=(0.05, 0.05, 0.01)).cast_to_unstructured_grid()
    centres = grid.cell_centers().points
    grid.cell_data["velocity"] = np.column_stack([centres[:, 0] + centres[:, 1], np.zeros(len(centres)),
                                                  np.zeros(len(centres))])
    grid.cell_data["solid_fraction"] = np.zeros(grid.n_cells)
    return grid


def test_the_speed_slice_shows_the_fastest_and_slowest_corners_where_they_are(tmp_path):
    series(tmp_path, "fluid", grid_with_speed())
    assert [p.file for p in pictures.render(tmp_path, ["flow"])] == ["flow_speed.png"]
    path = tmp_path / "flow_speed.png"
    not_blank(path)
    fast, slow = nearest(path, VIRIDIS_MAX), nearest(path, VIRIDIS_MIN)
    # viewed from +z with y up: (1, 1) is the top right, (0, 0) the bottom left of the square
    assert fast[1] > slow[1] + 200 and fast[0] < slow[0] - 200, (fast, slow)


def solid_with_fields():
    """A unit cube of tets: displacement growing with x (largest at x = 1), a contact face z = 0
    in contact for x < 0.5 with a pressure 1 - x there, a fluid pressure on the top face."""
    import pyvista as pv

    mesh = box_tetrahedra((6, 6, 6))
    solid = pv.UnstructuredGrid({pv.CellType.TETRA: mesh.cells}, mesh.points)
    x = solid.points
    solid.point_data["displacement"] = np.column_stack([0.01 * x[:, 0], np.zeros(len(x)), np.zeros(len(x))])
    solid.point_data["von_mises"] = 1e6 * (1 + x[:, 0])
    slave = np.isclose(x[:, 2], 0.0)
    solid.point_data["slave"] = slave.astype(float)
    solid.point_data["in_contact"] = (slave & (x[:, 0] < 0.5)).astype(float)
    solid.point_data["contact_pressure"] = np.where(solid.point_data["in_contact"] > 0, 1e6 * (1 - x[:, 0]), 0.0)
    solid.point_data["pressure"] = np.where(np.isclose(x[:, 2], 1.0), 1e5, 0.0)
    return solid


def test_every_effect_has_its_pictures_and_none_is_blank(tmp_path):
    series(tmp_path, "solid", solid_with_fields())
    series(tmp_path, "fluid", grid_with_speed())
    made = pictures.render(tmp_path, ["elasticity", "flow", "contact"])
    assert [p.file for p in made] == ["solid_displacement.png", "solid_von_mises.png", "flow_speed.png",
                                      "fluid_pressure_on_faces.png", "contact_pressure.png", "contact_map.png"]
    for p in made:
        not_blank(tmp_path / p.file)
    assert "warped by" in made[0].caption
    only_solid = pictures.render(tmp_path, ["elasticity"])  # only what the scene simulated
    assert [p.file for p in only_solid] == ["solid_displacement.png", "solid_von_mises.png"]


def pieces(out: Path, name: str, mesh, axis: int) -> None:
    """`mesh` as the only step of the series `name` as a coupler on 2 ranks writes it: a .pvtu of
    two .vtu pieces cut at the middle along `axis`, the points on the cut in both."""
    from coupler.output.results import _arrays, _pvtu, _vtk_type

    below = mesh.cell_centers().points[:, axis] < 0.5
    names = []
    for rank, cells in enumerate((below, ~below)):
        piece = mesh.extract_cells(np.flatnonzero(cells))
        names.append(f"{name}_0000_p{rank}.vtu")
        piece.save(out / names[-1])
    layout = (_vtk_type(piece.points), _arrays({k: piece.point_data[k] for k in piece.point_data.keys()}),
              _arrays({k: piece.cell_data[k] for k in piece.cell_data.keys()}))
    (out / f"{name}_0000.pvtu").write_text(_pvtu(layout, names))
    (out / f"{name}.pvd").write_text(f'<VTKFile type="Collection"><Collection><DataSet timestep="1" '
                                     f'file="{name}_0000.pvtu"/></Collection></VTKFile>')


def test_the_pieces_of_a_coupler_on_two_ranks_draw_as_the_whole(tmp_path):
    """The solid and the fluid written in two pieces each (the pictures are drawn after the run from
    the files of a coupler on 2 ranks) are read as one connected mesh, the cut's points merged: the
    same pictures with the same figures as the whole files (the wetted faces: the top face's 49
    vertices, no face at the cut)."""
    from coupler.output.drawing import read

    whole, parts = tmp_path / "whole", tmp_path / "parts"
    whole.mkdir(), parts.mkdir()
    solid, fluid = solid_with_fields(), grid_with_speed()
    series(whole, "solid", solid), series(whole, "fluid", fluid)
    pieces(parts, "solid", solid, 0), pieces(parts, "fluid", fluid, 0)
    joined = read(parts / "solid_0000.pvtu")
    assert (joined.n_points, joined.n_cells) == (solid.n_points, solid.n_cells)
    effects = ["elasticity", "flow", "contact"]
    drawn = [{p.file: p.figures for p in pictures.render(d, effects)} for d in (whole, parts)]
    assert list(drawn[1]) == list(drawn[0]) == ["solid_displacement.png", "solid_von_mises.png", "flow_speed.png",
                                                "fluid_pressure_on_faces.png", "contact_pressure.png",
                                                "contact_map.png"]
    assert drawn[0]["fluid_pressure_on_faces.png"]["wetted_vertices"] == 49
    for file, figures in drawn[0].items():
        assert drawn[1][file] == pytest.approx(figures, rel=1e-12), file


def test_a_renderer_that_fails_says_why(tmp_path):
    (tmp_path / "solid.pvd").write_text('<DataSet timestep="1" file="missing.vtu"/>')
    with pytest.raises(RuntimeError, match="the renderer exited with code"):
        pictures.render(tmp_path, ["elasticity"])


def browse(page_path: Path) -> dict:
    """Load `page_path` in headless chromium: console problems, images [complete, width, alt],
    the body's text and the links' targets."""
    if shutil.which("chromium") is None:
        pytest.fail("chromium is not installed: scripts/install.sh installs it (the report page test needs it)")
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=shutil.which("chromium"), args=["--no-sandbox"])
        page = browser.new_page()
        problems = []
        page.on("console", lambda m: problems.append(m.text) if m.type in ("error", "warning") else None)
        page.on("pageerror", lambda e: problems.append(str(e)))
        page.goto(page_path.as_uri())
        seen = {"problems": problems,
                "images": page.evaluate("Array.from(document.images).map(i => [i.complete, i.naturalWidth, i.alt])"),
                "text": page.inner_text("body"),
                "links": page.evaluate("Array.from(document.links).map(a => a.href)")}
        browser.close()
    return seen


def test_a_run_renders_its_pictures_and_a_report_a_browser_loads(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("VARCOUPLE_PICTURES", "1")
    case = copy_case(CASES / "small_fracture", tmp_path, {"steps = 2": "steps = 1"})
    out = tmp_path / "out"
    assert main(["run", str(case), "--output", str(out)]) == 0, capsys.readouterr().err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["pictures"] == ["solid_displacement.png", "solid_von_mises.png", "flow_speed.png",
                                   "fluid_pressure_on_faces.png"]
    assert summary["phases_seconds"]["pictures"] > 0
    for name in summary["pictures"]:
        not_blank(out / name)
    seen = browse(out / "index.html")
    assert not seen["problems"], seen["problems"]
    images = seen["images"]
    assert len(images) == 5 and all(done and width > 0 for done, width, _ in images), images  # 4 + residuals
    assert "completed" in seen["text"] and "pressure_trace" in seen["text"] and "simpleFoam" in seen["text"]


def test_a_study_page_links_its_runs_and_a_browser_loads_it(tmp_path, capsys):
    out = tmp_path / "study"
    code = main(["study", str(CASES / "standin_flow"), "--vary", 'coupling.acceleration=["aitken","iqn-ils"]',
                 "-o", str(out)])
    assert code == 0, capsys.readouterr().err
    seen = browse(out / "index.html")
    assert not seen["problems"], seen["problems"]
    assert len(seen["images"]) == 1 and seen["images"][0][0] and seen["images"][0][1] > 0  # the study's plot
    runs = [link for link in seen["links"] if link.endswith("/index.html")]
    assert len(runs) == 2 and all(Path(link.removeprefix("file://")).is_file() for link in runs), seen["links"]
    for link in runs:  # each run's own page loads too
        run = browse(Path(link.removeprefix("file://")))
        assert not run["problems"] and "completed" in run["text"], run


def test_the_report_of_a_failed_run_says_so(tmp_path):
    summary = {"case": "cases/x", "status": "not_converged", "error": "InnerSolveNotConverged: boom", "steps": []}
    page = write_page(tmp_path, summary, []).read_text()
    assert 'class="status bad">not_converged' in page and "boom" in page and "No step finished" in page


def test_solvers_that_report_their_history_get_a_convergence_plot(tmp_path):
    from coupler.output.plots import solver_convergence
    from coupler.protocol.wire import SolveReport

    report = SolveReport("contact multilevel", True, 4, 1e-11, 1e-10, history=(1e-2, 1e-5, 1e-8, 1e-11))
    assert SolveReport.from_dict(report.as_dict()) == report  # the history travels
    steps = [{"step": 0, "solves": {"solid": [report.as_dict()]}}]
    assert solver_convergence(tmp_path / "convergence.png", steps)
    not_blank(tmp_path / "convergence.png")
    assert not solver_convergence(tmp_path / "none.png", [{"step": 0, "solves": {"solid": []}}])
    exact = SolveReport("contact active_set", True, 1, 0.0, 1e-10, history=(0.0,))  # its criterion exactly met
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # matplotlib warns of a log axis without positive values
        assert not solver_convergence(tmp_path / "zeros.png", [{"step": 0, "solves": {"solid": [exact.as_dict()]}}])
        assert solver_convergence(tmp_path / "both.png", [{"step": s, "solves": {"solid": [r.as_dict()]}}
                                                          for s, r in enumerate((exact, report))])


def test_the_mid_surface_lies_halfway_across_the_open_cells_of_a_column():
    """A column of six unit cells, fractions 1, 0.5, 0, 0, 0.25, 1: the lower block is 1.5 high,
    the open aperture 3.25, the mid-surface at 3.125, where a speed equal to the height is 3.125;
    a closed column has aperture and speed 0."""
    from coupler.output.fracture_maps import mid_surface

    fraction = np.array([[[1, 0.5, 0, 0, 0.25, 1], [1, 1, 1, 1, 1, 1]]], float)
    velocity = np.zeros((1, 2, 6, 3))
    velocity[..., 0] = np.arange(6) + 0.5  # the speed at each cell centre is its height
    aperture, height, speed = mid_surface(fraction, velocity, 1.0)
    assert aperture[0, 0] == pytest.approx(3.25) and height[0, 0] == pytest.approx(3.125)
    assert speed[0, 0] == pytest.approx(3.125)
    assert aperture[0, 1] == 0 and speed[0, 1] == 0


def fracture_solid():
    """The unit cube of tets as the lower block: its face z = 0 the slave face, with the gap
    1e-4 (1 - y) (widest at y = 0), in contact nowhere."""
    solid = solid_with_fields()
    y = solid.points[:, 1]
    solid.point_data["gap"] = np.where(solid.point_data["slave"] > 0, 1e-4 * (1 - y), 0.0)
    solid.point_data["in_contact"] = np.zeros(solid.n_points)
    return solid


def panel(path: Path, index: int, colour) -> np.ndarray:
    """(row, column) of the pixels closest to `colour` in panel `index` of two side by side,
    above the colour bar."""
    img = image(path)
    width = img.shape[1] // 2
    img = img[: int(0.85 * len(img)), index * width:(index + 1) * width]
    distance = np.linalg.norm(img - np.asarray(colour, float), axis=2)
    rows, cols = np.nonzero(distance <= distance.min() + 10)
    return np.array([rows.mean(), cols.mean()])


def cmap_rgb(name: str, at: float) -> np.ndarray:
    import matplotlib

    return 255 * np.asarray(matplotlib.colormaps[name](at)[:3])


def hm_summary() -> dict:
    """A run's summary with two load steps of a hydro-mechanical fracture."""
    steps = [{"step": k, "t": k + 1.0, "iterations": 3, "residuals": [1e-6], "converged": True,
              "figures": {"solid": {"stress": stress}},
              "fracture": {"mechanical_aperture": e_m, "hydraulic_aperture": e_h, "contact_area_fraction": c,
                           "flow_rate": 1e-9, "mean_face_pressure": 2.5e5}}
             for k, (stress, e_m, e_h, c) in enumerate([(1e6, 9e-5, 8e-5, 0.03), (4e6, 7e-5, 6e-5, 0.07)])]
    return {"case": "cases/hm", "status": "completed", "effects": ["elasticity", "contact", "flow"], "steps": steps}


def test_the_fracture_map_shows_the_widest_aperture_and_the_fastest_flow_where_they_are(tmp_path):
    """Per step of a contact + flow run: the aperture (widest at y = 0: bottom of the left panel)
    and the mid-surface speed (x + y: fastest at the top right of the right panel)."""
    series(tmp_path, "solid", fracture_solid())
    series(tmp_path, "fluid", grid_with_speed())
    (tmp_path / "summary.json").write_text(json.dumps(hm_summary()))
    made = pictures.render(tmp_path, ["elasticity", "contact", "flow"])
    assert [p.file for p in made][-1] == "fracture_step_0000.png"
    path = tmp_path / "fracture_step_0000.png"
    not_blank(path)
    assert made[-1].title == "Fracture, step 0, 1 MPa" and "largest 100 um" in made[-1].caption
    wide, narrow = panel(path, 0, cmap_rgb("cividis", 1.0)), panel(path, 0, cmap_rgb("cividis", 0.0))
    assert wide[0] > narrow[0] + 200 and abs(wide[1] - narrow[1]) < 50, (wide, narrow)
    fast, slow = panel(path, 1, VIRIDIS_MAX), panel(path, 1, VIRIDIS_MIN)
    assert fast[1] > slow[1] + 200 and fast[0] < slow[0] - 200, (fast, slow)
    # only for a scene with contact and flow, and a solid with the contact faces' gap
    assert "fracture_step_0000.png" not in [p.file for p in pictures.render(tmp_path, ["elasticity", "contact"])]
    series(tmp_path, "solid", solid_with_fields())
    assert "fracture_step_0000.png" not in [p.file for p in pictures.render(tmp_path, ["elasticity", "contact",
                                                                                        "flow"])]


def test_the_report_of_a_fracture_run_shows_apertures_against_stress_and_the_maps(tmp_path):
    from coupler.output.plots import apertures_plot
    from coupler.output.publish import publish

    series(tmp_path, "solid", fracture_solid())
    series(tmp_path, "fluid", grid_with_speed())
    summary = hm_summary()
    (tmp_path / "summary.json").write_text(json.dumps(summary))
    page = publish(tmp_path, summary, pictures=True, log=lambda _: None).read_text()
    assert "fracture_step_0000.png" in summary["pictures"]
    not_blank(tmp_path / "apertures.png")
    assert "Apertures against stress" in page and 'alt="apertures.png"' in page and 'alt="fracture_step_0000.png"' in page
    # e_m above e_h: the e_m line's markers (viridis blue) above the e_h line's (green) at both stresses
    e_m, e_h = nearest(tmp_path / "apertures.png", (49, 104, 142)), nearest(tmp_path / "apertures.png", (53, 183, 121))
    assert e_m[0] < e_h[0], (e_m, e_h)
    assert not apertures_plot(tmp_path / "none.png", [{"step": 0, "figures": {"solid": {"stress": 1e6}}}])


def test_the_apertures_plot_draws_the_error_estimate_of_e_h_as_bars(tmp_path):
    """Steps with ``hydraulic_aperture_error`` (15 um on an axis of about 100 um): the e_h line's
    green spans more pixel rows than without (the bars above and below each marker)."""
    from coupler.output.plots import apertures_plot

    def green_rows(path):
        img = image(path)
        return np.unique(np.nonzero(np.linalg.norm(img - np.array([53.0, 183.0, 121.0]), axis=2) < 30)[0]).size

    steps = hm_summary()["steps"]
    assert apertures_plot(tmp_path / "plain.png", steps)
    for step in steps:
        step["fracture"]["hydraulic_aperture_error"] = 1.5e-5
    assert apertures_plot(tmp_path / "bars.png", steps)
    not_blank(tmp_path / "bars.png")
    assert green_rows(tmp_path / "bars.png") > green_rows(tmp_path / "plain.png") + 20
