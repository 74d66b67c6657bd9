"""Helpers of the command-line tests: run ``varcouple`` in-process, check a one-line error."""

from __future__ import annotations

import meshio
import numpy as np

from coupler.cli import main
from transfer.generate import box_hexahedra, box_tetrahedra


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


#: a scene of the effect transfer between src.vtu and dst.vtu (:func:`transfer_case`)
TRANSFER_SCENE = """[physics]
effects = ["transfer"]
[transfer]
source = "src.vtu"
target = "dst.vtu"
field = "{field}"
methods = ["l2", "pseudo_l2"]
"""
CHECK = """[check]
kind = "exact_transfer"
exact = "{exact}"
tolerance = {tolerance}
"""


def transfer_case(directory, field="T", check="", target=None):
    """`directory` as a transfer case: src.vtu, a jittered tet box with T = 1 + x - 2 y + 3 z (points)
    and k = 7 (cells); dst.vtu, a hexahedral box (`target`: another mesh); scene.toml, ending with
    `check`."""
    src = box_tetrahedra((3, 3, 3), jitter=0.2, seed=4)
    write_mesh(directory / "src.vtu", src, {"T": 1 + src.points @ [1.0, -2.0, 3.0]}, {"k": np.full(src.num_cells, 7.0)})
    write_mesh(directory / "dst.vtu", target if target is not None else box_hexahedra((4, 4, 4)))
    (directory / "scene.toml").write_text(TRANSFER_SCENE.format(field=field) + check)
    return directory
