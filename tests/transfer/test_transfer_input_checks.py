"""Honest runs: inputs the transfer used to reject wrongly, or accept silently with a wrong
or unfinished result (cell orientation, length units, quadrature degree, output files,
the error of the [transfer] scene)."""

import json
import time
import warnings

import meshio
import numpy as np
import pytest
from scipy.spatial import Delaunay

from transfer.meshfile import MeshFile
from transfer import FunctionSpace, Mesh, MeshError, OverlapWarning, QuadratureError, Transfer, TransferError
from transfer.generate import box_hexahedra, box_tetrahedra, rectangle

from cli_helpers import assert_clean_error, run_cli, write_mesh
from vc_helpers import Linear


def write_scene(case, source, target, field="T", more='method = "l2"\n'):
    """A transfer scene in the directory `case` (files relative to it); `more`: further lines."""
    case.mkdir(exist_ok=True)
    (case / "scene.toml").write_text(f'[physics]\neffects = ["transfer"]\n[transfer]\nsource = "{source}"\n'
                                     f'target = "{target}"\nfield = "{field}"\n{more}')
    return case


def run_scene(capsys, case, out):
    """stdout and summary.json of ``varcouple run CASE --output OUT``, which must succeed."""
    code, stdout, err = run_cli(capsys, "run", case, "--output", out)
    assert code == 0, err
    return stdout, json.loads((out / "summary.json").read_text())


# -- orientation: a convention of the file, not an error ---------------------------------
def delaunay_cube(n=40, seed=3):
    """scipy's Delaunay tetrahedra of the unit cube's corners and n random points: about half
    of them have negative orientation."""
    corners = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], float)
    points = np.vstack([corners, np.random.default_rng(seed).uniform(0, 1, (n, 3))])
    return points, Delaunay(points).simplices


def volumes(points, cells):
    """Signed volumes of tetrahedra, from scratch."""
    p = points[cells]
    return np.einsum("ij,ij->i", p[:, 1] - p[:, 0], np.cross(p[:, 2] - p[:, 0], p[:, 3] - p[:, 0])) / 6


def test_negative_tetrahedra_are_reordered_on_request():
    points, cells = delaunay_cube()
    negative = volumes(points, cells) < 0
    with pytest.raises(MeshError, match=r"is inverted"):  # strict by default (a deformation inverting cells)
        Mesh(points, cells, "tetra")
    m = Mesh(points, cells, "tetra", reorient=True)
    assert 0 < m.reoriented == np.count_nonzero(negative) < len(cells)
    assert np.all(volumes(m.points, m.cells) > 0)
    np.testing.assert_array_equal(np.sort(m.cells, axis=1), np.sort(cells, axis=1))  # same cells, same order
    np.testing.assert_array_equal(m.cells[~negative], cells[~negative])
    np.testing.assert_allclose(m.cell_measures().sum(), 1.0, rtol=1e-13)
    assert Mesh(m.points, m.cells, "tetra").reoriented == 0


@pytest.mark.parametrize("side", ["source", "target"])
def test_delaunay_mesh_transfers_a_linear_field_exactly(side, method):
    points, cells = delaunay_cube()
    delaunay = FunctionSpace(Mesh(points, cells, "tetra", reorient=True), "P1")
    box = FunctionSpace(box_tetrahedra((3, 4, 2), jitter=0.2, seed=5), "P1")
    source, target = (delaunay, box) if side == "source" else (box, delaunay)
    f = Linear(7)
    T = Transfer.assemble(source, target, method)
    assert T.covered.all()
    np.testing.assert_allclose(T(source.interpolate(f)), target.interpolate(f), rtol=0, atol=1e-12)


def test_mirrored_hexahedron_is_reordered_a_partly_inverted_one_is_not():
    m = box_hexahedra((2, 1, 1))
    mirrored = m.cells.copy()
    mirrored[1] = mirrored[1][[4, 5, 6, 7, 0, 1, 2, 3]]  # top and bottom swapped: every corner negative
    with pytest.raises(MeshError, match=r"cell 1 is inverted"):
        Mesh(m.points, mirrored, "hexahedron")
    fixed = Mesh(m.points, mirrored, "hexahedron", reorient=True)
    assert fixed.reoriented == 1
    np.testing.assert_array_equal(fixed.cells, m.cells)
    twisted = m.cells.copy()
    twisted[1, [0, 1]] = twisted[1, [1, 0]]  # some corners negative, others positive: not a convention
    with pytest.raises(MeshError, match=r"cell 1 is inverted"):
        Mesh(m.points, twisted, "hexahedron", reorient=True)


def test_degenerate_cells_stay_errors_with_reorient():
    points, cells = delaunay_cube()
    points = points.copy()
    points[cells[0, 3]] = points[cells[0, :3]].mean(axis=0)  # on the plane of the other three
    with pytest.raises(MeshError, match=r"degenerate"):
        Mesh(points, cells, "tetra", reorient=True)


@pytest.fixture
def delaunay_file(tmp_path):
    """A .vtu of the Delaunay cube with a cell field k = 1 + 10 x + 100 y + 1000 z at the centroids
    (different in every cell) and the linear point field T."""
    points, cells = delaunay_cube()
    k = (1 + points[cells].mean(axis=1) @ [10.0, 100.0, 1000.0])
    path = tmp_path / "delaunay.vtu"
    meshio.write(path, meshio.Mesh(points, [("tetra", cells)], point_data={"T": Linear(7)(points)},
                                   cell_data={"k": [k]}))
    return path, cells, k


def test_file_reading_reorients_and_keeps_cell_data(delaunay_file, tmp_path, capsys):
    path, cells, k = delaunay_file
    mf = MeshFile.read(path)
    assert mf.mesh.reoriented == np.count_nonzero(volumes(mf.raw.points, cells) < 0) > 0
    assert "reordered" in mf.describe()
    # P0 from the file onto itself is the identity: each value stays with its cell
    out = tmp_path / "out.vtu"
    code, stdout, err = run_cli(capsys, "transfer", path, path, "-f", "k", "-o", out, "--method", "pseudo_l2")
    assert code == 0, err
    assert f"{mf.mesh.reoriented} of {len(cells)} tetra cells" in stdout
    res = meshio.read(out)
    np.testing.assert_allclose(res.cell_data["k"][0], k, rtol=1e-13)
    np.testing.assert_array_equal(np.sort(res.cells[0].data, axis=1), np.sort(cells, axis=1))


def test_scene_records_reoriented_cells(delaunay_file, tmp_path, capsys):
    path, cells, _ = delaunay_file
    write_mesh(tmp_path / "box.vtu", box_tetrahedra((2, 2, 2)))
    stdout, summary = run_scene(capsys, write_scene(tmp_path, path.name, "box.vtu"), tmp_path / "out")
    n = np.count_nonzero(volumes(meshio.read(path).points, cells) < 0)
    figures = summary["steps"][0]["figures"]
    assert figures["source"]["reoriented_cells"] == n > 0 and figures["target_l2"]["reoriented_cells"] == 0
    assert f"{n} of {len(cells)} tetra cells had negative orientation" in stdout


# -- quadrature degree: bounded -----------------------------------------------------------
@pytest.mark.parametrize("degree", [0, 21, 99, 2.5, True])
def test_quadrature_degree_out_of_range_is_refused_at_once(degree):
    cube = FunctionSpace(box_tetrahedra((1, 1, 1)), "P1")
    start = time.perf_counter()
    with pytest.raises(QuadratureError, match=rf"quadrature degree {degree!r}.*1 to 20"):
        Transfer.assemble(cube, cube, "l2", quadrature_degree=degree)
    assert time.perf_counter() - start < 0.5
    assert issubclass(QuadratureError, TransferError) and issubclass(QuadratureError, ValueError)


def test_largest_quadrature_degree_is_accepted():
    src, dst = box_tetrahedra((1, 1, 1)), box_tetrahedra((1, 2, 1), jitter=0.1)
    T = Transfer.assemble(FunctionSpace(src, "P1"), FunctionSpace(dst, "P1"), "l2", quadrature_degree=20)
    assert T.stats["quadrature_degree"] == 20 and T.stats["quadrature_points"] == 1001
    f = Linear(3)
    np.testing.assert_allclose(T(FunctionSpace(src, "P1").interpolate(f)), f(dst.points), atol=1e-11)


def test_cli_and_scene_refuse_a_huge_quadrature_degree(delaunay_file, tmp_path, capsys):
    path, _, _ = delaunay_file
    out = tmp_path / "out.vtu"
    code, _, err = run_cli(capsys, "transfer", path, path, "-f", "T", "-o", out, "--quadrature-degree", "99")
    assert_clean_error(code, err, "--quadrature-degree", "99", "1 to 20")
    assert not out.exists()
    case = write_scene(tmp_path, path.name, path.name, more='method = "l2"\nquadrature_degree = 99\n')
    code, _, err = run_cli(capsys, "run", case)
    assert_clean_error(code, err, "scene.toml: [transfer] quadrature_degree", "99", "1 to 20")
    assert not (case / "results").exists()


# -- length units and placement: warned, with both boxes ------------------------------------
def p1(mesh):
    return FunctionSpace(mesh, "P1")


MM = box_tetrahedra((3, 3, 3), upper=(1000, 1000, 1000), jitter=0.2, seed=1, name="rock_mm.vtu")
M = box_tetrahedra((2, 2, 2), jitter=0.2, seed=2, name="fluid_m.vtu")


def test_source_in_mm_target_in_m_warns_with_both_boxes_and_the_factor():
    with pytest.warns(OverlapWarning) as caught:
        T = Transfer.assemble(p1(MM), p1(M), "l2")
    assert T.covered.all()  # fully covered: the wrong result looks complete
    assert [str(w.message) for w in caught] == T.warnings == T.stats["warnings"]
    (text,) = T.warnings
    for words in ("rock_mm.vtu", "fluid_m.vtu", "factor 1000", "[0, 0, 0]..[1000, 1000, 1000]",
                  "[0, 0, 0]..[1, 1, 1]", "units"):
        assert words in text, (words, text)


def test_target_in_mm_warns_too():
    with pytest.warns(OverlapWarning, match=r"factor 1000: .*\[0, 0, 0\]\.\.\[1, 1, 1\]"):
        T = Transfer.assemble(p1(M), p1(MM), "pseudo_l2")
    assert 0 < T.covered_fraction < 0.1


def test_small_overlap_of_both_meshes_warns():
    shifted = box_tetrahedra((2, 2, 2), lower=(0.95, 0, 0), upper=(1.95, 1, 1), name="shifted")
    with pytest.warns(OverlapWarning) as caught:
        T = Transfer.assemble(p1(M), p1(shifted), "l2")
    (text,) = T.warnings
    assert len(caught) == 1 and "5%" in text and "[0.95, 0, 0]..[1.95, 1, 1]" in text


def test_nested_meshes_and_surfaces_apart_do_not_warn():
    """A body 5 times smaller inside a grid (immersed solid) and two parallel surfaces 0.01 apart
    (contact: paired by proximity, their boxes do not overlap) are normal."""
    small = box_tetrahedra((2, 2, 2), lower=(0.4, 0.4, 0.4), upper=(0.6, 0.6, 0.6), name="small")
    top, bottom = rectangle((4, 4), height=lambda x, y: 0 * x + 0.01), rectangle((5, 3))
    with warnings.catch_warnings():
        warnings.simplefilter("error", OverlapWarning)
        for source, target in [(M, small), (small, M)]:
            assert Transfer.assemble(p1(source), p1(target), "l2").warnings == []
        assert Transfer.assemble(p1(top), p1(bottom), "pseudo_l2").warnings == []


def test_cli_and_scene_report_the_units_warning(tmp_path, capsys):
    for mesh in (MM, M):
        write_mesh(tmp_path / mesh.name, mesh, {"T": Linear(1)(mesh.points)})
    code, stdout, err = run_cli(capsys, "transfer", tmp_path / MM.name, tmp_path / M.name, "-f", "T",
                                "-o", tmp_path / "out.vtu")
    assert code == 0, err
    (line,) = [line for line in stdout.splitlines() if line.startswith("warning: ")]
    assert "factor 1000" in line and "[0, 0, 0]..[1000, 1000, 1000]" in line
    case = write_scene(tmp_path, MM.name, M.name, more='methods = ["l2", "pseudo_l2"]\n')
    stdout, summary = run_scene(capsys, case, tmp_path / "out")
    assert len(summary["warnings"]) == 1 and "factor 1000" in summary["warnings"][0]
    assert stdout.count("warning: ") == 1 and summary["warnings"][0] in stdout


# -- output files: formats that drop the field, inputs overwritten ---------------------------
@pytest.fixture
def pair(tmp_path):
    """src.vtu (tets, point field T, cell field k) and dst.vtu (hexahedra) in tmp_path/in."""
    d = tmp_path / "in"
    d.mkdir()
    src, dst = box_tetrahedra((2, 2, 2), jitter=0.2, seed=3), box_hexahedra((3, 3, 3))
    k = np.arange(src.num_cells, dtype=float)
    return write_mesh(d / "src.vtu", src, {"T": Linear(2)(src.points)}, {"k": k}), write_mesh(d / "dst.vtu", dst)


@pytest.mark.parametrize("name, field, words", [
    ("out.msh", "T", ["out.msh", "'ansys'", "point data 'T', 'covered'"]),
    ("out.stl", "k", ["out.stl", "'stl'", "hexahedron cells"]),
    ("out.ply", "T", ["out.ply", "'ply'", "hexahedron cells"]),
    ("out.inp", "k", ["out.inp", "'abaqus'", "cell data 'k', 'covered'"]),
])
def test_output_format_that_drops_the_field_is_refused(pair, tmp_path, capsys, name, field, words):
    src, dst = pair
    code, stdout, err = run_cli(capsys, "transfer", src, dst, "-f", field, "-o", tmp_path / name)
    assert_clean_error(code, err, *words, "use .vtu or .vtk")
    assert "covered" not in stdout  # refused before the transfer ran
    assert not (tmp_path / name).exists()


@pytest.mark.parametrize("name", ["out.vtk", "out.vtu"])
def test_output_formats_that_keep_the_fields_are_written(pair, tmp_path, capsys, name):
    src, dst = pair
    code, stdout, err = run_cli(capsys, "transfer", src, dst, "-f", "T", "-o", tmp_path / name)
    assert code == 0, err
    res = meshio.read(tmp_path / name)
    np.testing.assert_allclose(res.point_data["T"], Linear(2)(res.points), atol=1e-12)


def test_output_over_an_input_is_refused_and_the_input_kept(pair, tmp_path, capsys):
    src, dst = pair
    before = src.read_bytes(), dst.read_bytes()
    (tmp_path / "link.vtu").symlink_to(dst)
    (tmp_path / "sub").mkdir()
    for out, which in [(src, src), (tmp_path / "sub" / ".." / "in" / "dst.vtu", dst),
                       (tmp_path / "link.vtu", dst)]:
        code, _, err = run_cli(capsys, "transfer", src, dst, "-f", "T", "-o", out)
        assert_clean_error(code, err, str(out), f"is the input file {which}", "overwrite")
    assert (src.read_bytes(), dst.read_bytes()) == before


def test_scene_output_over_an_input_is_refused(pair, tmp_path, capsys):
    src, dst = pair
    (src.parent / "source_0000.vtu").symlink_to(src)  # what the scene writes into its output directory
    case = write_scene(tmp_path, "in/source_0000.vtu", "in/dst.vtu")  # inputs in the case: --output over them
    before = src.read_bytes()
    code, _, err = run_cli(capsys, "run", case, "--output", src.parent)
    assert_clean_error(code, err, "source_0000.vtu", "overwrite", "input of the scene")
    assert src.read_bytes() == before and not (src.parent / "summary.json").exists()


# -- the error of the [transfer] scene: against exact, by quadrature ---------------------------
@pytest.mark.parametrize("mesh, family", [(box_tetrahedra((1, 1, 1)), "P1"), (box_hexahedra((1, 1, 1)), "Q1")])
def test_l2_error_of_the_interpolant_of_x_squared(mesh, family):
    """Every vertex of the unit cube has x in {0, 1}, so the interpolant of x^2 is x:
    ||x - x^2||^2 = 1/3 - 1/2 + 1/5 = 1/30 and ||x^2||^2 = 1/5 over the cube."""
    space = FunctionSpace(mesh, family)
    square = lambda p: p[:, 0] ** 2  # noqa: E731
    error, norm = space.l2_squares(space.interpolate(square), square)
    assert error == pytest.approx(1 / 30, rel=1e-13) and norm == pytest.approx(1 / 5, rel=1e-13)


def test_l2_error_of_constants_and_linear_fields():
    cube = FunctionSpace(box_hexahedra((1, 1, 1)), "Q0")  # 1/2 against x: ||x - 1/2||^2 = 1/12
    assert cube.l2_squares(np.array([0.5]), lambda p: p[:, 0])[0] == pytest.approx(1 / 12, rel=1e-13)
    f = Linear(5)
    for space in (FunctionSpace(box_tetrahedra((3, 2, 2), jitter=0.2, seed=1), "P1"),
                  FunctionSpace(box_hexahedra((2, 3, 2), jitter=0.2, seed=1), "Q1")):
        error, norm = space.l2_squares(space.interpolate(f), f)
        assert error < 1e-30 * norm and norm > 1
        half = space.mesh.cell_vertices()[:, :, 0].mean(axis=1) < 0.5
        assert 0 < half.sum() < space.mesh.num_cells  # a subset of the cells: the norm of f there only
        assert space.l2_squares(space.interpolate(f), f, cells=half)[1] < norm


@pytest.fixture
def cube_case(tmp_path):
    """A scene directory and a function writing cube.vtu (the six tets of the unit cube) with the
    point field T = f and a scene from it onto itself, with [case] and exact = `exact`."""
    def make(f, exact, case="description"):
        cube = box_tetrahedra((1, 1, 1))
        write_mesh(tmp_path / "cube.vtu", cube, {"T": f(cube.points)})
        more = (f'methods = ["l2", "pseudo_l2"]\n[check]\nkind = "exact_transfer"\nexact = "{exact}"\ntolerance = 1.0\n'
                f'[case]\n{case} = "x^2 on the unit cube"\n')
        return write_scene(tmp_path, "cube.vtu", "cube.vtu", more=more)

    return make


@pytest.mark.parametrize("exact, error", [("x**2", np.sqrt(1 / 6)), ("1 + x - 2*y + 3*z", 0.0)])
def test_scene_reports_the_true_l2_error_and_the_interpolant_distance(cube_case, tmp_path, capsys, exact, error):
    """Source and target are the same six tetrahedra: both methods give back the source, which
    is the interpolant of exact at the target dofs (distance 0), while the L2 error of the
    interpolant of x^2 against x^2 is sqrt(1/30) / sqrt(1/5) = sqrt(1/6) (see above)."""
    f = {"x**2": lambda p: p[:, 0] ** 2, "1 + x - 2*y + 3*z": lambda p: 1 + p @ [1.0, -2.0, 3.0]}[exact]
    stdout, summary = run_scene(capsys, cube_case(f, exact), tmp_path / "out")
    assert summary["description"] == "x^2 on the unit cube"
    for m in summary["check"]["methods"].values():
        assert m["relative_interpolant_distance"] < 1e-14
        assert m["relative_l2_error"] == pytest.approx(error, rel=1e-12, abs=1e-15)
    assert stdout.count(" L2 error ") == 2


def test_case_table_keys_are_checked(cube_case, capsys):
    code, _, err = run_cli(capsys, "run", cube_case(lambda p: p[:, 0], "x", case="title"))
    assert_clean_error(code, err, "[case] title", "unknown key")
    code, stdout, err = run_cli(capsys, "check", cube_case(lambda p: p[:, 0], "x"))
    assert code == 0, err
