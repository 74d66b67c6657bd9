"""Private memory of the distributed solid-to-grid transfer on 1 and P ranks, in isolation: the
operator of bench/ranks.py's ``xlarge`` scene (the ``rough_fracture`` solid, 307,200 P1 tets, to
its 84 x 44 x 44 Q0 grid, pseudo-L2, as the coupler on P ranks builds it) assembled `--repeat`
times on each rank count, the previous one dropped first (as every rebuild from the deformed
solid does).

Each rank holds its slab of the grid along the longest axis (as ``coupler.fsi.ranks.GridSlab``)
and its share of the solid (slabs along z: the two blocks, as the solid ranks of the generator
hold them). Per rank: the private memory (RssAnon) before the first assembly, after each one, and
the peak of the resident memory during each (VmHWM, reset before it through /proc/self/clear_refs),
all above the baseline; ``--trim`` returns the freed heap to the system after every assembly
(malloc_trim). Docs: docs/scaling.md, "A coupled run on several ranks".

    .venv/bin/python bench/transfer_memory.py [--ranks 1 2] [--repeat 4] [--shape 80 40 8] [--grid 84 44 44]
"""

from __future__ import annotations

import argparse
import ctypes
import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

#: the rough_fracture parameters of bench/ranks.py's scenes (shape given on the command line)
FRACTURE = {"size": [0.05, 0.025], "height": 0.005, "aperture": 0.001, "min_aperture": 0.0005, "rms": 0.00015,
            "hurst": 0.8, "mismatch_length": 0.0125, "seed": 4}
#: the fluid grid of cases/small_fracture
LOWER, UPPER = (0.0, 0.0, -0.0006), (0.05, 0.025, 0.0016)


def status_mb() -> dict[str, float]:
    fields = {}
    for line in Path("/proc/self/status").read_text().splitlines():
        key = line.split(":", 1)[0]
        if key in ("RssAnon", "VmHWM", "VmRSS"):
            fields[key] = int(line.split()[1]) / 1024
    return fields


def child(args) -> None:
    import numpy as np
    from mpi4py import MPI
    from petsc4py import PETSc

    from transfer import StructuredGrid
    from transfer.distributed import Part, assemble
    from transfer.generators import generate
    from transfer.petsc import destroy_dropped
    from transfer.partition import slabs
    from coupler.protocol.slabs import slab_bounds

    comm = MPI.COMM_WORLD
    libc = ctypes.CDLL("libc.so.6")
    mesh = generate("rough_fracture", {**FRACTURE, "shape": list(args.shape)}).mesh
    source = Part.of_cells(mesh, np.flatnonzero(slabs(mesh, comm.size, 2) == comm.rank), "P1")
    num_tets = mesh.num_cells
    del mesh
    G = StructuredGrid(LOWER, (np.array(UPPER) - LOWER) / args.grid, args.grid)
    d, bounds = slab_bounds(G.shape, comm.size, "longest")
    lower, upper = [0, 0, 0], list(G.shape)
    lower[d], upper[d] = bounds[comm.rank], bounds[comm.rank + 1]
    target = Part.grid_block(G, lower, upper, "Q0")
    T = assemble(source, target, "pseudo_l2", comm)  # imports and first-use pages out of the baseline
    T = None
    destroy_dropped(comm)
    libc.malloc_trim(0)
    comm.Barrier()
    base = status_mb()
    runs = []
    for _ in range(args.repeat):
        Path("/proc/self/clear_refs").write_text("5")  # VmHWM := VmRSS
        T = None
        T = assemble(source, target, "pseudo_l2", comm)
        during = status_mb()
        if args.trim:
            libc.malloc_trim(0)
        after = status_mb()
        runs.append({"peak_mb": round(during["VmHWM"] - base["VmRSS"], 1),
                     "private_after_mb": round(after["RssAnon"] - base["RssAnon"], 1)})
    stats = T.stats
    record = {"rank": comm.rank, "baseline_private_mb": round(base["RssAnon"], 1), "runs": runs,
              "target_cells": stats["target_cells"], "source_cells_held": stats["source_cells_held"],
              "B_local_nonzeros": T.B.getInfo(PETSc.Mat.InfoType.LOCAL)["nz_used"], "pairs_intersected": stats["pairs_intersected"],
              "tets": num_tets, "grid_cells": int(np.prod(G.shape))}
    records = comm.gather(record)
    if comm.rank == 0:
        print(json.dumps(records))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--ranks", nargs="+", type=int, default=[1, 2])
    ap.add_argument("--repeat", type=int, default=4)
    ap.add_argument("--shape", nargs=3, type=int, default=[80, 40, 8])
    ap.add_argument("--grid", nargs=3, type=int, default=[84, 44, 44])
    ap.add_argument("--trim", action="store_true", help="malloc_trim(0) after every assembly")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        child(args)
        return 0
    env = dict(os.environ, OMP_NUM_THREADS="1", OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    for p in args.ranks:
        cmd = ["mpirun", "-n", str(p), sys.executable, __file__, "--child", "--repeat", str(args.repeat),
               "--shape", *map(str, args.shape), "--grid", *map(str, args.grid)] + ["--trim"] * args.trim
        out = subprocess.run(cmd, capture_output=True, text=True, env=env, check=True).stdout
        records = json.loads(out.strip().splitlines()[-1])
        for r in records:
            print(f"{p} rank(s), rank {r['rank']}: {r['target_cells']} grid cells, {r['source_cells_held']} tets held, "
                  f"B {r['B_local_nonzeros']:.0f} nonzeros; base {r['baseline_private_mb']} MB private; "
                  "per assembly peak / private after [MB]: "
                  + ", ".join(f"{x['peak_mb']} / {x['private_after_mb']}" for x in r["runs"]), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
