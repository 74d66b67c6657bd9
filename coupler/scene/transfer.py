"""A ``[transfer]`` scene: carry a field from a source mesh file to a target mesh file with
one or more methods (cases/README.md documents every key)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from coupler.errors import SceneError
from coupler.protocol.expressions import check_expression
from transfer import QuadratureError
from transfer.operators import METHODS
from transfer.quadrature import MAX_DEGREE, check_degree

from .tables import STUDIES, Table, output_directory

#: table -> key -> one-line description (also the list of allowed keys)
KEYS = {
    "case": {"description": "one line on what the case shows"},
    "transfer": {
        "source": "source mesh file, relative to the case directory",
        "target": "target mesh file, relative to the case directory",
        "field": "name of a point (or cell) field of the source file",
        "method": f"transfer method, one of {', '.join(METHODS)}",
        "methods": "list of transfer methods, run one after the other",
        "exact": "optional: the field as an expression in x, y, z (numpy), to measure the error",
        "quadrature_degree": f"optional: quadrature degree, 1 to {MAX_DEGREE} (default: exact for the bases)",
        "threads": "optional: threads of the assembly kernel (default 1)",
    },
    "output": {
        "directory": "output directory, relative to the case directory (default 'results')",
        "slice_z": "optional: height of the horizontal slice in the plot (default: middle of the target)",
    },
}




@dataclass
class TransferScene:
    path: Path  # the scene file, as given (relative paths stay relative in messages)
    case_dir: Path
    description: str
    source: Path
    target: Path
    field: str
    methods: list[str]
    exact: str | None
    quadrature_degree: int | None
    threads: int
    output_dir: Path
    slice_z: float | None

    def error(self, table: str, key: str, reason: str) -> SceneError:
        return SceneError(f"{self.path}: [{table}] {key}: {reason}")


def parse(path: Path, case_dir: Path, data: dict, output) -> TransferScene:
    for table, value in data.items():
        if table not in KEYS:
            raise SceneError(f"{path}: unknown table [{table}]; known tables: "
                             f"{', '.join(f'[{t}]' for t in KEYS)} (a transfer scene), [physics] "
                             f"and the tables of a coupled scene, or a study's {', '.join(f'[{m}]' for m in STUDIES)}")
    if "transfer" not in data:
        raise SceneError(f"{path}: [transfer]: missing table (keys: {', '.join(KEYS['transfer'])})")
    case = Table(path, "case", data.get("case", {}), KEYS["case"])
    tr = Table(path, "transfer", data["transfer"], KEYS["transfer"])
    out = Table(path, "output", data.get("output", {}), KEYS["output"])
    source, target = tr.file("source", case_dir), tr.file("target", case_dir)
    field = tr.string("field")
    if "method" in tr.data and "methods" in tr.data:
        raise tr.error("methods", "give either method or methods, not both")
    if "methods" in tr.data:
        methods = tr.strings("methods", choices=METHODS)
        if not methods:
            raise tr.error("methods", f"must be a non-empty list of methods, e.g. {list(METHODS)}")
    elif "method" in tr.data:
        methods = [tr.string("method", choices=METHODS)]
    else:
        methods_list = ", ".join(f'"{m}"' for m in METHODS)
        raise tr.error("method", f'missing (give method = "{METHODS[0]}" or methods = [{methods_list}])')
    exact = tr.string("exact", None)
    if exact is not None:
        check_expression(exact, tr.where("exact"))
    qdeg = tr.integer("quadrature_degree", None) if "quadrature_degree" in tr.data else None
    if qdeg is not None:
        try:
            check_degree(qdeg)
        except QuadratureError as exc:
            raise tr.error("quadrature_degree", str(exc)) from None
    slice_z = out.number("slice_z", None)
    return TransferScene(path=path, case_dir=case_dir, description=case.string("description", None) or "",
                         source=source, target=target, field=field, methods=methods, exact=exact,
                         quadrature_degree=qdeg, threads=tr.integer("threads", 1),
                         output_dir=output_directory(case_dir, out, output), slice_z=slice_z)
