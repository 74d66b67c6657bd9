"""``varcouple check|run`` on an ``[obstacle]`` scene: a body pressed onto the plane below
it, solved on semi-geometric hierarchies (paper section 4.3; ``cases/cube_obstacle``,
``cases/cube_obstacle_large``, ``cases/rock_obstacle``).

The scene's keys are :data:`TABLES` (documented in cases/README.md). Each entry of
``[hierarchy] levels`` is one run (with the matching entry of ``[body] cells``); written to
the output directory: ``solution_L<levels>.vtu`` (displacement, contact, contact force) with
the hierarchy's grids beside it (``solution_L<levels>_grid<k>.vtu``), ``convergence.png``
(step length per iteration) and ``summary.json``.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from nonsmooth.hierarchy import semi_geometric_hierarchy
from nonsmooth.obstacle import obstacle_qp
from nonsmooth.solvers import solve
from transfer.fracture import fracture_blocks, rough_surface
from transfer.grid import StructuredGrid
from transfer.mesh import lattice_tetrahedra

from coupler.errors import NotConverged
from coupler.output.results import write_summary
from coupler.scene.tables import Table, check_tables, output_directory

#: table -> key -> one-line description (also the list of allowed keys); cases/README.md
TABLES = {
    "case": {"description": "free text"},
    "obstacle": {"displacement": "[ux, uy, uz] imposed on the top face",
                 "gap": "distance of the plane below the body's lowest point (default 0)"},
    "body": {"shape": "'cube' or 'rock'", "size": "cube: edge length; rock: [Lx, Ly, height]",
             "cells": "one per run: cube: cells per axis; rock: [nx, ny, nz]",
             "rms": "rock: RMS height of the rough bottom face", "hurst": "rock: Hurst exponent (default 0.8)",
             "seed": "rock: seed of the rough surface (default 1)"},
    "material": {"E": "Young's modulus", "nu": "Poisson's ratio"},
    "hierarchy": {"levels": "one per run: levels including the fine mesh", "coarse_shape": "cells of the "
                  "coarsest grid per axis", "margin": "grid enlargement per side, fraction of the body size",
                  "threads": "threads of the projection assembly (default 1)"},
    "solver": {"method": "'multilevel', 'active_set' or 'snes_vi'", "tolerance": "step length (default 1e-12)",
               "max_iterations": "default 200", "smoothing": "Gauss-Seidel sweeps per level (default 3)"},
    "output": {"directory": "default 'results'"},
}
METHODS = ("multilevel", "active_set", "snes_vi")


@dataclass
class ObstacleScene:
    path: Path
    case_dir: Path
    description: str
    shape: str  # 'cube' or 'rock'
    size: float | list  # cube: edge length; rock: [Lx, Ly, height]
    cells: list  # one per run
    rms: float
    hurst: float
    seed: int
    E: float
    nu: float
    displacement: list
    gap: float
    levels: list  # one per run
    coarse_shape: list
    margin: float
    threads: int
    method: str
    tolerance: float
    max_iterations: int
    smoothing: int
    output_dir: Path


def parse(path: Path, case_dir: Path, data: dict, output=None) -> ObstacleScene:
    """Validate an ``[obstacle]`` scene (already read from TOML); SceneError naming file, table and key."""
    check_tables(path, data, TABLES, "an [obstacle] scene")
    t = {name: Table(path, name, data.get(name, {}), keys) for name, keys in TABLES.items()}
    body, h, s = t["body"], t["hierarchy"], t["solver"]
    shape = body.string("shape", choices=("cube", "rock"))
    if shape == "cube":
        cells, size = body.numbers("cells", integer=True, minimum=1), body.number("size", positive=True)
    else:
        cells = body.data.get("cells")
        if not isinstance(cells, list) or not cells or any(
                not isinstance(c, list) or len(c) != 3 or any(isinstance(n, bool) or not isinstance(n, int) or n < 1
                                                              for n in c) for c in cells):
            raise body.error("cells", f"must be a non-empty list of [nx, ny, nz] lists of positive integers, "
                                      f"got {cells!r}")
        size = body.vector("size")
        if min(size) <= 0:
            raise body.error("size", f"must be positive, got {size}")
    levels = h.numbers("levels", integer=True, minimum=2)  # distinct: the outputs are named by it
    if len(levels) != len(cells):
        raise h.error("levels", f"{len(levels)} entries but [body] cells has {len(cells)}: one each per run")
    return ObstacleScene(
        path=path, case_dir=case_dir, description=t["case"].string("description", None) or "", shape=shape,
        size=size, cells=cells, rms=body.number("rms", 0.0, minimum=0.0), hurst=body.number("hurst", 0.8),
        seed=body.integer("seed", 1, minimum=0), E=t["material"].number("E", positive=True),
        nu=t["material"].number("nu", minimum=-1, maximum=0.4999),
        displacement=t["obstacle"].vector("displacement"), gap=t["obstacle"].number("gap", 0.0, minimum=0.0),
        levels=levels, coarse_shape=h.shape("coarse_shape", [2, 2, 2]), margin=h.number("margin", 0.0, minimum=0.0),
        threads=h.integer("threads", 1), method=s.string("method", "multilevel", choices=METHODS),
        tolerance=s.number("tolerance", 1e-12, positive=True), max_iterations=s.integer("max_iterations", 200),
        smoothing=s.integer("smoothing", 3), output_dir=output_directory(case_dir, t["output"], output))


def plan_lines(scene: ObstacleScene) -> list[str]:
    """What ``varcouple check`` prints for an obstacle scene."""
    size = f"{scene.size:g} m cube" if scene.shape == "cube" else \
        f"{' x '.join(f'{v:g}' for v in scene.size)} m rock block, rough bottom (RMS {scene.rms:g} m)"
    runs = ", ".join(f"{lv} levels on {c if scene.shape == 'rock' else [c] * 3} cells"
                     for lv, c in zip(scene.levels, scene.cells))
    return [f"study         obstacle: {size} pressed onto the plane {scene.gap:g} m below its lowest point, "
            f"top face moved by {scene.displacement} m",
            f"material      E {scene.E:g} Pa, nu {scene.nu:g}",
            f"runs          {runs}; coarsest grid {scene.coarse_shape} cells, margin {scene.margin:g}",
            f"solver        {scene.method}, tolerance {scene.tolerance:g}, at most {scene.max_iterations} "
            f"iterations (in this process, no participants)"]


def body_mesh(scene: ObstacleScene, cells) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(points, tets, top nodes) of the body at one resolution."""
    if scene.shape == "cube":
        size = scene.size
        grid = StructuredGrid.from_bounds([0.0] * 3, [size] * 3, [cells] * 3)
        points, tets = grid.points, lattice_tetrahedra(grid.shape)
    else:  # the upper block of transfer.fracture: flat top, rough bottom face
        (lx, ly, height), (nx, ny, nz) = scene.size, cells
        rough = rough_surface((nx, ny), (lx, ly), scene.hurst, scene.rms, scene.seed, periodic=False)
        block = fracture_blocks((nx, ny, nz), (lx, ly), height, (rough - scene.rms, rough)).upper
        points, tets = block.points, block.cells
    top = np.flatnonzero(np.isclose(points[:, 2], points[:, 2].max(), rtol=0, atol=1e-9 * np.ptp(points)))
    return points, tets, top


def options(scene: ObstacleScene, hierarchy) -> dict:
    """Solver options of the scene's method (the multilevel one gets the hierarchy)."""
    if scene.method == "multilevel":
        nu = scene.smoothing
        return {"hierarchy": hierarchy, "tol": scene.tolerance, "maxiter": scene.max_iterations,
                "presmooth": nu, "postsmooth": nu, "coarse_smooth": nu}
    return {}


def build(scene: ObstacleScene, levels: int, cells, nthreads: int | None = None):
    """Mesh, obstacle problem and hierarchy of one run: (points, tets, top, qp, hierarchy, seconds).
    `nthreads` overrides ``[hierarchy] threads``."""
    t0 = time.perf_counter()
    points, tets, top = body_mesh(scene, cells)
    plane = points[:, 2].min() - scene.gap
    qp = obstacle_qp(points, tets, scene.E, scene.nu, top, scene.displacement, plane)
    t1 = time.perf_counter()
    hierarchy = semi_geometric_hierarchy(points, tets, levels, scene.coarse_shape,
                                         margin=scene.margin, nthreads=nthreads or scene.threads)
    return points, tets, top, qp, hierarchy, {"assembly": t1 - t0, "hierarchy": time.perf_counter() - t1}


def solve_level(scene: ObstacleScene, levels: int, cells) -> tuple[dict, dict]:
    """One run: mesh, obstacle problem, hierarchy, solve. Returns (summary entry, fields)."""
    points, tets, top, qp, hierarchy, seconds = build(scene, levels, cells)
    sol = solve(qp, scene.method, **options(scene, hierarchy))
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


def run(scene: ObstacleScene, log=print) -> dict:
    """Run every (levels, cells) pair of the scene and write the outputs; the summary."""
    out = scene.output_dir
    out.mkdir(parents=True, exist_ok=True)
    runs, written = [], []
    for levels, cells in zip(scene.levels, scene.cells):
        entry, fields = solve_level(scene, levels, cells)
        written.append(out / f"solution_L{levels}.vtu")
        write_vtu(written[-1], fields)
        runs.append(entry)
        log(f"{levels} levels  {entry['dofs']:>8,} dofs  sizes {entry['level_sizes']}  {entry['iterations']:3d} "
            f"iterations  rate {entry['asymptotic_rate']:.3f}  contact nodes {entry['contact_nodes']}  "
            f"solve {entry['seconds']['solve']:.1f} s")
    name = scene.case_dir.resolve().name
    plot_convergence(out / "convergence.png", runs, f"{name}: {scene.method}")
    failed = [r for r in runs if not r["converged"]]
    summary = {"scene": str(scene.path), "case": name, "description": scene.description, "method": scene.method,
               "tolerance": scene.tolerance, "runs": runs, "load_average": list(os.getloadavg()),
               "status": "not_converged" if failed else "completed"}
    write_summary(out, summary)
    if failed:
        r = failed[0]
        raise NotConverged(f"{scene.method} did not converge on {r['levels']} levels: {r['iterations']} iterations, "
                           f"tolerance {scene.tolerance:g}; raise [solver] max_iterations")
    for f in written:
        log(f"wrote {f} (and its grids {f.stem}_grid<k>.vtu)")
    log(f"wrote {out / 'convergence.png'}")
    log(f"wrote {out / 'summary.json'}")
    return summary
