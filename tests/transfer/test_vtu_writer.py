"""MeshFile writes .vtu at zlib level VTU_ZLIB_LEVEL (transfer/meshfile.py): the level
reaches meshio's writer, the values read back exactly, and meshio is left as it was."""

import zlib

import meshio
import numpy as np

import transfer.meshfile as meshfile
from transfer.generate import box_tetrahedra
from transfer.meshfile import MeshFile


def written(tmp_path, level, monkeypatch):
    """Size and read-back of a 12^3 box's P1 field written at zlib `level`."""
    mesh = box_tetrahedra((12, 12, 12), (0, 0, 0), (1, 1, 1), jitter=0.2, seed=1)
    meshio.write(tmp_path / "in.vtu", meshio.Mesh(mesh.points, [("tetra", mesh.cells)]))
    values = np.sin(mesh.points[:, 0]) * mesh.points[:, 1]
    monkeypatch.setattr(meshfile, "VTU_ZLIB_LEVEL", level)
    out = tmp_path / f"out{level}.vtu"
    MeshFile.read(tmp_path / "in.vtu").write(out, {"f": ("point", values)})
    return out.stat().st_size, values, meshio.read(out).point_data["f"]


def test_the_level_reaches_the_writer_and_the_values_read_back(tmp_path, monkeypatch):
    stored, values, back0 = written(tmp_path, 0, monkeypatch)  # level 0: zlib blocks, stored
    fast, _, back1 = written(tmp_path, 1, monkeypatch)
    default, _, back6 = written(tmp_path, 6, monkeypatch)
    for back in (back0, back1, back6):
        np.testing.assert_array_equal(back, values)
    assert fast < 0.5 * stored
    assert default < fast < 1.1 * default  # level 1: a few per cent larger than meshio's default


def test_meshio_is_left_with_zlib():
    from meshio.vtu import _vtu

    data = bytes(range(256)) * 64
    with meshfile.vtu_zlib_level(1):
        assert _vtu.zlib.compress(data) == zlib.compress(data, 1)
        assert _vtu.zlib.decompress(_vtu.zlib.compress(data)) == data
    assert _vtu.zlib is zlib
