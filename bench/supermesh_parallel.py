"""libsupermesh's own parallel driver, parallel_supermesh, as the benchmarks' comparison
point: bench/supermesh_parallel.F90 is built on demand with mpif90 against the PyPI package
``libsupermesh`` (optional: `.venv/bin/pip install libsupermesh`; never a test dependency),
and run under mpirun on the same meshes, cut into the same parts as ours."""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
from pathlib import Path

import numpy as np

SOURCE = Path(__file__).resolve().parent / "supermesh_parallel.F90"


class ParallelSupermesh:
    """Build once; :meth:`measure` a P1-P1 coupling matrix on N ranks."""

    def __init__(self):
        self.error, self.exe, self.version = None, None, None
        try:
            import libsupermesh
        except Exception as exc:  # noqa: BLE001 - any import failure means: no baseline
            self.error = f"not installed ({type(exc).__name__}: {exc}); `pip install libsupermesh`"
            return
        from importlib.metadata import version

        self.version = version("libsupermesh")
        lib = Path(libsupermesh.get_library())
        self._tmp = tempfile.TemporaryDirectory(prefix="supermesh_parallel_")
        exe = Path(self._tmp.name) / "supermesh_parallel"
        fc = shutil.which("mpif90")
        if fc is None:
            self.error = "mpif90 not found"
            return
        build = subprocess.run([fc, "-O3", "-cpp", f"-I{lib.parent.parent / 'include'}", str(SOURCE), "-o", str(exe),
                                f"-L{lib.parent}", f"-l:{lib.name}", f"-Wl,-rpath,{lib.parent}",
                                ], capture_output=True, text=True, timeout=300)
        if build.returncode:
            self.error = f"the driver did not build: {build.stderr.strip()[-500:]}"
            return
        self.exe = exe

    @property
    def available(self) -> bool:
        return self.exe is not None

    def measure(self, source, target, source_owner, target_owner, ranks: int, repeat: int = 1) -> dict:
        """parallel_supermesh + CSR summation of B on `ranks` ranks (owner: rank of each cell);
        the fastest of `repeat` runs (the time is the slowest rank's)."""
        if not self.available:
            return {"available": False, "reason": self.error}
        with tempfile.TemporaryDirectory(prefix="supermesh_parts_") as parts:
            for name, mesh, owner in (("source", source, source_owner), ("target", target, target_owner)):
                for rank in range(ranks):
                    _write_part(Path(parts) / f"{name}_{ranks}_{rank}.bin", mesh, np.flatnonzero(owner == rank))
            env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1", OMP_NUM_THREADS="1")
            runs = []
            for _ in range(max(1, repeat)):
                proc = subprocess.run(["mpirun", "-n", str(ranks), "--oversubscribe", "--bind-to", "none",
                                       str(self.exe), parts], capture_output=True, text=True, env=env, timeout=1800)
                if proc.returncode:
                    return {"available": False, "reason": f"the driver failed: {proc.stderr.strip()[-500:]}"}
                words = proc.stdout.split()
                runs.append({words[i]: float(words[i + 1]) for i in range(0, len(words) - 1, 2)})
        best = min(runs, key=lambda r: r["seconds"])
        return {"available": True, "version": self.version, "ranks": ranks, "seconds": best["seconds"],
                "seconds_all": [r["seconds"] for r in runs], "pairs_intersected": int(best["pairs"]),
                "triplets": int(best["triplets"]), "nnz": int(best["nnz"]),
                "what": "libsupermesh parallel_supermesh (bounding boxes, communication, R-tree search, tet "
                        "clipping) with the P1 x P1 products integrated exactly per piece into triplets, "
                        "summed into CSR rows (bench/supermesh_parallel.F90, mpif90 -O3); slowest rank"}


def _write_part(path: Path, mesh, cells: np.ndarray) -> None:
    """One rank's cells as the driver reads them (see bench/supermesh_parallel.F90)."""
    nodes, local = np.unique(mesh.cells[cells], return_inverse=True)
    with open(path, "wb") as f:
        np.array([len(nodes), len(cells)], dtype=np.int32).tofile(f)
        np.ascontiguousarray(mesh.points[nodes], dtype=np.float64).tofile(f)
        (local.reshape(len(cells), -1) + 1).astype(np.int32).tofile(f)
        nodes.astype(np.int32).tofile(f)
