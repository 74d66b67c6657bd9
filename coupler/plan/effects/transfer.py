"""Effect ``transfer``: a field carried from a source mesh file to a target mesh file by each
method of paper 2.1 (``T = D^-1 B``, eq. 3; ``pseudo_l2``: the dual basis of eq. 4), no solver.

The files are participants the coupler serves in its own process (``mesh_file``: the source
with its field, one target per method); one exchange per method carries the field with the
``l2`` or ``pseudo_l2`` projection operator (NaN where the source does not reach the target's
dofs), and the generic output writes each participant's mesh with its fields
(``source_0000.vtu``, ``target_<method>_0000.vtu`` with the field and ``covered``). Comparing
with a known field is the ``[check] kind = "exact_transfer"``.
"""

from coupler.errors import SceneError
from coupler.scene.tables import Table
from transfer import QuadratureError, TransferError
from transfer.meshfile import MeshFile
from transfer.operators import METHODS
from transfer.quadrature import MAX_DEGREE, check_degree

NAME = "transfer"
DESCRIPTION = "a field carried from a source mesh file to a target mesh file by each method (no solver)"
ORDER = 5
TABLES = {"transfer": {
    "source": "source mesh file inside the case directory, relative to it",
    "target": "target mesh file inside the case directory, relative to it",
    "field": "name of a point (or cell) field of the source file",
    "method": f"transfer method, one of {', '.join(METHODS)}",
    "methods": "list of transfer methods, each carried to its own copy of the target",
    "quadrature_degree": f"quadrature degree on the intersections, 1 to {MAX_DEGREE} (default: exact for the bases)",
    "threads": "threads of the assembly kernel (default 1)"}}


def parse(scene, data: dict) -> None:
    """[transfer]: the two files (read here: a bad file, field or pair of meshes is a scene error),
    the field and the methods."""
    if "transfer" not in data:
        raise SceneError(f"{scene.path}: [transfer] source: missing: the effect 'transfer' needs a [transfer] table "
                         f"(keys: {', '.join(TABLES['transfer'])})")
    t = Table(scene.path, "transfer", data["transfer"], TABLES["transfer"])
    files = {key: t.file(key, scene.case_dir) for key in ("source", "target")}
    name = t.string("field")
    if "method" in t.data and "methods" in t.data:
        raise t.error("methods", "give either method or methods, not both")
    if "methods" in t.data:
        methods = t.strings("methods", choices=METHODS)
        if not methods:
            raise t.error("methods", f"must be a non-empty list of methods, e.g. {list(METHODS)}")
    elif "method" in t.data:
        methods = [t.string("method", choices=METHODS)]
    else:
        listed = ", ".join(f'"{m}"' for m in METHODS)
        raise t.error("method", f'missing (give method = "{METHODS[0]}" or methods = [{listed}])')
    degree = t.integer("quadrature_degree", None) if "quadrature_degree" in t.data else None
    if degree is not None:
        try:
            check_degree(degree)
        except QuadratureError as exc:
            raise t.error("quadrature_degree", str(exc)) from None
    read = {}
    for key, path in files.items():
        try:
            read[key] = MeshFile.read(path)
        except TransferError as exc:
            raise t.error(key, str(exc)) from None
    try:
        field = read["source"].field(name)
    except TransferError as exc:
        raise t.error("field", str(exc)) from None
    try:
        spaces = {key: f.space(field.kind) for key, f in read.items()}
    except TransferError as exc:
        raise t.error("target", str(exc)) from None
    scene.effect_settings[NAME] = {
        "source": str(files["source"].resolve()), "target": str(files["target"].resolve()), "field": name,
        "kind": field.kind, "shape": list(field.values.shape[1:]), "methods": methods, "quadrature_degree": degree,
        "threads": t.integer("threads", 1), "cells": {key: f.mesh.num_cells for key, f in read.items()},
        "source_dofs": spaces["source"].dof_coordinates}


def in_process_cells(scene) -> list:
    """The meshes served in the coupler's process (coupler/run/preflight.py)."""
    s = scene.effect_settings[NAME]
    where = f"{scene.path}: [transfer]"
    return [("source", s["cells"]["source"], f"{where} source")] + [
        (f"target_{method}", s["cells"]["target"], f"{where} target") for method in s["methods"]]


def plan(scene, plan) -> None:
    from coupler.plan.plan import Exchange, PlannedParticipant

    s = scene.effect_settings[NAME]
    field = s["field"]
    location = {"location": "cells"} if s["kind"] == "cell" else {}  # the rows of a P0/Q0 field are cells
    plan.participants.append(PlannedParticipant("source", "mesh_file", "coupler.standins", 1,
                                                {"file": s["source"], "field": field, **location}, in_process=True))
    options = {"kind": s["kind"], "fill": "nan", "threads": s["threads"]}
    if s["quadrature_degree"] is not None:
        options["quadrature_degree"] = s["quadrature_degree"]
    space = "P1/Q1 at the points" if s["kind"] == "point" else "P0/Q0 in the cells"
    for method in s["methods"]:
        target = f"target_{method}"
        plan.participants.append(PlannedParticipant(target, "mesh_file", "coupler.standins", 1,
                                                    {"file": s["target"], **location}, in_process=True))
        plan.exchanges.append(Exchange([f"source.{field}"], f"{target}.{field}", method, "", options=options,
                                       description=f"{space}, T = D^-1 B (paper 2.1, eq. 3-4); NaN where the "
                                                   f"source does not reach"))
    plan.iteration = (f"one transfer per method ({', '.join(s['methods'])}), no solver: the files are served in "
                      f"the coupler's process")
