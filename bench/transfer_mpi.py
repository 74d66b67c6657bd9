"""Distributed transfer benchmark: the P1-P1 coupling operator on 1 and 2 MPI ranks
(Transfer.assemble(..., comm=)), side by side with libsupermesh's own parallel driver on 1
and 2 ranks measured in the same run; parallel efficiency T(1) / (N T(N)) against the goal
of 90 %, where the time goes per rank (exchange, kernel, PETSc matrices, apply), what
travels (cells and bytes per rank) and the memory per element, for docs/scaling.md.

    .venv/bin/python bench/transfer_mpi.py                 # 48k x 83k tets, 1 and 2 ranks
    .venv/bin/python bench/transfer_mpi.py --quick -o t.json
    .venv/bin/python bench/transfer_mpi.py --cli           # `varcouple transfer` end to end, 94k x 118k tets

With --cli: the command as a user runs it, on one rank and under ``mpirun -n 2``, the files
written first (a P1 field on the source), as .vtu (rank 0 reads them and sends the parts),
as .pvtu of 2 pieces (each rank reads its own), and the target as the .xdmf of
``solid_fenicsx.convert`` (each rank reads its rows, then the cells go to the bisection's
ranks; the source as .pvtu): the wall time from start to exit, each rank's CPU time and peak
resident memory (/usr/bin/time) above the same command's on a 750 x 1,296 tet pair (the
interpreter, MPI and PETSc: what the process costs whatever the mesh) and the cells it read,
as ratios against the one-rank .vtu run of the same benchmark and against the same inputs on
one rank, and the output files compared with the one-rank .vtu run's (equal to 1e-12).

Both codes cut both meshes by the same coordinate bisection (bench/supermesh_parallel.py
writes the same parts for libsupermesh). Times are the slowest rank's, the minimum over
--repeat runs; the machine's 2 cores are shared, so the load average is recorded with every
figure: MPI timings under load are not speed-ups.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
# as in bench/transfer.py: the `transfer` package, not this folder's transfer.py
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != Path(__file__).resolve().parent]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

DEFAULT_OUTPUT = ROOT / "bench" / "results" / "transfer_mpi.json"
GOAL_EFFICIENCY = 0.90
#: lattice cells per axis (6 tets per cube) of the source and the target
SIZES = {"small": (20, 24), "quick": (5, 6), "cli": (25, 27)}
CLI_OUTPUT = ROOT / "bench" / "results" / "transfer_cli_mpi.json"
#: goals of issue 32 item 3 (on a quiet machine): time T(1) / T(2), and peak memory per rank against one rank's
GOAL_CLI_SPEEDUP, GOAL_CLI_MEMORY = 1.6, 0.6
RANKS = (1, 2)


def meshes(size: str):
    from transfer.generate import box_tetrahedra

    ns, nt = SIZES[size]
    return (box_tetrahedra((ns,) * 3, jitter=0.2, seed=1, name="source"),
            box_tetrahedra((nt,) * 3, jitter=0.2, seed=2, name="target"))


# -- the worker: one rank of `mpirun -n N python bench/transfer_mpi.py --worker SIZE` ----------
def worker(size: str, repeat: int) -> None:
    from mpi4py import MPI

    from petsc4py import PETSc  # initialised before the clock starts: not assembly
    from transfer import Transfer
    from transfer.distributed import Part
    from transfer.partition import bisection

    comm = MPI.COMM_WORLD
    src, dst = meshes(size)
    ps, pt = (Part.of_cells(m, np.flatnonzero(bisection(m, comm.size) == comm.rank), "P1") for m in (src, dst))
    u = np.sin(3 * ps.mesh.points[:, 0]) + ps.mesh.points[:, 1]
    rss_before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    runs = []
    for _ in range(max(1, repeat)):
        comm.Barrier()
        start = time.perf_counter()
        operator = Transfer.assemble(ps, pt, "l2", comm=comm)
        assemble = time.perf_counter() - start
        start = time.perf_counter()
        operator(u)
        apply = time.perf_counter() - start
        s = operator.stats
        mine = {"assemble": assemble, "apply": apply, "exchange": s["exchange_seconds"], "kernel": s["kernel_seconds"],
                "wait": s["wait_seconds"], "matrices": s["matrix_seconds"]}
        runs.append({k: comm.allreduce(v, op=MPI.MAX) for k, v in mine.items()})
    best = min(runs, key=lambda r: r["assemble"])
    x = s["exchange"]
    per_rank = comm.gather({"target_cells": pt.num_cells, "source_cells_own": ps.num_cells,
                            "source_cells_held": s["source_cells_held"], "cells_sent": x.cells_sent,
                            "cells_received": x.cells_received, "bytes_sent": x.bytes_sent,
                            "bytes_received": x.bytes_received, "neighbours": len(x.sent_to),
                            "peak_rss_increase_bytes": 1024 * (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
                                                               - rss_before),
                            "B_nnz_owned": operator.B.getInfo(PETSc.Mat.InfoType.LOCAL)["nz_used"]})
    if comm.rank == 0:
        print(json.dumps({"ranks": comm.size, "seconds": best, "seconds_all": [r["assemble"] for r in runs],
                          "pairs_tested": s["pairs_tested"], "pairs_intersected": s["pairs_intersected"],
                          "per_rank": per_rank}))


# -- the driver ---------------------------------------------------------------------------------
def _mpirun(ranks: int, *args) -> dict:
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1", OMP_NUM_THREADS="1")
    cmd = ["mpirun", "-n", str(ranks), "--oversubscribe", "--bind-to", "none", sys.executable, __file__, *args]
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=ROOT, timeout=3600)
    if proc.returncode:
        raise RuntimeError(f"{' '.join(cmd)} failed: {proc.stderr[-2000:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def _supermesh():
    import importlib.util

    spec = importlib.util.spec_from_file_location("supermesh_parallel", ROOT / "bench" / "supermesh_parallel.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.ParallelSupermesh()


def _efficiency(seconds: dict) -> float | None:
    """T(1) / (2 T(2)), None without both times."""
    if not all(seconds.values()):
        return None
    return seconds[1] / (2 * seconds[2])


def _command(src: Path, dst: Path, out: Path, ranks: int, files: Path) -> dict:
    """`varcouple transfer` on `ranks` (1: without mpirun): wall seconds to exit, peak RSS and CPU
    seconds (user + system) of each rank, the cells and points each rank read (the command's
    ``read`` line)."""
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1", OMP_NUM_THREADS="1")
    for old in files.glob("rss_*"):
        old.unlink()
    timed = f'exec /usr/bin/time -f "%M %U %S" -o {files}/rss_${{OMPI_COMM_WORLD_RANK:-0}} "$@"'
    cmd = ["sh", "-c", timed, "sh", sys.executable, "-m", "coupler.cli", "transfer", str(src), str(dst),
           "--field", "u", "-o", str(out)]
    if ranks > 1:
        cmd = ["mpirun", "-n", str(ranks), "--oversubscribe", "--bind-to", "none", *cmd]
    start = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=ROOT, timeout=3600)
    seconds = time.perf_counter() - start
    if proc.returncode:
        raise RuntimeError(f"{' '.join(cmd)} failed: {proc.stderr[-2000:]}")
    timings = [(files / f"rss_{r}").read_text().split()[-3:] for r in range(ranks)]  # KB, user s, system s
    run = {"seconds": seconds, "peak_rss_bytes": [1024 * int(t[0]) for t in timings],
           "cpu_seconds": [float(t[1]) + float(t[2]) for t in timings], "load_average": list(os.getloadavg())}
    read = next((line for line in proc.stdout.splitlines() if line.startswith("read ")), None)
    if read is not None:  # read    files opened per rank [..]; cells read per rank [..], points [..]
        run["cells_read"] = json.loads(read.split("cells read per rank ")[1].split("]")[0] + "]")
        run["points_read"] = json.loads(read.rsplit("points ", 1)[1])
    return run


def _write_inputs(size: str, files: Path) -> tuple[int, int]:
    """The source (with the P1 field u) and the target of `size` as .vtu and as .pvtu of 2 pieces
    (bisection, as a coupler on 2 ranks writes them) in `files`, and the target as the XDMF +
    HDF5 of ``python -m solid_fenicsx.convert`` (dolfinx's cell order, on one rank); their
    numbers of tets."""
    import meshio

    from coupler.output.results import write_pieces
    from transfer import Mesh
    from transfer.partition import bisection

    files.mkdir(exist_ok=True)
    src, dst = meshes(size)
    u = np.sin(3 * src.points[:, 0]) + src.points[:, 1]
    for name, mesh, data in (("src", src, {"u": u}), ("dst", dst, {})):
        whole = meshio.Mesh(mesh.points, [("tetra", mesh.cells)], point_data=data)
        meshio.write(files / f"{name}.vtu", whole)
        write_pieces(whole, files / f"{name}.pvtu", bisection(Mesh.from_meshio(whole), 2))
    subprocess.run([sys.executable, "-m", "solid_fenicsx.convert", str(files / "dst.vtu"), str(files / "dst.xdmf")],
                   check=True, capture_output=True, cwd=ROOT, timeout=600)
    return src.num_cells, dst.num_cells


#: (label, ranks, source format, target format) of the --cli runs; the first is the baseline, the
#: serial command on single files
CLI_RUNS = (("vtu_1", 1, "vtu", "vtu"), ("vtu_2", 2, "vtu", "vtu"), ("pvtu_1", 1, "pvtu", "pvtu"),
            ("pvtu_2", 2, "pvtu", "pvtu"), ("xdmf_1", 1, "pvtu", "xdmf"), ("xdmf_2", 2, "pvtu", "xdmf"))


def _by_coordinates(mesh) -> np.ndarray:
    """The output field in the lexicographic order of the points (a .pvtu's output numbers them otherwise)."""
    return mesh.point_data["u"][np.lexsort(mesh.points.T[::-1])]


def _one_rank(label: str) -> str:
    """The one-rank run of the inputs of `label`."""
    return label.rsplit("_", 1)[0] + "_1"


def cli(repeat: int, size: str, output: Path) -> dict:
    """`varcouple transfer` end to end on 1 and 2 ranks (module docstring)."""
    import tempfile

    import meshio

    with tempfile.TemporaryDirectory() as tmp:
        base, files = Path(tmp) / "base", Path(tmp) / "files"
        _write_inputs("quick", base)
        ns, nt = _write_inputs(size, files)
        print(f"varcouple transfer: P1 -> P1, {ns:,} x {nt:,} tets, 1 and 2 ranks, repeat {repeat}; load average "
              f"{os.getloadavg()}", flush=True)
        result = {"benchmark": "transfer_cli_mpi", "size": size, "source_tets": ns, "target_tets": nt,
                  "load_average_at_start": list(os.getloadavg()), "goal_speedup": GOAL_CLI_SPEEDUP,
                  "goal_memory_ratio": GOAL_CLI_MEMORY, "runs": {}, "base": {}}
        for label, ranks, src, dst in CLI_RUNS:
            # the same command on the 750 x 1,296-tet pair: what the process costs whatever the mesh
            result["base"][label] = _command(base / f"src.{src}", base / f"dst.{dst}", base / "out.vtu", ranks, base)
            runs = []
            for _ in range(max(1, repeat)):
                runs.append(_command(files / f"src.{src}", files / f"dst.{dst}", files / f"out_{label}.vtu", ranks,
                                     files))
                print(f"  {label} ({src} -> {dst}): {runs[-1]['seconds']:.2f} s, CPU per rank "
                      f"{[round(c, 2) for c in runs[-1]['cpu_seconds']]} s, peak memory per rank "
                      f"{[round(b / 1e6) for b in runs[-1]['peak_rss_bytes']]} MB (tiny pair: "
                      f"{[round(b / 1e6) for b in result['base'][label]['peak_rss_bytes']]} MB), cells read per "
                      f"rank {runs[-1].get('cells_read', 'not said')}; load average {runs[-1]['load_average']}",
                      flush=True)
            best = min(runs, key=lambda r: r["seconds"])
            best["peak_rss_above_base_bytes"] = [p - b for p, b in zip(best["peak_rss_bytes"],
                                                                       result["base"][label]["peak_rss_bytes"])]
            result["runs"][label] = {"ranks": ranks, "input": [src, dst], "best": best, "all": runs}
        out = {label: meshio.read(files / f"out_{label}.vtu") for label, *_ in CLI_RUNS}
        result["max_relative_difference"], result["same_uncovered"] = {}, {}
        a = _by_coordinates(out["vtu_1"])
        for label, *_ in CLI_RUNS[1:]:
            b = _by_coordinates(out[label])
            result["max_relative_difference"][label] = float(np.nanmax(np.abs(a - b)) / np.nanmax(np.abs(a)))
            result["same_uncovered"][label] = bool(np.array_equal(np.isnan(a), np.isnan(b)))
    best = {label: run["best"] for label, run in result["runs"].items()}
    two = [label for label, ranks, *_ in CLI_RUNS if ranks == 2]
    # against the serial command (vtu_1) and against the same inputs on one rank
    result["speedup"] = {label: best["vtu_1"]["seconds"] / best[label]["seconds"] for label, *_ in CLI_RUNS[1:]}
    result["speedup_same_input"] = {label: best[_one_rank(label)]["seconds"] / best[label]["seconds"] for label in two}
    result["memory_ratio_per_rank"] = {label: [p / best["vtu_1"]["peak_rss_above_base_bytes"][0]
                                               for p in best[label]["peak_rss_above_base_bytes"]]
                                       for label, *_ in CLI_RUNS[1:]}
    result["memory_ratio_same_input"] = {label: [p / best[_one_rank(label)]["peak_rss_above_base_bytes"][0]
                                                 for p in best[label]["peak_rss_above_base_bytes"]] for label in two}
    result["load_average_at_end"] = list(os.getloadavg())
    result["pass"] = {label: {"speedup": result["speedup"][label] >= GOAL_CLI_SPEEDUP,
                              "memory": max(result["memory_ratio_per_rank"][label]) <= GOAL_CLI_MEMORY,
                              "equal": result["max_relative_difference"][label] <= 1e-12
                              and result["same_uncovered"][label]} for label, *_ in CLI_RUNS[1:]}
    for label in two:
        result["pass"][label]["speedup_same_input"] = result["speedup_same_input"][label] >= GOAL_CLI_SPEEDUP
        result["pass"][label]["memory_same_input"] = max(result["memory_ratio_same_input"][label]) <= GOAL_CLI_MEMORY
    verdict = lambda ok: "PASS" if ok else "MISS"  # noqa: E731
    for label, *_ in CLI_RUNS[1:]:
        ok = result["pass"][label]
        print(f"{label} against vtu_1: speed-up {result['speedup'][label]:.2f}x (goal {GOAL_CLI_SPEEDUP}x on a quiet "
              f"machine): {verdict(ok['speedup'])}; peak memory above the tiny pair's, per rank / one rank's "
              f"{[round(r, 2) for r in result['memory_ratio_per_rank'][label]]} (goal <= {GOAL_CLI_MEMORY}): "
              f"{verdict(ok['memory'])}; output differs by {result['max_relative_difference'][label]:.1e} "
              f"relative: {verdict(ok['equal'])}")
    for label in two:
        ok, one = result["pass"][label], _one_rank(label)
        print(f"{label} against {one}: speed-up {result['speedup_same_input'][label]:.2f}x: "
              f"{verdict(ok['speedup_same_input'])}; peak memory per rank / one rank's "
              f"{[round(r, 2) for r in result['memory_ratio_same_input'][label]]}: {verdict(ok['memory_same_input'])}")
    print(f"load average {result['load_average_at_end']} (2 cores)")
    output.parent.mkdir(parents=True, exist_ok=True)
    output.write_text(json.dumps(result, indent=2) + "\n")
    print(f"wrote {output}")
    return result


def main(argv=None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--quick", action="store_true", help="tiny meshes, 1 repeat: a smoke run")
    p.add_argument("--cli", action="store_true", help="`varcouple transfer` end to end on 1 and 2 ranks: time, "
                                                      "peak memory per rank (bench/results/transfer_cli_mpi.json)")
    p.add_argument("--repeat", type=int, default=3, help="runs per figure, the minimum is reported (default: 3)")
    p.add_argument("-o", "--output", type=Path, default=DEFAULT_OUTPUT)
    p.add_argument("--worker", metavar="SIZE", help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.worker:
        worker(args.worker, args.repeat)
        return {}
    if args.cli:
        return cli(1 if args.quick else args.repeat, "quick" if args.quick else "cli",
                   CLI_OUTPUT if args.output == DEFAULT_OUTPUT else args.output)
    size, repeat = ("quick", 1) if args.quick else ("small", args.repeat)
    src, dst = meshes(size)
    print(f"distributed transfer: P1 -> P1, {src.num_cells:,} x {dst.num_cells:,} tets, ranks {list(RANKS)}, "
          f"repeat {repeat}; load average {os.getloadavg()}", flush=True)
    from transfer.partition import bisection

    lsm = _supermesh()
    result = {"benchmark": "transfer_mpi", "size": size, "source_tets": src.num_cells, "target_tets": dst.num_cells,
              "load_average_at_start": list(os.getloadavg()), "goal_efficiency": GOAL_EFFICIENCY,
              "ours": {}, "libsupermesh": {}}
    for ranks in RANKS:
        result["ours"][ranks] = _mpirun(ranks, "--worker", size, "--repeat", str(repeat))
        result["ours"][ranks]["load_average"] = list(os.getloadavg())
        result["libsupermesh"][ranks] = lsm.measure(src, dst, bisection(src, ranks), bisection(dst, ranks), ranks,
                                                    repeat)
        result["libsupermesh"][ranks]["load_average"] = list(os.getloadavg())
    ours = {n: r["seconds"]["assemble"] for n, r in result["ours"].items()}
    theirs = {n: r.get("seconds") for n, r in result["libsupermesh"].items()}
    result["efficiency"] = {"ours": _efficiency(ours), "libsupermesh": _efficiency(theirs)}
    eff = result["efficiency"]["ours"]
    result["pass"] = eff is not None and eff >= GOAL_EFFICIENCY
    result["load_average_at_end"] = list(os.getloadavg())
    result["prediction"] = predict(result)
    _print(result, ours, theirs)
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(json.dumps(result, indent=2, default=str) + "\n")
    print(f"wrote {args.output}")
    return result


#: weak-scaling model inputs that this machine cannot measure (2 cores, one host): a cluster
#: interconnect's bandwidth and latency, assumed
BANDWIDTH, LATENCY = 5e9, 2e-6
#: total elements (source + target, in the proportions of the measured pair) and ranks
PREDICT_ELEMENTS, PREDICT_RANKS = (1e6, 1e8, 2e9), (1, 64, 12_288)
#: memory of one rank of the machine here
RANK_MEMORY = 24e9


def predict(result) -> dict:
    """Weak-scaling prediction from the per-element costs measured on 1 rank and the halo
    measured on 2 (docs/scaling.md): per rank, time = target cells x (kernel + matrices +
    exchange bookkeeping per target cell) + halo bytes / bandwidth + messages x latency +
    the O(P) collectives (box allgather, counts alltoall)."""
    one, two = result["ours"][1], result["ours"][2]
    n_t, n_s = result["target_tets"], result["source_tets"]
    part = one["per_rank"][0]
    per_target = {k: one["seconds"][k] / n_t for k in ("kernel", "matrices", "exchange")}
    memory = part["peak_rss_increase_bytes"] / (n_t + n_s)
    received = np.mean([p["cells_received"] for p in two["per_rank"]])
    bytes_per_cell = sum(p["bytes_received"] for p in two["per_rank"]) / max(
        sum(p["cells_received"] for p in two["per_rank"]), 1)
    halo = received / n_s ** (2 / 3)  # one cut through the whole box: halo cells per (source cells)^(2/3)
    share_t = n_t / (n_t + n_s)
    rows = []
    for total in PREDICT_ELEMENTS:
        for ranks in PREDICT_RANKS:
            t_cells, s_cells = share_t * total / ranks, (1 - share_t) * total / ranks
            compute = t_cells * sum(per_target.values())
            halo_cells = 0.0 if ranks == 1 else 6 * halo * s_cells ** (2 / 3)  # a cube's six faces
            neighbours = 0 if ranks == 1 else min(ranks - 1, 26)
            comm = (halo_cells * bytes_per_cell / BANDWIDTH + 2 * neighbours * LATENCY
                    + (0 if ranks == 1 else ranks * 96 / BANDWIDTH + 16 * ranks / BANDWIDTH
                       + 4 * np.log2(ranks) * LATENCY))
            rank_memory = memory * (t_cells + s_cells) + halo_cells * bytes_per_cell
            rows.append({"elements": total, "ranks": ranks, "elements_per_rank": total / ranks,
                         "compute_seconds": compute, "communication_seconds": comm, "seconds": compute + comm,
                         "halo_cells_per_rank": halo_cells, "halo_bytes_per_rank": halo_cells * bytes_per_cell,
                         "memory_per_rank_bytes": rank_memory, "fits": rank_memory < RANK_MEMORY})
    return {"per_target_cell_seconds": per_target, "memory_bytes_per_element": memory,
            "halo_cells_per_source_cells_two_thirds": halo, "bytes_per_halo_cell": bytes_per_cell,
            "bandwidth_assumed": BANDWIDTH, "latency_assumed": LATENCY, "rows": rows}


def _print(result, ours, theirs):
    rows = []
    for n in RANKS:
        o, lsm = result["ours"][n]["seconds"], result["libsupermesh"][n]
        rows.append(f"{n:>5}  {ours[n]:9.3f} s  {o['exchange']:8.3f} s  {o['kernel']:8.3f} s  {o['wait']:8.3f} s  "
                    f"{o['matrices']:8.3f} s  "
                    f"{o['apply'] * 1e3:7.1f} ms  "
                    + (f"{lsm['seconds']:9.3f} s  {lsm['seconds'] / ours[n]:5.2f}x" if lsm.get("available") else
                       "libsupermesh not available"))
    print("ranks  assemble    exchange    kernel      wait        matrices    apply       libsupermesh  ratio")
    print("\n".join(rows))
    for n in RANKS:
        for r, part in enumerate(result["ours"][n]["per_rank"]):
            print(f"  {n} ranks, rank {r}: {part['target_cells']:,} target cells, source {part['source_cells_own']:,} own "
                  f"+ {part['cells_received']:,} received ({part['bytes_received'] / 1e6:.2f} MB), sent "
                  f"{part['cells_sent']:,} ({part['bytes_sent'] / 1e6:.2f} MB), peak memory +"
                  f"{part['peak_rss_increase_bytes'] / 1e6:.0f} MB")
    pred = result["prediction"]
    print(f"per target cell: " + ", ".join(f"{k} {v * 1e6:.2f} us" for k, v in pred["per_target_cell_seconds"].items())
          + f"; memory {pred['memory_bytes_per_element']:.0f} B per element; halo "
          f"{pred['halo_cells_per_source_cells_two_thirds']:.2f} x n^(2/3) cells of {pred['bytes_per_halo_cell']:.0f} B")
    print("predicted (weak scaling): elements  ranks  per rank    time      of which communication  memory per rank")
    for r in pred["rows"]:
        print(f"  {r['elements']:10.0e}  {r['ranks']:6d}  {r['elements_per_rank']:9.3g}  {r['seconds']:8.3g} s  "
              f"{r['communication_seconds']:8.2g} s  {r['memory_per_rank_bytes'] / 1e9:8.3g} GB"
              f"{'' if r['fits'] else ' (does not fit 24 GB)'}")
    eff = result["efficiency"]
    fmt = lambda e: "-" if e is None else f"{100 * e:.0f} %"  # noqa: E731
    print(f"efficiency 1 -> 2 ranks: ours {fmt(eff['ours'])}, libsupermesh {fmt(eff['libsupermesh'])} "
          f"(goal {100 * GOAL_EFFICIENCY:.0f} %): {'PASS' if result['pass'] else 'MISS'}; load average "
          f"{result['load_average_at_end']}")


if __name__ == "__main__":
    main()
