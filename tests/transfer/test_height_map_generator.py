"""transfer.generators.measured_fracture and .height_maps: blocks around a fracture whose faces
are height maps (an .npz of both faces, or one XYZ file per face). The faces' heights at the
lattice nodes are the map's (every map node, or every coarsen-th one: sampled, not averaged),
the two formats give the same mesh, and every bad map is refused with one line naming the
parameter and the reason."""

from __future__ import annotations

import numpy as np
import pytest

from transfer.generators import cells, generate, notes, parameters
from transfer.generators.height_maps import read_npz, read_xyz, write_npz, write_xyz
from transfer.generators.surfaces import fracture_pair

NX, NY, DX, DY = 9, 5, 2.0e-3, 3.0e-3  # map nodes along x and y, spacing [m]


def faces(seed=3):
    """(lower, upper) heights (ny, nx): a synthetic rough pair, the lower face off zero mean."""
    lower, upper = fracture_pair((NX - 1, NY - 1), ((NX - 1) * DX, (NY - 1) * DY), aperture=3e-4, rms=2e-4,
                                 mismatch_length=4e-3, seed=seed, min_aperture=0.0, periodic=False)
    return lower.T + 1.5e-3, upper.T + 1.5e-3


@pytest.fixture
def npz(tmp_path):
    lower, upper = faces()
    return str(write_npz(tmp_path / "map.npz", lower, upper, (DX, DY)))


def face_heights(block, face, dx=DX, dy=DY):
    """{(i, j): z} of a face's nodes, (i, j) the map node under them."""
    nodes = np.unique(block.faces[face])
    x, y, z = block.points[nodes].T
    i, j = np.rint(x / dx).astype(int), np.rint(y / dy).astype(int)
    assert np.abs(x - i * dx).max() < 1e-15 and np.abs(y - j * dy).max() < 1e-15  # the nodes are map nodes
    return dict(zip(zip(i.tolist(), j.tolist()), z))


def test_the_faces_are_the_map_at_every_node(npz):
    lower, upper = faces()
    block = generate("measured_fracture", {"surfaces": npz, "height": 0.01, "layers": 2})
    assert block.num_cells == cells("measured_fracture", {"surfaces": npz, "height": 0.01, "layers": 2})
    assert block.mesh.num_cells == 2 * 6 * (NX - 1) * (NY - 1) * 2  # valid, positively oriented tets
    for face, heights in (("fracture_lower", lower), ("fracture_upper", upper)):
        on_mesh = face_heights(block, face)
        assert len(on_mesh) == NX * NY
        assert max(abs(z - heights[j, i]) for (i, j), z in on_mesh.items()) <= 1e-12
    z = block.points[:, 2]
    bottom, top = np.unique(block.faces["bottom"]), np.unique(block.faces["top"])
    assert np.ptp(z[bottom]) == 0 and np.ptp(z[top]) == 0 and z[top[0]] - z[bottom[0]] > 0.02
    assert block.info["map_nodes"] == f"{NX} x {NY}" and block.info["raised_nodes"] == 0


def test_a_coarsened_lattice_samples_the_map(tmp_path):
    """coarsen = 2: every second map node, heights sampled there (not averaged over the
    neighbours); ratio = 2: the upper face on every fourth node."""
    lower, upper = faces()
    lower = np.pad(lower, ((0, 4), (0, 0)), mode="reflect")  # 9 x 9 nodes: 8 cells, divisible by 4
    upper = np.pad(upper, ((0, 4), (0, 0)), mode="reflect")
    path = write_npz(tmp_path / "map.npz", lower, upper, (DX, DY))
    block = generate("measured_fracture", {"surfaces": str(path), "height": 0.01, "layers": 1, "coarsen": 2,
                                           "ratio": 2})
    for face, heights, stride in (("fracture_lower", lower, 2), ("fracture_upper", upper, 4)):
        on_mesh = face_heights(block, face)
        assert sorted(on_mesh) == [(i, j) for i in range(0, NX, stride) for j in range(0, 9, stride)]
        assert max(abs(z - heights[j, i]) for (i, j), z in on_mesh.items()) <= 1e-12
    averaged = (lower[1:-1, 1:-1] + lower[:-2, 1:-1] + lower[2:, 1:-1] + lower[1:-1, :-2] + lower[1:-1, 2:]) / 5
    assert abs(face_heights(block, "fracture_lower")[(2, 2)] - averaged[1, 1]) > 1e-6  # sampled, not smoothed


def test_the_npz_and_the_xyz_files_give_the_same_mesh(tmp_path, npz):
    lower, upper = faces()
    xyz = {name: str(write_xyz(tmp_path / f"{name}.xyz", h, (DX, DY))) for name, h in (("lower", lower),
                                                                                        ("upper", upper))}
    shuffled = np.loadtxt(xyz["upper"])[np.random.default_rng(1).permutation(NX * NY)]  # any order of lines
    np.savetxt(xyz["upper"], shuffled, fmt="%.17g", delimiter=",")  # and commas
    a = generate("measured_fracture", {"surfaces": npz, "height": 0.01, "layers": 2})
    b = generate("measured_fracture", {**xyz, "height": 0.01, "layers": 2})
    assert np.array_equal(a.cells, b.cells) and np.array_equal(a.cell_tags, b.cell_tags)
    assert all(np.array_equal(a.faces[n], b.faces[n]) for n in a.faces)
    assert np.abs(a.points - b.points).max() <= 1e-17
    heights, spacing, origin = read_xyz(xyz["upper"])
    assert np.array_equal(heights, upper) and spacing == pytest.approx((DX, DY), rel=1e-15) and origin == (0, 0)


def test_an_xyz_map_keeps_its_origin(tmp_path):
    lower, upper = faces()
    xyz = {name: str(write_xyz(tmp_path / f"{name}.xyz", h, (DX, DY), origin=(0.5, -0.25)))
           for name, h in (("lower", lower), ("upper", upper))}
    block = generate("measured_fracture", {**xyz, "height": 0.01, "layers": 1})
    assert block.points[:, :2].min(axis=0) == pytest.approx([0.5, -0.25], abs=1e-15)
    assert block.points[:, :2].max(axis=0) == pytest.approx([0.5 + (NX - 1) * DX, -0.25 + (NY - 1) * DY], abs=1e-15)


def test_apertures_below_the_minimum_are_raised_within_the_tolerance(tmp_path):
    lower, upper = faces()
    upper[2, 3] = lower[2, 3] - 4e-6  # interpenetrating by 4 um
    path = str(write_npz(tmp_path / "map.npz", lower, upper, (DX, DY)))
    block = generate("measured_fracture", {"surfaces": path, "height": 0.01, "layers": 1, "tolerance": 5e-6,
                                           "min_aperture": 1e-6})
    assert face_heights(block, "fracture_upper")[(3, 2)] == pytest.approx(lower[2, 3] + 1e-6, abs=1e-15)
    assert block.info["raised_nodes"] == int(np.sum(upper - lower < 1e-6)) >= 1
    with pytest.raises(ValueError, match=r"^surfaces: the faces interpenetrate by 4e-06 m \(more than the "
                                         r"tolerance 1e-06 m\) at x = 0.006, y = 0.006 m from the map's origin; raise "
                                         r"them with min_aperture or accept them with tolerance$"):
        parameters("measured_fracture", {"surfaces": path, "height": 0.01, "tolerance": 1e-6})


def _npz(tmp_path, **arrays):
    lower, upper = faces()
    data = {"lower": lower, "upper": upper, "spacing": np.array([DX, DY]), **arrays}
    path = tmp_path / "bad.npz"
    np.savez(path, **{k: v for k, v in data.items() if v is not None})
    return str(path)


def _xyz(tmp_path, name, heights=None, edit=None):
    path = tmp_path / f"{name}.xyz"
    write_xyz(path, faces()[name == "upper"] if heights is None else heights, (DX, DY))
    if edit:
        lines = path.read_text().splitlines()
        path.write_text("\n".join(edit(lines)) + "\n")
    return str(path)


def _nan(h):
    h = h.copy()
    h[3, 4] = np.nan
    return h


BAD_NPZ = [
    ({"upper": None}, r"surfaces: .*bad.npz has no array 'upper' \(it holds: lower, spacing\)$"),
    ({"lower": _nan(faces()[0])}, r"surfaces: array 'lower' of .*bad.npz has 1 NaN or infinite heights, the first "
                                  r"at row 3, column 4$"),
    ({"upper": faces()[1][:, :-1]}, r"surfaces: the faces of .*bad.npz have different extents: lower \(5, 9\), "
                                    r"upper \(5, 8\) nodes \(ny, nx\)$"),
    ({"spacing": np.array([DX, 0.0])}, r"surfaces: array 'spacing' of .*bad.npz must be \[dx, dy\], two positive "
                                       r"numbers; got \[0.002, 0.0\]$"),
    ({"lower": np.zeros(5)}, r"surfaces: array 'lower' of .*bad.npz must be numbers of shape \(ny, nx\), at least "
                             r"2 x 2; got float64 \(5,\)$"),
]


@pytest.mark.parametrize("arrays, message", BAD_NPZ)
def test_a_bad_npz_map_is_named(tmp_path, arrays, message):
    with pytest.raises(ValueError, match=message):
        parameters("measured_fracture", {"surfaces": _npz(tmp_path, **arrays), "height": 0.01})


BAD_XYZ = [
    ("lower", {"heights": _nan(faces()[0])}, r"lower: .*lower.xyz has 1 NaN or infinite heights, the first at row "
                                             r"3, column 4$"),
    ("upper", {"edit": lambda lines: lines[:1] + [lines[1].replace("0 ", "0.0002 ", 1)] + lines[2:]},
     r"upper: .*upper.xyz: not a regular grid: x = 0.0002 \(point 1 of the file\) lies 0.0002 m off the grid of "
     r"spacing 0.002 m from 0 m$"),
    ("upper", {"edit": lambda lines: lines[:-1]},
     r"upper: .*upper.xyz: not a regular grid: the node x = 0.016, y = 0.012 is given 0 times \(44 points for 9 x 5 "
     r"nodes\)$"),
    ("upper", {"edit": lambda lines: lines + lines[-1:]},
     r"upper: .*upper.xyz: not a regular grid: the node x = 0.016, y = 0.012 is given 2 times"),
    ("upper", {"heights": faces()[1][:-1]}, r"upper: the faces have different extents: nodes \(ny, nx\) \(4, 9\) "
                                            r"against the lower face's \(5, 9\)$"),
    ("upper", {"edit": lambda lines: lines + ["1 2"]}, r"upper: .*upper.xyz is not a text file of x y z lines"),
]


@pytest.mark.parametrize("name, bad, message", BAD_XYZ)
def test_a_bad_xyz_map_is_named(tmp_path, name, bad, message):
    files = {face: _xyz(tmp_path, face, **(bad if face == name else {})) for face in ("lower", "upper")}
    with pytest.raises(ValueError, match=message):
        parameters("measured_fracture", {**files, "height": 0.01})


@pytest.mark.parametrize("values, message", [
    ({"surfaces": "nowhere.npz"}, r"surfaces: no file nowhere.npz$"),
    ({}, r"surfaces: give either surfaces \(an .npz of both faces\) or lower and upper \(XYZ files\)$"),
    ({"lower": "a.xyz"}, r"upper: missing \(the other face's XYZ file\)$"),
    ({"surfaces": 3}, r"surfaces: must be a file name, got 3$"),
    ({"periodic": "yes"}, r"periodic: must be true or false, got 'yes'$"),
    ({"ratio": 0}, r"ratio: must lie in \[1, inf\), got 0$"),
])
def test_bad_parameters_are_named(npz, values, message):
    values = {"surfaces": npz, **values} if "periodic" in values or "ratio" in values else values
    with pytest.raises(ValueError, match=message):
        parameters("measured_fracture", {"height": 0.01, **values})


def test_the_readers_give_what_the_writers_wrote(npz):
    (lower, upper), spacing = read_npz(npz)
    assert np.array_equal(lower, faces()[0]) and np.array_equal(upper, faces()[1]) and spacing == (DX, DY)


SCAN, SCAN_DX = 32, 0.5e-3  # a scanner's 2^n nodes per side (its cells are 2^n - 1), spacing [m]


def scan(tmp_path, periodic=False, touching=False):
    """A SCAN x SCAN node map written as an .npz: (path, lower, upper), (ny, nx) each; `periodic`: one
    period of a periodic pair (the last row and column not repeated); `touching`: the faces in first
    contact where the aperture would be negative, the upper face there one round-off step below the
    lower (as ``lower + aperture`` with a zero aperture rounds)."""
    n = SCAN if periodic else SCAN - 1  # cells of the synthesis (periodic: one more node, then left off)
    lower, upper = fracture_pair((n, n), (n * SCAN_DX, n * SCAN_DX), aperture=1e-4 if touching else 3e-4, rms=2e-4,
                                 mismatch_length=4e-3, seed=7, min_aperture=0.0, periodic=periodic)
    lower, upper = lower.T + 1.5e-3, upper.T + 1.5e-3
    if periodic:
        lower, upper = lower[:-1, :-1], upper[:-1, :-1]  # one period: n nodes, the closing row and column left off
    if touching:
        touch = upper - lower <= 0
        upper = np.where(touch, np.nextafter(lower, -np.inf), upper)
    return str(write_npz(tmp_path / "scan.npz", lower, upper, (SCAN_DX, SCAN_DX))), lower, upper


def assert_faces_are_the_map(block, lower, upper, nodes, wrap=None):
    """Each face's nodes are the map nodes `nodes` (lower face) / every second of them (upper,
    ratio 2) and its heights the map's there (`wrap`: the map's period in nodes)."""
    for face, heights in (("fracture_lower", lower), ("fracture_upper", upper)):
        on_mesh = face_heights(block, face, SCAN_DX, SCAN_DX)
        coarse = max(1, int((len(nodes) - 1) / 2 + 0.5))  # upper cells: two lower ones, the last one to three
        along = nodes if face == "fracture_lower" else np.append(nodes[:2 * coarse - 1:2], nodes[-1])
        assert sorted(on_mesh) == [(i, j) for i in along for j in along]
        period = wrap or len(heights)
        assert max(abs(z - heights[j % period, i % period]) for (i, j), z in on_mesh.items()) == 0.0


@pytest.mark.parametrize("coarsen", [2, 4, 8])
def test_a_map_of_any_node_count_loads_with_its_last_cell_taking_the_remainder(tmp_path, coarsen):
    """32 nodes are 31 cells, divisible by no coarsening: the lattice takes every coarsen-th node and
    the last node, so the mesh spans the map's extent and its faces are the map at their nodes."""
    path, lower, upper = scan(tmp_path)
    values = {"surfaces": path, "height": 0.01, "layers": 1, "coarsen": coarsen, "ratio": 2}
    block = generate("measured_fracture", values)
    n = round(31 / coarsen)
    nodes = np.append(coarsen * np.arange(n), 31)  # the last lattice cell from (n-1) coarsen to 31
    assert block.num_cells == cells("measured_fracture", values) and block.mesh.num_cells == block.num_cells
    assert block.points[:, :2].max(axis=0) == pytest.approx([31 * SCAN_DX] * 2, abs=1e-15)
    assert_faces_are_the_map(block, lower, upper, nodes)
    last = 31 - coarsen * (n - 1)
    assert f"the last {last}" in block.info["lattice"] and coarsen / 2 <= last < 1.5 * coarsen
    assert any(f"map of 32 x 32 nodes; lattice {n} x {n}" in line
               for line in notes("measured_fracture", values))


def test_a_periodic_map_is_closed_by_its_first_row_and_column(tmp_path):
    """32 nodes of one period span 32 cells (the period): coarsen 8 is 4 whole lattice cells, the
    last column and row of nodes the first's heights."""
    path, lower, upper = scan(tmp_path, periodic=True)
    assert lower.shape == (SCAN, SCAN)
    values = {"surfaces": path, "height": 0.01, "layers": 1, "coarsen": 8, "ratio": 2, "periodic": True}
    block = generate("measured_fracture", values)
    assert block.points[:, :2].max(axis=0) == pytest.approx([SCAN * SCAN_DX] * 2, abs=1e-15)
    assert_faces_are_the_map(block, lower, upper, np.arange(0, SCAN + 1, 8), wrap=SCAN)
    assert block.info["lattice"].startswith("4 x 4, map cells per lattice cell 8 (x), 8 (y)")
    assert block.info["periodic"].endswith("32 x 32 cells, 0.016 x 0.016 m")
    assert block.num_cells == cells("measured_fracture", values)
    closed = write_npz(tmp_path / "closed.npz", *(np.pad(h, ((0, 1), (0, 1)), mode="wrap") for h in (lower, upper)),
                       (SCAN_DX, SCAN_DX))  # already closed: periodic would repeat the first row and column
    with pytest.raises(ValueError, match=r"^periodic: the map's last row and column repeat its first already"):
        parameters("measured_fracture", {**values, "surfaces": str(closed)})


def test_a_pair_in_first_contact_loads_as_is(tmp_path):
    """Faces that touch at zero load, their aperture a round-off below zero, load without a key:
    the default tolerance is relative to the map's RMS height; the touching nodes close to zero
    aperture. A real overlap is still refused, and min_aperture raises the touching nodes."""
    path, lower, upper = scan(tmp_path, touching=True)
    touch = upper < lower
    assert touch.any() and (lower - upper)[touch].max() < 1e-18
    block = generate("measured_fracture", {"surfaces": path, "height": 0.01, "layers": 1, "coarsen": 4})
    assert block.info["min_aperture"] == 0.0 and block.info["raised_nodes"] == int(touch.sum())
    (note,) = notes("measured_fracture", {"surfaces": path, "height": 0.01, "coarsen": 4})[1:]
    assert note.startswith(f"measured_fracture: {int(touch.sum())} map nodes' overlaps closed to touching (up to ")
    raised = generate("measured_fracture", {"surfaces": path, "height": 0.01, "layers": 1, "coarsen": 4,
                                            "min_aperture": 1e-6})
    assert raised.info["min_aperture"] == pytest.approx(1e-6, rel=1e-9)
    upper[touch] = lower[touch] - 1e-9  # an overlap of 1 nm: 5e-6 of the RMS height
    overlap = str(write_npz(tmp_path / "overlap.npz", lower, upper, (SCAN_DX, SCAN_DX)))
    with pytest.raises(ValueError, match=r"^surfaces: the faces interpenetrate by 1e-09 m \(more than the tolerance "
                                         r"[0-9.e-]+ m, 1e-09 of the RMS height\)"):
        parameters("measured_fracture", {"surfaces": overlap, "height": 0.01})


def test_the_notes_say_the_upper_lattices_remainder_and_mesh_nothing(tmp_path, monkeypatch):
    """coarsen 4 of 31 cells: 8 lattice cells (the last 3 map cells wide: 7 x 4 + 3), ratio 3 of those
    8: upper cells of 3, 3 and 2 lower cells (before: the upper remainder went unsaid, and the notes
    built both blocks' lattices to say it)."""
    from transfer.generators import measured_fracture

    monkeypatch.setattr(measured_fracture, "mortar_lattices", None)  # notes must not mesh
    path, _, _ = scan(tmp_path)
    (line,) = notes("measured_fracture", {"surfaces": path, "height": 0.01, "coarsen": 4, "ratio": 3})
    assert line.endswith("upper lattice 3 x 3, lower cells per upper cell 3, the last 2 (x), 3, the last 2 (y)")
    even = write_npz(tmp_path / "even.npz", *(h[:25, :25] for h in scan(tmp_path)[1:]), (SCAN_DX, SCAN_DX))
    assert notes("measured_fracture", {"surfaces": str(even), "height": 0.01, "coarsen": 4, "ratio": 3}) == []


def test_a_closed_map_against_a_flat_face_is_not_closed_again(tmp_path):
    """A scan against a plate: the flat face repeats its edges trivially; the closed upper map is
    still refused with periodic (before: accepted, its first row and column repeated)."""
    _, lower, upper = scan(tmp_path, periodic=True)
    closed = np.pad(upper, ((0, 1), (0, 1)), mode="wrap")
    plate = write_npz(tmp_path / "plate.npz", np.full(closed.shape, lower.min() - 1e-3), closed, (SCAN_DX, SCAN_DX))
    with pytest.raises(ValueError, match=r"^periodic: the map's last row and column repeat its first already"):
        parameters("measured_fracture", {"surfaces": str(plate), "height": 0.01, "coarsen": 8, "periodic": True})
