"""The three fluids side by side: the OpenFOAM participant (stock binaries, a relaunch per
coupling iteration), the Chorin participant (fluid_chorin, state in memory) and the Reynolds
participant (fluid_reynolds: the local cubic law in the fracture's plane, no 3D flow).

* ``coupled``: each case (default small_fracture, added_mass_heavy, added_mass_light) run
  through ``varcouple run`` once per fluid (the one ``participant`` line swapped): wall time,
  fluid time and its share, coupling iterations, wall time per coupling iteration, the maximum
  displacement per step, the pressure drop per step (mean pressure of the fluid-centred cells of
  the inlet column minus the outlet column), and the Chorin run's differences to the OpenFOAM
  run; the transient cases also with the Chorin fluid in the OpenFOAM fluid's rigid-body model
  (``chorin_bodies``: ``solid_velocity = "bodies"``), the same discrete problem, so that the
  per-cell run's difference is the model's; the Reynolds fluid where it can run (no dynamics);
* ``plates``: the fluid alone on the immersed plates of cases/parallel_plates (4 to 32 cells
  across the aperture, offset 0.3 of a cell), run once per fluid as well: error of the flow rate
  against the cubic law (the scene's [check]) and the fluid's time (set-up and solve) per fluid
  (accuracy against cost).
* ``hm_fracture`` (``--hm``): cases/hm_fracture as shipped with the Chorin and the Reynolds fluid:
  e_h, e_m, Q per stress and the fluid's time, the Chorin fluid's time over the Reynolds fluid's
  (goal >= 100); and the Reynolds solve alone on a 256 x 256 rough aperture map (seconds per solve).
* ``hm_fracture_map`` (``--map``): cases/hm_fracture_map, the Reynolds fluid coupled on a 256 x 256
  aperture map (contact + flow): the time of a stress by phase (solid with its contact and platen
  search, the coupler's transfers and rebuilds of the solid fractions, the Reynolds participant)
  and the Reynolds solves' own seconds.

* ``ranks`` (with ``--ranks 1 2``): the Chorin fluid on MPI ranks by grid slabs: the lid-driven
  cavity (Re 100; 64^2 and 128^2 cells, and a 3D cavity of 40^3) for a fixed number of
  pseudo-time steps under ``mpirun -n R`` with each Poisson solver (time per step, the pressure
  Poisson solves' share), and small_fracture coupled with ``[solvers.fluid] ranks = R`` (wall and
  fluid time). The machine's load average is recorded before and after: MPI ranks that share
  their cores with other jobs wait on each other, so timings under load are no speed-ups.

Goals (PASS/MISS): coupled small_fracture at least 2x faster end to end with the Chorin fluid; the
Reynolds fluid's time on hm_fracture at least 100x below the Chorin fluid's.

    .venv/bin/python bench/fluids.py [--cases small_fracture ...] [--across 4 8 16 32] [--ranks 1 2] [--hm]
                                     [--map [NX NY NZ]] [--quick] [-o FILE]

``--quick`` (smoke test): small_fracture only, plates at 4 and 8 across; output
bench/results/fluids_quick.json unless ``-o`` is given.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

FLUIDS = ("openfoam", "chorin", "reynolds")
#: the Chorin fluid in the OpenFOAM fluid's rigid-body model (scenes with dynamics)
BODIES = {"substeps = 1": 'substeps = 1\nsolid_velocity = "bodies"'}
CASES = ("small_fracture", "added_mass_heavy", "added_mass_light")
GOAL_SPEEDUP = 2.0
GOAL_REYNOLDS = 100.0  # the Chorin fluid's time over the Reynolds fluid's on hm_fracture


def pressure_drop(out: Path, step: int) -> float | None:
    """Mean pressure of the fluid-centred cells (solid fraction < 1/2) of the first grid column
    minus that of the last, from the fluid's VTU of ``step``."""
    import meshio

    path = out / f"fluid_{step:04d}.vtu"
    if not path.exists():
        return None
    m = meshio.read(path)
    nx, ny, nz = (len(np.unique(np.round(m.points[:, d], 12))) - 1 for d in range(3))  # a structured box
    p = m.cell_data["pressure"][0].reshape(nz, ny, nx)
    fluid = m.cell_data["solid_fraction"][0].reshape(nz, ny, nx) < 0.5
    return float(p[..., 0][fluid[..., 0]].mean() - p[..., -1][fluid[..., -1]].mean())


def run_case(case: str, fluid: str, replace: dict | None = None) -> dict:
    """``varcouple run`` on a copy of cases/CASE with ``participant = FLUID`` for the fluid (and the
    text replacements `replace` in its scene)."""
    from coupler.cli import main

    with tempfile.TemporaryDirectory(prefix=f"bench-fluids-{case}-{fluid}-") as tmp:
        copy = Path(tmp) / case
        shutil.copytree(ROOT / "cases" / case, copy, ignore=shutil.ignore_patterns("results"))
        scene = (copy / "scene.toml").read_text()
        line = next((f'participant = "{f}"' for f in FLUIDS if f'participant = "{f}"' in scene), None)
        if line is None:
            raise SystemExit(f"cases/{case}/scene.toml: no fluid 'participant = ...' line to swap")
        scene = scene.replace(line, f'participant = "{fluid}"')
        if fluid != "openfoam":  # simpleFoam's iteration budget is not a pseudo-time step budget
            scene = scene.replace("max_iterations = 3000\n", "")
        for old, new in (replace or {}).items():
            scene = scene.replace(old, new)
        (copy / "scene.toml").write_text(scene)
        out = Path(tmp) / "out"
        t0 = time.perf_counter()
        code = main(["run", str(copy), "--output", str(out)])
        wall = time.perf_counter() - t0
        summary = json.loads((out / "summary.json").read_text())
        steps = summary.get("steps", [])
        phases = summary.get("phases_seconds", {})
        iterations = sum(s.get("iterations", 0) for s in steps)
        fluid_seconds = phases.get("fluid", 0.0)
        fluid_log = out / "logs" / "fluid.log"
        solves = re.findall(r"Reynolds flow rate .*, ([0-9.]+) s$", fluid_log.read_text(), re.M) \
            if fluid_log.exists() else []
        return {"fluid": fluid, "exit_code": code, "status": summary.get("status"), "error": summary.get("error"),
                "wall_seconds": wall, "fluid_seconds": fluid_seconds,
                "fluid_share": fluid_seconds / wall if wall else None,
                "coupling_iterations": iterations, "iterations_per_step": [s.get("iterations") for s in steps],
                "seconds_per_coupling_iteration": wall / iterations if iterations else None,
                "fluid_seconds_per_coupling_iteration": fluid_seconds / iterations if iterations else None,
                "max_displacement": [s.get("max_displacement") for s in steps],
                "pressure_drop": pressure_drop(out, len(steps) - 1) if steps else None,
                "pressure_drop_per_step": [pressure_drop(out, k) for k in range(len(steps))],
                "fluid_setup_seconds": phases.get("fluid setup", 0.0), "check": summary.get("check"),
                "fracture": [s["fracture"] for s in steps if "fracture" in s],
                "fluid_cells": summary.get("sizes", {}).get("fluid", {}).get("cells"),
                "fluid_solves": steps[-1]["solves"].get("fluid", []) if steps else [],
                "phases_seconds": phases, "geometry_update": summary.get("geometry_update"),
                "reynolds_solve_seconds": [float(t) for t in solves]}


def compare(runs: dict, chorin: str = "chorin") -> dict:
    """The run ``chorin`` (its key in ``runs``: a Chorin or the Reynolds run) against the OpenFOAM
    run: relative differences and the speed-up."""
    of, ch = runs["openfoam"], runs[chorin]
    out = {"speedup_end_to_end": of["wall_seconds"] / ch["wall_seconds"],
           "fluid_speedup": of["fluid_seconds"] / ch["fluid_seconds"] if ch["fluid_seconds"] else None,
           "max_displacement_difference": [b / a - 1 if a and b else None
                                           for a, b in zip(of["max_displacement"], ch["max_displacement"])],
           "pressure_drop_difference_per_step": [b / a - 1 if a and b else None for a, b in
                                                 zip(of["pressure_drop_per_step"], ch["pressure_drop_per_step"])]}
    if of["pressure_drop"] and ch["pressure_drop"]:
        out["pressure_drop_difference"] = ch["pressure_drop"] / of["pressure_drop"] - 1
    return out


def plates_side_by_side(across) -> list[dict]:
    """cases/parallel_plates at offset 0.3 with both fluids: the error against the cubic law (its
    [check]) and the fluid's seconds (set-up and solve)."""
    rows = []
    for n in across:
        replace = {"cells_across = 8 ": f"cells_across = {n} ", "offset = 0.25 ": "offset = 0.3 "}
        runs = {fluid: run_case("parallel_plates", fluid, {**replace, **({"max_iterations = 5000\n": ""}
                                                                         if fluid != "openfoam" else {})})
                for fluid in FLUIDS}
        rows.append({"cells_across": n, "cells": runs["openfoam"]["fluid_cells"],
                     **{fluid: {"error": r["check"]["relative_difference"] if r["check"] else None,
                                "seconds": r["fluid_setup_seconds"] + r["fluid_seconds"],
                                "iterations": sum(s["iterations"] for s in r["fluid_solves"]),
                                "converged": r["status"] == "completed"} for fluid, r in runs.items()}})
    return rows


def hm_side_by_side() -> dict:
    """cases/hm_fracture as shipped, once with the Chorin and once with the Reynolds fluid: the
    fracture's figures per stress and the fluid's time; then the Reynolds solve alone on a
    256 x 256 rough aperture map with contacts (the seconds of one solve, the best of three)."""
    from fluid_reynolds.reynolds import solve

    out = {"load_average_before": os.getloadavg()}
    for fluid in ("chorin", "reynolds"):
        r = run_case("hm_fracture", fluid)
        out[fluid] = {k: r[k] for k in ("status", "wall_seconds", "fluid_seconds", "coupling_iterations",
                                         "iterations_per_step", "fracture")}
        rows = "; ".join(f"e_h {1e6 * f['hydraulic_aperture']:.2f} um, e_m {1e6 * f['mechanical_aperture']:.2f} um, "
                         f"Q {f['flow_rate']:.3e}" for f in r["fracture"])
        print(f"  {fluid:9s} {r['status']}: wall {r['wall_seconds']:.2f} s, fluid {r['fluid_seconds']:.3f} s; {rows}")
    out["fluid_time_chorin_over_reynolds"] = out["chorin"]["fluid_seconds"] / out["reynolds"]["fluid_seconds"]
    out["hydraulic_aperture_reynolds_over_chorin"] = [
        a["hydraulic_aperture"] / b["hydraulic_aperture"] - 1
        for a, b in zip(out["reynolds"]["fracture"], out["chorin"]["fracture"])]
    rng = np.random.default_rng(0)
    aperture = np.maximum(1e-4 * (rng.random((256, 256)) - 0.1), 0.0)  # about 10 % of the cells closed
    seconds = []
    for _ in range(3):
        t0 = time.perf_counter()
        flow = solve(aperture, (0.1 / 256, 0.1 / 256), 1e-3, {"xmin": 1.0, "xmax": 0.0})
        seconds.append(time.perf_counter() - t0)
    out["map_256"] = {"cells": aperture.size, "closed": int((aperture == 0).sum()), "seconds": min(seconds),
                      "flow_rate": flow.flow_rate, "residual": flow.residual}
    out["load_average_after"] = os.getloadavg()
    print(f"  the Chorin fluid's time over the Reynolds fluid's: {out['fluid_time_chorin_over_reynolds']:.0f}x; e_h "
          f"Reynolds against Chorin per stress: "
          + ", ".join(f"{d:+.1%}" for d in out["hydraulic_aperture_reynolds_over_chorin"])
          + f"; a 256 x 256 map: {min(seconds):.3f} s per solve")
    return out


def map_per_stress(shape=None) -> dict:
    """cases/hm_fracture_map (the Reynolds fluid on a 256 x 256 aperture map; ``shape`` another
    [geometry.fluid] shape): where the time of a stress goes, each phase of the run (solid with its
    contact and platen search, the coupler's transfers and its rebuilds of the solid fractions of
    the fluid grid, the Reynolds participant) per stress and per coupling iteration, and the
    Reynolds solves' own seconds (its log)."""
    replace = {"shape = [256, 256, 24]": f"shape = {list(shape)}"} if shape else {}
    out = {"load_average_before": os.getloadavg()}
    r = run_case("hm_fracture_map", "reynolds", replace)
    steps, iterations = len(r["iterations_per_step"]), r["coupling_iterations"]
    out.update({k: r[k] for k in ("status", "wall_seconds", "fluid_seconds", "iterations_per_step", "fracture",
                                  "fluid_cells", "phases_seconds", "geometry_update", "reynolds_solve_seconds")})
    out["per_stress"] = {phase: seconds / steps for phase, seconds in r["phases_seconds"].items()}
    out["per_stress"]["wall"] = r["wall_seconds"] / steps
    out["per_coupling_iteration"] = {phase: seconds / iterations for phase, seconds in r["phases_seconds"].items()}
    out["load_average_after"] = os.getloadavg()
    print(f"  {r['status']}: {r['fluid_cells']:,} fluid cells, wall {r['wall_seconds']:.1f} s, {steps} stresses, "
          f"coupling iterations {r['iterations_per_step']}")
    print("  per stress: " + ", ".join(f"{phase} {seconds:.2f} s" for phase, seconds in out["per_stress"].items()))
    if r["reynolds_solve_seconds"]:
        print(f"  the Reynolds solve itself: {min(r['reynolds_solve_seconds']):.3f} to "
              f"{max(r['reynolds_solve_seconds']):.3f} s per coupling iteration")
    return out


#: the cavities of the ranks section: name -> (shape, pseudo-time steps timed)
CAVITIES = {"64^2": ((64, 64, 1), 200), "128^2": ((128, 128, 1), 100), "40^3": ((40, 40, 40), 30)}


def cavity_steps(shape, steps: int, poisson: str) -> dict:
    """On the ranks of MPI.COMM_WORLD: ``steps`` pseudo-time steps of the lid-driven cavity at Re 100
    from rest (one set-up step first, untimed); seconds per step and in the Poisson solves (rank 0's)."""
    from mpi4py import MPI

    from fluid_chorin.solver import ChorinSolver
    from fluid_chorin.spec import ChorinSpec

    comm = MPI.COMM_WORLD
    n = max(shape)
    closed = "wall" if shape[2] > 1 else "empty"
    config = {"grid": {"origin": [0, 0, 0], "spacing": [1 / n] * 3, "shape": list(shape)}, "inlet": "wall",
              "outlet": "wall", "walls": "wall", "rho": 1.0, "mu": 0.01, "poisson": poisson,
              "boundaries": {"zmin": closed, "zmax": closed, "ymax": {"velocity": [1.0, 0.0, 0.0]}}}
    solver = ChorinSolver(ChorinSpec.from_config(config), comm)
    dt = solver.stable_dt(solver.state)
    solver.state = solver.step(dt, solver.state, solver.state)[0]  # the Poisson set-up
    poisson_seconds, solve = 0.0, solver.poisson(dt).solve

    def timed(rhs):
        nonlocal poisson_seconds
        t = time.perf_counter()
        out = solve(rhs)
        poisson_seconds += time.perf_counter() - t
        return out

    solver.poisson(dt).solve = timed
    comm.Barrier()
    t0 = time.perf_counter()
    for _ in range(steps):
        new, _, report = solver.step(dt, solver.state, solver.state)
        solver.state = new
    comm.Barrier()
    seconds = time.perf_counter() - t0
    return {"ranks": comm.size, "cells": int(np.prod(shape)), "steps": steps, "poisson": report.method,
            "poisson_iterations": report.iterations, "seconds_per_step": seconds / steps,
            "poisson_share": poisson_seconds / seconds}


def ranks_side_by_side(ranks) -> dict:
    """The cavities under ``mpirun -n R`` and small_fracture with R chorin ranks, for each R."""
    import subprocess

    from coupler.protocol.mpi import mpi_environment

    env = dict(mpi_environment(), OMP_NUM_THREADS="1")
    out = {"load_average_before": os.getloadavg(), "cavity": [], "small_fracture": []}
    for name, (shape, steps) in CAVITIES.items():
        for poisson in ("direct", "gamg"):
            for r in ranks:
                cmd = [shutil.which("mpirun") or "mpirun", "-n", str(r), "--oversubscribe", sys.executable,
                       __file__, "--cavity", *map(str, shape), str(steps), poisson]
                proc = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=ROOT)
                if proc.returncode:
                    raise SystemExit(f"the {name} cavity on {r} ranks failed: {proc.stderr[-2000:]}")
                row = {"grid": name, **json.loads(proc.stdout.strip().splitlines()[-1])}
                out["cavity"].append(row)
                print(f"  cavity {name:6s} {row['poisson']:18s} {r} rank{'s' * (r > 1)}: "
                      f"{1e3 * row['seconds_per_step']:8.2f} ms per step, Poisson {row['poisson_share']:.0%}")
    for r in ranks:
        run = run_case("small_fracture", "chorin", {'penalization = "wall"': f'penalization = "wall"\nranks = {r}'})
        out["small_fracture"].append({"ranks": r, **run})
        print(f"  small_fracture, chorin on {r} rank{'s' * (r > 1)}: {run['status']}, {run['wall_seconds']:.2f} s "
              f"end to end, fluid {run['fluid_seconds']:.2f} s, iterations {run['iterations_per_step']}, "
              f"max displacement {run['max_displacement'][-1]:.6e} m")
    out["load_average_after"] = os.getloadavg()
    print(f"  load average before {out['load_average_before'][0]:.2f}, after {out['load_average_after'][0]:.2f} "
          f"({os.cpu_count()} cores: timings under load are no speed-ups)")
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", nargs="*", default=list(CASES), choices=CASES, help="none: skip the coupled runs")
    ap.add_argument("--across", nargs="*", type=int, default=[4, 8, 16, 32], help="none: skip the plates")
    ap.add_argument("--quick", action="store_true", help="small_fracture and plates at 4, 8 across only")
    ap.add_argument("--ranks", nargs="+", type=int, help="also the Chorin fluid on these MPI rank counts")
    ap.add_argument("--hm", action="store_true", help="also hm_fracture with the Chorin and the Reynolds fluid")
    ap.add_argument("--map", nargs="*", type=int, metavar="N",
                    help="also cases/hm_fracture_map (the Reynolds fluid on a 256 x 256 aperture map; N: the "
                         "[geometry.fluid] shape instead, three integers): the time of a stress by phase")
    ap.add_argument("--cavity", nargs=5, metavar=("NX", "NY", "NZ", "STEPS", "POISSON"),
                    help="(run under mpirun by --ranks) time the cavity's steps, print JSON")
    ap.add_argument("-o", "--output", type=Path)
    args = ap.parse_args(argv)
    if args.cavity:
        *shape, steps, poisson = args.cavity
        row = cavity_steps(tuple(int(n) for n in shape), int(steps), poisson)
        if row["ranks"] == 1 or __import__("mpi4py.MPI").MPI.COMM_WORLD.rank == 0:
            print(json.dumps(row))
        return row
    if args.quick:
        args.cases, args.across = ["small_fracture"], [4, 8]
    output = args.output or ROOT / "bench" / "results" / ("fluids_quick.json" if args.quick else "fluids_ranks.json"
                                                           if args.ranks and not args.cases else "fluids.json")
    os.environ.setdefault("VARCOUPLE_PICTURES", "0")  # time the solvers, not the renderings
    result = {"date": time.strftime("%Y-%m-%d %H:%M:%S"), "platform": platform.platform(),
              "cpu_count": os.cpu_count(), "load_average_before": os.getloadavg(), "coupled": {}, "goals": {}}
    for case in args.cases:
        dynamic = "substeps = 1" in (ROOT / "cases" / case / "scene.toml").read_text()
        runs = {fluid: run_case(case, fluid) for fluid in FLUIDS if fluid != "reynolds" or not dynamic}
        if dynamic:
            runs["chorin_bodies"] = run_case(case, "chorin", BODIES)
        result["coupled"][case] = {"runs": runs, "chorin_against_openfoam": compare(runs)}
        extra = "chorin_bodies" if dynamic else "reynolds"  # the Reynolds fluid refuses dynamics
        result["coupled"][case][f"{extra}_against_openfoam"] = compare(runs, extra)
        print(f"\n{case}")
        print(f"  {'fluid':13s} {'status':10s} {'wall s':>7s} {'fluid s':>8s} {'share':>6s} {'iters':>6s} "
              f"{'s/iter':>7s} {'max displacement [m]':>22s} {'dp [Pa]':>8s}")
        for fluid, r in runs.items():
            disp = r["max_displacement"][-1] if r["max_displacement"] else float("nan")
            dp = r["pressure_drop"] if r["pressure_drop"] is not None else float("nan")
            print(f"  {fluid:13s} {str(r['status']):10s} {r['wall_seconds']:7.2f} {r['fluid_seconds']:8.2f} "
                  f"{r['fluid_share']:6.2f} {r['coupling_iterations']:6d} {r['seconds_per_coupling_iteration']:7.3f} "
                  f"{disp:22.4e} {dp:8.1f}")
        for key in ("chorin_against_openfoam", f"{extra}_against_openfoam"):
            c = result["coupled"][case][key]
            diffs = ", ".join(f"{d:+.2%}" if d is not None else "-" for d in c["max_displacement_difference"])
            drops = ", ".join(f"{d:+.2%}" if d is not None else "-" for d in c["pressure_drop_difference_per_step"])
            print(f"  {key.replace('_', ' ')}: {c['speedup_end_to_end']:.2f}x end to end, fluid "
                  f"{c['fluid_speedup']:.1f}x; max displacement per step {diffs}; pressure drop per step {drops}")
    if "small_fracture" in result["coupled"]:
        speedup = result["coupled"]["small_fracture"]["chorin_against_openfoam"]["speedup_end_to_end"]
        result["goals"]["small_fracture_speedup"] = {"value": speedup, "goal": f">= {GOAL_SPEEDUP}",
                                                     "status": "PASS" if speedup >= GOAL_SPEEDUP else "MISS"}
    if args.across:
        print("\nimmersed plates (fluid alone, offset 0.3): error against the cubic law and seconds")
        print(f"  {'across':>6s} {'cells':>6s} {'openfoam err':>13s} {'s':>6s} {'chorin err':>11s} {'s':>6s} "
              f"{'reynolds err':>13s} {'s':>6s}")
    result["plates"] = plates_side_by_side(args.across)
    for row in result["plates"]:
        print(f"  {row['cells_across']:6d} {row['cells']:6d} " + " ".join(
            f"{row[f]['error']:+{len(f) + 4}.3%} {row[f]['seconds']:6.2f}" for f in FLUIDS))
    if args.hm:
        print("\nhm_fracture as shipped: the 3D Chorin fluid and the Reynolds fluid")
        result["hm_fracture"] = hm_side_by_side()
        speedup = result["hm_fracture"]["fluid_time_chorin_over_reynolds"]
        done = all(result["hm_fracture"][f]["status"] == "completed" for f in ("chorin", "reynolds"))
        result["goals"]["hm_fracture_reynolds_fluid_time"] = {  # a run that failed early is fast: no PASS
            "value": speedup, "goal": f">= {GOAL_REYNOLDS:g}, both runs completed",
            "status": "PASS" if done and speedup >= GOAL_REYNOLDS else "MISS"}
    if args.map is not None:
        print("\nhm_fracture_map: the Reynolds fluid on a full aperture map")
        result["hm_fracture_map"] = map_per_stress(args.map or None)
    if args.ranks:
        print("\nthe Chorin fluid on MPI ranks by grid slabs")
        result["ranks"] = ranks_side_by_side(args.ranks)
    for name, g in result["goals"].items():
        print(f"goal {name}: {g['value']:.2f} ({g['goal']}) {g['status']}")
    result["load_average_after"] = os.getloadavg()
    output.parent.mkdir(parents=True, exist_ok=True)
    output.write_text(json.dumps(result, indent=1))
    print(f"written {output}")
    return result


if __name__ == "__main__":
    main()
