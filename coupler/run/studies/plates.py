"""``varcouple check|run`` on a ``[plates]`` scene: the immersed parallel-plates study of
issue 4 (cases/parallel_plates), the fluid alone against the cubic law.

Two flat rock blocks leave a gap of aperture w inside a 2D structured grid whose lines do
not follow the block faces (:mod:`fluid_openfoam.plates`). For every resolution (cells
across the aperture), every fraction handling (``methods``) and every plate offset against
the grid lines, one simpleFoam solve in this process (no participants, no coupling); the
flow rate per unit width is compared with ``Q = w^3 dp / (12 mu L)``. Written to the output
directory: ``summary.json`` (per method and resolution the error at each offset, the worst
one, the time per solve; per method the observed order of the worst error in the cells
across; every run), ``plates.png`` (accuracy against cost), and ``plates_<method>_NNNN.vtu``
with ``plates_<method>.pvd`` (velocity, pressure, solid fraction at the first offset, NNNN
cells across; the .pvd's "time" is the number of cells across). ``[check]``: the run fails (exit 1) when
the worst |error| over the offsets at ``cells_across`` exceeds ``tolerance``.
"""

from __future__ import annotations

import platform
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from coupler.scene.tables import Table, check_tables, output_directory

#: table -> key -> one-line description (also the list of allowed keys); cases/README.md
TABLES = {
    "case": {"description": "one line on what the case shows"},
    "plates": {"aperture": "gap w between the blocks [m]", "length": "length L along x (inlet to outlet) [m]",
               "pressure_drop": "dp between inlet (xmin) and outlet (xmax) [Pa]"},
    "materials": {"fluid": "table: density, viscosity"},
    "study": {"cells_across": "list of resolutions: grid cells across the aperture",
              "methods": "list of fraction handlings: wall, linear, power, binary",
              "offsets": "list of positions of the lower plate against the grid lines, in cells, in [0, 1)"},
    "solvers": {"fluid": "table: tolerance, max_iterations, penalization_exponent"},
    "check": {"cells_across": "the resolution checked (one of study cells_across)",
              "method": "the method checked (default: the first of study methods)",
              "tolerance": "largest accepted |Q / Q_cubic - 1| over the offsets"},
    "output": {"directory": "output directory, relative to the case (default 'results')"},
}
SOLVER_KEYS = {"tolerance": "simpleFoam residual tolerance (p and U)",
               "max_iterations": "simpleFoam iterations at most",
               "penalization_exponent": "exponent of method 'power'"}


@dataclass
class PlatesScene:
    path: Path
    case_dir: Path
    description: str
    plates: object  # fluid_openfoam.plates.Plates
    cells_across: list[int]
    methods: list[str]
    offsets: list[float]
    solver: dict
    check: dict | None
    output_dir: Path



def parse(path: Path, case_dir: Path, data: dict, output=None) -> PlatesScene:
    """Validate a ``[plates]`` scene (already read from TOML)."""
    from fluid_openfoam.plates import METHODS, Plates

    check_tables(path, data, TABLES, "a [plates] scene")
    case = Table(path, "case", data.get("case", {}), TABLES["case"])
    geo = Table(path, "plates", data["plates"], TABLES["plates"])
    materials = Table(path, "materials", data.get("materials", {}), TABLES["materials"])
    water = Table(path, "materials.fluid", materials.data.get("fluid", {}),
                  {"density": "[kg/m^3]", "viscosity": "dynamic viscosity [Pa s]"})
    plates = Plates(w=geo.number("aperture", positive=True), length=geo.number("length", positive=True),
                    dp=geo.number("pressure_drop", positive=True),
                    mu=water.number("viscosity", default=1e-3, positive=True),
                    rho=water.number("density", default=1000.0, positive=True))
    study = Table(path, "study", data.get("study", {}), TABLES["study"])
    cells = study.numbers("cells_across", integer=True, minimum=1)
    methods = study.strings("methods", ["wall"], choices=METHODS)
    if not methods:
        raise study.error("methods", f"name at least one of {', '.join(METHODS)}")
    offsets = study.numbers("offsets", [0.3], minimum=0.0, below=1.0)
    solvers = Table(path, "solvers", data.get("solvers", {}), TABLES["solvers"])
    fluid = Table(path, "solvers.fluid", solvers.data.get("fluid", {}), SOLVER_KEYS)
    solver = {"tolerance": fluid.number("tolerance", 1e-7, positive=True),
              "max_iterations": fluid.integer("max_iterations", 5000),
              "exponent": fluid.number("penalization_exponent", 3.0, positive=True)}
    if "penalization_exponent" in fluid.data and "power" not in methods:
        raise fluid.error("penalization_exponent", "applies to method 'power' only")
    check = None
    if "check" in data:
        t = Table(path, "check", data["check"], TABLES["check"])
        check = {"cells_across": t.integer("cells_across"), "method": t.string("method", methods[0], tuple(methods)),
                 "tolerance": t.number("tolerance", positive=True)}
        if check["cells_across"] not in cells:
            raise t.error("cells_across", f"{check['cells_across']} is not one of [study] cells_across {cells}")
    out = Table(path, "output", data.get("output", {}), TABLES["output"])
    return PlatesScene(path=path, case_dir=case_dir, description=case.string("description", None) or "",
                       plates=plates, cells_across=cells, methods=methods, offsets=offsets, solver=solver,
                       check=check, output_dir=output_directory(case_dir, out, output))


def plan_lines(scene: PlatesScene) -> list[str]:
    """What ``varcouple check`` prints for a plates scene."""
    from fluid_openfoam.plates import NX

    p = scene.plates
    runs = len(scene.cells_across) * len(scene.methods) * len(scene.offsets)
    out = [f"study         immersed parallel plates against the cubic law Q = w^3 dp / (12 mu L) = {p.q_cubic:.4g} m^2/s",
           f"geometry      aperture {p.w:g} m, length {p.length:g} m, pressure drop {p.dp:g} Pa; fluid density "
           f"{p.rho:g} kg/m^3, viscosity {p.mu:g} Pa s",
           f"grids         {NX} x (n + 5) x 1 cells (2D), n = {', '.join(map(str, scene.cells_across))} cells "
           f"across the aperture",
           f"runs          {len(scene.methods)} method{'s' * (len(scene.methods) > 1)} ({', '.join(scene.methods)}) x "
           f"{len(scene.offsets)} offset{'s' * (len(scene.offsets) > 1)} ({', '.join(f'{o:g}' for o in scene.offsets)}) x "
           f"{len(scene.cells_across)} resolutions = {runs} simpleFoam solves (fluid alone, in this process)"]
    if scene.check:
        c = scene.check
        out.append(f"check         worst |Q / Q_cubic - 1| over the offsets < {c['tolerance']:g} at "
                   f"{c['cells_across']} cells across (method {c['method']})")
    return out


def run(scene: PlatesScene, log=print) -> dict:
    """Run the study of `scene`, write its outputs, return the summary."""
    from fluid_openfoam import plates as _plates

    from coupler.errors import NotConverged
    from coupler.output.results import write_summary

    out = Path(scene.output_dir)
    out.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    runs, table, fields = [], [], {}
    with tempfile.TemporaryDirectory(prefix="varcouple-plates-") as tmp:
        for method in scene.methods:
            for n in scene.cells_across:
                rs = []
                for off in scene.offsets:
                    r = _plates.run(n, method, off, Path(tmp) / f"{method}-{n}-{off}", scene.solver["exponent"],
                                    scene.solver["tolerance"], scene.plates, scene.solver["max_iterations"],
                                    keep_fields=off == scene.offsets[0])
                    if "fields" in r:
                        fields[method, n] = r.pop("fields")
                    rs.append(r)
                runs += rs
                worst = max((r["error"] for r in rs), key=abs)
                row = {"method": method, "n_across": n, "cells": rs[0]["cells"],
                       "errors": {f"{r['offset']:g}": r["error"] for r in rs}, "error_worst": worst,
                       "time_solve_mean": sum(r["time_solve"] for r in rs) / len(rs),
                       "time_total_mean": sum(r["time_total"] for r in rs) / len(rs),
                       "all_converged": all(r["converged"] for r in rs)}
                table.append(row)
                log(f"{method:7s} {n:3d} across: error {', '.join(f'{e:+.3%}' for e in row['errors'].values())} "
                    f"at offsets {', '.join(row['errors'])}; worst {worst:+.3%}; {row['time_total_mean']:.2f} s "
                    f"per run (solve {row['time_solve_mean']:.2f} s){'' if row['all_converged'] else '; NOT converged'}")
    written = _write_fields(out, fields) + [_plot(table, scene, out / "plates.png")]
    p = scene.plates
    summary = {"scene": str(scene.path), "case": "parallel_plates", "cubic_law": "Q = w^3 dp / (12 mu L)",
               "aperture": p.w, "length": p.length, "pressure_drop": p.dp, "viscosity": p.mu, "density": p.rho,
               "Q_cubic": p.q_cubic, "offsets": scene.offsets, "solver": scene.solver, "table": table, "runs": runs,
               "platform": {"python": platform.python_version(), "machine": platform.machine()}}
    summary["order"] = {m: observed_order([r for r in table if r["method"] == m]) for m in scene.methods}
    log("observed order of the worst error: " + ", ".join(f"{m} {o:.2f}" for m, o in summary["order"].items()
                                                          if o is not None))
    if scene.check:
        c = scene.check
        row = next(r for r in table if r["method"] == c["method"] and r["n_across"] == c["cells_across"])
        passed = abs(row["error_worst"]) < c["tolerance"] and row["all_converged"]
        summary["check"] = {**c, "error_worst": row["error_worst"], "passed": passed}
        log(f"check: worst error {row['error_worst']:+.3%} at {c['cells_across']} cells across ({c['method']}), "
            f"tolerance {c['tolerance']:g}: {'PASS' if passed else 'FAIL'}")
    summary["wall_seconds"] = time.perf_counter() - start
    summary["outputs"] = [f.name for f in written] + ["summary.json"]
    unconverged = [r for r in table if not r["all_converged"]]
    summary["status"] = "not_converged" if unconverged else "completed"
    write_summary(out, summary)
    if unconverged:
        r = unconverged[0]
        raise NotConverged(f"simpleFoam did not converge with {r['method']} at {r['n_across']} cells across; raise "
                           f"[solvers.fluid] max_iterations")
    for f in written:
        log(f"wrote {f}")
    log(f"wrote {out / 'summary.json'}")
    return summary


def observed_order(rows: list) -> float | None:
    """Least-squares slope of -log|worst error| against log(cells across) (None for fewer than
    two resolutions)."""
    import numpy as np

    if len(rows) < 2:
        return None
    n = np.log([r["n_across"] for r in rows])
    e = np.log([max(abs(r["error_worst"]), 1e-300) for r in rows])
    return float(-np.polyfit(n, e, 1)[0])


def _write_fields(out: Path, fields: dict) -> list[Path]:
    """plates_<method>.vtu per resolution and a .pvd whose time is the number of cells across."""
    from transfer import StructuredGrid

    from coupler.output.results import Series

    written = []
    for method in dict.fromkeys(m for m, _ in fields):
        series = None
        for (m, n), f in fields.items():
            if m != method:
                continue
            g = f["grid"]
            grid = StructuredGrid(g["origin"], g["spacing"], g["shape"])
            if series is None:
                series = Series(out, f"plates_{method}", grid)
            series.mesh = grid  # one grid per resolution
            written.append(series.write(n, float(n), cell_data={"velocity": f["velocity"], "pressure": f["pressure"],
                                                                 "solid_fraction": f["solid_fraction"]}))
        written.append(out / f"plates_{method}.pvd")
    return written


def _plot(table: list, scene: PlatesScene, path: Path) -> Path:
    """Accuracy against cost: worst |error| over the offsets against cells across and against
    the time per solve."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    label = {"binary": "binary centre mask", "linear": "exact fractions, linear drag",
             "power": "exact fractions, D_max f^k", "wall": "exact fractions, sub-cell wall drag"}
    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 4))
    for m in scene.methods:
        rows = [r for r in table if r["method"] == m]
        err = [max(abs(r["error_worst"]), 1e-6) for r in rows]
        a.loglog([r["n_across"] for r in rows], err, "o-", label=label[m])
        b.loglog([r["time_total_mean"] for r in rows], err, "o-", label=label[m])
        for r, e in zip(rows, err):
            b.annotate(str(r["n_across"]), (r["time_total_mean"], e), fontsize=7, xytext=(3, 3),
                       textcoords="offset points")
    if scene.check:
        for ax in (a, b):
            ax.axhline(scene.check["tolerance"], color="k", ls=":", lw=1)
        a.axvline(scene.check["cells_across"], color="k", ls=":", lw=1)
    a.set(xlabel="cells across the aperture", ylabel="worst |Q / Q_cubic - 1| over offsets",
          title="accuracy against resolution")
    b.set(xlabel="wall time per solve (s): setup + simpleFoam", ylabel="worst |Q / Q_cubic - 1| over offsets",
          title="accuracy against cost (labels: cells across)")
    a.legend(fontsize=8)
    for ax in (a, b):
        ax.grid(True, which="both", alpha=0.3)
    fig.suptitle(f"{scene.case_dir.resolve().name}: immersed plates, offsets {', '.join(f'{o:g}' for o in scene.offsets)}")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
