"""``varcouple run`` on a ``[transfer]`` scene: carry a field from a source mesh
file to a target mesh file with each method, and write the results.

Written to the output directory (and nowhere else; other files there are left
alone): ``source.vtu``, ``target_<method>.vtu`` (the field, ``covered`` and,
with ``exact``, ``error`` = transferred - exact at the target dofs),
``transfer.png`` and ``summary.json``.
"""

from __future__ import annotations

import json
import math
import platform
from collections.abc import Callable
from pathlib import Path

import numpy as np

from transfer import TransferError

from coupler.errors import CouplerError, SceneError
from coupler.output.plots import transfer_figure
from coupler.protocol.expressions import evaluate_expression
from coupler.run.projection import project
from coupler.scene.transfer import TransferScene
from transfer.meshfile import MeshFile, family, one_line, same_file

SUMMARY = "summary.json"
FIGURE = "transfer.png"

#: warn when `exact` differs from the source field at the source dofs by more than this (relative)
EXACT_MISMATCH_RTOL = 1e-6


def _finite(x):
    """A JSON-safe number: None for NaN/inf."""
    x = float(x)
    return x if math.isfinite(x) else None


def _mesh_summary(mf: MeshFile, kind: str) -> dict:
    space = mf.space(kind)
    return {"file": str(mf.path), "cell_type": mf.mesh.cell_type, "cells": mf.mesh.num_cells,
            "points": mf.mesh.num_points, "space": space.family, "dofs": space.num_dofs,
            "reoriented_cells": mf.mesh.reoriented}


def _relative(a: float, b: float) -> float:
    return a / b if b > 0 else float("nan")


def _errors(space, values, covered, error, exact) -> dict:
    """Errors of the transferred field u_h (dof `values`, `error` = values - f at the dofs)
    against f = `exact`: ``max_error`` at the covered dofs; ``relative_l2_error`` =
    ||u_h - f|| / ||f|| in L2 over the target cells whose dofs are all covered (quadrature,
    :meth:`transfer.FunctionSpace.l2_error`); ``relative_interpolant_distance`` =
    ||u_h - I_h f||_M / ||I_h f||_M with the mass matrix M over the covered dofs, which is
    zero when u_h is the interpolant I_h f, however far f is from the target space."""
    e, interpolant = error[covered], (values - error)[covered]
    mass = space.mass_matrix()[covered][:, covered]

    def mass_norm(v):
        return math.sqrt(max(float(v @ (mass @ v)), 0.0))

    l2, norm = space.l2_error(values, exact, cells=covered[space.cell_dofs].all(axis=1))
    return {"max_error": float(np.max(np.abs(e))) if e.size else float("nan"),
            "relative_l2_error": _relative(l2, norm),
            "relative_interpolant_distance": _relative(mass_norm(e), mass_norm(interpolant))}


def _read(scene: TransferScene, key: str) -> MeshFile:
    try:
        return MeshFile.read(getattr(scene, key))
    except (CouplerError, TransferError) as exc:
        raise scene.error("transfer", key, str(exc)) from None


def run(scene: TransferScene, log: Callable[[str], None] = print) -> dict:
    """Run the transfers of `scene`, write the outputs, return the summary."""
    log(f"scene {scene.path}")
    source = _read(scene, "source")
    target = _read(scene, "target")
    try:
        field = source.field(scene.field)
    except TransferError as exc:
        raise scene.error("transfer", "field", str(exc)) from None
    kind = field.kind
    try:
        src_space, dst_space = source.space(kind), target.space(kind)
    except TransferError as exc:
        raise scene.error("transfer", "target", str(exc)) from None
    log(f"source {source.path}: {source.describe()}; {field.describe()} -> {src_space.family}")
    log(f"target {target.path}: {target.describe()} -> {dst_space.family}")
    for name in ["source.vtu", *(f"target_{method}.vtu" for method in scene.methods), FIGURE, SUMMARY]:
        clash = same_file(scene.output_dir / name, (source.path, target.path, scene.path))
        if clash is not None:
            raise SceneError(f"{scene.output_dir / name}: is {clash}, an input of the scene: writing there "
                             f"would overwrite it; choose another output directory")

    exact_fn = None
    exact_info = None
    if scene.exact is not None:
        if field.values.ndim != 1:
            raise scene.error("transfer", "exact", f"is a scalar expression but field {field.name!r} has "
                                                   f"shape {field.values.shape[1:]} per {kind}")

        def exact_fn(points):
            return evaluate_expression(scene.exact, points)

        try:
            at_source = exact_fn(src_space.dof_coordinates)
        except Exception as exc:  # noqa: BLE001 - e.g. sin(x, y): TypeError from numpy
            raise scene.error("transfer", "exact", f"cannot evaluate {scene.exact!r}: {one_line(exc)}") from None
        if not np.all(np.isfinite(at_source)):
            raise scene.error("transfer", "exact", f"{scene.exact!r} is not finite at every source "
                                                   f"{kind} (e.g. log or sqrt of a negative number)")
        mismatch = float(np.max(np.abs(at_source - field.values)))
        scale = max(float(np.max(np.abs(field.values))), np.finfo(float).tiny)
        exact_info = {"expression": scene.exact, "source_max_difference": mismatch}
        if kind == "point" and mismatch > EXACT_MISMATCH_RTOL * scale:
            log(f"warning: exact differs from {field.name!r} at the source points by up to {mismatch:.3g}: "
                f"the errors below are against exact, not against the source field")

    results, warned = [], []
    for method in scene.methods:
        p = project(field, src_space, dst_space, method, quadrature_degree=scene.quadrature_degree,
                    threads=scene.threads)
        entry = {"method": method, "values": p.values, "assembly_seconds": p.assembly_seconds,
                 "kernel_seconds": p.kernel_seconds, "apply_seconds": p.apply_seconds,
                 "covered_fraction": p.covered_fraction, "uncovered_dofs": p.uncovered,
                 "conservation_error": p.conservation_error, "covered": p.covered,
                 "quadrature": p.operator.stats.get("quadrature_degree")}
        line = (f"[{method}] assembled in {p.assembly_seconds:.3f} s, applied in {1e3 * p.apply_seconds:.1f} ms; "
                f"covered {100 * p.covered_fraction:.2f}% ({p.uncovered} uncovered); "
                f"conservation error {p.conservation_error:.2e}")
        if exact_fn is not None:
            entry["error"] = p.values - exact_fn(dst_space.dof_coordinates)
            entry.update(_errors(dst_space, p.values, p.covered, entry["error"], exact_fn))
            line += (f"; L2 error vs exact {entry['relative_l2_error']:.3e} (relative; distance to its interpolant "
                     f"{entry['relative_interpolant_distance']:.3e}), max error at the dofs {entry['max_error']:.3e}")
        log(line)
        for text in p.operator.warnings:
            if text not in warned:  # the same for every method: a property of the two meshes
                warned.append(text)
                log(f"warning: {text}")
        results.append(entry)

    out = scene.output_dir
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise CouplerError(f"{out}: cannot create the output directory: {exc.strerror or exc}") from None
    written = []

    def wrote(name):
        written.append(name)
        log(f"wrote {out / name}")

    source.write(out / "source.vtu", {field.name: (kind, field.values)})
    wrote("source.vtu")
    for r in results:
        name = f"target_{r['method']}.vtu"
        data = {field.name: (kind, r["values"]), "covered": (kind, r["covered"].astype(np.uint8))}
        if "error" in r:
            data["error"] = (kind, r["error"])
        target.write(out / name, data)
        wrote(name)

    try:
        slice_z = transfer_figure(out / FIGURE, field=field.name, source=src_space,
                                  source_values=field.values,
                                  target=dst_space, results=results, exact=exact_fn, slice_z=scene.slice_z,
                                  title=f"{scene.case_dir.resolve().name}: {Path(source.path).name} -> "
                                        f"{Path(target.path).name}")
    except OSError as exc:
        raise CouplerError(f"{out / FIGURE}: cannot write: {exc.strerror or exc}") from None
    wrote(FIGURE)

    summary = {
        "scene": str(scene.path),
        "status": "completed",
        "description": scene.description,
        "field": {"name": field.name, "kind": kind, "shape": list(field.values.shape[1:]),
                  "source_space": family(source.mesh, kind), "target_space": family(target.mesh, kind)},
        "source": _mesh_summary(source, kind),
        "target": _mesh_summary(target, kind),
        "methods": {
            r["method"]: {k: (_finite(r[k]) if isinstance(r[k], float) else r[k])
                          for k in ("assembly_seconds", "kernel_seconds", "apply_seconds", "covered_fraction",
                                    "uncovered_dofs", "conservation_error", "max_error", "relative_l2_error",
                                    "relative_interpolant_distance", "quadrature")
                          if k in r} | {"output": f"target_{r['method']}.vtu"}
            for r in results},
        "exact": exact_info,
        "warnings": warned,
        "threads": scene.threads,
        "plot": {"file": FIGURE, "slice_z": slice_z},
        "platform": {"python": platform.python_version(), "machine": platform.machine()},
    }
    written.append(SUMMARY)
    summary["outputs"] = written
    try:
        (out / SUMMARY).write_text(json.dumps(summary, indent=2, allow_nan=False) + "\n")
    except OSError as exc:
        raise CouplerError(f"{out / SUMMARY}: cannot write: {exc.strerror or exc}") from None
    log(f"wrote {out / SUMMARY}")
    return summary
