"""The solid's mesh from an XDMF file read in parallel (solid_fenicsx.mesh.read_xdmf, written by
python -m solid_fenicsx.convert; tests/solid_fenicsx/mpi_xdmf_cases.py under mpirun): the same mesh
as the .msh it was converted from (points, cells, tagged facets and cells by name), each rank
holding its share only, the input numbering the file's rows on any number of ranks, the same
elastic solution, and one error naming file and reason on every rank for a bad file."""

from __future__ import annotations

import shutil

import pytest

pytest.importorskip("dolfinx")

from vc_helpers import ROOT, run_mpi  # noqa: E402

SCRIPT = ROOT / "tests" / "solid_fenicsx" / "mpi_xdmf_cases.py"
MSH = ROOT / "cases" / "small_fracture" / "solid.msh"
BOUNDARIES = ("boundaries (facet tags): bottom = 1 (400 facets), top = 2 (400 facets), fracture_lower = 3 (400 facets),"
              " fracture_upper = 4 (400 facets), xmin = 5 (80 facets), xmax = 6 (80 facets), ymin = 7 (160 facets), "
              "ymax = 8 (160 facets)")
REGIONS = "regions (cell tags): lower_block = 1 (2400 tetrahedra), upper_block = 2 (2400 tetrahedra)"


@pytest.mark.skipif(shutil.which("mpirun") is None, reason="mpirun not installed")
@pytest.mark.parametrize("ranks", [1, 2, 3])
def test_the_xdmf_read_in_parallel_is_the_msh_mesh(ranks, tmp_path):
    found = run_mpi(SCRIPT, ranks, tmp_path)
    assert found["ranks"] == ranks
    path = tmp_path / "solid.xdmf"
    assert found["report"].splitlines() == [
        f"wrote {path} and solid.h5: 1386 points, 4800 tetrahedra, written by {ranks} rank(s)", BOUNDARIES, REGIONS]
    assert found["same"] == dict.fromkeys(("points", "counts", "cells", "boundaries", "regions", "facets",
                                           "tagged cells"), True)
    held = found["held"]  # (points a rank holds, owned and ghost; all points)
    assert all(total == 1386 for _, total in held)
    assert ranks == 1 or max(n for n, _ in held) <= (1 / ranks + 0.1) * 1386
    assert found["displacement"] < 1e-12
    numbering = found["numbering"]  # (ranks reading, input numbering == the file's rows) per rank
    assert numbering["job"] == [[ranks, True]] * ranks
    assert numbering["split"] == [[max(1, ranks - 1), True]] * max(1, ranks - 1) + [[1, True]] * (ranks > 1)
    errors = found["errors"]
    assert all(e == errors[0] for e in errors)  # every rank raised, the same one line
    assert errors[0] == {
        "missing": f"{tmp_path}/nothing.xdmf: no such file",
        "not XML": f"{tmp_path}/text.xdmf: not an XDMF file (syntax error: line 1, column 0)",
        "not HDF5": f"{tmp_path}/garbage.xdmf: garbage.h5 is not an HDF5 file",
        "no HDF5": f"{tmp_path}/alone.xdmf: its HDF5 file alone.h5 does not exist (dolfinx reads the .h5 of the "
                   f"same name)",
        "no dataset": f"{tmp_path}/dataset.xdmf: dolfinx cannot read it (Failed to open HDF5 dataset by name)",
        "hexahedra": f"{tmp_path}/hexahedra.xdmf: cells are Hexahedron, not linear tetrahedra",
        "facet grid": f"{tmp_path}/solid.xdmf: no facet tags 'walls' (grids: ['cell_tags', 'facet_tags', 'mesh'])",
        "tag": f"{tmp_path}/solid.xdmf: boundary 'top': no facet tag 9 (tags: [1, 2, 3, 4, 5, 6, 7, 8])"}


def test_convert_reports_the_names_and_refuses_bad_input(tmp_path, capsys):
    from solid_fenicsx.convert import main
    from solid_fenicsx.mesh import read_mesh

    out = tmp_path / "solid.xdmf"
    assert main([str(MSH), str(out)]) == 0
    assert capsys.readouterr().out.splitlines()[-2:] == [BOUNDARIES, REGIONS]
    solid = read_mesh(out)
    assert solid.boundaries == {"bottom": 1, "top": 2, "fracture_lower": 3, "fracture_upper": 4, "xmin": 5,
                                "xmax": 6, "ymin": 7, "ymax": 8}
    assert solid.regions == {"lower_block": 1, "upper_block": 2}
    assert (solid.num_points, solid.num_cells) == (1386, 4800)
    for argv, message in (([str(MSH), str(tmp_path / "solid.vtu")], f"{tmp_path}/solid.vtu: the output must be an "
                                                                   ".xdmf file"),
                          ([str(MSH), str(tmp_path / "no" / "s.xdmf")], f"{tmp_path}/no/s.xdmf: no directory "
                                                                       f"{tmp_path}/no"),
                          ([str(tmp_path / "none.msh"), str(out)], f"{tmp_path}/none.msh: File {tmp_path}/none.msh "
                                                                  f"not found.")):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert err == f"python -m solid_fenicsx.convert: error: {message}\n"
    (tmp_path / "blocked.h5").mkdir()  # the HDF5 file cannot be made: one line, no traceback
    assert main([str(MSH), str(tmp_path / "blocked.xdmf")]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"python -m solid_fenicsx.convert: error: {tmp_path}/blocked.xdmf: cannot write it (")
    assert err.count("\n") == 1 and "Traceback" not in err


def test_the_coupler_counts_the_cells_of_an_xdmf_from_its_xml(tmp_path, monkeypatch):
    """varcouple's memory estimate of a scene with a solid.xdmf reads the XML only (no meshio,
    which cannot read dolfinx's layout); a bad file is a scene error naming the key."""
    from coupler.errors import SceneError
    from coupler.run.preflight import estimate
    from coupler.scene import load
    from solid_fenicsx.convert import main
    from transfer.meshfile import MeshFile
    from vc_helpers import copy_case

    case = copy_case(MSH.parent, tmp_path, {'mesh = "solid.msh"': 'mesh = "solid.xdmf"'})
    assert main([str(MSH), str(case / "solid.xdmf")]) == 0

    def refuse(*args, **kwargs):
        raise AssertionError("meshio read the mesh")

    monkeypatch.setattr(MeshFile, "read", refuse)
    assert [(e.name, e.cells) for e in estimate(load(case)) if e.name == "solid"] == [("solid", 4800)]
    (case / "solid.h5").write_text("no data\n")
    with pytest.raises(SceneError) as error:
        estimate(load(case))
    assert str(error.value) == f"{case}/scene.toml: [geometry.solid] mesh: solid.h5 is not an HDF5 file"
