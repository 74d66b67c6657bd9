"""Memory of the solid's mesh on N ranks: the peak resident memory (VmHWM) of every rank after
building the ``rough_fracture`` mesh of bench/ranks.py's large scene (40 x 20 x 4: 38,400 tets)
and finer ones, these ways:

* ``blocks``: each rank makes its own block of cells and points (solid_fenicsx.mesh.generated_mesh);
* ``msh``: rank 0 reads it from a gmsh file (meshio, written beforehand by this script) and
  scatters blocks (solid_fenicsx.mesh.read_mesh, what small_fracture's solid.msh gets);
* ``xdmf``: every rank reads its own rows of that file converted to XDMF + HDF5 beforehand
  (``python -m solid_fenicsx.convert`` on one rank; solid_fenicsx.mesh.read_mesh of the .xdmf);
* ``scattered``: rank 0 makes the whole mesh and scatters blocks (solid_fenicsx.mesh.from_arrays);
* ``root``: rank 0 makes the whole mesh, validates it and hands it to dolfinx (the path before
  blocks).

Each (way, shape, N) is its own ``mpirun -n N`` (a fresh process per rank); the runs replace
those of the same (way, shape, N) in the output file and keep the others. Docs: docs/scaling.md
"A coupled run on several ranks: what is gathered where".

    .venv/bin/python bench/solid_mesh.py [--shapes 40,20,4 80,40,8] [--ranks 1 2] [--ways msh xdmf] [-o FILE]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from transfer.generators import generate  # noqa: E402
PARAMETERS = {"size": [0.05, 0.025], "height": 0.005, "aperture": 0.001, "min_aperture": 0.0005, "rms": 0.00015,
              "hurst": 0.8, "mismatch_length": 0.0125, "seed": 4}
WAYS = ("blocks", "msh", "xdmf", "scattered", "root")


def rank_main(way: str, shape: list, path: str) -> None:
    """One rank: build the mesh `way` (``msh``, ``xdmf``: read `path` with that suffix), print every
    rank's peak memory [MB] from rank 0 as JSON."""
    import numpy as np
    from mpi4py import MPI

    from solid_fenicsx.mesh import _prepare, from_arrays, from_blocks, generated_mesh, read_mesh
    from transfer.generators import generate

    comm, p = MPI.COMM_WORLD, {**PARAMETERS, "shape": shape}
    if way == "blocks":
        solid = generated_mesh("rough_fracture", p, comm=comm)
    elif way in ("msh", "xdmf"):
        solid = read_mesh(Path(path).with_suffix(f".{way}"), comm=comm)
    else:
        block = generate("rough_fracture", p) if comm.rank == 0 else None
        triangles, tags = block.tagged_triangles() if block else (None, None)
        args = (block.points, block.cells, triangles, tags) if block else (None,) * 4
        if way == "root" and block:  # validated and compacted on rank 0 as before
            args = _prepare(*args)
        if way == "scattered":
            solid = from_arrays(*args, tag_names=block.face_tags if block else None, comm=comm)
        else:
            empty = (np.empty((0, 3)), np.empty((0, 4), np.int64), np.empty((0, 3), np.int64), np.empty(0, np.int32))
            solid = from_blocks(*(args if block else empty), tag_names=block.face_tags if block else None, comm=comm)
            del block, args
    peak = [int(line.split()[1]) for line in Path("/proc/self/status").read_text().splitlines()
            if line.startswith("VmHWM:")][0]
    peaks = comm.gather(round(peak / 1024, 1))
    if comm.rank == 0:
        print(json.dumps({"way": way, "shape": shape, "ranks": comm.size, "cells": solid.num_cells,
                          "peak_rss_mb": peaks}))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--shapes", nargs="+", default=["40,20,4", "80,40,8"])
    ap.add_argument("--ranks", nargs="+", type=int, default=[1, 2])
    ap.add_argument("--ways", nargs="+", default=list(WAYS), choices=WAYS)
    ap.add_argument("-o", "--output", type=Path, default=ROOT / "bench" / "results" / "solid_mesh.json")
    args = ap.parse_args(argv)
    env = dict(os.environ, OMP_NUM_THREADS="1", PYTHONPATH=str(ROOT))
    runs = json.loads(args.output.read_text())["runs"] if args.output.exists() else []
    with tempfile.TemporaryDirectory(prefix="varcouple-solid-mesh-") as tmp:
        for shape in args.shapes:
            path = Path(tmp) / f"rough_{shape.replace(',', 'x')}.msh"
            generate("rough_fracture", {**PARAMETERS, "shape": [int(n) for n in shape.split(",")]}).write(path)
            if "xdmf" in args.ways:
                subprocess.run([sys.executable, "-m", "solid_fenicsx.convert", str(path), str(path.with_suffix(".xdmf"))],
                               capture_output=True, env=env, check=True)
            for ranks in args.ranks:
                for way in args.ways:
                    cmd = ["mpirun", "-n", str(ranks), "--oversubscribe", sys.executable, __file__, "--rank", way, shape,
                           str(path)]
                    out = subprocess.run(cmd, capture_output=True, text=True, env=env, check=True).stdout
                    run = json.loads(out.strip().splitlines()[-1])
                    runs = [r for r in runs if (r["way"], r["shape"], r["ranks"]) != (way, run["shape"], ranks)]
                    runs.append(run)
                    print(run, flush=True)
    args.output.write_text(json.dumps({"runs": runs}, indent=1) + "\n")
    print(f"wrote {args.output}")
    return 0


if __name__ == "__main__":
    if sys.argv[1:2] == ["--rank"]:
        rank_main(sys.argv[2], [int(n) for n in sys.argv[3].split(",")], sys.argv[4])
    else:
        sys.exit(main())
