"""Memory of a coupled run on several ranks: the peak resident memory (VmHWM) of the coupler
process and of every participant process and rank, with the solid on N and the OpenFOAM fluid
on M MPI ranks (N, M in {1, 2}); beside it the peaks of its private part (RssAnon: heap, stacks)
and of the shared memory it maps (RssShmem: zenoh's pools, whose pages count in every process
that maps them), sampled.

Each run is ``varcouple run`` in a child process, its process tree read from /proc every
20 ms: the coupler (the ``varcouple run`` process), the solid's ranks (``python -m
solid_fenicsx``, rank from ``OMPI_COMM_WORLD_RANK``), the fluid participant's ranks (``python -m
fluid_openfoam``, one process per processor of the decomposed case) and simpleFoam's ranks
(relaunched every coupling iteration: the largest over the launches). A process that lives less than the polling interval
may be missed; the figures are lower bounds by at most the last 20 ms of growth.

Scenes (one time step each):

* ``small``: cases/small_fracture (4,800 tets, 21 x 11 x 11 = 2,541 fluid cells);
* ``large``: the same fracture generated 4 times finer in the plane (``rough_fracture``,
  shape 40 x 20 x 4: 38,400 tets) in a 42 x 22 x 22 grid (20,328 fluid cells), so that the
  per-cell costs stand out from the processes' fixed memory (Python, dolfinx, PETSc, MPI);
* ``xlarge`` (on request: ``--scenes xlarge``; minutes a run with the Chorin fluid on 2 cores):
  8 times ``large`` (shape 80 x 40 x 8: 307,200 tets; an 84 x 44 x 44 grid: 162,624 cells),
  where the coupler's per-cell memory outweighs its fixed part; fluid tolerance 1e-5 and
  coupling tolerance 1e-3 (memory, not accuracy, is measured), messaging timeout 3600 s.

With ``--fluid chorin`` the fluid is the Chorin fluid on M slab ranks instead (``python -m
fluid_chorin``, each rank measured). ``--coupler-ranks 1 2`` runs each pair with the coupler on
P ranks too (``[coupling] ranks = P``: each coupler rank ``python -m coupler.cli`` measured), into
bench/results/ranks_coupler.json by default.

Docs: docs/scaling.md "A coupled run on several ranks: what is gathered where".

    .venv/bin/python bench/ranks.py [--scenes small large] [--pairs 1,1 2,1 1,2 2,2] [--fluid chorin]
                                    [--coupler-ranks 1 2] [-o FILE]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from coupler.run.launch import descendants  # noqa: E402

SMALL = ROOT / "cases" / "small_fracture"

#: scene text replacements per scene (on top of one step and the ranks)
SCENES = {
    "small": {},
    "large": {
        'mesh = "solid.msh"              # two blocks, 4800 tetrahedra (make_mesh.py)\n'
        "boundaries = { bottom = 1, top = 2, fracture_lower = 3, fracture_upper = 4 }":
        'generator = "rough_fracture"\n'
        "parameters = { shape = [40, 20, 4], size = [0.05, 0.025], height = 0.005, aperture = 0.001, "
        "min_aperture = 0.0005, rms = 0.00015, hurst = 0.8, mismatch_length = 0.0125, seed = 4 }",
        "shape = [21, 11, 11]": "shape = [42, 22, 22]",
    },
    "xlarge": {
        'mesh = "solid.msh"              # two blocks, 4800 tetrahedra (make_mesh.py)\n'
        "boundaries = { bottom = 1, top = 2, fracture_lower = 3, fracture_upper = 4 }":
        'generator = "rough_fracture"\n'
        "parameters = { shape = [80, 40, 8], size = [0.05, 0.025], height = 0.005, aperture = 0.001, "
        "min_aperture = 0.0005, rms = 0.00015, hurst = 0.8, mismatch_length = 0.0125, seed = 4 }",
        "shape = [21, 11, 11]": "shape = [84, 44, 44]",
        # a measurement of memory, not of accuracy: looser tolerances (fewer pseudo-time steps and
        # coupling iterations) and a fluid advance may take longer than the default 300 s
        "tolerance = 1e-7 ": "tolerance = 1e-5 ", "tolerance = 1e-6\n": "tolerance = 1e-3\n",
        "[coupling]\n": "[messaging]\ntimeout = 3600.0\n\n[coupling]\n",
    },
}


#: the fluid participant's line in the scene per ``--fluid`` (the Chorin fluid has no max_iterations of simpleFoam)
FLUIDS = {"openfoam": {}, "chorin": {'participant = "openfoam"': 'participant = "chorin"', "max_iterations = 3000\n": ""}}


def scene_text(scene: str, solid_ranks: int, fluid_ranks: int, fluid: str = "openfoam", coupler_ranks: int = 1) -> str:
    text = (SMALL / "scene.toml").read_text()
    for old, new in FLUIDS[fluid].items():
        text = text.replace(old, new)
    replace = {"steps = 2": "steps = 1",
               'participant = "solid_fenicsx"': f'participant = "solid_fenicsx"\nranks = {solid_ranks}',
               f'participant = "{fluid}"': f'participant = "{fluid}"\nranks = {fluid_ranks}',
               'acceleration = "iqn-ils"': f'acceleration = "iqn-ils"\nranks = {coupler_ranks}', **SCENES[scene]}
    for old, new in replace.items():
        if old not in text:
            raise SystemExit(f"bench/ranks.py: {old!r} not in cases/small_fracture/scene.toml")
        text = text.replace(old, new)
    return text + "\n[output]\npictures = false   # the coupler's memory without VTK's rendering\n"


def _read(pid: int, name: str) -> str:
    try:
        return Path(f"/proc/{pid}/{name}").read_bytes().decode(errors="replace")
    except OSError:
        return ""


def role(pid: int, root: int) -> str | None:
    """Which process of the run ``pid`` is (None: a launcher or helper not measured)."""
    argv = _read(pid, "cmdline").split("\0")
    env = dict(e.split("=", 1) for e in _read(pid, "environ").split("\0") if "=" in e)
    rank = env.get("OMPI_COMM_WORLD_RANK", "0")
    if "coupler.cli" in argv:  # the coupler on P ranks, started by `varcouple run` under mpirun
        return f"coupler rank {rank}"
    if pid == root:
        return "coupler"
    if "solid_fenicsx" in argv:
        return f"solid rank {rank}"
    if "fluid_openfoam" in argv:
        return f"fluid rank {rank}"
    if "fluid_chorin" in argv:
        return f"chorin rank {rank}"
    if argv and Path(argv[0]).name in ("simpleFoam", "pimpleFoam"):
        return f"{Path(argv[0]).name} rank {rank}"
    return None


#: what is read of /proc/PID/status: the peak resident memory (the kernel's own high-water mark)
#: and, sampled, its private part (heap, stacks) and the shared memory mapped (zenoh's pools: the
#: same pages are counted in every process that maps them)
MEMORY = {"VmHWM": "peak_rss_mb", "RssAnon": "peak_private_mb", "RssShmem": "peak_shared_mb"}


def memory_kb(pid: int) -> dict[str, int]:
    """The :data:`MEMORY` figures of process `pid` now [kB] (empty once it is gone)."""
    out = {}
    for line in _read(pid, "status").splitlines():
        key = line.split(":", 1)[0]
        if key in MEMORY:
            out[MEMORY[key]] = int(line.split()[1])
    return out


def measured_run(scene: str, solid_ranks: int, fluid_ranks: int, work: Path, fluid: str = "openfoam",
                 coupler_ranks: int = 1) -> dict:
    """One ``varcouple run``: wall time, status and the peak resident memory [MB] per process
    (with the coupler on several ranks the ``varcouple run`` that starts them is not measured)."""
    case = work / f"{scene}_n{solid_ranks}_m{fluid_ranks}_{fluid}_p{coupler_ranks}"
    case.mkdir(parents=True)
    for f in SMALL.iterdir():
        if f.is_file() and f.name != "scene.toml":
            (case / f.name).symlink_to(f)
    (case / "scene.toml").write_text(scene_text(scene, solid_ranks, fluid_ranks, fluid, coupler_ranks))
    out = case / "results"
    peaks: dict[str, dict[str, int]] = {}
    t0 = time.perf_counter()
    proc = subprocess.Popen([str(ROOT / ".venv" / "bin" / "varcouple"), "run", str(case), "--output", str(out)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    done = threading.Event()

    def poll():
        while not done.is_set():
            for pid in [proc.pid, *descendants(proc.pid)]:
                name = role(pid, proc.pid)
                if name is not None and not (name == "coupler" and coupler_ranks > 1):
                    peak = peaks.setdefault(name, {})
                    for figure, kb in memory_kb(pid).items():
                        peak[figure] = max(peak.get(figure, 0), kb)
            time.sleep(0.02)

    thread = threading.Thread(target=poll, daemon=True)
    thread.start()
    _, err = proc.communicate()
    done.set()
    thread.join()
    wall = time.perf_counter() - t0
    summary = json.loads((out / "summary.json").read_text()) if (out / "summary.json").exists() else {}
    return {"scene": scene, "fluid": fluid, "solid_ranks": solid_ranks, "fluid_ranks": fluid_ranks,
            "coupler_ranks": coupler_ranks, "coupler_holdings": summary.get("coupler_ranks"),
            "exit": proc.returncode,
            "error": err.decode(errors="replace").strip().splitlines()[-1:] if proc.returncode else [],
            "status": summary.get("status"), "wall_seconds": round(wall, 2), "sizes": summary.get("sizes"),
            "iterations": summary.get("iterations"),
            **{figure: {k: round(v.get(figure, 0) / 1024, 1) for k, v in sorted(peaks.items())}
               for figure in MEMORY.values()}}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenes", nargs="+", default=["small", "large"], choices=list(SCENES))
    ap.add_argument("--pairs", nargs="+", default=["1,1", "2,1", "1,2", "2,2"],
                    help="solid ranks,fluid ranks")
    ap.add_argument("--fluid", choices=list(FLUIDS), default="openfoam")
    ap.add_argument("--coupler-ranks", nargs="+", type=int, default=None, metavar="P",
                    help="coupler ranks of every run (default: 1, the one-process coupler)")
    ap.add_argument("-o", "--output", type=Path,
                    help="default bench/results/ranks.json (ranks_chorin.json with --fluid chorin)")
    args = ap.parse_args(argv)
    if args.output is None:
        name = ("ranks_coupler.json" if args.coupler_ranks else
                "ranks.json" if args.fluid == "openfoam" else "ranks_chorin.json")
        args.output = ROOT / "bench" / "results" / name
    runs = []
    with tempfile.TemporaryDirectory(prefix="varcouple-ranks-") as tmp:
        for scene in args.scenes:
            for pair, p in ((pair, p) for pair in args.pairs for p in args.coupler_ranks or [1]):
                n, m = (int(x) for x in pair.split(","))
                run = measured_run(scene, n, m, Path(tmp), args.fluid, p)
                runs.append(run)
                print(f"{scene:6s} solid {n} fluid {m} coupler {p}: exit {run['exit']}, {run['wall_seconds']:6.1f} s, "
                      + ", ".join(f"{k} {v:.0f} MB (private {run['peak_private_mb'][k]:.0f})"
                                  for k, v in run["peak_rss_mb"].items()), flush=True)
    result = {"machine": {"cpus": os.cpu_count(), "platform": platform.platform(),
                          "load_average_after": os.getloadavg()},
              "runs": runs}
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(json.dumps(result, indent=1) + "\n")
    print(f"wrote {args.output}")
    return 0 if all(r["exit"] == 0 for r in runs) else 1


if __name__ == "__main__":
    sys.exit(main())
