"""transfer.generators: self-affine rough surfaces, matched fracture pairs, the two rock blocks, the
registry of case generators."""

from __future__ import annotations

import numpy as np
import pytest

from transfer import Mesh
from transfer.generators.blocks import BLOCK_TAGS, FACE_TAGS, fracture_blocks
from transfer.generators.surfaces import (fracture_pair, measure_hurst, node_weights, rough_surface, surface_integral,
                                          surface_mean)

SIZE = (1.0, 0.5)


def _rms(h, size):
    return np.sqrt(surface_mean((h - surface_mean(h, size)) ** 2, size))


# -- surfaces -------------------------------------------------------------------
@pytest.mark.parametrize("hurst", [0.5, 0.8])
def test_rough_surface_hurst_exponent(hurst):
    h = rough_surface((256, 256), (1.0, 1.0), hurst=hurst, rms=0.01, seed=7)
    assert h.shape == (257, 257)
    # the spectrum of a periodic surface is the requested power law (random phases only)
    assert abs(measure_hurst(h, (1.0, 1.0), "spectrum") - hurst) < 0.02
    # an independent estimate: RMS height difference vs lag (biased low near H = 1)
    assert abs(measure_hurst(h, (1.0, 1.0), "variogram") - hurst) < 0.1
    # a non-periodic surface (synthesized on a larger grid and cropped)
    g = rough_surface((256, 256), (1.0, 1.0), hurst=hurst, rms=0.01, seed=7, periodic=False)
    assert not np.allclose(g[0], g[-1])
    assert abs(measure_hurst(g, (1.0, 1.0), "variogram") - hurst) < 0.1
    assert abs(measure_hurst(g, (1.0, 1.0), "spectrum") - hurst) < 0.1


def test_rough_surface_mean_rms_seed_and_cutoff():
    shape = (64, 32)
    h = rough_surface(shape, SIZE, hurst=0.8, rms=0.02, seed=3)
    assert h.shape == (65, 33)
    assert abs(surface_mean(h, SIZE)) < 1e-15 and abs(_rms(h, SIZE) - 0.02) < 1e-12
    assert np.array_equal(h[0], h[-1]) and np.array_equal(h[:, 0], h[:, -1])  # periodic
    assert np.array_equal(h, rough_surface(shape, SIZE, hurst=0.8, rms=0.02, seed=3))
    assert not np.allclose(h, rough_surface(shape, SIZE, hurst=0.8, rms=0.02, seed=4))
    g = rough_surface(shape, SIZE, hurst=0.8, rms=0.02, seed=3, periodic=False)
    assert abs(surface_mean(g, SIZE)) < 1e-15 and abs(_rms(g, SIZE) - 0.02) < 1e-12
    # cutoff: no power at wavelengths shorter than it
    c = rough_surface(shape, SIZE, hurst=0.8, rms=0.02, seed=3, cutoff=0.1)
    f = np.abs(np.fft.fft2(c[:-1, :-1])) ** 2
    k = np.hypot(*np.meshgrid(np.fft.fftfreq(64, SIZE[0] / 64), np.fft.fftfreq(32, SIZE[1] / 32), indexing="ij"))
    assert f[k > 10.0].max() < 1e-20 * f.max() and f[(k > 0) & (k <= 10.0)].min() > 0


def test_node_weights_integrate_p1_exactly():
    w = node_weights((8, 4), SIZE)
    assert abs(w.sum() - 0.5) < 1e-15
    x, y = np.meshgrid(np.linspace(0, 1, 9), np.linspace(0, 0.5, 5), indexing="ij")
    assert abs(surface_integral(1 + 2 * x - 3 * y, SIZE) - (0.5 + 0.5 - 3 * 0.125)) < 1e-14


def test_node_weights_of_a_grid_that_is_not_uniform_integrate_p1_exactly():
    """A lattice whose last cell takes a remainder (a height map's): the weights on its own axes."""
    xs, ys = np.array([0.0, 0.25, 0.5, 0.75, 1.0 - 1e-9, 1.0]), np.array([0.0, 0.2, 0.4, 0.5])
    w = node_weights((5, 3), SIZE, (xs, ys))
    assert abs(w.sum() - 0.5) < 1e-15 and w.min() > 0
    x, y = np.meshgrid(xs, ys, indexing="ij")
    assert abs(surface_integral(1 + 2 * x - 3 * y, SIZE, (xs, ys)) - (0.5 + 0.5 - 3 * 0.125)) < 1e-14
    uniform = (np.linspace(0, 1, 9), np.linspace(0, 0.5, 5))
    assert np.allclose(node_weights((8, 4), SIZE, uniform), node_weights((8, 4), SIZE), rtol=1e-13, atol=0)


def test_fracture_pair_matched_above_mismatch_length():
    shape, size, lam = (128, 64), SIZE, 0.1
    lower, upper = fracture_pair(shape, size, aperture=1.0, hurst=0.8, rms=0.01, mismatch_length=lam, seed=11)
    assert lower.shape == upper.shape == (129, 65)
    assert np.min(upper - lower) > 0.5  # no contact: the difference is the pure mismatch
    k = np.hypot(*np.meshgrid(np.fft.fftfreq(128, size[0] / 128), np.fft.fftfreq(64, size[1] / 64),
                              indexing="ij"))
    fl, fu = np.fft.fft2(lower[:-1, :-1]), np.fft.fft2(upper[:-1, :-1])
    long = (k > 0) & (k < 1 / lam)
    short = k > 1 / lam
    # identical at wavelengths above the mismatch length: no power in the aperture there
    pd = np.abs(fu - fl) ** 2
    assert pd[long].max() < 1e-24 * (np.abs(fl[long]) ** 2).max()
    # same spectrum, independent phases below: aperture power = twice a surface's power
    pl, pu = np.abs(fl[short]) ** 2, np.abs(fu[short]) ** 2
    assert np.allclose(pl, pu, rtol=1e-10)
    ratio = pd[short].sum() / pl.sum()
    assert 1.7 < ratio < 2.3
    # both faces are rough with the requested statistics
    assert abs(_rms(lower, size) - 0.01) < 1e-12 and abs(_rms(upper, size) - 0.01) < 1e-12
    assert abs(surface_mean(lower, size)) < 1e-15


def test_fracture_pair_aperture_contact_and_seed():
    shape = (64, 32)
    lower, upper = fracture_pair(shape, SIZE, aperture=0.01, hurst=0.8, rms=0.02, mismatch_length=0.25,
                                 seed=5, min_aperture=0.002)
    a = upper - lower
    contact = np.isclose(a, 0.002, rtol=0, atol=1e-15)
    assert 0.01 < contact.mean() < 0.5  # some contact
    assert a.min() >= 0.002 - 1e-15
    assert abs(surface_mean(a, SIZE) - 0.01) < 1e-12  # mean kept after the clipping
    again = fracture_pair(shape, SIZE, aperture=0.01, hurst=0.8, rms=0.02, mismatch_length=0.25,
                          seed=5, min_aperture=0.002)
    assert np.array_equal(again[0], lower) and np.array_equal(again[1], upper)
    # default min_aperture 0: surfaces touch, never cross
    lo, up = fracture_pair(shape, SIZE, aperture=0.005, rms=0.02, mismatch_length=0.25, seed=5)
    assert (up - lo).min() == 0.0 and abs(surface_mean(up - lo, SIZE) - 0.005) < 1e-12
    with pytest.raises(ValueError, match="min_aperture"):
        fracture_pair(shape, SIZE, aperture=0.001, min_aperture=0.002)


# -- blocks ---------------------------------------------------------------------
@pytest.fixture(scope="module")
def blocks():
    shape = (24, 12)
    lower, upper = fracture_pair(shape, SIZE, aperture=0.01, rms=0.02, mismatch_length=0.25, seed=2,
                                 min_aperture=0.001)
    return fracture_blocks((24, 12, 4), SIZE, 0.2, (lower, upper), origin=(1.0, -2.0), grading=1.5)


def _normals(points, tris):
    p = points[tris]
    return 0.5 * np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])  # area-weighted


def test_blocks_valid_faces_and_heights(blocks):
    for blk in (blocks.lower, blocks.upper, blocks.solid):
        mesh = Mesh(blk.points, blk.cells, "tetra")  # validation: no inverted or degenerate tet
        assert mesh.cell_measures(signed=True).min() > 0
        assert np.all(blk.cell_tags > 0)
        # the named triangles are the whole closed boundary, oriented outward: divergence theorem
        all_tris = np.concatenate(list(blk.faces.values()))
        flux = np.sum(_normals(blk.points, all_tris)[:, 2] * blk.points[all_tris][:, :, 2].mean(axis=1))
        assert abs(flux - mesh.cell_measures().sum()) < 1e-12
        assert np.abs(_normals(blk.points, all_tris).sum(axis=0)).max() < 1e-12
        assert set(FACE_TAGS) >= set(blk.faces)
    assert set(blocks.lower.faces) == {"bottom", "fracture_lower", "xmin", "xmax", "ymin", "ymax"}
    assert set(blocks.upper.faces) == {"top", "fracture_upper", "xmin", "xmax", "ymin", "ymax"}
    assert set(blocks.solid.faces) == set(FACE_TAGS)
    assert {n: len(f) for n, f in blocks.lower.faces.items()} == {
        "bottom": 576, "fracture_lower": 576, "xmin": 96, "xmax": 96, "ymin": 192, "ymax": 192}
    lower, upper = blocks.heights
    dx, dy = SIZE[0] / 24, SIZE[1] / 12
    for blk, name, h, sign in ((blocks.lower, "fracture_lower", lower, 1), (blocks.upper, "fracture_upper", upper, -1)):
        v = np.unique(blk.faces[name])
        assert len(v) == 25 * 13
        p = blk.points[v]
        i = np.rint((p[:, 0] - 1.0) / dx).astype(int)
        j = np.rint((p[:, 1] + 2.0) / dy).astype(int)
        assert np.array_equal(p[:, 2], h[i, j])  # exactly the surface heights at the nodes
        assert np.all(sign * _normals(blk.points, blk.faces[name])[:, 2] > 0)  # facing the fracture
    # aperture field at the nodes
    assert abs(surface_mean(blocks.aperture, SIZE) - 0.01) < 1e-12
    assert abs(blocks.aperture.min() - 0.001) < 1e-15
    # flat outer faces; sides where they belong
    assert np.all(blocks.lower.points[np.unique(blocks.lower.faces["bottom"]), 2] == -0.2)
    top = surface_mean(upper, SIZE) + 0.2
    assert np.allclose(blocks.upper.points[np.unique(blocks.upper.faces["top"]), 2], top, rtol=0, atol=1e-15)
    assert np.all(blocks.solid.points[np.unique(blocks.solid.faces["xmax"]), 0] == 2.0)
    assert np.all(blocks.solid.points[np.unique(blocks.solid.faces["ymin"]), 1] == -2.0)


def test_block_volumes_match_the_surface_integrals(blocks):
    lower, upper = blocks.heights
    area = SIZE[0] * SIZE[1]
    v_low = area * 0.2 + surface_integral(lower, SIZE)
    v_up = area * 0.2 - (surface_integral(upper, SIZE) - area * surface_mean(upper, SIZE))
    assert abs(blocks.lower.volume() - v_low) < 1e-14
    assert abs(blocks.upper.volume() - v_up) < 1e-14
    assert abs(blocks.upper.volume() - area * 0.2) < 1e-14
    assert abs(blocks.solid.volume() - v_low - v_up) < 1e-14
    # the void between the faces is aperture x area
    gap = (area * (0.4 + surface_mean(upper, SIZE))) - blocks.solid.volume()
    assert abs(gap - 0.01 * area) < 1e-14


def test_layers_graded_toward_the_fracture(blocks):
    z = blocks.lower.points[:, 2].reshape(5, 13, 25)[:, 0, 0]  # one column, bottom to fracture
    steps = np.diff(z)
    assert np.allclose(steps[:-1] / steps[1:], 1.5)


def test_bad_geometry_raises():
    flat = np.zeros((5, 5))
    with pytest.raises(ValueError, match="below the bottom"):
        fracture_blocks((4, 4, 2), (1, 1), 0.1, (flat - 0.2, flat + 0.1))
    with pytest.raises(ValueError, match="shape"):
        fracture_blocks((4, 3, 2), (1, 1), 0.1, (flat, flat + 0.1))
    with pytest.raises(ValueError, match="cross"):
        fracture_blocks((4, 4, 2), (1, 1), 0.1, (flat, flat - 0.01))
    # parallel plates: flat heights work
    plates = fracture_blocks((4, 4, 2), (1, 1), 0.5, (flat, flat + 0.1))
    assert abs(plates.upper.volume() - 0.5) < 1e-14 and plates.upper.points[:, 2].min() == 0.1
    assert isinstance(plates.solid.mesh, Mesh)


def test_meshio_round_trip_with_tags(blocks, tmp_path):
    meshio = pytest.importorskip("meshio")
    for blk in (blocks.lower, blocks.upper, blocks.solid):
        for suffix in (".msh", ".vtu"):
            m = meshio.read(blk.write(tmp_path / f"{blk.name}{suffix}"))
            assert np.allclose(m.points, blk.points, rtol=0, atol=1e-15)
            tets = np.concatenate([c.data for c in m.cells if c.type == "tetra"])
            assert np.array_equal(tets, blk.cells)
            tags = np.concatenate([m.cell_data["gmsh:physical"][i] for i, c in enumerate(m.cells)
                                   if c.type == "triangle"])
            tris = np.concatenate([c.data for c in m.cells if c.type == "triangle"])
            for name, faces in blk.faces.items():
                got = tris[tags == FACE_TAGS[name]]
                assert np.array_equal(np.sort(np.sort(got, 1), 0), np.sort(np.sort(faces, 1), 0))
            if suffix == ".msh":
                assert {n: int(v[0]) for n, v in m.field_data.items() if int(v[1]) == 2} == \
                    {n: FACE_TAGS[n] for n in blk.faces}
                assert all(int(m.field_data[n][1]) == 3 for n in BLOCK_TAGS if n in m.field_data)


def test_solid_fenicsx_reads_the_tags(blocks, tmp_path):
    pytest.importorskip("dolfinx")
    from mpi4py import MPI

    from solid_fenicsx.mesh import read_mesh

    comm = MPI.COMM_WORLD
    path = comm.bcast(str(blocks.solid.write(tmp_path / "solid.msh")) if comm.rank == 0 else None, root=0)
    solid = read_mesh(path)
    assert solid.boundaries == FACE_TAGS
    assert solid.num_cells == len(blocks.solid.cells)
    for name, faces in blocks.solid.faces.items():
        assert comm.allreduce(len(solid.facets(name))) == len(faces)
    # VTU keeps the tags (named by their number: meshio's VTU drops field_data)
    path = comm.bcast(str(blocks.lower.write(tmp_path / "lower.vtu")) if comm.rank == 0 else None, root=0)
    lower = read_mesh(path)
    assert lower.boundaries == {str(FACE_TAGS[n]): FACE_TAGS[n] for n in blocks.lower.faces}
    assert comm.allreduce(len(lower.facets(str(FACE_TAGS["fracture_lower"])))) == 576


def test_rough_fracture_generator_is_reproducible(tmp_path):
    """The same parameters write the same file (cases/*/make_mesh.py regenerate committed meshes)."""
    import meshio

    from transfer.generators import generate

    params = dict(shape=[8, 4, 2], size=[0.02, 0.01], height=2e-3, aperture=1e-3, min_aperture=0.5e-3,
                  rms=0.1e-3, hurst=0.8, mismatch_length=5e-3, seed=3)
    solid = generate("rough_fracture", params)
    solid.write(tmp_path / "a.msh")
    generate("rough_fracture", params).write(tmp_path / "b.msh")
    assert (tmp_path / "a.msh").read_bytes() == (tmp_path / "b.msh").read_bytes()
    m = meshio.read(tmp_path / "a.msh")
    assert sum(len(b.data) for b in m.cells if b.type == "tetra") == 2 * 8 * 4 * 2 * 6
    assert solid.info["mean_aperture"] == pytest.approx(1e-3, rel=1e-12)
    assert "mean_aperture: 0.001" in solid.describe() and "face fracture_lower: 64 triangles" in solid.describe()
