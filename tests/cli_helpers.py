"""Helpers of the command-line tests: run ``varcouple`` in-process, check a one-line error."""

from __future__ import annotations

import meshio

from coupler.cli import main


def run_cli(capsys, *argv):
    """(exit code, stdout, stderr) of ``varcouple ARGV``."""
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def assert_clean_error(code, err, *words):
    """Exit code 2 and one line ``varcouple: error: ...`` containing each of `words`."""
    assert code == 2
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("varcouple: error: "), err
    for w in words:
        assert w in lines[0], (w, lines[0])


def write_mesh(path, mesh, point_data=None, cell_data=None):
    """Write a :class:`transfer.Mesh` with fields (cell data: one array) to `path`."""
    meshio.write(path, meshio.Mesh(mesh.points, [(mesh.cell_type, mesh.cells)], point_data=point_data or {},
                                   cell_data={k: [v] for k, v in (cell_data or {}).items()}))
    return path
