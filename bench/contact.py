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

Goals: active-set iterations per load step that do not grow with refinement
(finest level's largest count at most the coarsest's + 1); time to solution at least 2x
below SNES VI at the finest level (both problems).

    .venv/bin/python bench/contact.py [--quick] [-o OUT.json]

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
                         "seconds": state.seconds["solve"] + state.seconds["assemble"],
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
    ap.add_argument("-o", "--output", default=None, help="JSON output (default bench/results/contact.json)")
    a = ap.parse_args(argv)
    out = Path(a.output) if a.output else ROOT / "bench" / "results" / ("contact_quick.json" if a.quick else "contact.json")
    hs, shapes = ((0.12, 0.09), ((6, 6, 2), (8, 8, 3))) if a.quick else ((0.06, 0.04, 0.025), ((8, 8, 3), (16, 16, 5), (24, 24, 6)))
    hertz_steps = 2 if a.quick else 3
    platen = [0.16e-3, 0.32e-3] if a.quick else [0.08e-3, 0.16e-3, 0.24e-3, 0.32e-3]
    result = {"meta": {"date": datetime.now(timezone.utc).isoformat(timespec="seconds"), "platform": platform.platform(),
                       "cpu_count": os.cpu_count(), "load_average_before": os.getloadavg(),
                       "note": "machine shared with other engineers: times are indicative"},
              "args": {"quick": a.quick, "hertz_h": list(hs), "fracture_shapes": [list(s) for s in shapes],
                       "hertz_load_steps": hertz_steps, "fracture_platen_displacements": platen}}
    with tempfile.TemporaryDirectory() as tmp:
        result["hertz"] = [compare(hertz_level(tmp, h, hertz_steps)) for h in hs]
    result["fracture"] = [compare(fracture_level(s, platen)) for s in shapes]
    result["goals"] = {"hertz": goals(result["hertz"]), "fracture": goals(result["fracture"])}
    result["meta"]["load_average_after"] = os.getloadavg()
    lines = table("Hertz (half-sphere on a block)", result["hertz"], "h") + [""]
    lines += table("Rough fracture closure", result["fracture"], "shape") + [""]
    for problem, g in result["goals"].items():
        lines.append(f"{problem}: active-set iterations per step {g['active_set_iterations_do_not_grow']['coarsest_max']}"
                     f" -> {g['active_set_iterations_do_not_grow']['finest_max']} "
                     f"{g['active_set_iterations_do_not_grow']['status']}; SNES VI {g['snes_vi_iterations']['coarsest_max']}"
                     f" -> {g['snes_vi_iterations']['finest_max']}; time SNES VI / active set at the finest level "
                     f"{g['time_2x_below_snes_vi_at_finest']['ratio']:.2f} (goal >= 2) "
                     f"{g['time_2x_below_snes_vi_at_finest']['status']}")
    print("\n".join(lines))
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=2, default=float))
    print(f"written {out.relative_to(ROOT) if out.is_relative_to(ROOT) else out}")
    return result


if __name__ == "__main__":
    main()
