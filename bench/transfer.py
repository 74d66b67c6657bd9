"""Transfer benchmark: cost of the coupling matrix B (paper section 2.1, eq. 3) against a
same-mesh mass matrix, mesh -> structured grid throughput, accuracy against cost of the
quadrature, and threads. Prints a table and writes every figure to JSON.

    .venv/bin/python bench/transfer.py                  # small: 48k x 83k tets
    .venv/bin/python bench/transfer.py --sizes all --threads 1 2
    .venv/bin/python bench/transfer.py --quick -o t.json        # smoke run (seconds)

Section 0 is the goal of the parallel transfer issue: the serial CLI end to end (`varcouple
transfer` in this process: read, assemble, apply, write) against libsupermesh's own parallel
driver, parallel_supermesh plus the assembly of B, on one rank (bench/supermesh_parallel.py),
with the kernel split into search, rejection tests, clipping, integration and rows/CSR (the
kernel's `stages`), and the previous kernel in the same run with `--previous-kernel SO` (a
_kernels .so built from an older commit).

Every figure is measured in the same run, on the same machine: the baselines (a P1 mass
matrix on the target mesh, with our vectorised assembly and with dolfinx) and, when the
PyPI package ``libsupermesh`` is importable, libsupermesh itself (its R-tree search and
tet-tet clipping, driven by ``bench/supermesh_driver.c``). Times are the minimum over
``--repeat`` runs: the machine is shared, so the minimum is the least disturbed run.
"""

from __future__ import annotations

import argparse
import ctypes
import datetime as _dt
import gc
import json
import logging
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import scipy
import scipy.sparse as sp

ROOT = Path(__file__).resolve().parent.parent
# run as a script, this file's folder comes first on sys.path and its name would shadow
# the `transfer` package: look the package up from the repository root instead
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != Path(__file__).resolve().parent]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from transfer import FunctionSpace, StructuredGrid, Transfer, coupling_operator  # noqa: E402
from transfer.generate import box_tetrahedra  # noqa: E402

DEFAULT_OUTPUT = ROOT / "bench" / "results" / "transfer.json"

#: goal of the parallel transfer issue: the serial CLI end to end this many times faster than
#: libsupermesh's parallel_supermesh + B on one rank
GOAL_END_TO_END_RATIO = 5.0

#: the transfer goals
GOAL_TETS_PER_SECOND = 50_000
GOAL_MASS_RATIO = 50.0
#: not measured here: quoted from the issue
REFERENCE = {
    "libsupermesh_48k_x_83k_seconds": 4.9,
    "libsupermesh_ratio_to_mass_matrix": 250.0,
    "cores": 1,
    "source": "issue #2: libsupermesh on these machines",
}

#: lattice cells per axis (6 tets per cube): source, target
SIZES = {
    "small": (20, 24),  # 48,000 x 82,944 tets
    "large": (30, 36),  # 162,000 x 279,936 tets
}
QUICK_SIZE = (4, 5)
JITTER = 0.2
SOLID_BOX = ((0.2, 0.1, 0.3), (0.8, 0.9, 0.7))


def field(x):
    """The smooth field of the accuracy study: sin(pi x) cos(pi y) exp(z)."""
    return np.sin(np.pi * x[:, 0]) * np.cos(np.pi * x[:, 1]) * np.exp(x[:, 2])


# -- helpers ----------------------------------------------------------------------------
def _best(fn, repeat):
    """Run fn() `repeat` times; (min seconds, all seconds, last result)."""
    times, result = [], None
    for _ in range(max(1, repeat)):
        gc.collect()
        start = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - start)
    return min(times), times, result


def _assemble(source, target, repeat, **kwargs):
    """coupling_operator `repeat` times: stats of the fastest, min kernel and wall times."""
    kernel, wall, coupling = [], [], None
    for _ in range(max(1, repeat)):
        coupling = None
        gc.collect()
        start = time.perf_counter()
        coupling = coupling_operator(source, target, **kwargs)
        wall.append(time.perf_counter() - start)
        kernel.append(coupling.stats["assembly_seconds"])
    stats = dict(coupling.stats)
    return {
        "assembly_seconds": min(kernel),
        "assembly_seconds_all": kernel,
        "wall_seconds": min(wall),
        "wall_seconds_all": wall,
        "pairs_tested": stats["pairs_tested"],
        "pairs_intersected": stats["pairs_intersected"],
        "quadrature_degree": stats["quadrature_degree"],
        "quadrature_points": stats["quadrature_points"],
        "nthreads": stats["nthreads"],
        "nnz_B": int(coupling.B.nnz),
    }, coupling


def _rel_max(a: sp.spmatrix, b: sp.spmatrix) -> float:
    """||a - b||_max / ||b||_max over the entries."""
    diff = (a - b).tocsr()
    dmax = float(np.abs(diff.data).max()) if diff.nnz else 0.0
    return dmax / float(np.abs(b.data).max())


def _rel_l2(x, ref, mass) -> float:
    """Relative L2 norm of x - ref for the mass matrix `mass` (NaN entries ignored)."""
    ok = np.isfinite(x) & np.isfinite(ref)
    e = np.where(ok, x - ref, 0.0)
    r = np.where(ok, ref, 0.0)
    return float(np.sqrt(max(e @ (mass @ e), 0.0) / (r @ (mass @ r))))


def _table(headers, rows) -> str:
    cells = [[str(h) for h in headers]] + [[str(c) for c in row] for row in rows]
    widths = [max(len(r[i]) for r in cells) for i in range(len(headers))]
    lines = ["  ".join(c.rjust(w) if i else c.ljust(w) for i, (c, w) in enumerate(zip(row, widths)))
             for row in cells]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines)


def _s(seconds) -> str:
    if seconds is None:
        return "-"
    return f"{seconds * 1e3:.1f} ms" if seconds < 1 else f"{seconds:.3f} s"


def _g(x, fmt=".3g") -> str:
    return "-" if x is None else format(x, fmt)


def _say(text=""):
    print(text, flush=True)


def machine_info() -> dict:
    info = {
        "date": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "platform": platform.platform(),
        "machine": platform.machine(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "cpu_count": os.cpu_count(),
        "cpu_affinity": len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None,
        "load_average_at_start": list(os.getloadavg()) if hasattr(os, "getloadavg") else None,
        "shared_machine_note": "other users may load the machine; times are min over repeats",
    }
    try:
        with open("/proc/cpuinfo") as f:
            info["cpu_model"] = next((ln.split(":", 1)[1].strip() for ln in f if ln.startswith("model name")), None)
    except OSError:
        info["cpu_model"] = None
    try:
        out = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "HEAD"], capture_output=True, text=True, timeout=10)
        dirty = subprocess.run(["git", "-C", str(ROOT), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=10)
        info["git_commit"] = out.stdout.strip() or None
        info["git_dirty"] = bool(dirty.stdout.strip())
        info["git_modified"] = [line[3:] for line in dirty.stdout.splitlines()]
    except (OSError, subprocess.SubprocessError):
        info["git_commit"] = None
    try:  # the compiled kernels are what is measured: say whether they are older than their sources
        from transfer import _kernels

        built = Path(_kernels.__file__).stat().st_mtime
        sources = [f.stat().st_mtime for f in (ROOT / "transfer" / "_kernels").glob("*.[ch]pp")]
        info["kernels"] = {"file": Path(_kernels.__file__).name,
                           "built": _dt.datetime.fromtimestamp(built, _dt.timezone.utc).isoformat(timespec="seconds"),
                           "older_than_sources": bool(sources) and built < max(sources)}
    except (ImportError, OSError, AttributeError):
        info["kernels"] = None
    for env in ("OMP_NUM_THREADS", "OPENBLAS_CORETYPE"):
        info[env] = os.environ.get(env)
    return info


# -- baseline (b): dolfinx --------------------------------------------------------------
class DolfinxMass:
    """P1 mass matrix assembly with dolfinx (serial, COMM_SELF) on a given tet mesh."""

    def __init__(self):
        self.error = None
        try:
            from mpi4py import MPI
            import dolfinx
            import dolfinx.fem
            import dolfinx.fem.petsc
            import dolfinx.mesh
            import ufl
        except Exception as exc:  # noqa: BLE001 - any import failure means: no baseline
            self.error = f"{type(exc).__name__}: {exc}"
            return
        self.MPI, self.dolfinx, self.ufl = MPI, dolfinx, ufl
        self.version = dolfinx.__version__

    @property
    def available(self):
        return self.error is None

    def measure(self, mesh, repeat) -> dict:
        if not self.available:
            return {"available": False, "reason": self.error}
        dolfinx, ufl = self.dolfinx, self.ufl
        root = logging.getLogger()
        level = root.level
        root.setLevel(logging.WARNING)  # the form JIT logs every compiler call at INFO
        try:
            start = time.perf_counter()
            domain = ufl.Mesh(ufl.VectorElement("Lagrange", "tetrahedron", 1))
            dmesh = dolfinx.mesh.create_mesh(self.MPI.COMM_SELF, mesh.cells.astype(np.int64), mesh.points, domain)
            mesh_seconds = time.perf_counter() - start
            V = dolfinx.fem.FunctionSpace(dmesh, ("Lagrange", 1))
            u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
            start = time.perf_counter()
            form = dolfinx.fem.form(u * v * ufl.dx)  # JIT (or its disk cache)
            form_seconds = time.perf_counter() - start
            warm = dolfinx.fem.petsc.assemble_matrix(form)  # warm-up: first call excluded
            warm.assemble()
            warm.destroy()
        finally:
            root.setLevel(level)

        def full():  # sparsity pattern + matrix creation + element loop + finalisation
            A = dolfinx.fem.petsc.assemble_matrix(form)
            A.assemble()
            return A

        seconds, all_seconds, A = _best(full, repeat)
        total = float(A.getValuesCSR()[2].sum())
        size = A.getSize()
        A.destroy()
        A = dolfinx.fem.petsc.create_matrix(form)

        def into_existing():  # element loop + finalisation into an allocated matrix
            A.zeroEntries()
            dolfinx.fem.petsc.assemble_matrix(A, form)
            A.assemble()

        existing, existing_all, _ = _best(into_existing, repeat)
        A.destroy()
        return {
            "available": True,
            "version": self.version,
            "seconds": seconds,
            "seconds_all": all_seconds,
            "into_existing_matrix_seconds": existing,
            "into_existing_matrix_seconds_all": existing_all,
            "create_mesh_seconds": mesh_seconds,
            "form_compile_seconds": form_seconds,
            "num_cells": int(dmesh.topology.index_map(3).size_local),
            "matrix_size": list(size),
            "sum_of_entries": total,  # = volume of the mesh
            "what": "dolfinx.fem.petsc.assemble_matrix(form(u*v*dx)) + A.assemble(), after a warm-up",
        }


def ours_mass(target: FunctionSpace, repeat) -> dict:
    def assemble():
        target.mesh._cache.clear()  # cell volumes are cached on the mesh: measure them too
        return target.mass_matrix()

    seconds, all_seconds, M = _best(assemble, repeat)
    return {"available": True, "seconds": seconds, "seconds_all": all_seconds, "nnz": int(M.nnz),
            "sum_of_entries": float(M.sum()),
            "what": "FunctionSpace(target, 'P1').mass_matrix(), cell volumes included"}


# -- libsupermesh (measured when importable) --------------------------------------------
class Supermesh:
    """libsupermesh from the PyPI package (a shared library), driven by supermesh_driver.c."""

    DRIVER = Path(__file__).resolve().parent / "supermesh_driver.c"

    def __init__(self):
        self.error, self.lib = None, None
        try:
            import libsupermesh
        except Exception as exc:  # noqa: BLE001
            self.error = (f"not installed ({type(exc).__name__}: {exc}); `pip install libsupermesh` builds "
                          "an sdist needing gfortran, MPI and the rtree wheel")
            return
        try:
            libfile = Path(libsupermesh.get_library())
            self.version = getattr(libsupermesh, "__version__", None) or _dist_version("libsupermesh")
            self._tmp = tempfile.TemporaryDirectory(prefix="supermesh_driver_")
            so = Path(self._tmp.name) / "supermesh_driver.so"
            cc = os.environ.get("CC", "cc")
            subprocess.run([cc, "-O3", "-shared", "-fPIC", str(self.DRIVER), "-o", str(so),
                            f"-L{libfile.parent}", f"-l:{libfile.name}", f"-Wl,-rpath,{libfile.parent}"],
                           check=True, capture_output=True, text=True, timeout=120)
            lib = ctypes.CDLL(str(so))
        except Exception as exc:  # noqa: BLE001
            detail = getattr(exc, "stderr", "") or ""
            self.error = f"installed, but the driver did not build or load: {exc} {detail}".strip()
            return
        dbl = np.ctypeslib.ndpointer(np.float64, flags="C_CONTIGUOUS")
        lng = np.ctypeslib.ndpointer(np.int64, flags="C_CONTIGUOUS")
        i32 = np.ctypeslib.ndpointer(np.int32, flags="C_CONTIGUOUS")
        lib.lsm_p1p1.restype = ctypes.c_long
        lib.lsm_p1p1.argtypes = [ctypes.c_long, dbl, ctypes.c_long, lng] * 2 + [dbl, lng]
        lib.lsm_fetch.restype = None
        lib.lsm_fetch.argtypes = [i32, i32, dbl]
        self.lib = lib

    @property
    def available(self):
        return self.lib is not None

    def _once(self, source, target):
        sp_, sc = np.ascontiguousarray(source.points), np.ascontiguousarray(source.cells, dtype=np.int64)
        tp, tc = np.ascontiguousarray(target.points), np.ascontiguousarray(target.cells, dtype=np.int64)
        times, counts = np.zeros(2), np.zeros(2, dtype=np.int64)
        start = time.perf_counter()
        nnz = self.lib.lsm_p1p1(len(sp_), sp_, len(sc), sc, len(tp), tp, len(tc), tc, times, counts)
        kernel = time.perf_counter() - start
        if nnz < 0:
            raise MemoryError("libsupermesh driver: out of memory")
        rows, cols, vals = np.empty(nnz, np.int32), np.empty(nnz, np.int32), np.empty(nnz)
        self.lib.lsm_fetch(rows, cols, vals)
        B = sp.csr_matrix((vals, (rows, cols)), shape=(len(tp), len(sp_)))
        total = time.perf_counter() - start
        return B, {"kernel": kernel, "search": times[0], "clip_integrate": times[1], "total": total,
                   "tested": int(counts[0]), "intersected": int(counts[1])}

    def measure(self, source, target, repeat, B_ours) -> dict:
        if not self.available:
            return {"available": False, "reason": self.error}
        runs, B = [], None
        for _ in range(max(1, repeat)):
            B = None
            gc.collect()
            B, r = self._once(source, target)
            runs.append(r)
        best = min(runs, key=lambda r: r["total"])
        return {
            "available": True,
            "version": self.version,
            "seconds": best["total"],
            "seconds_all": [r["total"] for r in runs],
            "search_seconds": min(r["search"] for r in runs),
            "clip_integrate_seconds": min(r["clip_integrate"] for r in runs),
            "kernel_seconds": min(r["kernel"] for r in runs),
            "to_csr_seconds": min(r["total"] - r["kernel"] for r in runs),
            "pairs_tested": best["tested"],
            "pairs_intersected": best["intersected"],
            "max_rel_difference_to_ours": _rel_max(B, B_ours),
            "what": ("libsupermesh tree_intersection_finder + intersect_tets_real, each piece integrated "
                     "exactly (bench/supermesh_driver.c, -O3, 1 thread); seconds = search + clip + "
                     "integrate + COO->CSR (scipy)"),
        }


def _dist_version(name):
    try:
        from importlib.metadata import version

        return version(name)
    except Exception:  # noqa: BLE001
        return None


# -- 0. end to end against libsupermesh's parallel driver ---------------------------------
def _parallel_supermesh():
    """bench/supermesh_parallel.py, loaded by path (this folder is not on sys.path)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("supermesh_parallel", ROOT / "bench" / "supermesh_parallel.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


#: the kernel's stages (transfer/_kernels/common.hpp, vc::Stage): each run stops after one
STAGES = {1: "search", 2: "reject", 3: "clip", 4: "integrate", 5: "rows_and_csr"}


def _load_kernels(path):
    """A build of transfer/_kernels from another commit (a .so file), for --previous-kernel."""
    import importlib.machinery
    import importlib.util
    import types

    sys.modules.setdefault("previous", types.ModuleType("previous"))
    loader = importlib.machinery.ExtensionFileLoader("previous._kernels", str(path))
    module = importlib.util.module_from_spec(importlib.util.spec_from_file_location("previous._kernels", str(path),
                                                                                     loader=loader))
    loader.exec_module(module)
    return module


def _kernel_cpu(kernels, S, T, repeat, **kwargs) -> float:
    src, dst = S.mesh, T.mesh
    times = []
    for _ in range(max(1, repeat)):
        start = time.process_time()  # CPU time: on a shared machine less disturbed than wall time
        kernels.assemble_volume(src.points, src.cells, kernels.TET, 1, dst.points, dst.cells, kernels.TET, 1,
                                np.empty((0, 4)), np.empty(0), False, False, S.num_dofs, T.num_dofs, None, 1, **kwargs)
        times.append(time.process_time() - start)
    return min(times)


def _kernel_stages(S, T, repeat, previous=None) -> dict:
    """Kernel CPU seconds of each stage (the difference of runs stopped after it and before
    it), and of the whole kernel with and without the rejection tests; with `previous`
    (another build's module) its whole kernel too, measured between these runs."""
    from transfer import _kernels

    upto = {stage: _kernel_cpu(_kernels, S, T, repeat, stages=stage) for stage in STAGES}
    out = {name: upto[stage] - upto.get(stage - 1, 0.0) for stage, name in STAGES.items()}
    out["kernel"] = upto[5]
    out["kernel_without_rejection"] = _kernel_cpu(_kernels, S, T, repeat, reject=False)
    if previous is not None:
        out["previous_kernel"] = _kernel_cpu(previous, S, T, repeat)
        out["kernel_again"] = _kernel_cpu(_kernels, S, T, repeat)
        out["previous_over_new"] = out["previous_kernel"] / min(upto[5], out["kernel_again"])
    return out


def bench_end_to_end(label, n_source, n_target, repeat, previous=None) -> dict:
    """`varcouple transfer` on the pair (files written here), phase by phase, against
    parallel_supermesh + B on one rank, both measured now."""
    import meshio

    from coupler.cli import main as cli
    from transfer.meshfile import MeshFile

    src, dst = _meshes(n_source, n_target)
    S, T = FunctionSpace(src, "P1"), FunctionSpace(dst, "P1")
    res = {"size": label, "source_tets": src.num_cells, "target_tets": dst.num_cells}
    with tempfile.TemporaryDirectory(prefix="transfer_bench_") as tmp:
        tmp = Path(tmp)
        meshio.write(tmp / "src.vtu", meshio.Mesh(src.points, [("tetra", src.cells)],
                                                  point_data={"f": S.interpolate(field)}))
        meshio.write(tmp / "dst.vtu", meshio.Mesh(dst.points, [("tetra", dst.cells)]))
        argv = ["transfer", str(tmp / "src.vtu"), str(tmp / "dst.vtu"), "--field", "f", "-o", str(tmp / "out.vtu")]
        with open(os.devnull, "w") as quiet:
            def run_cli():
                saved, sys.stdout = sys.stdout, quiet
                try:
                    assert cli(argv) == 0
                finally:
                    sys.stdout = saved
            res["cli_seconds"], res["cli_seconds_all"], _ = _best(run_cli, repeat)
        read, _, (source, target) = _best(lambda: (MeshFile.read(tmp / "src.vtu"), MeshFile.read(tmp / "dst.vtu")),
                                          repeat)
        u = source.field("f").flat
        rest = []  # Transfer.assemble beyond the kernel, run by run

        def assemble():
            start = time.perf_counter()
            op = Transfer.assemble(source.space("point"), target.space("point"), "l2")
            rest.append(time.perf_counter() - start - op.stats["assembly_seconds"])
            return op

        _, _, operator = _best(assemble, repeat)
        solve, _, v = _best(lambda: operator(u), repeat)
        fields = {"f": ("point", v), "covered": ("point", operator.covered.astype(np.uint8))}
        write, _, _ = _best(lambda: target.write(tmp / "again.vtu", fields), repeat)
    stages = _kernel_stages(S, T, repeat, previous)
    res["phases"] = {"read": read, **{name: stages[name] for name in STAGES.values()},
                     "assembly_rest": min(rest), "solve": solve, "write": write,
                     "what": ("read/write: MeshFile (meshio); search, reject (separating-plane tests), clip, "
                              "integrate (moments, local blocks), rows_and_csr (rows of B and D, COO to CSR): kernel "
                              "CPU seconds by stage; assembly_rest: Transfer.assemble beyond the kernel (scipy "
                              "matrices, coverage, solver set-up); solve: T u (CG on D)")}
    res["kernel_stages"] = stages
    res["kernel_seconds"] = operator.stats["assembly_seconds"]
    res["pairs_tested"], res["pairs_intersected"] = operator.stats["pairs_tested"], operator.stats["pairs_intersected"]
    lsm = _parallel_supermesh().ParallelSupermesh()
    one = np.zeros(src.num_cells, np.int64), np.zeros(dst.num_cells, np.int64)
    res["libsupermesh_parallel"] = lsm.measure(src, dst, *one, ranks=1, repeat=repeat)
    base = res["libsupermesh_parallel"]
    ratio = base["seconds"] / res["cli_seconds"] if base["available"] else None
    res["assembly_ratio"] = base["seconds"] / res["kernel_seconds"] if base["available"] else None
    res["goal"] = {"goal": GOAL_END_TO_END_RATIO, "value": ratio,
                   "pass": None if ratio is None else ratio >= GOAL_END_TO_END_RATIO,
                   "what": "libsupermesh parallel_supermesh + B on 1 rank / varcouple transfer end to end (1 thread)"}
    return res


def print_end_to_end(res):
    _say(f"\n== 0. end to end, P1 -> P1, {res['size']}: {res['source_tets']:,} x {res['target_tets']:,} tets, "
         f"1 thread, 1 rank ==")
    ph = res["phases"]
    rows = [[name, _s(ph[name])] for name in ("read", *STAGES.values(), "assembly_rest", "solve", "write")]
    rows.append(["varcouple transfer (end to end)", _s(res["cli_seconds"])])
    base = res["libsupermesh_parallel"]
    rows.append(["libsupermesh parallel_supermesh + B", _s(base["seconds"]) if base["available"] else "not available"])
    _say(_table(["phase", "time (min)"], rows))
    _say(f"pairs tested / intersected: {res['pairs_tested']:,} / {res['pairs_intersected']:,}")
    st = res["kernel_stages"]
    _say(f"kernel CPU {_s(st['kernel'])}, without the rejection tests {_s(st['kernel_without_rejection'])}"
         + (f"; previous kernel {_s(st['previous_kernel'])}: {st['previous_over_new']:.2f}x" if "previous_kernel" in st
            else ""))
    goal = res["goal"]
    if goal["value"] is None:
        _say(f"libsupermesh: {base['reason']}")
    else:
        _say(f"end to end: ours {goal['value']:.2f}x faster than libsupermesh's parallel driver on one rank "
             f"(goal {goal['goal']:.0f}x): {'PASS' if goal['pass'] else 'MISS'}; Transfer.assemble's kernel "
             f"{res['assembly_ratio']:.2f}x")


# -- 1. P1-P1 tet-tet ------------------------------------------------------------------
def _meshes(n_source, n_target, lower=(0, 0, 0), upper=(1, 1, 1)):
    src = box_tetrahedra((n_source,) * 3, lower, upper, jitter=JITTER, seed=1, name="source")
    dst = box_tetrahedra((n_target,) * 3, lower, upper, jitter=JITTER, seed=2, name="target")
    return src, dst


def _transfer_timings(S, T, repeat, coupling_l2, exact_l2_stats) -> dict:
    """Transfer setup + apply of one scalar field, for l2 and pseudo_l2."""
    u = S.interpolate(field)
    exact = T.interpolate(field)
    mass = T.mass_matrix()
    out = {}
    for method in ("l2", "pseudo_l2"):
        if method == "l2":
            asm, coupling = exact_l2_stats, coupling_l2
        else:
            asm, coupling = _assemble(S, T, repeat, method=method)
        setup, setup_all, tr = _best(lambda: Transfer(S, T, method, coupling), repeat)
        start = time.perf_counter()
        v = tr.apply(u)
        first = time.perf_counter() - start
        apply_s, apply_all, v = _best(lambda: tr.apply(u), repeat)
        iterations = getattr(tr._solve, "iterations", None)
        out[method] = {
            "assembly_seconds": asm["assembly_seconds"],
            "assembly_wall_seconds": asm["wall_seconds"],
            "setup_seconds": setup,
            "setup_seconds_all": setup_all,
            "first_apply_seconds": first,
            "apply_seconds": apply_s,
            "apply_seconds_all": apply_all,
            "total_seconds": asm["wall_seconds"] + setup + first,
            "cg_iterations": iterations,
            "covered_fraction": tr.covered_fraction,
            "conservation_error": tr.conservation_error(u),
            "l2_error_vs_interpolant": _rel_l2(v, exact, mass),
            "what": ("assembly = coupling_operator(method); setup = Transfer(...) from the coupling "
                     "(coverage, solver); apply = T(u) of one scalar field; total = assembly wall + "
                     "setup + first apply"),
        }
    return out


def bench_p1p1(label, n_source, n_target, repeat, dolfinx_mass, supermesh, transfers=True) -> dict:
    src, dst = _meshes(n_source, n_target)
    S, T = FunctionSpace(src, "P1"), FunctionSpace(dst, "P1")
    asm, coupling = _assemble(S, T, repeat)
    res = {
        "size": label,
        "source_tets": src.num_cells,
        "target_tets": dst.num_cells,
        "source_dofs": S.num_dofs,
        "target_dofs": T.num_dofs,
        "jitter": JITTER,
        "seeds": [1, 2],
        **asm,
        "target_tets_per_second": dst.num_cells / asm["assembly_seconds"],
        "B_sum_minus_volume": float(coupling.B.sum() - 1.0),
    }
    res["mass_matrix"] = {"ours": ours_mass(T, repeat), "dolfinx": dolfinx_mass.measure(dst, repeat)}
    for name, base in res["mass_matrix"].items():
        res[f"ratio_to_mass_{name}"] = asm["assembly_seconds"] / base["seconds"] if base["available"] else None
    headline = "dolfinx" if res["mass_matrix"]["dolfinx"]["available"] else "ours"
    res["headline_baseline"] = headline
    res["libsupermesh"] = supermesh.measure(src, dst, repeat, coupling.B)
    lsm = res["libsupermesh"]
    if lsm["available"]:
        res["speedup_vs_libsupermesh_measured"] = lsm["seconds"] / asm["assembly_seconds"]
        # search + clip + integrate only, without the driver's COO -> CSR summation
        res["speedup_vs_libsupermesh_kernel_only"] = lsm["kernel_seconds"] / asm["assembly_seconds"]
        lsm["ratio_to_mass"] = {name: lsm["seconds"] / base["seconds"] if base["available"] else None
                                for name, base in res["mass_matrix"].items()}
    if label == "small":
        res["speedup_vs_reference"] = REFERENCE["libsupermesh_48k_x_83k_seconds"] / asm["assembly_seconds"]
    res["goals"] = {
        "target_tets_per_second_per_core": {"goal": GOAL_TETS_PER_SECOND, "value": res["target_tets_per_second"],
                                            "pass": res["target_tets_per_second"] >= GOAL_TETS_PER_SECOND},
        "ratio_to_mass_matrix": {"goal": GOAL_MASS_RATIO, "baseline": headline,
                                 "value": res[f"ratio_to_mass_{headline}"],
                                 "pass": res[f"ratio_to_mass_{headline}"] <= GOAL_MASS_RATIO},
    }
    if transfers:
        res["transfer"] = _transfer_timings(S, T, repeat, coupling, asm)
    return res


def print_p1p1(res):
    mm = res["mass_matrix"]
    lsm = res["libsupermesh"]
    _say(f"\n== 1. P1-P1 tet -> tet, {res['size']}: {res['source_tets']:,} x {res['target_tets']:,} tets "
         f"(jitter {res['jitter']}), 1 thread ==")
    rows = [
        ["B (coupling_operator, l2)", _s(res["assembly_seconds"]), _s(res["wall_seconds"]),
         f"{res['target_tets_per_second']:,.0f}", "-",
         f"{res['pairs_tested']:,} / {res['pairs_intersected']:,}"],
        ["mass matrix, ours (numpy)", _s(mm["ours"]["seconds"]), "-",
         f"{res['target_tets'] / mm['ours']['seconds']:,.0f}", _g(res["ratio_to_mass_ours"], ".1f"), "-"],
    ]
    d = mm["dolfinx"]
    if d["available"]:
        rows.append([f"mass matrix, dolfinx {d['version']}", _s(d["seconds"]), "-",
                     f"{res['target_tets'] / d['seconds']:,.0f}", _g(res["ratio_to_mass_dolfinx"], ".1f"), "-"])
        rows.append(["  (into an existing matrix)", _s(d["into_existing_matrix_seconds"]), "-",
                     f"{res['target_tets'] / d['into_existing_matrix_seconds']:,.0f}",
                     _g(res["assembly_seconds"] / d["into_existing_matrix_seconds"], ".1f"), "-"])
    else:
        rows.append(["mass matrix, dolfinx", "not available", "-", "-", "-", "-"])
    if lsm["available"]:
        rows.append([f"libsupermesh {lsm['version']} (measured)", _s(lsm["seconds"]), "-",
                     f"{res['target_tets'] / lsm['seconds']:,.0f}", "-",
                     f"{lsm['pairs_tested']:,} / {lsm['pairs_intersected']:,}"])
        rows.append(["  search / clip+integrate / to CSR",
                     f"{_s(lsm['search_seconds'])} / {_s(lsm['clip_integrate_seconds'])} / "
                     f"{_s(lsm['to_csr_seconds'])}", "-", "-", "-", "-"])
    else:
        rows.append(["libsupermesh", "not installed", "-", "-", "-", "-"])
    _say(_table(["", "time (min)", "wall", "target tets/s", "B / mass", "pairs tested / intersected"], rows))
    if lsm["available"]:
        ratio = lsm["ratio_to_mass"][res["headline_baseline"]]
        _say(f"libsupermesh measured: ours is {res['speedup_vs_libsupermesh_measured']:.2f}x faster "
             f"({res['speedup_vs_libsupermesh_kernel_only']:.2f}x against its search + clip + integrate alone); "
             f"libsupermesh = {ratio:.0f}x the mass matrix ({res['headline_baseline']}); "
             f"max |B_lsm - B_ours| / max |B_ours| = {lsm['max_rel_difference_to_ours']:.1e}")
    else:
        _say(f"libsupermesh: {lsm['reason']}")
    if "speedup_vs_reference" in res:
        _say(f"reference ({REFERENCE['source']}): {REFERENCE['libsupermesh_48k_x_83k_seconds']} s, "
             f"~{REFERENCE['libsupermesh_ratio_to_mass_matrix']:.0f}x a mass matrix -> ours is "
             f"{res['speedup_vs_reference']:.1f}x faster")
    if "transfer" in res:
        rows = []
        for method, t in res["transfer"].items():
            rows.append([method, _s(t["assembly_seconds"]), _s(t["setup_seconds"]), _s(t["first_apply_seconds"]),
                         _s(t["apply_seconds"]), _s(t["total_seconds"]), _g(t["cg_iterations"]),
                         _g(t["conservation_error"], ".1e"), _g(t["l2_error_vs_interpolant"], ".2e")])
        _say(_table(["Transfer", "assembly", "setup", "1st apply", "apply", "total", "CG its",
                     "conservation", "L2 err vs f_h"], rows))
    for name, g in res["goals"].items():
        if name == "target_tets_per_second_per_core":
            text = f">= {g['goal']:,} target tets/s per core: {g['value']:,.0f}"
        else:
            text = f"within {g['goal']:.0f}x of the same-mesh mass matrix ({g['baseline']}): {g['value']:.1f}x"
        _say(f"{'PASS' if g['pass'] else 'MISS'}  {text}")


# -- 2. solid mesh -> structured grid ---------------------------------------------------
def bench_grid(n_solid, grid_cells, repeat) -> dict:
    lower, upper = SOLID_BOX
    solid = box_tetrahedra((n_solid,) * 3, lower, upper, jitter=JITTER, seed=3, name="solid")
    grid = StructuredGrid.from_bounds((0, 0, 0), (1, 1, 1), (grid_cells,) * 3, name="fluid grid")
    volume = float(np.prod(np.subtract(upper, lower)))
    res = {"solid_tets": solid.num_cells, "solid_box": [list(lower), list(upper)], "grid_shape": list(grid.shape),
           "grid_cells": grid.num_cells, "grid_points": grid.num_points, "solid_volume": volume}
    cases = [("P0 tet -> Q0 grid", solid, "P0", grid, "Q0"),
             ("P1 tet -> Q1 grid", solid, "P1", grid, "Q1"),
             ("Q1 grid -> P1 tet", grid, "Q1", solid, "P1")]
    res["cases"] = []
    for name, smesh, sfam, tmesh, tfam in cases:
        asm, coupling = _assemble(FunctionSpace(smesh, sfam), FunctionSpace(tmesh, tfam), repeat)
        entry = {"name": name, **asm,
                 "solid_tets_per_second": solid.num_cells / asm["assembly_seconds"],
                 "grid_cells_per_second": grid.num_cells / asm["assembly_seconds"]}
        if sfam == "P0":
            cell_volume = np.asarray(coupling.B.sum(axis=1)).ravel()  # solid volume in each grid cell
            fractions = cell_volume / float(np.prod(grid.spacing))
            entry["volume_fractions"] = {
                "sum_of_solid_volume": float(cell_volume.sum()),
                "relative_error_vs_box_volume": abs(float(cell_volume.sum()) - volume) / volume,
                "relative_error_vs_tet_volumes": abs(float(cell_volume.sum()) - float(solid.cell_measures().sum()))
                / float(solid.cell_measures().sum()),
                "full_cells": int(np.count_nonzero(fractions > 1 - 1e-12)),
                "cut_cells": int(np.count_nonzero((fractions > 1e-12) & (fractions <= 1 - 1e-12))),
                "max_fraction": float(fractions.max()),
            }
        res["cases"].append(entry)
    return res


def print_grid(res):
    _say(f"\n== 2. solid tet mesh -> structured grid: {res['solid_tets']:,} tets in "
         f"{res['solid_box'][0]}..{res['solid_box'][1]}, grid {'x'.join(map(str, res['grid_shape']))} "
         f"({res['grid_cells']:,} cells) on [0,1]^3, 1 thread ==")
    rows = [[c["name"], _s(c["assembly_seconds"]), _s(c["wall_seconds"]), str(c["quadrature_degree"]),
             f"{c['solid_tets_per_second']:,.0f}", f"{c['grid_cells_per_second']:,.0f}",
             f"{c['pairs_tested']:,} / {c['pairs_intersected']:,}"] for c in res["cases"]]
    _say(_table(["", "assembly", "wall", "quad deg", "solid tets/s", "grid cells/s", "pairs tested / intersected"],
                rows))
    vf = res["cases"][0]["volume_fractions"]
    _say(f"Q0 volume fractions: sum = {vf['sum_of_solid_volume']:.15g} (solid volume {res['solid_volume']:.15g}), "
         f"relative error {vf['relative_error_vs_box_volume']:.1e} (vs sum of tet volumes "
         f"{vf['relative_error_vs_tet_volumes']:.1e}); {vf['full_cells']:,} full, {vf['cut_cells']:,} cut cells")


# -- 3. accuracy against cost -----------------------------------------------------------
def bench_accuracy(n_source, n_target, grid_cells, repeat) -> dict:
    src, dst = _meshes(n_source, n_target)
    S, T = FunctionSpace(src, "P1"), FunctionSpace(dst, "P1")
    mass = T.mass_matrix()
    u = S.interpolate(field)
    out = {"p1p1": {"source_tets": src.num_cells, "target_tets": dst.num_cells, "rows": []}}
    ref_stats, ref = _assemble(S, T, repeat)
    ref_v = Transfer(S, T, "l2", ref).apply(u)
    f_h = T.interpolate(field)
    for q in [None, 1, 2, 3, 4, 5]:
        stats, c = (ref_stats, ref) if q is None else _assemble(S, T, repeat, quadrature_degree=q)
        v = Transfer(S, T, "l2", c).apply(u)
        out["p1p1"]["rows"].append({
            "quadrature_degree": "exact" if q is None else q,
            "quadrature_points": stats["quadrature_points"],
            "assembly_seconds": stats["assembly_seconds"],
            "B_rel_max_error": _rel_max(c.B, ref.B),
            "D_rel_max_error": _rel_max(c.D, ref.D),
            "projection_rel_l2_diff_vs_exact": _rel_l2(v, ref_v, mass),
            "projection_rel_max_diff_vs_exact": float(np.nanmax(np.abs(v - ref_v)) / np.nanmax(np.abs(ref_v))),
            "projection_rel_l2_error_vs_f_h": _rel_l2(v, f_h, mass),
        })
    grid = StructuredGrid.from_bounds((0, 0, 0), (1, 1, 1), (grid_cells,) * 3)
    G = FunctionSpace(grid, "Q1")
    ug = G.interpolate(field)
    out["grid_q1_p1"] = {"grid_shape": list(grid.shape), "target_tets": dst.num_cells, "reference": "default (4)",
                         "rows": []}
    ref_stats, ref = _assemble(G, T, repeat)
    ref_v = Transfer(G, T, "l2", ref).apply(ug)
    for q in [1, 2, 3, 4, 5, 6]:
        stats, c = _assemble(G, T, repeat, quadrature_degree=q)
        v = Transfer(G, T, "l2", c).apply(ug)
        out["grid_q1_p1"]["rows"].append({
            "quadrature_degree": q,
            "is_default": q == ref_stats["quadrature_degree"],
            "quadrature_points": stats["quadrature_points"],
            "assembly_seconds": stats["assembly_seconds"],
            "B_rel_max_error": _rel_max(c.B, ref.B),
            "D_rel_max_error": _rel_max(c.D, ref.D),
            "projection_rel_l2_diff_vs_default": _rel_l2(v, ref_v, mass),
            "projection_rel_max_diff_vs_default": float(np.nanmax(np.abs(v - ref_v)) / np.nanmax(np.abs(ref_v))),
            "projection_rel_l2_error_vs_f_h": _rel_l2(v, f_h, mass),
        })
    out["grid_q1_p1"]["default_quadrature_degree"] = ref_stats["quadrature_degree"]
    return out


def print_accuracy(res):
    p = res["p1p1"]
    _say(f"\n== 3. accuracy vs cost: P1 -> P1, {p['source_tets']:,} x {p['target_tets']:,} tets, "
         f"f = sin(pi x) cos(pi y) exp(z), l2 ==")
    rows = [[str(r["quadrature_degree"]), str(r["quadrature_points"]) if r["quadrature_degree"] != "exact" else "-",
             _s(r["assembly_seconds"]), _g(r["B_rel_max_error"], ".1e"), _g(r["D_rel_max_error"], ".1e"),
             _g(r["projection_rel_l2_diff_vs_exact"], ".1e"), _g(r["projection_rel_max_diff_vs_exact"], ".1e"),
             _g(r["projection_rel_l2_error_vs_f_h"], ".2e")] for r in p["rows"]]
    _say(_table(["quad degree", "points", "assembly", "|B-B_ex|/|B_ex| max", "D err", "Tu diff L2", "Tu diff max",
                 "L2 err vs f_h"], rows))
    g = res["grid_q1_p1"]
    _say(f"\n   Q1 grid {'x'.join(map(str, g['grid_shape']))} -> P1 {g['target_tets']:,} tets "
         f"(reference: default degree {g['default_quadrature_degree']})")
    rows = [[f"{r['quadrature_degree']}{' (default)' if r['is_default'] else ''}", str(r["quadrature_points"]),
             _s(r["assembly_seconds"]), _g(r["B_rel_max_error"], ".1e"), _g(r["D_rel_max_error"], ".1e"),
             _g(r["projection_rel_l2_diff_vs_default"], ".1e"), _g(r["projection_rel_max_diff_vs_default"], ".1e"),
             _g(r["projection_rel_l2_error_vs_f_h"], ".2e")] for r in g["rows"]]
    _say(_table(["quad degree", "points", "assembly", "|B-B_def|/|B_def| max", "D err", "Tu diff L2", "Tu diff max",
                 "L2 err vs f_h"], rows))


# -- 4. threads ---------------------------------------------------------------------------
def bench_threads(p1p1_results, sizes, threads, repeat) -> list:
    out = []
    for res in p1p1_results:
        n_source, n_target = sizes[res["size"]]
        src, dst = _meshes(n_source, n_target)
        S, T = FunctionSpace(src, "P1"), FunctionSpace(dst, "P1")
        base = res["assembly_seconds"]
        rows = [{"nthreads": 1, "assembly_seconds": base, "speedup": 1.0, "efficiency": 1.0,
                 "target_tets_per_second": res["target_tets_per_second"]}]
        for n in threads:
            if n == 1:
                continue
            asm, _ = _assemble(S, T, repeat, nthreads=n)
            t = asm["assembly_seconds"]
            rows.append({"nthreads": n, "assembly_seconds": t, "assembly_seconds_all": asm["assembly_seconds_all"],
                         "speedup": base / t, "efficiency": base / t / n,
                         "target_tets_per_second": dst.num_cells / t})
        out.append({"size": res["size"], "rows": rows})
    return out


def print_threads(res):
    for entry in res:
        _say(f"\n== 4. threads: P1-P1 {entry['size']} ==")
        _say(_table(["threads", "assembly", "speed-up", "efficiency", "target tets/s"],
                    [[str(r["nthreads"]), _s(r["assembly_seconds"]), f"{r['speedup']:.2f}x",
                      f"{100 * r['efficiency']:.0f}%", f"{r['target_tets_per_second']:,.0f}"] for r in entry["rows"]]))


# -- main ---------------------------------------------------------------------------------
def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--sizes", choices=["small", "large", "all"], default="small",
                   help="small: 48k x 83k tets; large: 162k x 280k; all: both (default: small)")
    p.add_argument("--threads", type=int, nargs="+", default=[1],
                   help="thread counts for the P1-P1 assembly (default: 1); 1 thread is always measured")
    p.add_argument("--repeat", type=int, default=3, help="runs per figure, the minimum is reported (default: 3)")
    p.add_argument("-o", "--output", type=Path, default=DEFAULT_OUTPUT, help=f"JSON file (default: {DEFAULT_OUTPUT})")
    p.add_argument("--quick", action="store_true", help="tiny meshes, 1 repeat: a smoke run of every code path")
    p.add_argument("--no-transfer", action="store_true", help="skip the Transfer setup/apply timings")
    p.add_argument("--previous-kernel", type=Path, metavar="SO",
                   help="a _kernels .so built from another commit: its kernel is timed in the same run (section 0)")
    args = p.parse_args(argv)
    if any(n < 1 for n in args.threads):
        p.error("--threads must be positive")
    if args.repeat < 1:
        p.error("--repeat must be at least 1")
    return args


def main(argv=None) -> dict:
    args = parse_args(argv)
    if args.quick:
        sizes = {"quick": QUICK_SIZE}
        repeat = 1
        grid_setup = (4, 12)  # solid lattice, grid cells per axis
        accuracy_setup = (3, 4, 6)
    else:
        names = ["small", "large"] if args.sizes == "all" else [args.sizes]
        sizes = {name: SIZES[name] for name in names}
        repeat = args.repeat
        grid_setup = (20, 64)  # 48,000 solid tets, 64^3 grid
        accuracy_setup = (10, 12, 16)  # 6,000 x 10,368 tets, 16^3 grid
    started = time.perf_counter()
    result = {
        "benchmark": "transfer",
        "meta": machine_info(),
        "args": {"sizes": list(sizes), "threads": args.threads, "repeat": repeat, "quick": args.quick},
        "reference": REFERENCE,
        "goals": {"target_tets_per_second_per_core": GOAL_TETS_PER_SECOND, "max_ratio_to_mass_matrix": GOAL_MASS_RATIO},
    }
    _say(f"transfer benchmark: sizes {list(sizes)}, repeat {repeat} (min reported), threads {args.threads}; "
         f"{result['meta']['cpu_count']} CPUs, load average {result['meta']['load_average_at_start']}")

    dolfinx_mass = DolfinxMass()
    supermesh = Supermesh()
    result["meta"]["dolfinx"] = dolfinx_mass.version if dolfinx_mass.available else f"unavailable: {dolfinx_mass.error}"
    result["meta"]["libsupermesh"] = supermesh.version if supermesh.available else supermesh.error

    result["end_to_end"] = []
    for label, (ns, nt) in sizes.items():
        res = bench_end_to_end(label, ns, nt, repeat, _load_kernels(args.previous_kernel) if args.previous_kernel
                               else None)
        result["end_to_end"].append(res)
        print_end_to_end(res)

    result["p1p1"] = []
    for label, (ns, nt) in sizes.items():
        res = bench_p1p1(label, ns, nt, repeat, dolfinx_mass, supermesh, transfers=not args.no_transfer)
        result["p1p1"].append(res)
        print_p1p1(res)

    result["grid"] = bench_grid(*grid_setup, repeat)
    print_grid(result["grid"])

    result["accuracy"] = bench_accuracy(*accuracy_setup, repeat)
    print_accuracy(result["accuracy"])

    result["threads"] = bench_threads(result["p1p1"], sizes, args.threads, repeat)
    if any(n != 1 for n in args.threads):
        print_threads(result["threads"])

    result["meta"]["load_average_at_end"] = list(os.getloadavg()) if hasattr(os, "getloadavg") else None
    result["meta"]["benchmark_seconds"] = time.perf_counter() - started
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(json.dumps(result, indent=2, default=_json_default) + "\n")
    _say(f"\nwrote {args.output} ({result['meta']['benchmark_seconds']:.0f} s)")
    return result


def _json_default(x):
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    raise TypeError(f"{type(x).__name__} is not JSON serialisable")


if __name__ == "__main__":
    main()
