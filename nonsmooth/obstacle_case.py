"""Obstacle cases (paper section 4.3): a body pressed onto the plane below it,
solved on semi-geometric hierarchies; ``cases/cube_obstacle`` and ``cases/rock_obstacle``.

A case directory holds ``problem.toml`` (keys in :data:`KEYS`, documented in
cases/README.md) and is run by its ``run.py``. Each entry of ``[hierarchy]
levels`` is one run (with the matching entry of ``[body] cells``); the outputs
are ``solution_L<levels>.vtu`` (displacement, contact, contact force) with the
hierarchy's grids beside it (``solution_L<levels>_grid<k>.vtu``),
``convergence.png`` (step length per iteration) and ``summary.json``.
"""

from __future__ import annotations

import json
import os
import sys
import time
import tomllib
from pathlib import Path

import numpy as np

from coupler.scene import SceneError, Table, output_directory
from transfer.fracture import fracture_blocks, rough_surface
from transfer.grid import StructuredGrid
from transfer.mesh import lattice_tetrahedra

from .hierarchy import semi_geometric_hierarchy
from .obstacle import obstacle_qp
from .solvers import solve

PROBLEM_FILE = "problem.toml"

KEYS = {
    "case": {"description": "free text"},
    "body": {"shape": "'cube' or 'rock'", "size": "cube: edge length; rock: [Lx, Ly, height]",
             "cells": "one per run: cube: cells per axis; rock: [nx, ny, nz]",
             "rms": "rock: RMS height of the rough bottom face", "hurst": "rock: Hurst exponent (default 0.8)",
             "seed": "rock: seed of the rough surface (default 1)"},
    "material": {"E": "Young's modulus", "nu": "Poisson's ratio"},
    "load": {"displacement": "[ux, uy, uz] of the top face", "gap": "plane below the lowest point (default 0)"},
    "hierarchy": {"levels": "one per run: levels including the fine mesh", "coarse_shape": "cells of the "
                  "coarsest grid per axis", "margin": "grid enlargement per side, fraction of the body size"},
    "solver": {"method": "'multilevel', 'active_set' or 'snes_vi'", "tolerance": "step length (default 1e-12)",
               "max_iterations": "default 200", "smoothing": "Gauss-Seidel sweeps per level (default 3)"},
    "output": {"directory": "default 'results'"},
}


def _int_list(table: Table, key: str, entry) -> list:
    value = table.data.get(key)
    if not isinstance(value, list) or not value or not all(entry(v) for v in value):
        raise table.error(key, f"must be a non-empty list ({table.keys[key]}), got {value!r}")
    return value


def load(case_dir, output=None) -> dict:
    """The validated problem of a case directory; SceneError naming file, table and key."""
    case_dir = Path(case_dir)
    path = case_dir / PROBLEM_FILE
    if not path.is_file():
        raise SceneError(f"{case_dir}: no {PROBLEM_FILE} in the case directory")
    with open(path, "rb") as f:
        data = tomllib.load(f)
    for name in data:
        if name not in KEYS:
            raise SceneError(f"{path}: [{name}]: unknown table; known tables: {', '.join(KEYS)}")
    t = {name: Table(path, name, data.get(name, {}), keys) for name, keys in KEYS.items()}
    body, h = t["body"], t["hierarchy"]
    shape = body.string("shape", choices=("cube", "rock"))
    is_int = lambda v: isinstance(v, int) and not isinstance(v, bool) and v >= 1
    if shape == "cube":
        cells, size = _int_list(body, "cells", is_int), body.number("size", positive=True)
    else:
        cells = _int_list(body, "cells", lambda v: isinstance(v, list) and len(v) == 3 and all(map(is_int, v)))
        size = body.vector("size")
        if min(size) <= 0:
            raise body.error("size", f"must be positive, got {size}")
    levels = _int_list(h, "levels", lambda v: is_int(v) and v >= 2)
    if len(levels) != len(cells):
        raise h.error("levels", f"{len(levels)} entries but [body] cells has {len(cells)}: one each per run")
    return {
        "path": path, "description": t["case"].string("description", ""), "shape": shape, "cells": cells,
        "size": size, "rms": body.number("rms", 0.0, minimum=0.0), "hurst": body.number("hurst", 0.8),
        "seed": body.integer("seed", 1, minimum=0),
        "E": t["material"].number("E", positive=True), "nu": t["material"].number("nu", minimum=-1, maximum=0.4999),
        "displacement": t["load"].vector("displacement"), "gap": t["load"].number("gap", 0.0, minimum=0.0),
        "levels": levels, "coarse_shape": h.shape("coarse_shape", [2, 2, 2]),
        "margin": h.number("margin", 0.0, minimum=0.0),
        "method": t["solver"].string("method", "multilevel", choices=("multilevel", "active_set", "snes_vi")),
        "tolerance": t["solver"].number("tolerance", 1e-12, positive=True),
        "max_iterations": t["solver"].integer("max_iterations", 200),
        "smoothing": t["solver"].integer("smoothing", 3),
        "output_dir": output_directory(case_dir, t["output"], output),
    }


def body_mesh(problem: dict, cells) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(points, tets, top nodes) of the body at one resolution."""
    if problem["shape"] == "cube":
        size = problem["size"]
        grid = StructuredGrid.from_bounds([0.0] * 3, [size] * 3, [cells] * 3)
        points, tets = grid.points, lattice_tetrahedra(grid.shape)
    else:  # the upper block of transfer.fracture: flat top, rough bottom face
        (lx, ly, height), (nx, ny, nz) = problem["size"], cells
        rough = rough_surface((nx, ny), (lx, ly), problem["hurst"], problem["rms"], problem["seed"], periodic=False)
        block = fracture_blocks((nx, ny, nz), (lx, ly), height, (rough - problem["rms"], rough)).upper
        points, tets = block.points, block.cells
    top = np.flatnonzero(np.isclose(points[:, 2], points[:, 2].max(), rtol=0, atol=1e-9 * np.ptp(points)))
    return points, tets, top


def options(problem: dict, hierarchy) -> dict:
    """Solver options of the problem's method (the multilevel one gets the hierarchy)."""
    if problem["method"] == "multilevel":
        nu = problem["smoothing"]
        return {"hierarchy": hierarchy, "tol": problem["tolerance"], "maxiter": problem["max_iterations"],
                "presmooth": nu, "postsmooth": nu, "coarse_smooth": nu}
    return {}


def build(problem: dict, levels: int, cells, nthreads: int = 1):
    """Mesh, obstacle problem and hierarchy of one run: (points, tets, top, qp, hierarchy, seconds)."""
    t0 = time.perf_counter()
    points, tets, top = body_mesh(problem, cells)
    plane = points[:, 2].min() - problem["gap"]
    qp = obstacle_qp(points, tets, problem["E"], problem["nu"], top, problem["displacement"], plane)
    t1 = time.perf_counter()
    hierarchy = semi_geometric_hierarchy(points, tets, levels, problem["coarse_shape"],
                                         margin=problem["margin"], nthreads=nthreads)
    return points, tets, top, qp, hierarchy, {"assembly": t1 - t0, "hierarchy": time.perf_counter() - t1}


def solve_level(problem: dict, levels: int, cells, nthreads: int = 1) -> tuple[dict, dict]:
    """One run: mesh, obstacle problem, hierarchy, solve. Returns (summary entry, fields)."""
    points, tets, top, qp, hierarchy, seconds = build(problem, levels, cells, nthreads)
    sol = solve(qp, problem["method"], **options(problem, hierarchy))
    u = sol.x.reshape(-1, 3)
    force = -qp.multiplier(sol.x).reshape(-1, 3)  # A x - b: the obstacle's push on the body (up)
    prescribed = np.zeros(len(points), bool)
    prescribed[top] = True
    contact = (u[:, 2] <= qp.lower[2::3]) & ~prescribed
    force[~contact] = 0.0
    entry = {"levels": levels, "cells": cells, "nodes": len(points), "tets": len(tets), "dofs": qp.size,
             "level_sizes": hierarchy.sizes, "iterations": sol.iterations, "converged": sol.converged,
             "asymptotic_rate": sol.info.get("asymptotic_rate"), "final_step": sol.history[-1] if sol.history else None,
             "step_history": sol.history, "contact_nodes": int(contact.sum()),
             "contact_force_z": float(force[:, 2].sum()),
             "max_penetration": float(max(0.0, np.max(qp.lower[2::3] - u[:, 2]))),
             "kkt_residual": qp.kkt_residual(sol.x), "energy": qp.energy(sol.x),
             "seconds": {**seconds, "solve": sol.seconds}}
    fields = {"points": points, "tets": tets, "displacement": u, "contact": contact.astype(np.uint8),
              "contact_force": force}
    fields["grids"] = [(grid, kept) for grid, kept in zip(hierarchy.grids, hierarchy.kept)]
    return entry, fields


def write_vtu(path: Path, fields: dict) -> None:
    """The solution on the fine mesh, and each coarse grid of the hierarchy beside it
    (``<stem>_grid<k>.vtu``, point data ``kept``: 0 where the basis function was dropped)."""
    import meshio

    data = {k: v for k, v in fields.items() if k not in ("points", "tets", "grids")}
    meshio.Mesh(fields["points"], [("tetra", fields["tets"])], point_data=data).write(path)
    for k, (grid, kept) in enumerate(fields.get("grids", [])):
        mask = np.zeros(grid.num_points, np.uint8)
        mask[kept] = 1
        mesh = grid.to_meshio()
        mesh.point_data["kept"] = mask
        mesh.write(path.with_name(f"{path.stem}_grid{k}.vtu"))


def plot_convergence(path: Path, runs: list[dict], title: str) -> None:
    """Step length against iteration per run (paper figure 14, left)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    for r in runs:
        ax.semilogy(np.arange(1, len(r["step_history"]) + 1), r["step_history"], "o-", ms=3,
                    label=f"{r['levels']} levels, {r['dofs']:,} dofs")
    ax.set_xlabel("iteration")
    ax.set_ylabel("step length ||x_k+1 - x_k||")
    ax.set_title(title)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def run_case(case_dir, output=None, only_levels=None, nthreads: int = 1, log=print) -> dict:
    """Run every (levels, cells) pair of a case (or those in `only_levels`) and write the outputs."""
    problem = load(case_dir, output)
    out = problem["output_dir"]
    out.mkdir(parents=True, exist_ok=True)
    runs = []
    for levels, cells in zip(problem["levels"], problem["cells"]):
        if only_levels and levels not in only_levels:
            continue
        entry, fields = solve_level(problem, levels, cells, nthreads)
        write_vtu(out / f"solution_L{levels}.vtu", fields)
        runs.append(entry)
        log(f"{levels} levels  {entry['dofs']:>8,} dofs  sizes {entry['level_sizes']}  {entry['iterations']:3d} "
            f"iterations  rate {entry['asymptotic_rate']:.3f}  contact nodes {entry['contact_nodes']}  "
            f"solve {entry['seconds']['solve']:.1f} s")
    if not runs:
        raise SceneError(f"{problem['path']}: [hierarchy] levels: none of {only_levels} is listed")
    plot_convergence(out / "convergence.png", runs, f"{Path(case_dir).name}: {problem['method']}")
    summary = {"case": Path(case_dir).name, "description": problem["description"], "method": problem["method"],
               "tolerance": problem["tolerance"], "runs": runs,
               "load_average": list(os.getloadavg())}
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    return summary


def main(case_dir, argv=None) -> int:
    """Command line of a case's run.py: ``[--levels L ...] [--output DIR] [--threads N]``."""
    import argparse

    parser = argparse.ArgumentParser(description=f"obstacle case {Path(case_dir).name}")
    parser.add_argument("--levels", type=int, nargs="+", help="only these entries of [hierarchy] levels")
    parser.add_argument("--output", help="output directory (default: [output] directory of the case)")
    parser.add_argument("--threads", type=int, default=2, help="threads of the projection assembly")
    args = parser.parse_args(argv)
    try:
        run_case(case_dir, args.output, args.levels, args.threads)
    except SceneError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    return 0
