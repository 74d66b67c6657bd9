"""Contact solvers: the primal-dual active set method (CG + GAMG) against PETSc SNES VI
(vinewtonrsls, CG + BoomerAMG) on the same transformed contact problems (paper eq. 10-11).

Hertz (cases/hertz: half-sphere on a block, contact cells h = 0.06, 0.04, 0.025 m) and the
rough fracture (the specimen of cases/fracture_closure as a 0.1 m box; lattices 8, 16, 24 per
side, upper face 2x coarser) at three refinements, each in load steps that start
from the previous step (Hertz: platen displacement 0.02 m in 3 steps; fracture: 0.08 ..
0.32 mm in 4 steps, about 2 to 20 MPa). Per level and solver: dofs, iterations per load
step, Krylov iterations, wall time, and the largest difference between the two solvers'
displacements. The active set method is also run with BoomerAMG (the AMG SNES VI has to
use: GAMG fails inside vinewtonrsls in PETSc 3.18), to tell the method's share of the
speed-up from the AMG's.

Goals: one contact solve per stress with ``method = "constraint"``, in less time than the
search; active-set iterations per load step that do not grow with refinement
(finest level's largest count at most the coarsest's + 1); time to solution at least 2x
below SNES VI at the finest level (both problems).

The cost of a stress (issue 30): the solid participant of cases/fracture_closure (the
cylinder at lattices 8 and 16 per side) and of cases/measured_fracture (coarsen 2 and 1)
closed by the stress-controlled platen through its steps, the AMG set up at every
active-set iteration ("from scratch", the old behaviour) against once per contact solve
(``amg_reuse``), the two in the same run: per stress the wall time (the step's reported
``seconds`` and its split: assembly, AMG set-up, solves, other, platen search), contact
solves, active-set and Krylov iterations; the ratios from scratch / reused, and the largest
difference of the closures. The same with the platen's displacement one more unknown of a
single contact solve (``method = "constraint"``, the AMG reused), against the search with the
reused AMG: time per stress, contact solves per stress, the closures' difference, the
process's peak memory after each run (runs in order: constraint, from scratch, reused). ``--baseline OLD.json`` (this bench's output for the previous
commit, measured in the same session) adds the ratios of contact solves and time per stress
of the reused AMG, old / new (the platen search's share).

    .venv/bin/python bench/contact.py [--quick] [--only stress] [--baseline OLD.json] [-o OUT.json]

The machine is shared: the load average before and after is recorded; times are
indicative. ``--quick``: two tiny levels per problem, two load steps (the smoke test).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import tempfile
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.output import finish  # noqa: E402

from coupler.plan.plan import make_plan  # noqa: E402
from coupler.scene import load  # noqa: E402
from solid_fenicsx.contact_hertz import PUSH, hertz_contact  # noqa: E402
from solid_fenicsx.participant import SolidParticipant  # noqa: E402
from transfer.generators import generate  # noqa: E402

#: name -> (solver, options); "active_set_hypre" separates the method from the AMG
SOLVERS = {"active_set": ("active_set", {}), "snes_vi": ("snes_vi", {}),
           "active_set_hypre": ("active_set", {"amg": "hypre"})}


def load_steps(contact, holder, values) -> dict:
    """Solve the load steps (platen displacements down, `holder` of all components or of z
    alone), each from the last; the figures."""
    per_step, start = [], time.perf_counter()
    for d in values:
        holder.value = [0.0, 0.0, -d] if np.size(holder.value) == 3 else -d
        state = contact.solve()
        per_step.append({"iterations": state.solution.iterations,
                         "krylov_iterations": state.solution.krylov_iterations,
                         "seconds": state.seconds["total"],
                         "active_nodes": int(state.active.sum())})
    return {"dofs": contact.num_dofs, "steps": per_step, "wall_seconds": time.perf_counter() - start,
            "iterations": [s["iterations"] for s in per_step],
            "krylov_iterations": int(sum(s["krylov_iterations"] for s in per_step)),
            "u": contact.elasticity.u.x.array.copy()}


def hertz_level(tmp, h, steps) -> dict:
    out = {"h": h}
    for name, (solver, options) in SOLVERS.items():
        contact, holder = hertz_contact(tmp, h, solver, **options)
        out[name] = load_steps(contact, holder, [PUSH * k / steps for k in range(1, steps + 1)])
    return out


def fracture_contact(shape, solver, options):
    """The contact and the top platen's displacement holder of cases/fracture_closure's solid as
    a 0.1 m box on the lattice `shape`, the platen displacement-controlled (a Dirichlet load)."""
    config = make_plan(load(ROOT / "cases" / "fracture_closure")).participant("solid").config
    generated = config["generator"]["parameters"]
    generated.update(shape="box", size=0.1, lattice=list(shape))
    info = generate("fracture_specimen", generated).info
    config["contact"].update(solver=solver, search_distance=2 * info["max_initial_aperture"] + generated["rms"])
    config["loads"][1:] = [{"type": "dirichlet", "boundary": "top", "value": 0.0, "components": ["x", "y"]},
                           {"type": "dirichlet", "boundary": "top", "value": 0.0, "components": ["z"]}]
    p = SolidParticipant()
    p.comm, p.rank = None, 0
    p.configure(config)
    p.contact.options = dict(options)  # each solver's own defaults, as for Hertz
    return p.contact, p.loads[2].holder


def fracture_level(shape, displacements) -> dict:
    out = {"shape": list(shape)}
    for name, (solver, options) in SOLVERS.items():
        out[name] = load_steps(*fracture_contact(shape, solver, options), displacements)
    return out


def compare(level) -> dict:
    a, s = level["active_set"], level["snes_vi"]
    level["solver_difference"] = float(np.max(np.abs(a["u"] - s["u"])) / np.max(np.abs(a["u"])))
    level["time_ratio_snes_vi_over_active_set"] = s["wall_seconds"] / a["wall_seconds"]
    level["time_ratio_snes_vi_over_active_set_hypre"] = s["wall_seconds"] / level["active_set_hypre"]["wall_seconds"]
    for name in SOLVERS:
        del level[name]["u"]
    level["dofs"] = a["dofs"]
    return level


def stress_participant(case: str, parameters: dict, stresses, reuse: bool, method: str = "search") -> SolidParticipant:
    """The configured solid of `case` with its generator's `parameters` changed, the platen's
    `stresses` and `method`, and the AMG reused (or set up at every active-set iteration)."""
    config = make_plan(load(ROOT / "cases" / case)).participant("solid").config
    config["generator"]["parameters"].update(parameters)
    platen = next(ld for ld in config["loads"] if ld["type"] == "platen")
    platen.update(value=list(stresses), method=method)
    config["steps"] = len(stresses)
    p = SolidParticipant()
    p.comm, p.rank = None, 0
    p.configure(config)
    p.contact.options["amg_reuse"] = reuse
    return p


STRESS_FIGURES = ("seconds", "seconds_assembly", "seconds_amg_setup", "seconds_solves", "seconds_other",
                  "seconds_platen_search", "contact_solves", "step_iterations", "step_krylov_iterations",
                  "closure", "platen_displacement", "area_fraction")
COUNTS = ("contact_solves", "step_iterations", "step_krylov_iterations")


def stress_steps(case, parameters, stresses, reuse, method="search") -> dict:
    """Each stress of `case` in turn: the step's figures, its measured wall time and whether
    every inner solve converged; the process's peak resident memory after the run."""
    p = stress_participant(case, parameters, stresses, reuse, method)
    steps = []
    for k, stress in enumerate(stresses):
        start = time.perf_counter()
        p.advance(k, 0, float(k), 1.0, {})
        wall = time.perf_counter() - start
        reports, figures = p.take_reports()
        failed = [r for r in reports if not r.converged]
        if failed:  # a ratio of times means nothing beside a solve that did not converge
            raise SystemExit(f"{case} {parameters} at {stress:g} Pa ({'reused' if reuse else 'from scratch'} AMG): "
                             f"{failed[0].solver} did not converge: {failed[0].detail}")
        steps.append({"stress": stress, "wall_seconds": wall, "converged": True,
                      "amg_setups_last_solve": p.static.state.solution.info.get("amg_setups"),
                      **{k: int(figures[k]) if k in COUNTS else figures[k] for k in STRESS_FIGURES}})
    return {"dofs": p.contact.num_dofs, "steps": steps, "peak_memory_mb": peak_memory_mb(),
            **{f"total_{k}": sum(st[k] for st in steps) for k in ("wall_seconds", "contact_solves",
                                                                   "step_iterations", "step_krylov_iterations",
                                                                   "seconds_amg_setup")}}


def peak_memory_mb() -> float:
    """The process's peak resident memory so far [MB] (a run's peak when it is the largest yet)."""
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def stress_level(case, parameters, stresses) -> dict:
    out = {"case": case, "parameters": parameters}
    for name, reuse, method in (("constraint", True, "constraint"), ("from_scratch", False, "search"),
                                ("reused", True, "search")):
        out[name] = stress_steps(case, parameters, stresses, reuse, method)
    a, b, c = out["from_scratch"], out["reused"], out["constraint"]
    out["ratio_time_search_over_constraint"] = b["total_wall_seconds"] / c["total_wall_seconds"]
    out["constraint_closure_difference"] = max(abs(x["closure"] - y["closure"]) / abs(x["closure"])
                                               for x, y in zip(b["steps"], c["steps"]))
    out["dofs"] = b["dofs"]
    out["ratio_time_from_scratch_over_reused"] = a["total_wall_seconds"] / b["total_wall_seconds"]
    out["ratio_krylov_reused_over_from_scratch"] = b["total_step_krylov_iterations"] / a["total_step_krylov_iterations"]
    out["closure_difference"] = max(abs(x["closure"] - y["closure"]) / abs(x["closure"])
                                    for x, y in zip(a["steps"], b["steps"]))
    out["seconds_reported_over_wall"] = min(st["seconds"] / st["wall_seconds"] for st in a["steps"] + b["steps"])
    return out


def against(baseline: dict, levels: list) -> list[dict]:
    """Per case in both runs: the reused AMG's contact solves per stress and total time, the
    baseline's and this run's, as ratios old / new."""
    old = {(lv["case"], json.dumps(lv["parameters"])): lv["reused"] for lv in baseline.get("stress", [])}
    rows = []
    for lv in levels:
        b = old.get((lv["case"], json.dumps(lv["parameters"])))
        if b is None or [st["stress"] for st in b["steps"]] != [st["stress"] for st in lv["reused"]["steps"]]:
            continue
        new = lv["reused"]
        rows.append({"case": lv["case"], "parameters": lv["parameters"],
                     "baseline_contact_solves": [st["contact_solves"] for st in b["steps"]],
                     "contact_solves": [st["contact_solves"] for st in new["steps"]],
                     "ratio_solves": b["total_contact_solves"] / new["total_contact_solves"],
                     "ratio_time": b["total_wall_seconds"] / new["total_wall_seconds"],
                     "ratio_krylov": b["total_step_krylov_iterations"] / new["total_step_krylov_iterations"]})
    return rows


def stress_pairs(levels, title: str, runs: tuple, total) -> list[str]:
    """Per stress of each case the figures of two runs (``runs``: (label, key) each) side by side
    (their AMG set-up time too when one sets it up from scratch) and the time ratio first /
    second; ``total(level)``: the case's summary after its name."""
    amg = any(key == "from_scratch" for _, key in runs)
    head = [f"{label + ': s':>13} {'solves':>6} {'its':>4} {'krylov':>6}" + (f" {'amg s':>6}" if amg else "")
            for label, _ in runs]
    lines = [title, f"{'case':>18} {'dofs':>7} {'stress MPa':>10} | {head[0]} | {head[1]} | {'time ratio':>10}"]
    for lv in levels:
        name = f"{lv['case'].split('_')[0]} {','.join(str(v) for v in lv['parameters'].values())}"
        for a, b in zip(*(lv[key]["steps"] for _, key in runs)):
            cells = [f"{x['seconds']:>13.2f} {x['contact_solves']:>6} {x['step_iterations']:>4} "
                     f"{x['step_krylov_iterations']:>6}" + (f" {x['seconds_amg_setup']:>6.2f}" if amg else "")
                     for x in (a, b)]
            lines.append(f"{name:>18} {lv['dofs']:>7} {a['stress'] / 1e6:>10.3g} | {cells[0]} | {cells[1]} | "
                         f"{a['seconds'] / b['seconds']:>10.2f}")
        lines.append(f"{name:>18} total: {total(lv)}")
    return lines


#: the stress tables: (title, the two runs (label, key), the case's summary line)
STRESS_TABLES = (
    ("The cost of a stress: AMG set up at every active-set iteration (scratch) or once per contact solve (reused); "
     "per stress", (("scratch", "from_scratch"), ("reused", "reused")),
     lambda lv: f"time scratch / reused {lv['ratio_time_from_scratch_over_reused']:.2f}, Krylov reused / scratch "
                f"{lv['ratio_krylov_reused_over_from_scratch']:.2f}, closures differ by {lv['closure_difference']:.1e} "
                f"(relative), reported seconds / wall >= {lv['seconds_reported_over_wall']:.3f}"),
    ("The platen's displacement as one more unknown (constraint) against the search of full solves (search, AMG "
     "reused); per stress", (("search", "reused"), ("constraint", "constraint")),
     lambda lv: f"time search / constraint {lv['ratio_time_search_over_constraint']:.2f}, closures differ by "
                f"{lv['constraint_closure_difference']:.1e} (relative; the search within its stress tolerance), peak "
                f"memory {lv['constraint']['peak_memory_mb']:.0f} MB (constraint, first run) / "
                f"{lv['reused']['peak_memory_mb']:.0f} MB (after all three)"))


def stress_goals(levels) -> dict:
    one = all(st["contact_solves"] == 1 for lv in levels for st in lv["constraint"]["steps"])
    ratio = min(lv["ratio_time_search_over_constraint"] for lv in levels)
    return {"one_contact_solve_per_stress": {"status": "PASS" if one else "MISS",
                                             "solves": [[st["contact_solves"] for st in lv["constraint"]["steps"]]
                                                        for lv in levels]},
            "constraint_faster_than_search": {"worst_ratio": ratio, "status": "PASS" if ratio > 1 else "MISS"}}


def goals(levels) -> dict:
    coarse, fine = levels[0], levels[-1]
    grow = max(fine["active_set"]["iterations"]) <= max(coarse["active_set"]["iterations"]) + 1
    ratio = fine["time_ratio_snes_vi_over_active_set"]
    return {"active_set_iterations_do_not_grow": {
                "coarsest_max": max(coarse["active_set"]["iterations"]),
                "finest_max": max(fine["active_set"]["iterations"]), "status": "PASS" if grow else "MISS"},
            "snes_vi_iterations": {"coarsest_max": max(coarse["snes_vi"]["iterations"]),
                                   "finest_max": max(fine["snes_vi"]["iterations"])},
            "time_2x_below_snes_vi_at_finest": {"ratio": ratio, "status": "PASS" if ratio >= 2 else "MISS"}}


def table(name, levels, key) -> list[str]:
    lines = [f"{name}", f"{key:>12} {'dofs':>7} | {'active set: its/step':>22} {'krylov':>6} {'time s':>7} | "
             f"{'SNES VI: its/step':>20} {'krylov':>6} {'time s':>7} | {'ratio':>5} {'diff':>8} | "
             f"{'active set + BoomerAMG: time s':>30} {'ratio':>5}"]
    for lv in levels:
        a, s = lv["active_set"], lv["snes_vi"]
        lines.append(f"{str(lv[key]):>12} {lv['dofs']:>7} | {str(a['iterations']):>22} {a['krylov_iterations']:>6} "
                     f"{a['wall_seconds']:>7.2f} | {str(s['iterations']):>20} {s['krylov_iterations']:>6} "
                     f"{s['wall_seconds']:>7.2f} | {lv['time_ratio_snes_vi_over_active_set']:>5.2f} "
                     f"{lv['solver_difference']:>8.1e} | {lv['active_set_hypre']['wall_seconds']:>30.2f} "
                     f"{lv['time_ratio_snes_vi_over_active_set_hypre']:>5.2f}")
    return lines


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="tiny levels (smoke test)")
    ap.add_argument("--only", choices=["solvers", "stress"], default=None,
                    help="only the solver comparison or only the cost of a stress (default both)")
    ap.add_argument("--baseline", default=None, help="this bench's JSON of the previous commit: ratios against it")
    ap.add_argument("-o", "--output", default=None, help="JSON output (default bench/results/contact.json)")
    a = ap.parse_args(argv)
    stem = "contact" + ("_quick" if a.quick else "") + (f"_{a.only}" if a.only else "")
    out = Path(a.output) if a.output else ROOT / "bench" / "results" / f"{stem}.json"
    hs, shapes = ((0.12, 0.09), ((6, 6, 2), (8, 8, 3))) if a.quick else ((0.06, 0.04, 0.025), ((8, 8, 3), (16, 16, 5), (24, 24, 6)))
    hertz_steps = 2 if a.quick else 3
    platen = [0.16e-3, 0.32e-3] if a.quick else [0.08e-3, 0.16e-3, 0.24e-3, 0.32e-3]
    result = {"meta": {"date": datetime.now(timezone.utc).isoformat(timespec="seconds"), "platform": platform.platform(),
                       "cpu_count": os.cpu_count(), "load_average_before": os.getloadavg(),
                       "note": "machine shared with other engineers: times are indicative"},
              "args": {"quick": a.quick, "hertz_h": list(hs), "fracture_shapes": [list(s) for s in shapes],
                       "hertz_load_steps": hertz_steps, "fracture_platen_displacements": platen}}
    stress_cases = ([("fracture_closure", {"lattice": [8, 8, 3]}), ("measured_fracture", {"coarsen": 4})] if a.quick
                    else [("fracture_closure", {"lattice": list(s)}) for s in ((8, 8, 3), (16, 16, 5))]
                    + [("measured_fracture", {"coarsen": c}) for c in (2, 1)])
    stresses = [1e6, 5e6] if a.quick else [1e6, 5e6, 20e6]
    result["args"].update(stress_cases=stress_cases, stresses=stresses, only=a.only)
    lines = []
    if a.only != "stress":
        with tempfile.TemporaryDirectory() as tmp:
            result["hertz"] = [compare(hertz_level(tmp, h, hertz_steps)) for h in hs]
        result["fracture"] = [compare(fracture_level(s, platen)) for s in shapes]
        result["goals"] = {"hertz": goals(result["hertz"]), "fracture": goals(result["fracture"])}
        lines += table("Hertz (half-sphere on a block)", result["hertz"], "h") + [""]
        lines += table("Rough fracture closure", result["fracture"], "shape") + [""]
    if a.only != "solvers":
        result["stress"] = [stress_level(case, parameters, stresses) for case, parameters in stress_cases]
        for title, runs, total in STRESS_TABLES:
            lines += stress_pairs(result["stress"], title, runs, total) + [""]
        g = result["stress_goals"] = stress_goals(result["stress"])
        lines += [f"one contact solve per stress (constraint): {g['one_contact_solve_per_stress']['solves']} "
                  f"{g['one_contact_solve_per_stress']['status']}",
                  f"constraint faster than the search (time ratio search / constraint, the worst case): "
                  f"{g['constraint_faster_than_search']['worst_ratio']:.2f} {g['constraint_faster_than_search']['status']}",
                  ""]
        if a.baseline:
            result["against_baseline"] = against(json.loads(Path(a.baseline).read_text()), result["stress"])
            result["args"]["baseline"] = Path(a.baseline).name
            lines += [f"against {Path(a.baseline).name}: {r['case']} {r['parameters']}: contact solves per stress "
                      f"{r['baseline_contact_solves']} -> {r['contact_solves']} (ratio {r['ratio_solves']:.2f}), "
                      f"time old / new {r['ratio_time']:.2f}" for r in result["against_baseline"]] + [""]
    result["meta"]["load_average_after"] = os.getloadavg()
    lines.append(f"load average before {result['meta']['load_average_before'][0]:.2f}, after "
                 f"{result['meta']['load_average_after'][0]:.2f}")
    for problem, g in result.get("goals", {}).items():
        lines.append(f"{problem}: active-set iterations per step {g['active_set_iterations_do_not_grow']['coarsest_max']}"
                     f" -> {g['active_set_iterations_do_not_grow']['finest_max']} "
                     f"{g['active_set_iterations_do_not_grow']['status']}; SNES VI {g['snes_vi_iterations']['coarsest_max']}"
                     f" -> {g['snes_vi_iterations']['finest_max']}; time SNES VI / active set at the finest level "
                     f"{g['time_2x_below_snes_vi_at_finest']['ratio']:.2f} (goal >= 2) "
                     f"{g['time_2x_below_snes_vi_at_finest']['status']}")
    return finish(result, lines, out)


if __name__ == "__main__":
    main()
