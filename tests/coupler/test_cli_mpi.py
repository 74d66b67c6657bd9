"""``mpirun -n 2 varcouple transfer``: rank 0 reads the two files, once, and sends the other
rank its parts; the operator is assembled and applied on both, and rank 0 writes the file the
serial run writes (fields equal to 1e-12, the same uncovered dofs); an input error is said once."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys

import meshio
import numpy as np
import pytest

from transfer.generate import box_tetrahedra
from vc_helpers import ROOT, write_xdmf

pytestmark = pytest.mark.skipif(shutil.which("mpirun") is None, reason="no mpirun")


def varcouple(*argv, ranks=1):
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1", OMP_NUM_THREADS="1",
               PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    cmd = [sys.executable, "-m", "coupler.cli", "transfer", *map(str, argv)]
    if ranks > 1:
        cmd = ["mpirun", "-n", str(ranks), "--oversubscribe", *cmd]
    return subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=ROOT, timeout=180)


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """A source with a vector point field and a cell field; a target sticking out of it."""
    d = tmp_path_factory.mktemp("mpi_cli")
    src = box_tetrahedra((5, 5, 5), jitter=0.2, seed=4)
    dst = box_tetrahedra((4, 5, 6), lower=(0.3, -0.2, 0.1), upper=(1.3, 0.9, 0.8), jitter=0.2, seed=5)
    f = np.sin(3 * src.points[:, 0]) + src.points[:, 1] * src.points[:, 2]
    meshio.write(d / "src.vtu", meshio.Mesh(src.points, [("tetra", src.cells)],
                                            point_data={"u": np.column_stack([f, -2 * f, f**2])},
                                            cell_data={"k": [np.arange(src.num_cells, dtype=float)]}))
    meshio.write(d / "dst.vtu", meshio.Mesh(dst.points, [("tetra", dst.cells)]))
    return d


@pytest.mark.parametrize("name, kind, method", [("u", "point", "l2"), ("k", "cell", "pseudo_l2")])
def test_two_ranks_write_the_serial_file(files, name, kind, method):
    outputs = {}
    for ranks in (1, 2):
        out = files / f"{name}_{ranks}.vtu"
        proc = varcouple(files / "src.vtu", files / "dst.vtu", "--field", name, "-o", out, "--method", method,
                         ranks=ranks)
        assert proc.returncode == 0, proc.stderr[-3000:]
        assert proc.stdout.count("wrote ") == 1  # rank 0 alone reports and writes
        assert ("x 2 MPI ranks" in proc.stdout) == (ranks == 2)
        if ranks == 2:  # the files are opened by rank 0 alone, each once
            assert "read    files opened per rank [2, 0]" in proc.stdout
        outputs[ranks] = meshio.read(out)
    serial, mpi = outputs[1], outputs[2]
    np.testing.assert_array_equal(serial.points, mpi.points)
    np.testing.assert_array_equal(serial.cells[0].data, mpi.cells[0].data)
    data = (lambda m: m.point_data) if kind == "point" else (lambda m: {k: v[0] for k, v in m.cell_data.items()})
    a, b = data(serial), data(mpi)
    np.testing.assert_array_equal(a["covered"], b["covered"])
    assert 0 < a["covered"].sum() < len(a["covered"])  # the target sticks out: NaN there, in both
    np.testing.assert_array_equal(np.isnan(a[name]), np.isnan(b[name]))
    assert np.nanmax(np.abs(a[name] - b[name])) <= 1e-12 * np.nanmax(np.abs(a[name]))


def test_an_input_error_is_said_once(files):
    proc = varcouple(files / "src.vtu", files / "dst.vtu", "--field", "nope", "-o", files / "x.vtu", ranks=2)
    assert proc.returncode == 2
    assert proc.stderr.count("varcouple: error:") == 1
    assert "src.vtu: no field 'nope'" in proc.stderr and "Traceback" not in proc.stderr


def by_coordinates(m: meshio.Mesh, name: str, kind: str) -> np.ndarray:
    """The point (cell) field `name` of `m` in the lexicographic order of the points (cell centres)."""
    if kind == "point":
        return m.point_data[name][np.lexsort(m.points.T[::-1])]
    return m.cell_data[name][0][np.lexsort(m.points[m.cells[0].data].mean(axis=1).T[::-1])]


@pytest.mark.parametrize("name, kind, method", [("u", "point", "l2"), ("k", "cell", "pseudo_l2")])
def test_pieces_are_read_by_their_ranks(files, tmp_path, name, kind, method):
    """SRC and DST as .pvtu of 3 pieces each: rank 0 opens pieces 0 and 1 of each, rank 1 piece 2;
    the output is the same on 1 and 2 ranks and is the whole-file run's, point by point (cell by cell)."""
    from coupler.output.results import write_pieces
    from transfer import Mesh
    from transfer.partition import slabs

    for file in ("src", "dst"):
        mesh = meshio.read(files / f"{file}.vtu")
        write_pieces(mesh, tmp_path / f"{file}.pvtu", slabs(Mesh.from_meshio(mesh), 3, axis=0))
    outputs = {}
    for ranks in (1, 2):
        out = tmp_path / f"out_{ranks}.vtu"
        proc = varcouple(tmp_path / "src.pvtu", tmp_path / "dst.pvtu", "--field", name, "-o", out,
                         "--method", method, ranks=ranks)
        assert proc.returncode == 0, proc.stderr[-3000:]
        assert f"read    files opened per rank {[6] if ranks == 1 else [4, 2]}" in proc.stdout
        cells = [sum(len(meshio.read(tmp_path / f"{file}_p{i}.vtu").cells[0].data) for file in ("src", "dst")
                     for i in held) for held in ([range(3)] if ranks == 1 else [range(2), range(2, 3)])]
        assert f"cells read per rank {cells}" in proc.stdout  # each rank its own pieces' cells, no more
        outputs[ranks] = meshio.read(out)
    whole = tmp_path / "whole.vtu"
    proc = varcouple(files / "src.vtu", files / "dst.vtu", "--field", name, "-o", whole, "--method", method)
    assert proc.returncode == 0, proc.stderr[-3000:]
    serial, mpi, whole = outputs[1], outputs[2], meshio.read(whole)
    assert len(serial.points) == len(whole.points) and len(serial.cells[0].data) == len(whole.cells[0].data)
    np.testing.assert_array_equal(serial.points, mpi.points)
    np.testing.assert_array_equal(serial.cells[0].data, mpi.cells[0].data)
    for a, b in ((serial, mpi), (serial, whole)):
        np.testing.assert_array_equal(*(m.points[np.lexsort(m.points.T[::-1])] for m in (a, b)))
        np.testing.assert_array_equal(by_coordinates(a, "covered", kind), by_coordinates(b, "covered", kind))
        u, v = by_coordinates(a, name, kind), by_coordinates(b, name, kind)
        assert 0 < np.isnan(u).reshape(len(u), -1).any(axis=1).sum() < len(u)  # the target sticks out: NaN there
        np.testing.assert_array_equal(np.isnan(u), np.isnan(v))
        assert np.nanmax(np.abs(u - v)) <= 1e-12 * np.nanmax(np.abs(u))


def test_a_bad_piece_on_rank_1_is_said_once_by_rank_0(files, tmp_path):
    """The third piece (rank 1's) is missing: every rank stops with exit 2, rank 0 says which."""
    from coupler.output.results import write_pieces
    from transfer import Mesh
    from transfer.partition import slabs

    mesh = meshio.read(files / "src.vtu")
    write_pieces(mesh, tmp_path / "src.pvtu", slabs(Mesh.from_meshio(mesh), 3, axis=0))
    (tmp_path / "src_p2.vtu").unlink()
    proc = varcouple(tmp_path / "src.pvtu", files / "dst.vtu", "--field", "u", "-o", tmp_path / "x.vtu", ranks=2)
    assert proc.returncode == 2, proc.stderr[-3000:]
    assert proc.stderr.count("varcouple: error:") == 1
    assert "src_p2.vtu: file not found" in proc.stderr and "Traceback" not in proc.stderr
    assert not (tmp_path / "x.vtu").exists()


def test_an_xdmf_target_is_read_by_rows(files, tmp_path):
    """DST converted to XDMF + HDF5 by ``mpirun -n 2 python -m solid_fenicsx.convert``: each rank
    reads its own topology rows and the points they use (rank 0 also opens SRC: [2, 1]); the
    output is the same on 1 and 2 ranks and is the .vtu run's, point by point."""
    pytest.importorskip("dolfinx")
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1", OMP_NUM_THREADS="1")
    subprocess.run(["mpirun", "-n", "2", "--oversubscribe", sys.executable, "-m", "solid_fenicsx.convert",
                    str(files / "dst.vtu"), str(tmp_path / "dst.xdmf")], check=True, env=env, cwd=ROOT,
                   capture_output=True, timeout=180)
    outputs = {}
    for ranks, opened in ((1, [2]), (2, [2, 1]), (0, None)):
        out = tmp_path / f"out_{ranks}.vtu"
        target = files / "dst.vtu" if ranks == 0 else tmp_path / "dst.xdmf"  # 0: the .vtu, serially
        proc = varcouple(files / "src.vtu", target, "--field", "u", "-o", out, ranks=max(ranks, 1))
        assert proc.returncode == 0, proc.stderr[-3000:]
        assert opened is None or f"read    files opened per rank {opened}" in proc.stdout
        outputs[ranks] = meshio.read(out)
    np.testing.assert_array_equal(outputs[1].points, outputs[2].points)
    np.testing.assert_array_equal(outputs[1].cells[0].data, outputs[2].cells[0].data)
    for a, b in ((outputs[1], outputs[2]), (outputs[1], outputs[0])):
        np.testing.assert_array_equal(*(m.points[np.lexsort(m.points.T[::-1])] for m in (a, b)))
        u, v = by_coordinates(a, "u", "point"), by_coordinates(b, "u", "point")
        np.testing.assert_array_equal(np.isnan(u), np.isnan(v))
        assert np.nanmax(np.abs(u - v)) <= 1e-12 * np.nanmax(np.abs(u))


def test_each_rank_reads_its_rows_of_an_xdmf(files, tmp_path):
    """A 3,840-tet target as XDMF + HDF5, its points and cells in lattice order: on 2 ranks each
    reads half of the topology rows, and of the geometry little more than the points its rows use
    (the file's own order keeps them near: at most 60 % of the points each); the output is the
    one-rank run's."""
    dst = box_tetrahedra((8, 8, 10), lower=(0.3, -0.2, 0.1), upper=(1.3, 0.9, 0.8), jitter=0.2, seed=5)
    write_xdmf(tmp_path / "dst.xdmf", dst.points, dst.cells)
    n_src = len(meshio.read(files / "src.vtu").cells[0].data)
    outputs = {}
    for ranks in (1, 2):
        out = tmp_path / f"out_{ranks}.vtu"
        proc = varcouple(files / "src.vtu", tmp_path / "dst.xdmf", "--field", "k", "-o", out, ranks=ranks)
        assert proc.returncode == 0, proc.stderr[-3000:]
        line = next(x for x in proc.stdout.splitlines() if x.startswith("read    files opened per rank"))
        cells = [n_src + dst.num_cells // ranks] + [dst.num_cells // 2] * (ranks - 1)
        assert f"cells read per rank {cells}" in line  # rank 0 the source .vtu whole, each its rows
        points = json.loads(line.rsplit("points ", 1)[1])
        if ranks == 2:  # rank 0 also read the source's points
            assert max(points[1], points[0] - len(meshio.read(files / "src.vtu").points)) <= 0.6 * dst.num_points
        outputs[ranks] = meshio.read(out)
    u, v = (m.cell_data["k"][0] for m in (outputs[1], outputs[2]))
    np.testing.assert_array_equal(np.isnan(u), np.isnan(v))
    assert np.nanmax(np.abs(u - v)) <= 1e-12 * np.nanmax(np.abs(u))


@pytest.mark.parametrize("fault, message", [
    ("elements", "dst.xdmf: grid 'mesh': Topology NumberOfElements is 999 but its DataItem Dimensions 720 rows"),
    ("rows", "dst.xdmf: dst.h5:/Mesh/mesh/topology holds 720 x 4 but the XDMF's DataItem Dimensions say 999 x 4"),
    ("point", "dst.xdmf: dst.h5:/Mesh/mesh/topology refers to point 210; the geometry has 210 points"),
    ("h5", "dst.xdmf: its HDF5 file dst.h5 does not exist"),
])
def test_a_bad_xdmf_is_said_once_naming_it(files, tmp_path, fault, message):
    """An XDMF whose counts do not match its HDF5 data, or whose cells name a point past the
    geometry (on rank 1's rows), or without its .h5: exit 2 and one line naming the file and why."""
    import h5py

    dst = box_tetrahedra((4, 5, 6), jitter=0.2, seed=5)
    declared = {"elements": {"elements": 999}, "rows": {"topology_rows": 999, "elements": 999}}.get(fault, {})
    write_xdmf(tmp_path / "dst.xdmf", dst.points, dst.cells, **declared)
    if fault == "point":
        with h5py.File(tmp_path / "dst.h5", "r+") as f:
            f["/Mesh/mesh/topology"][-1, 2] = dst.num_points
    if fault == "h5":
        (tmp_path / "dst.h5").unlink()
    proc = varcouple(files / "src.vtu", tmp_path / "dst.xdmf", "--field", "u", "-o", tmp_path / "x.vtu", ranks=2)
    assert proc.returncode == 2, proc.stderr[-3000:]
    assert proc.stderr.count("varcouple: error:") == 1 and "Traceback" not in proc.stderr
    assert message in proc.stderr
    assert not (tmp_path / "x.vtu").exists()


def test_a_piece_whose_counts_do_not_match_its_data_is_named(files, tmp_path):
    """Rank 1's piece declares fewer points than it holds: exit 2, the piece named."""
    from coupler.output.results import write_pieces
    from transfer import Mesh
    from transfer.partition import slabs

    mesh = meshio.read(files / "src.vtu")
    write_pieces(mesh, tmp_path / "src.pvtu", slabs(Mesh.from_meshio(mesh), 2, axis=0))
    piece = meshio.read(tmp_path / "src_p1.vtu")
    meshio.write(tmp_path / "src_p1.vtu", piece, binary=False)
    text = (tmp_path / "src_p1.vtu").read_text()
    declared = f'NumberOfPoints="{len(piece.points)}"'
    assert declared in text
    (tmp_path / "src_p1.vtu").write_text(text.replace(declared, f'NumberOfPoints="{len(piece.points) - 5}"'))
    proc = varcouple(tmp_path / "src.pvtu", files / "dst.vtu", "--field", "u", "-o", tmp_path / "x.vtu", ranks=2)
    assert proc.returncode == 2, proc.stderr[-3000:]
    assert proc.stderr.count("varcouple: error:") == 1 and "Traceback" not in proc.stderr
    assert "src_p1.vtu: cannot read the mesh with meshio" in proc.stderr
