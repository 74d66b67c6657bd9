"""Output per coupler rank (docs/scaling.md, step 5): mpi_results_cases.py under mpirun (2 and 3
ranks, the third without cells) writes a .pvtu of per-rank .vtu pieces per step that VTK's
parallel reader (meshio on each piece without VTK) reads back as the serial file's cells, point
and cell fields; rank 0 writes the .pvd and summary.json with the figures reduced over the
ranks (max, min, sum), and a figure without a rule is named; one rank writes the serial files."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import meshio
import numpy as np
import pytest

from coupler.output.results import Series, reduce_figures
from transfer.generate import box_tetrahedra
from vc_helpers import run_mpi

HERE = Path(__file__).resolve().parent
needs_mpirun = pytest.mark.skipif(shutil.which("mpirun") is None, reason="mpirun not installed")


@pytest.fixture(scope="module", params=[2, 3])
def written(request, tmp_path_factory):
    out = tmp_path_factory.mktemp(f"ranks{request.param}")
    result = run_mpi(HERE / "mpi_results_cases.py", request.param, out)
    assert result["ranks"] == request.param
    return out, result


def read_parallel(path: Path) -> meshio.Mesh:
    """The pieces of a .pvtu joined, by VTK's XMLPUnstructuredGridReader if VTK is installed,
    else by meshio on each piece the .pvtu names."""
    try:
        import vtk
        from vtk.util.numpy_support import vtk_to_numpy
    except ImportError:
        import re

        pieces = [meshio.read(path.parent / p) for p in re.findall(r'Source="([^"]+)"', path.read_text())]
        offsets = np.cumsum([0] + [len(p.points) for p in pieces])
        return meshio.Mesh(np.concatenate([p.points for p in pieces]),
                           [("tetra", np.concatenate([p.cells[0].data + o for p, o in zip(pieces, offsets)]))],
                           point_data={k: np.concatenate([p.point_data[k] for p in pieces]) for k in pieces[0].point_data},
                           cell_data={k: [np.concatenate([p.cell_data[k][0] for p in pieces])]
                                      for k in pieces[0].cell_data})
    reader = vtk.vtkXMLPUnstructuredGridReader()
    reader.SetFileName(str(path))
    reader.Update()
    grid = reader.GetOutput()
    points = vtk_to_numpy(grid.GetPoints().GetData())
    cells = vtk_to_numpy(grid.GetCells().GetConnectivityArray()).reshape(-1, 4)
    pd, cd = grid.GetPointData(), grid.GetCellData()
    return meshio.Mesh(points, [("tetra", cells)],
                       point_data={pd.GetArrayName(i): vtk_to_numpy(pd.GetArray(i)) for i in range(pd.GetNumberOfArrays())},
                       cell_data={cd.GetArrayName(i): [vtk_to_numpy(cd.GetArray(i))] for i in range(cd.GetNumberOfArrays())})


def by_coordinates(mesh: meshio.Mesh) -> tuple[dict, dict]:
    """Point fields keyed by rounded coordinates, cell fields keyed by their vertices' coordinates."""
    keys = [tuple(np.round(p, 12)) for p in mesh.points]
    points = {k: tuple(np.concatenate([np.ravel(v[i]) for _, v in sorted(mesh.point_data.items())]))
              for i, k in enumerate(keys)}
    cells = {frozenset(keys[v] for v in cell): tuple(float(v[0][c]) for _, v in sorted(mesh.cell_data.items()))
             for c, cell in enumerate(mesh.cells[0].data)}
    return points, cells


@needs_mpirun
@pytest.mark.parametrize("step", [0, 3])
def test_pieces_read_back_as_the_serial_file(written, step):
    out, _ = written
    parallel = read_parallel(out / f"solid_{step:04d}.pvtu")
    serial = meshio.read(out / "serial" / f"solid_{step:04d}.vtu")
    assert len(parallel.cells[0].data) == len(serial.cells[0].data) == 216
    assert sorted(parallel.point_data) == sorted(serial.point_data) == ["displacement", "pressure"]
    assert sorted(parallel.cell_data) == sorted(serial.cell_data) == ["fraction", "owner_id"]
    assert by_coordinates(parallel) == by_coordinates(serial)  # shared vertices: the same values in each piece
    assert not (out / f"solid_{step:04d}_p2.vtu").exists()  # the third rank holds no cells: no piece


@needs_mpirun
def test_pvd_and_summary_on_rank_0(written):
    out, result = written
    assert (out / "solid.pvd").read_text() == (out / "serial" / "solid.pvd").read_text().replace(".vtu", ".pvtu")
    summary = json.loads((out / "summary.json").read_text())
    assert summary["steps"] == result["reduced"]
    for reduced, serial in zip(result["reduced"], result["serial"]):
        assert reduced == serial  # max displacement (max), cells (sum), min pressure (min), contact (max)
        assert isinstance(reduced["sizes"]["cells"], int) and reduced["contact"] is True
    assert result["error"] == ("summary figures mean_aperture: no rule to combine them over the coupler's ranks "
                               "(max, min or sum)")


def test_one_rank_writes_the_serial_files(tmp_path):
    from mpi4py import MPI

    mesh = box_tetrahedra((2, 1, 1))
    (tmp_path / "one").mkdir()
    (tmp_path / "serial").mkdir()
    for directory, comm in (("one", MPI.COMM_SELF), ("serial", None)):
        Series(tmp_path / directory, "s", mesh, comm).write(2, 0.1, point_data={"p": mesh.points[:, 0]})
    assert sorted(p.name for p in (tmp_path / "one").iterdir()) == ["s.pvd", "s_0002.vtu"]
    for name in ("s.pvd", "s_0002.vtu"):
        assert (tmp_path / "one" / name).read_bytes() == (tmp_path / "serial" / name).read_bytes()
    figures = {"max_displacement": 1.0, "mean": 2.0}
    assert reduce_figures(figures, {}, MPI.COMM_SELF) is figures  # serially: as it is, no rule needed
