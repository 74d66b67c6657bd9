"""The coupler on P MPI ranks (docs/scaling.md, step 3; coupler/run/ranks.py): small_fracture with
the Chorin fluid, with the pressure or the full traction on the rock, gives the one-rank coupler's
fields and summary to 1e-10 with the coupler on 2 ranks, each coupler rank holding a slab of the
grid and the solid cells over it (never the whole solid, whatever rank the solid's parts come
from); the transfer effect (mesh
files served in parts, the l2 and pseudo_l2 projections distributed, the exact_transfer check
from sums over the ranks' pieces) gives the one-rank run's fields, figures and check to 1e-10,
and so do the fixed solid served in parts with its checks cubic_law and lubrication
(parallel_plates, lubrication on 2 and 3 ranks), the fraction sampled at the cell centres and
hm_fracture driven by a flow rate (the control's errors stop every rank together); what would
need a whole field on one process refuses P > 1 with one line naming the scene file, the key and
the reason."""

from __future__ import annotations

import json
import re
import shutil
from types import SimpleNamespace

import meshio
import numpy as np
import pytest

from case_figures import _numbers
from cli_helpers import CHECK, transfer_case, write_mesh
from coupler import scene as scenes
from coupler.cli import main
from coupler.errors import EXIT_CODES, SceneError
from coupler.fsi.centres import centres_inside
from coupler.fsi.ranks import OPERATORS_RANKS
from coupler.plan.plan import make_plan
from coupler.run import ranks as ranks_run
from coupler.run.execute import coupler_ranks
from coupler.run.ranks import RanksRun
from test_rank_independence import TOLERANCE, assert_same, differences, run
from transfer import Mesh, StructuredGrid
from transfer.generate import box_hexahedra, box_tetrahedra
from vc_helpers import CASES, copy_case

needs_mpi = pytest.mark.skipif(shutil.which("mpirun") is None, reason="mpirun not installed")


def coupled(tmp_path, coupler: int, solid: int, fluid: int, pictures: bool = False, traction: str = "pressure"):
    """small_fracture's first step, Chorin fluid, with the coupler on `coupler` ranks (the key
    ``[coupling] ranks``: varcouple run starts itself under mpirun), its pictures rendered when
    `pictures`, the fluid's `traction` on the rock (``[coupling] traction``)."""
    keys = [f"ranks = {coupler}"] * (coupler > 1) + [f'traction = "{traction}"'] * (traction != "pressure")
    out = run(tmp_path / f"p{coupler}", solid, fluid, steps=1, fluid="chorin", fluid_tolerance="1e-7",
              coupling="\n".join(keys), pictures=pictures)
    return out


def holdings(out) -> list[dict]:
    return json.loads((out / "summary.json").read_text())["coupler_ranks"]


#: small_fracture's grid: slabs along x, cut at x = 10 cells on 2 coupler ranks
SMALL_GRID = StructuredGrid.from_bounds([0, 0, -6e-4], [0.05, 0.025, 1.6e-3], [21, 11, 11])


@needs_mpi
def test_two_coupler_ranks_give_the_serial_run(tmp_path):
    """Solid and fluid on 2 ranks each: coupler ranks 0 and 1 each talk to one rank of each; the
    fields of every VTU file (joined from each rank's piece) and every summary figure equal the
    one-rank coupler's to 1e-10, with the same iterations; each rank holds half the grid, the
    solid cells over it and a part of the interface vector only, and writes its pieces. The pictures,
    drawn after the run from the pieces, are the same files, and the figures they print (summary.json
    ``picture_figures``: largest displacement, largest von Mises on the cut, largest speed, the
    wetted faces' pressures and vertices) equal the one-rank coupler's to 1e-10 (with the rest of
    the summary)."""
    serial, ranks = coupled(tmp_path, 1, 2, 2, pictures=True), coupled(tmp_path, 2, 2, 2, pictures=True)
    assert_same(serial, ranks, "coupler on 2 ranks")
    drawn = [json.loads((d / "summary.json").read_text()) for d in (serial, ranks)]
    assert drawn[1]["pictures"] == drawn[0]["pictures"] == ["solid_displacement.png", "solid_von_mises.png",
                                                            "flow_speed.png", "fluid_pressure_on_faces.png"]
    assert drawn[1]["picture_figures"].keys() == drawn[0]["picture_figures"].keys() == set(drawn[0]["pictures"])
    assert drawn[1]["picture_figures"]["fluid_pressure_on_faces.png"]["wetted_vertices"] == 462
    assert all((ranks / name).stat().st_size > 0 for name in drawn[1]["pictures"])
    assert sorted(f.name for f in ranks.glob("*_0000*")) == [
        "fluid_0000.pvtu", "fluid_0000_p0.vtu", "fluid_0000_p1.vtu",
        "solid_0000.pvtu", "solid_0000_p0.vtu", "solid_0000_p1.vtu"]
    held = holdings(ranks)
    interface = json.loads((serial / "summary.json").read_text())["interface"]["vertices"]
    assert sum(h["interface_rows"] for h in held) == interface == 462
    assert all(0 < h["interface_rows"] < interface for h in held)
    assert len(held) == 2
    assert sum(h["grid_cells"] for h in held) == 21 * 11 * 11 and all(h["grid_cells"] < 21 * 11 * 11 for h in held)
    assert sum(h["solid_cells"] for h in held) == 4800 and all(0 < h["solid_cells"] < 4800 for h in held)
    solid_rows = json.loads((serial / "summary.json").read_text())["sizes"]["solid"]["vertices"]
    assert sum(h["solid_rows"] for h in held) == solid_rows and all(h["solid_rows"] < solid_rows for h in held)
    assert sum(h["interface_triangles"] for h in held) == 800


#: small_fracture's fraction sampled at the cell centres; the coupling to 1e-2: the binary mask makes the
#: fixed point discontinuous (at 1e-6 IQN-ILS stalls near 1e-3 as the mask flips cells), at 1e-2 it
#: converges in 3 iterations, the deformed solid's mask 12 cells off the undeformed one's
CELL_CENTRES = {'walls = "slip" ': 'solid_fraction = "cell_centre"\nwalls = "slip" ', "tolerance = 1e-6\n": "tolerance = 1e-2\n"}


@needs_mpi
def test_cell_centre_fractions_on_two_coupler_ranks(tmp_path):
    """The binary fraction of the deformed solid on 2 coupler ranks (the solid on 2 ranks, its parts
    not along the grid slabs: each slab's mask is the OR of the cells both ranks' tetrahedra hold a
    centre of): the one-rank coupler's fields and figures to 1e-10, the same iterations; the mask
    was rebuilt from the deformed solid (not the undeformed solid's)."""
    serial, ranks = (run(tmp_path / f"p{p}", 2, 1, steps=1, fluid="chorin", fluid_tolerance="1e-7",
                         scene=CELL_CENTRES, coupling=f"ranks = {p}" if p > 1 else "") for p in (1, 2))
    assert_same(serial, ranks, "cell-centre fractions, coupler on 2 ranks")
    solid, fluid = (meshio.read(serial / f"{name}_0000.vtu") for name in ("solid", "fluid"))
    masks = [centres_inside(Mesh(solid.points + u, solid.cells_dict["tetra"], "tetra", reorient=True), SMALL_GRID)
             for u in (0.0, solid.point_data["displacement"])]
    mask = fluid.cell_data["solid_fraction"][0]
    assert set(np.unique(mask)) == {0.0, 1.0} and np.array_equal(mask, masks[1]) and np.any(masks[0] != masks[1])


@pytest.mark.slow
@needs_mpi
def test_a_coupler_rank_without_participant_ranks(tmp_path):
    """Solid and fluid on one rank each: coupler rank 1 talks to none (it holds no rows of either)
    and still works its slab of the grid and the solid cells over it: the serial run to 1e-10."""
    serial, ranks = coupled(tmp_path, 1, 1, 1), coupled(tmp_path, 2, 1, 1)
    assert_same(serial, ranks, "coupler on 2 ranks, participants on 1")
    held = holdings(ranks)
    assert [h["solid_rows"] > 0 for h in held] == [True, False]
    assert [h["fluid_rows"] > 0 for h in held] == [True, False]
    assert all(h["grid_cells"] > 0 and h["solid_cells"] > 0 and h["interface_triangles"] > 0 for h in held)


@needs_mpi
def test_each_coupler_rank_works_on_the_solid_cells_over_its_slab(tmp_path):
    """The solid on one rank, the fluid on 2: coupler rank 1 talks to no solid rank (it holds none
    of the solid's rows) but works on the solid cells whose centroid lies over its grid slab (x
    beyond the cut; rank 0 those before it) and the wetted triangles that bound them, each cell in
    one rank's piece; the coordinates and fields of their vertices come from rank 0's rows, and a
    rebuild of the solid-to-grid transfer takes from the other rank only the cells near the cut
    (measured 40 and 80 of 4,800; 1,320 when rank 0 held every cell). The fields, every summary
    figure and the iterations equal the one-rank coupler's to 1e-10."""
    serial, ranks = coupled(tmp_path, 1, 1, 2), coupled(tmp_path, 2, 1, 2)
    assert_same(serial, ranks, "coupler on 2 ranks, solid on 1, fluid on 2")
    held = holdings(ranks)
    assert [h["solid_rows"] > 0 for h in held] == [True, False] and all(h["fluid_rows"] > 0 for h in held)
    assert sum(h["solid_cells"] for h in held) == 4800 and all(h["solid_cells"] > 0 for h in held)
    assert sum(h["interface_triangles"] for h in held) == 800 and all(h["interface_triangles"] > 0 for h in held)
    cut = SMALL_GRID.origin[0] + 10 * SMALL_GRID.spacing[0]
    for r, h in enumerate(held):
        piece = meshio.read(ranks / f"solid_0000_p{r}.vtu")
        x = piece.points[piece.cells_dict["tetra"]].mean(axis=1)[:, 0]
        assert len(x) == h["solid_cells"] and np.all(x < cut if r == 0 else x >= cut)
    assert sum(h["solid_to_grid_received"]["cells"] for h in held) < 4800 // 20


def assert_same_traction(serial, ranks, label: str) -> dict:
    """The fields, the summary and the iterations of two runs with traction "full" equal to 1e-10,
    the traction's figures among them (every one compared), the vertices' fits the same."""
    found = assert_same(serial, ranks, label)
    figures = [summary(d)["steps"][0]["traction"] for d in (serial, ranks)]
    assert figures[0]["fits"] == figures[1]["fits"] and figures[0]["fits"]["three samples"] > 0
    assert {f"summary /steps/0/traction/{k}" for k in ("shear_to_pressure", "viscous_force/0", "pressure_force/2")} \
        <= set(found)
    assert "solid_0000.vtu point:traction" in found
    return found


@needs_mpi
def test_full_traction_on_two_coupler_ranks(tmp_path):
    """traction = "full" (the traction (-p I + tau) n, three values per interface vertex, the wall
    shear from three velocity samples along the normal) with the solid and the fluid on one rank:
    coupler rank 1 holds none of their rows, only its slab of the grid, the solid cells and wetted
    triangles over it and half the interface vector's rows (the solid's velocity at them fetched
    from rank 0). The fields of every VTU file
    (the solid's traction among them), every summary figure (the traction's forces, ratio and fits)
    and the iterations equal the one-rank coupler's to 1e-10."""
    serial, ranks = (coupled(tmp_path, p, 1, 1, traction="full") for p in (1, 2))
    assert_same_traction(serial, ranks, "traction full, coupler on 2 ranks")
    held = holdings(ranks)
    assert all(h["interface_triangles"] > 0 for h in held) and sum(h["interface_triangles"] for h in held) == 800
    assert [h["interface_rows"] for h in held] == [231, 231]


@pytest.mark.slow
@needs_mpi
def test_full_traction_on_two_coupler_ranks_with_participant_ranks(tmp_path):
    """traction = "full" with the solid and the fluid on 2 ranks each: each coupler rank holds part
    of the wetted triangles and traces their deeper sampling surfaces from both grid slabs; the
    one-rank coupler's fields, figures and iterations to 1e-10."""
    serial, ranks = (coupled(tmp_path, p, 2, 2, traction="full") for p in (1, 2))
    assert_same_traction(serial, ranks, "traction full, coupler on 2 ranks, participants on 2")
    assert all(0 < h["interface_triangles"] < 800 for h in holdings(ranks))


@pytest.mark.slow
@needs_mpi
@pytest.mark.skipif(shutil.which("simpleFoam") is None, reason="OpenFOAM not installed")
def test_the_openfoam_fluid_on_two_coupler_ranks(tmp_path):
    """The OpenFOAM fluid (one participant process per processor of its decomposed case) and the
    solid on 2 ranks each: coupler ranks 0 and 1 each talk to one processor's process; the fields
    and the summary equal the one-rank coupler's to 1e-10, with the same iterations."""
    serial, ranks = (run(tmp_path / f"p{p}", 2, 2, steps=1, fluid="openfoam", fluid_tolerance="1e-7",
                         coupling=f"ranks = {p}" if p > 1 else "") for p in (1, 2))
    assert_same(serial, ranks, "OpenFOAM fluid, coupler on 2 ranks")
    held = holdings(ranks)
    assert all(0 < h["fluid_rows"] < 21 * 11 * 11 for h in held)


# -- the transfer effect: mesh files served in parts, the projections distributed ----------
PICTURES_OFF = "[output]\npictures = false\n"


def on_ranks(case, ranks: int):
    """The transfer scene `case` (a copy) run on `ranks` coupler ranks (``[coupling] ranks``) into
    case/out: the output directory."""
    with open(case / "scene.toml", "a") as f:
        f.write(f"\n[coupling]\nranks = {ranks}\n")
    out = case / "out"
    assert main(["run", str(case), "--output", str(out)]) == 0
    return out


def summary(out) -> dict:
    return json.loads((out / "summary.json").read_text())


@needs_mpi
def test_transfer_demo_on_two_coupler_ranks(tmp_path):
    """transfer_demo's mesh files served in two parts (coupler rank r serves part r of each file) and
    its l2 and pseudo_l2 projections distributed: every VTU field (joined from the pieces), every
    summary figure and the check's report equal the one-rank run's to 1e-10; the conservation
    errors (relative differences of two integrals, at rounding level) are below 1e-14 on both."""
    serial, ranks = (on_ranks(copy_case(CASES / "transfer_demo", tmp_path / f"p{p}",
                                        {'directory = "results"': 'directory = "results"\npictures = false'}), p)
                     for p in (1, 2))
    found = differences(serial, ranks)
    conservation = [k for k in found if k.endswith("/conservation_error")]
    assert len(conservation) == 2
    worst = max((k for k in found if k not in conservation), key=found.get)
    assert found[worst] < TOLERANCE, f"{worst} differs by {found[worst]:.2e}"
    assert "summary /check/methods/pseudo_l2/relative_interpolant_distance" in found
    assert "target_l2_0000.vtu point:pressure" in found and "target_pseudo_l2_0000.vtu point:covered" in found
    for s in map(summary, (serial, ranks)):
        assert s["check"]["passed"] and s["iterations"] == [1]
        for p in s["steps"][0]["projections"].values():
            assert p["conservation_error"] < 1e-14 and p["covered_fraction"] == 1 and p["uncovered_dofs"] == 0
    assert sorted(f.name for f in ranks.glob("target_l2_0000*")) == [
        "target_l2_0000.pvtu", "target_l2_0000_p0.vtu", "target_l2_0000_p1.vtu"]
    assert meshio.read(ranks / "target_l2_0000_p1.vtu").point_data["covered"].dtype == np.uint8  # as serially


@needs_mpi
def test_projections_on_two_ranks_reproduce_a_linear_field_and_conserve(tmp_path):
    """A linear field from jittered tetrahedra to hexahedra (a field both spaces contain) on 2
    coupler ranks: both projections give it at every target vertex (each piece) and conserve its
    integral; the check, from sums over the ranks' pieces, finds no error."""
    out = on_ranks(transfer_case(tmp_path, check=CHECK.format(exact="1 + x - 2*y + 3*z", tolerance=1e-12)
                                 + PICTURES_OFF), 2)
    s = summary(out)
    for m in s["check"]["methods"].values():
        assert m["relative_l2_error"] < 1e-13 and m["max_error"] < 1e-12
    for p in s["steps"][0]["projections"].values():
        assert p["conservation_error"] < 1e-13 and p["covered_fraction"] == 1
    for method in ("l2", "pseudo_l2"):
        pieces = sorted(out.glob(f"target_{method}_0000_p*.vtu"))
        assert len(pieces) == 2
        for piece in map(meshio.read, pieces):
            assert piece.cells[0].type == "hexahedron"
            np.testing.assert_allclose(piece.point_data["T"], 1 + piece.points @ [1.0, -2.0, 3.0], atol=1e-12)


@needs_mpi
def test_a_partly_covered_target_on_two_ranks(tmp_path):
    """A target twice as long as the source on 2 coupler ranks: the covered fraction and the
    uncovered dofs are the whole target's (not a rank's), as on one rank; each piece is NaN and not
    covered exactly where the source does not reach."""
    target = box_tetrahedra((4, 2, 2), upper=(2, 1, 1))
    runs = []
    for p in (1, 2):
        (tmp_path / f"p{p}").mkdir()
        check = CHECK.format(exact="1 + x - 2*y + 3*z", tolerance=1e-12) + PICTURES_OFF
        runs.append(summary(on_ranks(transfer_case(tmp_path / f"p{p}", check=check, target=target), p)))
    serial, ranks = (r["steps"][0]["projections"] for r in runs)
    for name, p in serial.items():
        assert 0 < p["uncovered_dofs"] == ranks[name]["uncovered_dofs"]
        assert 0 < p["covered_fraction"] == ranks[name]["covered_fraction"] < 1
        assert p["conservation_error"] < 1e-13 and ranks[name]["conservation_error"] < 1e-13
    assert runs[1]["check"]["passed"]
    for piece in map(meshio.read, sorted((tmp_path / "p2" / "out").glob("target_l2_0000_p*.vtu"))):
        covered = piece.point_data["covered"] == 1
        np.testing.assert_array_equal(covered, piece.points[:, 0] <= 1 + 1e-12)
        assert np.isnan(piece.point_data["T"][~covered]).all() and np.isfinite(piece.point_data["T"][covered]).all()


def cell_transfer(directory, ranks: int):
    """A cell field (P0) c = 1 + x - 2 y + 3 z at the centroids of jittered tetrahedra carried to
    hexahedra (Q0) twice as long (the half beyond x = 1 uncovered) on `ranks` coupler ranks,
    checked against the linear field: the output directory."""
    directory.mkdir()
    check = CHECK.format(exact="1 + x - 2*y + 3*z", tolerance=0.5) + PICTURES_OFF
    transfer_case(directory, field="c", check=check, target=box_hexahedra((4, 2, 2), upper=(2, 1, 1)))
    source = box_tetrahedra((3, 3, 3), jitter=0.2, seed=4)
    write_mesh(directory / "src.vtu", source, cell_data={"c": 1 + source.points[source.cells].mean(axis=1) @
                                                         [1.0, -2.0, 3.0]})
    return on_ranks(directory, ranks) if ranks > 1 else run_here(directory)


def run_here(case):
    out = case / "out"
    assert main(["run", str(case), "--output", str(out)]) == 0
    return out


@needs_mpi
def test_a_cell_field_transfer_on_two_and_three_coupler_ranks(tmp_path):
    """P0 -> Q0 on 2 and 3 coupler ranks (the files served in parts, their rows the cells): the
    written cell fields (pieces joined), the check's figures and the projections' covered fraction
    and uncovered cells equal the one-rank run's to 1e-12, the conservation errors (round-off) are
    below 1e-14 on every run; each piece holds cell data only, NaN and not covered exactly in its
    cells beyond the source."""
    serial = cell_transfer(tmp_path / "p1", 1)
    for p in (2, 3):
        ranks = cell_transfer(tmp_path / f"p{p}", p)
        found = differences(serial, ranks)
        conservation = [k for k in found if k.endswith("/conservation_error")]
        assert len(conservation) == 2
        worst = max((k for k in found if k not in conservation), key=found.get)
        assert found[worst] < 1e-12, f"{p} ranks: {worst} differs by {found[worst]:.2e}"
        assert {"target_l2_0000.vtu cell:c", "target_pseudo_l2_0000.vtu cell:covered", "source_0000.vtu cell:c",
                "summary /check/methods/l2/relative_l2_error"} <= set(found)
        for s in map(summary, (serial, ranks)):
            assert s["check"]["passed"] and s["sizes"]["target_l2"] == {"cells": 16, "vertices": 45}
            for projection in s["steps"][0]["projections"].values():
                assert projection["uncovered_dofs"] == 8 and projection["covered_fraction"] == 0.5
                assert projection["conservation_error"] < 1e-14
        pieces = sorted(ranks.glob("target_pseudo_l2_0000_p*.vtu"))
        assert len(pieces) == p
        for piece in map(meshio.read, pieces):
            assert not piece.point_data and piece.cells[0].type == "hexahedron"
            covered, c = piece.cell_data["covered"][0] == 1, piece.cell_data["c"][0]
            np.testing.assert_array_equal(covered, piece.points[piece.cells[0].data].mean(axis=1)[:, 0] < 1)
            assert np.isnan(c[~covered]).all() and np.isfinite(c[covered]).all()


def case_run(tmp_path, case: str, coupler: int, replace: dict, exit_code: int = 0) -> object:
    """`case` with the text replacements `replace`, the coupler on `coupler` ranks (``[coupling]
    ranks``), run to `exit_code`; its output directory."""
    scene_dir = copy_case(CASES / case, tmp_path / f"{case}{coupler}", replace)
    if coupler > 1:
        scene = scene_dir / "scene.toml"
        text = scene.read_text()
        scene.write_text(text.replace("[coupling]\n", f"[coupling]\nranks = {coupler}\n", 1) if "[coupling]\n" in text
                         else text + f"\n[coupling]\nranks = {coupler}\n")
    out = tmp_path / f"{case}{coupler}" / "out"
    assert main(["run", str(scene_dir), "--output", str(out)]) == exit_code, (case, coupler)
    return out


@needs_mpi
@pytest.mark.skipif(shutil.which("simpleFoam") is None, reason="OpenFOAM not installed")
def test_one_rank_participants_without_row_ids_on_two_coupler_ranks(tmp_path):
    """plates_fsi: the solid and the OpenFOAM fluid on one rank each give no row ids (a participant
    of one part sends its whole arrays): on 2 coupler ranks their part is rows 0..n-1, held by
    coupler rank 0, and the run gives the one-rank coupler's fields and iterations to 1e-10."""
    serial, ranks = (case_run(tmp_path, "plates_fsi", p, {}) for p in (1, 2))
    assert_same(serial, ranks, "plates_fsi, coupler on 2 ranks")
    held = holdings(ranks)
    assert [h["solid_rows"] > 0 for h in held] == [True, False] and [h["fluid_rows"] > 0 for h in held] == [True, False]


#: the IQN-ILS iterates' residuals of a transient run: its QR2 filter drops columns, which amplifies the
#: rounding of the ranks' sums (docs/scaling.md, step 4: 1e-11..1e-8 in the iterates, the same
#: iterations); the converged fields do not carry it
ITERATES = 1e-6


@needs_mpi
@pytest.mark.skipif(shutil.which("pimpleFoam") is None, reason="OpenFOAM not installed")
def test_the_added_mass_case_on_two_coupler_ranks(tmp_path):
    """added_mass_light (pimpleFoam and elastodynamics, 4 steps; Step 6's solid velocity on the grid,
    the OpenFOAM fluid's rigid bodies): on 2 coupler ranks every field and figure equals the
    one-rank coupler's to 1e-10 (measured 1.3e-12) with the same iterations per step; the coupling
    residuals of the iterates to 1e-6 (measured 5e-10; 4e-8 for added_mass_heavy, whose filter drops
    more columns)."""
    pictures = {"max_iterations = 30": "max_iterations = 30\n\n[output]\npictures = false"}
    serial, ranks = (case_run(tmp_path, "added_mass_light", p, pictures) for p in (1, 2))
    found = differences(serial, ranks)
    residuals = {k for k in found if "/residuals/" in k}
    assert residuals and max(found[k] for k in residuals) < ITERATES
    # the solid's volume outside the grid, 1.6e-6 = 1 - (volume inside) / (volume): its round-off absolutely
    outside = [summary(d)["geometry_update"]["solid_volume_outside_grid"] for d in (serial, ranks)]
    assert abs(outside[0] - outside[1]) < 1e-15
    worst = max((k for k in found if k not in residuals and "solid_volume_outside_grid" not in k), key=found.get)
    assert found[worst] < TOLERANCE, f"added_mass_light, coupler on 2 ranks: {worst} differs by {found[worst]:.2e}"
    assert "fluid_0003.vtu cell:solid_velocity" in found and "solid_0003.vtu point:velocity" in found
    assert summary(ranks)["iterations"] == summary(serial)["iterations"]


@needs_mpi
def test_a_solid_without_boundary_triangles_on_two_coupler_ranks(tmp_path):
    """standin_flow's spring solid gives no boundary triangles: the pressure is projected onto every
    solid vertex (the volume projection, distributed: each coupler rank the vertices of its solid
    parts, the interface vector every solid vertex split in the solid's row blocks). On 2 coupler
    ranks, the spring solid on 1 rank (coupler rank 1 holds no solid) and on 2, the fields, the
    figures and the iterations equal the one-rank coupler's to 1e-10; the solid's volume outside
    the grid (0 serially) is round-off."""
    no_pictures = {"max_iterations = 30": "max_iterations = 30\n\n[output]\npictures = false"}
    serial = case_run(tmp_path, "standin_flow", 1, no_pictures)
    for solid_ranks in (1, 2):
        spring = {"stiffness = 1.0e6": f"stiffness = 1.0e6\nranks = {solid_ranks}"}
        ranks = case_run(tmp_path / f"solid{solid_ranks}", "standin_flow", 2, {**no_pictures, **spring})
        assert_same_but_round_off(serial, ranks, f"spring solid on {solid_ranks}")
        assert summary(ranks)["interface"]["method"] == "volume projection"
        assert summary(ranks)["interface"]["vertices"] == summary(serial)["interface"]["vertices"] == 100
        held = holdings(ranks)
        assert [h["interface_rows"] for h in held] == [50, 50]
        assert [h["solid_rows"] > 0 for h in held] == [True, solid_ranks > 1]


#: figures that are round-off where the serial run has them 0 or near it, compared absolutely, with the
#: largest each may be: the solid's volume outside the grid (0 or one ulp of 1: its volume and the fluid
#: cells' sums in another order), the relative spread of the sections' flow rates (OpenFOAM's mass balance,
#: to its pressure solve's tolerance: 4e-10, fluid_openfoam.case.PRESSURE_TOLERANCE) and how far a flow
#: rate is from its target (a Stokes flow reaches it to round-off)
ROUND_OFF = {"/geometry_update/solid_volume_outside_grid": 1e-12, "/check/Q_spread": 1e-9,
             "/steps/0/flow_rate_control/relative_error": 1e-12}


def assert_same_but_round_off(serial, ranks, label: str) -> dict:
    """Every field, every summary figure and the check's report to 1e-10, the same iterations; the
    figures of :data:`ROUND_OFF` to 1e-15 absolutely. The differences found."""
    found = differences(serial, ranks)
    for key, largest in ROUND_OFF.items():
        figures = [summary(d) for d in (serial, ranks)]
        for part in key.strip("/").split("/"):
            figures = [f[int(part)] if isinstance(f, list) else f.get(part, {}) for f in figures]
        if figures != [{}, {}]:
            assert abs(figures[0] - figures[1]) < 1e-15 and max(figures) < largest, (label, key, figures)
    worst = max((k for k in found if k.removeprefix("summary ") not in ROUND_OFF), key=found.get)
    assert found[worst] < TOLERANCE, f"{label}: {worst} differs by {found[worst]:.2e}"
    assert summary(ranks)["iterations"] == summary(serial)["iterations"], label
    return found


#: the shipped fixed-solid cases, pictures off; parallel_plates with the Chorin fluid, its fraction exact and
#: at the cell centres, and driven by a flow rate (its check compares with the pressure drop the control found)
NO_PICTURES = {"steps = 1\n": "steps = 1\n\n[output]\npictures = false\n"}
PLATES = {**NO_PICTURES, 'participant = "openfoam"': 'participant = "chorin"  #', "max_iterations = 5000\n": ""}
FIXED_SOLID = {"parallel_plates": ("parallel_plates", PLATES),
               "parallel_plates, cell centres": ("parallel_plates", {
                   **PLATES, 'solid_fraction = "exact" ': 'solid_fraction = "cell_centre" '}),
               "parallel_plates, flow rate": ("parallel_plates", {**PLATES, "inlet_pressure = 1.0e-2 ": "flow_rate = 5.0e-11 #"}),
               "lubrication": ("lubrication", NO_PICTURES)}


@needs_mpi
@pytest.mark.parametrize("label", FIXED_SOLID)
def test_a_fixed_solid_and_its_check_on_two_and_three_coupler_ranks(tmp_path, label):
    """The fixed solid (rigid_solid, served in the coupler's process) in parts, coupler rank r its part
    r of the generated mesh, each rank working on the cells over its grid slab (parallel_plates's
    slabs cut across the gap: on 3 ranks the middle one holds none and writes no solid piece), and
    the one-way plan (the solid fraction only): on 2 and 3 coupler ranks
    every field (the pieces joined), every figure and the check's report (flow rates through the
    sections x = const summed from each rank's grid slab) equal the one-rank coupler's to 1e-10, the
    check passing as serially."""
    case, replace = FIXED_SOLID[label]
    serial = case_run(tmp_path, case, 1, replace)
    fraction = meshio.read(serial / "fluid_0000.vtu").cell_data["solid_fraction"][0]
    assert (set(np.unique(fraction)) == {0.0, 1.0}) is ("cell centres" in label)
    for p in (2, 3):
        ranks = case_run(tmp_path, case, p, replace)
        found = assert_same_but_round_off(serial, ranks, f"{case}, coupler on {p} ranks")
        assert "fluid_0000.vtu cell:solid_fraction" in found and "solid_0000.vtu point:displacement" in found
        reports = [summary(d)["check"] for d in (serial, ranks)]
        assert reports[0]["passed"] and {k: v for k, v in reports[1].items() if isinstance(v, (str, bool))} == {
            k: v for k, v in reports[0].items() if isinstance(v, (str, bool))}
        assert reports[0].keys() == reports[1].keys() and all(f"summary /check/{k}" in found
                                                              for k, v in reports[0].items() if type(v) is float)
        held = holdings(ranks)
        between = case == "parallel_plates" and p == 3  # the middle slab (y, across the gap) is fluid only
        assert [h["solid_cells"] > 0 for h in held] == [True] + [not between] * (p - 2) + [True]
        assert all(h["interface_rows"] == 0 for h in held)
        assert sum(h["solid_cells"] for h in held) == summary(serial)["sizes"]["solid"]["cells"]
        assert sorted(f.name for f in ranks.glob("solid_0000*")) == ["solid_0000.pvtu"] + [
            f"solid_0000_p{r}.vtu" for r in range(p) if held[r]["solid_cells"]]


@needs_mpi
@pytest.mark.skipif(shutil.which("simpleFoam") is None, reason="OpenFOAM not installed")
def test_parallel_plates_with_openfoam_on_two_coupler_ranks(tmp_path):
    """The shipped parallel_plates (simpleFoam on one rank, its rows held by coupler rank 0): the
    one-rank coupler's fields, figures and check to 1e-10."""
    serial, ranks = (case_run(tmp_path, "parallel_plates", p, NO_PICTURES) for p in (1, 2))
    assert_same_but_round_off(serial, ranks, "parallel_plates, OpenFOAM, coupler on 2 ranks")
    assert summary(ranks)["check"]["passed"]


#: block_compression's [check] against an x displacement 10 % y too large at y = 1 (the exact one is
#: 2.5e-5 x): the error 2.5e-6 x y / 2.75e-5 is largest, 1/11, at one vertex, x = y = 1 (P1 is exact
#: there: its own error, round-off, would differ from run to run by its whole size)
WRONG_X = {'kind = "uniaxial"\ntolerance = 1e-6': 'x = "2.5e-5 * x * (1 + 0.1 * y)"\nwhere = "z < 0.6"\ntolerance = 0.1',
           'linear_solver = "lu"': 'linear_solver = "lu"\nranks = 2'}


@needs_mpi
def test_a_displacement_check_on_two_coupler_ranks(tmp_path):
    """block_compression (solid on 2 ranks, LU) against a known wrong displacement: on 2 coupler
    ranks, each with one solid rank's vertices, the check (expression; uniaxial and sneddon share
    its comparison) reports the one-rank coupler's error, its largest at one rank's vertex, and
    the vertices of both ranks, like its fields, to 1e-10."""
    serial, ranks = (case_run(tmp_path, "block_compression", p, WRONG_X) for p in (1, 2))
    assert_same(serial, ranks, "block_compression, coupler on 2 ranks")
    reports = [json.loads((d / "summary.json").read_text())["check"] for d in (serial, ranks)]
    assert reports[1]["kind"] == "expression" and reports[1]["vertices"] == reports[0]["vertices"] == 75
    assert reports[1]["error"] == pytest.approx(1 / 11, rel=1e-6) and reports[1]["passed"]


@pytest.mark.slow
@needs_mpi
def test_sneddon_check_on_two_coupler_ranks(tmp_path):
    """pressurized_fracture (solid on one rank: its CG on 2 ranks stops where its partition lets
    it, 6e-9 apart from run to run): its Sneddon check on 2 coupler ranks, rank 1 holding no
    vertex, reports the one-rank coupler's figures to 1e-10."""
    serial, ranks = (case_run(tmp_path, "pressurized_fracture", p, {}) for p in (1, 2))
    assert_same(serial, ranks, "pressurized_fracture, coupler on 2 ranks")
    reports = [json.loads((d / "summary.json").read_text())["check"] for d in (serial, ranks)]
    assert reports[1]["kind"] == "sneddon" and reports[1]["vertices"] == reports[0]["vertices"] == 25


def hm_fracture(tmp_path, coupler: int, participants: int, replace: dict | None = None, code: int = 0):
    """cases/hm_fracture shortened (8 x 8 x 53 fluid cells, the first stress alone) with the
    coupler on `coupler` ranks and the solid and the Chorin fluid on `participants` ranks, and the
    text replacements `replace`, run to the exit `code`; its output directory."""
    ranks = f"\nranks = {participants}" if participants > 1 else ""
    slabs = '\nslab_axis = "x"' if participants > 1 else ""  # the fluid's slabs may not cut the gap's columns
    case = copy_case(CASES / "hm_fracture", tmp_path / f"hm{coupler}{participants}", {
        "shape = [16, 16, 53]": "shape = [8, 8, 53]", "stress = [1.0e6, 2.0e6, 4.0e6]": "stress = [1.0e6]",
        "steps = 3": "steps = 1", 'participant = "chorin"': f'participant = "chorin"{ranks}{slabs}',
        "max_iterations = 30": "max_iterations = 30" + (f"\nranks = {coupler}" if coupler > 1 else ""),
        **(replace or {})})
    with open(case / "scene.toml", "a") as f:
        f.write(f"\n[output]\npictures = false\n" + (f"\n[solvers.solid]{ranks}\n" if ranks else ""))
    out = tmp_path / f"hm{coupler}{participants}" / "out"
    assert main(["run", str(case), "--output", str(out)]) == code
    return out


def assert_same_fracture(serial, ranks, label: str, cancelled: tuple[str, ...] = ()) -> dict:
    """The fields of every VTU file and every summary figure to 1e-10, but the smallest gap of a
    closed contact (round-off, about 1e-18 m: below 1e-15 m on both) and the figures `cancelled`
    (differences of nearly equal numbers: to 1e-10 absolutely, as the coupling residuals); what
    :func:`differences` found."""
    found = differences(serial, ranks)
    reference = dict(_numbers(summary(serial)))
    for key in cancelled:
        found[f"summary {key}"] *= abs(reference[key])
    gaps = [k for k in found if k.endswith("/min_gap")]
    assert gaps and all(abs(json.loads((d / "summary.json").read_text())["steps"][0]["figures"]["solid"]["min_gap"])
                        < 1e-15 for d in (serial, ranks))
    worst = max((k for k in found if k not in gaps), key=found.get)
    assert found[worst] < TOLERANCE, f"{label}: {worst} differs by {found[worst]:.2e}"
    figures = [json.loads((d / "summary.json").read_text())["steps"][0]["fracture"] for d in (serial, ranks)]
    assert figures[0]["percolating"] is figures[1]["percolating"] is True
    assert 0 < figures[1]["contact_area_fraction"] < 1 and "summary /steps/0/fracture/flow_rate" in found
    assert "summary /steps/0/fracture/hydraulic_aperture_error" in found  # the fluid's coarse flow rate's estimate
    return found


@pytest.mark.slow
@needs_mpi
def test_hm_fracture_on_two_coupler_ranks(tmp_path):
    """The hydro-mechanical fracture (open pressure trace, fracture monitor) with the coupler on 2
    ranks, participants on one: coupler rank 1 holds no solid or fluid rows, only its slab of the
    grid, across whose cut (slabs along z, through the fracture) the open space percolates, and the
    solid cells over it (the upper block's: the contact share's mortar projection crosses the
    ranks). Slow: the flow-rate run below covers the same operators and holdings by default."""
    serial, ranks = hm_fracture(tmp_path, 1, 1), hm_fracture(tmp_path, 2, 1)
    assert_same_fracture(serial, ranks, "hm_fracture, coupler on 2 ranks")
    held = holdings(ranks)
    assert [h["solid_rows"] > 0 for h in held] == [True, False] and all(h["grid_cells"] for h in held)
    assert all(h["interface_triangles"] > 0 for h in held) and sum(h["interface_triangles"] for h in held) == 160


@pytest.mark.slow
@needs_mpi
def test_hm_fracture_on_two_coupler_ranks_with_participant_ranks(tmp_path):
    """Solid and Chorin fluid on 2 ranks each: each coupler rank holds part of both fracture faces
    (the contact share's mortar projection crosses the ranks); the one-rank coupler's results."""
    serial, ranks = hm_fracture(tmp_path, 1, 2), hm_fracture(tmp_path, 2, 2)
    assert_same_fracture(serial, ranks, "hm_fracture, coupler on 2 ranks, participants on 2")
    held = holdings(ranks)
    assert all(0 < h["interface_triangles"] < 160 for h in held)
    assert sum(h["interface_triangles"] for h in held) == 160


#: hm_fracture driven by a flow rate (tests/cases/test_flow_rate.py): dp about 1.4e5 Pa at 1 MPa
RATE = {"inlet_pressure = 3.0e5 ": "flow_rate = 5.0e-9 #"}


def assert_same_rate(serial, ranks, label: str) -> None:
    """The fracture's fields and figures as :func:`assert_same_fracture`, the control's among them
    (its relative error |Q / Q_target - 1|, about 6e-6, absolutely), the same iterations; the rate
    reached, the inlet pressure in no VTU (it is a figure)."""
    found = assert_same_fracture(serial, ranks, label, cancelled=("/steps/0/flow_rate_control/relative_error",))
    assert {"summary /steps/0/flow_rate_control/pressure_drop", "summary /steps/0/flow_rate_control/flow_rate",
            "summary /steps/0/flow_rate_control/relative_error"} <= set(found)
    runs = [summary(d) for d in (serial, ranks)]
    assert runs[0]["iterations"] == runs[1]["iterations"]
    control = runs[1]["steps"][0]["flow_rate_control"]
    assert control["relative_error"] <= 1e-5
    assert runs[1]["steps"][0]["fracture"]["pressure_drop"] == control["pressure_drop"]
    for piece in map(meshio.read, ranks.glob("fluid_0000_p*.vtu")):
        assert "inlet_pressure" not in piece.cell_data


@needs_mpi
def test_hm_fracture_driven_by_a_flow_rate_on_two_coupler_ranks(tmp_path):
    """The flow-rate control on 2 coupler ranks, participants on one: dp's row of the interface
    vector on rank 0, the flow rate and the percolation from both ranks' slabs; the one-rank
    coupler's fields, figures (flow_rate_control, fracture) and iterations."""
    serial, ranks = hm_fracture(tmp_path, 1, 1, RATE), hm_fracture(tmp_path, 2, 1, RATE)
    assert_same_rate(serial, ranks, "hm_fracture driven by a flow rate, coupler on 2 ranks")
    held = holdings(ranks)  # rank 1 holds no solid rows, its slab of the grid and the solid cells over it
    assert [h["solid_rows"] > 0 for h in held] == [True, False] and all(h["grid_cells"] for h in held)
    assert all(h["interface_triangles"] > 0 for h in held) and sum(h["interface_triangles"] for h in held) == 160


@pytest.mark.slow
@needs_mpi
def test_hm_fracture_driven_by_a_flow_rate_on_two_coupler_ranks_with_participant_ranks(tmp_path):
    """The same with the solid and the Chorin fluid on 2 ranks each: each coupler rank gives the
    inlet pressure to its fluid rank's part."""
    serial, ranks = hm_fracture(tmp_path, 1, 2, RATE), hm_fracture(tmp_path, 2, 2, RATE)
    assert_same_rate(serial, ranks, "hm_fracture driven by a flow rate, coupler on 2 ranks, participants on 2")


@needs_mpi
@pytest.mark.parametrize("replace, reason", [
    ({"inlet_pressure = 3.0e5 ": "flow_rate = 5.0e-8 #"},
     ", iteration 1: {scene}: [flow] flow_rate: the inlet pressure {p} Pa (pressure difference {p} "
     "Pa) reaches the confining stress 1e+06 Pa of [loads.2] stress at this step"),
    ({"E = 1.0e10": "E = 3.0e8", "shape = [16, 16, 53]": "shape = [8, 8, 27]",
      "upper = [0.02, 0.02, 0.00031]": "upper = [0.02, 0.02, 0.00032]",
      "inlet_pressure = 3.0e5 ": "flow_rate = 1.0e-11 #"},
     ": {scene}: [flow] flow_rate: no open path connects the inlet (xmin) with the outlet (xmax)"),
], ids=["confining_stress", "closed"])
def test_the_rate_control_stops_two_coupler_ranks_together(tmp_path, capfd, replace, reason):
    """An error the control decides (as tests/cases/test_flow_rate.py: ten times the rate needs an
    inlet pressure above the 1 MPa stress, found as dp is delivered; the soft rock closes, found
    as the step converges) is decided alike on both coupler ranks: one line, exit 4 on every rank,
    no rank left waiting for the other (no abort), nothing claimed."""
    out = hm_fracture(tmp_path, 2, 1, replace, code=EXIT_CODES["failed"])
    err = capfd.readouterr().err
    lines = [line for line in err.splitlines() if line.startswith("varcouple: error")]
    expected = re.escape("time step 0 (t = 0 .. 1)" + reason.format(scene=out.parent / "case" / "scene.toml", p="{p}"))
    expected = expected.replace(re.escape("{p}"), r"1\.\d+e\+06")  # the pressures the control found (1.26e6, 1.06e6)
    assert len(lines) == 1 and re.search(expected, lines[0]), err
    s = summary(out)
    assert "went on without it" not in err + s["error"] and s["status"] == "failed" and s["steps"] == []


# -- refusals: what needs a whole field on one process ------------------------------------
def refusal(tmp_path, case: str, replace: dict | None = None, append: str = "") -> str:
    scene_dir = copy_case(CASES / case, tmp_path / case, replace)
    if append:
        with open(scene_dir / "scene.toml", "a") as f:
            f.write(append)
    scene = scenes.load(scene_dir)
    with pytest.raises(SceneError) as err:
        RanksRun.admit(scene, make_plan(scene), SimpleNamespace(size=2))
    text = str(err.value)
    assert text.startswith(f"{scene.path}: ") and "\n" not in text and "2 coupler ranks" in text
    return text


def test_pictures_and_distributed_checks_are_admitted(tmp_path):
    """Pictures are drawn from the written files after the run; hertz, sneddon, uniaxial and
    expression evaluate from each rank's rows."""
    pictures = {"block_compression": {'directory = "results"': 'directory = "results"\npictures = true'}}
    for case in ("small_fracture", "pressurized_fracture", "hertz", "block_compression"):
        scene_dir = copy_case(CASES / case, tmp_path / case, pictures.get(case))
        if case not in pictures:
            with open(scene_dir / "scene.toml", "a") as f:
                f.write("\n[output]\npictures = true\n")
        scene = scenes.load(scene_dir)
        assert scene.output["pictures"] and (scene.check or case == "small_fracture")
        RanksRun.admit(scene, make_plan(scene), SimpleNamespace(size=2))


def test_the_hydro_mechanical_fracture_is_admitted(tmp_path):
    """hm_fracture's open pressure trace and fracture figures have distributed variants; a
    monitor without one is still refused, named."""
    scene_dir = copy_case(CASES / "hm_fracture", tmp_path / "hm")
    with open(scene_dir / "scene.toml", "a") as f:
        f.write("\n[output]\npictures = false\n")
    scene = scenes.load(scene_dir)
    plan = make_plan(scene)
    assert plan.monitors == ["fracture"] and "open_pressure_trace" in [e.operator for e in plan.exchanges]
    RanksRun.admit(scene, plan, SimpleNamespace(size=2))
    plan.monitors = ["fracture", "elsewhere"]
    with pytest.raises(SceneError, match=r"\[physics\] effects: the figures elsewhere need whole fields on one "
                                         r"process: not with 2 coupler ranks"):
        RanksRun.admit(scene, plan, SimpleNamespace(size=2))


def test_a_check_is_refused(tmp_path, monkeypatch):
    """A check kind without ``DISTRIBUTED`` is refused, the distributed kinds named."""
    from coupler.checks import lubrication

    monkeypatch.delattr(lubrication, "DISTRIBUTED")
    text = refusal(tmp_path, "lubrication", append="\n[output]\npictures = false\n")
    assert "[check] kind: 'lubrication' compares whole fields on one process" in text
    assert text.endswith("; on several ranks: cubic_law, exact_transfer, expression, hertz, sneddon, uniaxial")


def test_a_participant_served_whole_is_refused(tmp_path, monkeypatch):
    """A participant served in the coupler's process that is not served in parts is refused, named."""
    from coupler.run import ranks

    monkeypatch.setattr(ranks, "SERVED_IN_PARTS", ("mesh_file",))
    scene = (CASES / "parallel_plates" / "scene.toml").read_text()
    text = refusal(tmp_path, "parallel_plates", {scene[scene.index("[check]"):]: ""},
                   append="\n[output]\npictures = false\n")
    assert "[solvers.solid]: 'rigid_solid' is served whole in the coupler's process" in text


def test_full_traction_is_admitted(tmp_path):
    scene_dir = copy_case(CASES / "small_fracture", tmp_path / "full",
                          {'acceleration = "iqn-ils"': 'acceleration = "iqn-ils"\ntraction = "full"'})
    scene = scenes.load(scene_dir)
    plan = make_plan(scene)
    assert "viscous_traction" in [e.operator for e in plan.exchanges]
    RanksRun.admit(scene, plan, SimpleNamespace(size=2))


def test_an_operator_without_ranks_is_refused(tmp_path, monkeypatch):
    """The refusal's line for an operator that has no distributed variant (the table without the
    pressure trace's)."""
    monkeypatch.setattr(ranks_run, "OPERATORS_RANKS",
                        {k: v for k, v in OPERATORS_RANKS.items() if k != "pressure_trace"})
    text = refusal(tmp_path, "small_fracture", append="\n[output]\npictures = false\n")
    assert "the exchange to solid.pressure uses the operator 'pressure_trace', which needs whole fields on one " \
           "process" in text and "viscous_traction" in text


def test_the_key_and_the_job_must_agree(tmp_path, monkeypatch):
    case = copy_case(CASES / "small_fracture", tmp_path, {'acceleration = "iqn-ils"': 'acceleration = "iqn-ils"\nranks = 3'})
    scene = scenes.load(case)
    assert coupler_ranks(scene) == 3
    monkeypatch.setenv("OMPI_COMM_WORLD_SIZE", "2")
    with pytest.raises(SceneError, match=r"scene.toml: \[coupling\] ranks: 3, but this coupler runs on 2 MPI ranks"):
        coupler_ranks(scene)
