"""MeshFile writes .vtu at zlib level VTU_ZLIB_LEVEL (transfer/meshfile.py) through ISA-L
when the isal package is installed (plain zlib otherwise) and reads .vtu through it: the
level reaches meshio's writer, the files are standard zlib VTU that plain zlib, meshio and
VTK read back bit for bit, and meshio is left as it was."""

import zlib

import meshio
import numpy as np
import pytest

import transfer.meshfile as meshfile
from transfer.generate import box_tetrahedra
from transfer.meshfile import MeshFile

from isal import isal_zlib  # a dependency (pyproject.toml): the zlib cases below run beside it


def written(tmp_path, level, monkeypatch):
    """Size and read-back of a 12^3 box's P1 field written at zlib `level`."""
    mesh = box_tetrahedra((12, 12, 12), (0, 0, 0), (1, 1, 1), jitter=0.2, seed=1)
    meshio.write(tmp_path / "in.vtu", meshio.Mesh(mesh.points, [("tetra", mesh.cells)]))
    values = np.sin(mesh.points[:, 0]) * mesh.points[:, 1]
    monkeypatch.setattr(meshfile, "VTU_ZLIB_LEVEL", level)
    out = tmp_path / f"out{level}.vtu"
    MeshFile.read(tmp_path / "in.vtu").write(out, {"f": ("point", values)})
    return out.stat().st_size, values, meshio.read(out).point_data["f"]


@pytest.mark.parametrize("codec", ["isal", "zlib"])
def test_the_level_reaches_the_writer_and_the_values_read_back(tmp_path, monkeypatch, codec):
    if codec == "zlib":
        monkeypatch.setattr(meshfile, "isal_zlib", None)
    stored, values, back0 = written(tmp_path, 0, monkeypatch)  # level 0: zlib blocks, stored
    fast, _, back1 = written(tmp_path, 1, monkeypatch)
    default, _, back6 = written(tmp_path, 6, monkeypatch)
    for back in (back0, back1, back6):  # meshio.read outside MeshFile: plain zlib
        np.testing.assert_array_equal(back, values)
    assert fast < 0.5 * stored
    assert default < fast < 1.1 * default  # level 1: a few per cent larger than meshio's default


def test_isal_writes_standard_zlib_vtu_read_back_bit_for_bit(tmp_path):
    """ISA-L's streams (other bytes than zlib's) hold the same values for plain zlib,
    meshio (plain zlib) and VTK's own reader."""
    from vtk.util.numpy_support import vtk_to_numpy
    from vtkmodules.vtkIOXML import vtkXMLUnstructuredGridReader

    mesh = box_tetrahedra((10, 10, 10), (0, 0, 0), (1, 1, 1), jitter=0.2, seed=3)
    values = np.exp(mesh.points[:, 2]) * np.cos(7 * mesh.points[:, 0])
    meshio.write(tmp_path / "in.vtu", meshio.Mesh(mesh.points, [("tetra", mesh.cells)]))
    MeshFile.read(tmp_path / "in.vtu").write(tmp_path / "out.vtu", {"f": ("point", values)})

    data = values.tobytes()
    with meshfile.vtu_zlib_level(1):
        from meshio.vtu import _vtu

        stream = _vtu.zlib.compress(data)
    assert stream == isal_zlib.compress(data, 1) and stream != zlib.compress(data, 1)
    assert zlib.decompress(stream) == data

    back = meshio.read(tmp_path / "out.vtu")
    assert back.point_data["f"].tobytes() == values.tobytes()
    np.testing.assert_array_equal(back.points, mesh.points)
    np.testing.assert_array_equal(back.cells_dict["tetra"], mesh.cells)

    reader = vtkXMLUnstructuredGridReader()
    reader.SetFileName(str(tmp_path / "out.vtu"))
    reader.Update()
    grid = reader.GetOutput()
    assert vtk_to_numpy(grid.GetPointData().GetArray("f")).tobytes() == values.tobytes()
    np.testing.assert_array_equal(vtk_to_numpy(grid.GetPoints().GetData()), mesh.points)


def test_meshfile_reads_through_isal(tmp_path, monkeypatch):
    """MeshFile.read inflates meshio's zlib blocks with ISA-L (the values as plain zlib's)."""
    calls = []

    class Spy:
        @staticmethod
        def decompress(data):
            calls.append(len(data))
            return isal_zlib.decompress(data)

    mesh = box_tetrahedra((6, 6, 6), (0, 0, 0), (1, 1, 1), jitter=0.2, seed=2)
    meshio.write(tmp_path / "in.vtu", meshio.Mesh(mesh.points, [("tetra", mesh.cells)]))
    monkeypatch.setattr(meshfile, "isal_zlib", Spy)
    read = MeshFile.read(tmp_path / "in.vtu")
    assert calls
    np.testing.assert_array_equal(read.mesh.points, meshio.read(tmp_path / "in.vtu").points)


@pytest.mark.parametrize("codec", ["isal", "zlib"])
def test_meshio_is_left_with_zlib(monkeypatch, codec):
    from meshio.vtu import _vtu

    if codec == "zlib":
        monkeypatch.setattr(meshfile, "isal_zlib", None)
    data = bytes(range(256)) * 64
    with meshfile.vtu_zlib_level(1):
        expected = isal_zlib.compress(data, 1) if codec == "isal" else zlib.compress(data, 1)
        assert _vtu.zlib.compress(data) == expected
        assert _vtu.zlib.decompress(_vtu.zlib.compress(data)) == data
    assert _vtu.zlib is zlib
