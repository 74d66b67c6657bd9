"""Helpers shared by the tests (for the transfer tests, independent of the library where it
matters: geometry and quadrature here are written from scratch, not taken from `transfer`)."""

from __future__ import annotations

import importlib.util
import signal
from itertools import combinations
from pathlib import Path

import numpy as np
import pytest

from transfer import Mesh

#: the repository, its cases and benchmarks
ROOT = Path(__file__).resolve().parent.parent
CASES = ROOT / "cases"

#: shift of the partially overlapping target box (tests/conftest.py: shifted_tets)
SHIFT = np.array([0.37, 0.21, -0.13])


# -- benchmarks ---------------------------------------------------------------
def load_bench(name: str):
    """The module bench/NAME.py (benchmarks are scripts, not a package), for smoke runs of --quick."""
    path = ROOT / "bench" / f"{name}.py"
    spec = importlib.util.spec_from_file_location(f"bench_{name}", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


# -- fields ------------------------------------------------------------------
def rel_err(value, exact) -> float:
    """max |value - exact| / max |exact|."""
    value, exact = np.asarray(value, float), np.asarray(exact, float)
    return float(np.max(np.abs(value - exact)) / np.max(np.abs(exact)))


class Linear:
    """A random affine field u(x) = c + a.(x - x0), scalar or with k components."""

    def __init__(self, seed: int, k: int | None = None, x0=(0.0, 0.0, 0.0)):
        rng = np.random.default_rng(seed)
        shape = () if k is None else (k,)
        self.a = rng.uniform(-2.0, 2.0, (3,) + shape)
        self.c = rng.uniform(1.0, 3.0, shape) * rng.choice([-1.0, 1.0], shape)
        self.x0 = np.asarray(x0, float)

    def __call__(self, x):
        return self.c + (np.asarray(x, float) - self.x0) @ self.a

    def box_integral(self, lo, hi) -> np.ndarray:
        """Exact integral over the box [lo, hi] (volume times the value at the centre)."""
        lo, hi = np.asarray(lo, float), np.asarray(hi, float)
        return np.prod(hi - lo) * self(0.5 * (lo + hi))


# -- geometry ----------------------------------------------------------------
def signed_volumes(mesh: Mesh) -> np.ndarray:
    p = mesh.points[mesh.cells]
    return np.einsum("ij,ij->i", p[:, 1] - p[:, 0], np.cross(p[:, 2] - p[:, 0], p[:, 3] - p[:, 0])) / 6.0


def tet_box_overlap(tet: np.ndarray, lo, hi, with_centroid: bool = False):
    """Volume of (tetrahedron with vertices tet (4, 3)) intersected with the box [lo, hi]
    (and, with_centroid, the centroid of the intersection).

    Brute force, independent of the kernels: the intersection is the convex
    polytope of 10 half-spaces; its vertices are the feasible intersection
    points of plane triples, its volume that of their convex hull."""
    from scipy.spatial import ConvexHull, QhullError

    normals, offsets = [], []
    for i in range(4):
        o = [k for k in range(4) if k != i]
        n = np.cross(tet[o[1]] - tet[o[0]], tet[o[2]] - tet[o[0]])
        if n @ (tet[i] - tet[o[0]]) > 0:
            n = -n
        n = n / np.linalg.norm(n)
        normals.append(n)
        offsets.append(n @ tet[o[0]])
    for d in range(3):
        e = np.zeros(3)
        e[d] = 1.0
        normals += [-e, e]
        offsets += [-lo[d], hi[d]]
    normals, offsets = np.array(normals), np.array(offsets)
    verts = []
    for tri in combinations(range(len(normals)), 3):
        A = normals[list(tri)]
        if abs(np.linalg.det(A)) < 1e-12:
            continue
        x = np.linalg.solve(A, offsets[list(tri)])
        if np.all(normals @ x <= offsets + 1e-12):
            verts.append(x)
    empty = (0.0, np.zeros(3)) if with_centroid else 0.0
    if len(verts) < 4:
        return empty
    verts = np.array(verts)
    try:
        hull = ConvexHull(verts)
    except QhullError:  # flat: zero volume
        return empty
    if not with_centroid:
        return float(hull.volume)
    # cone the hull's boundary triangles from an inner point
    inner = verts[hull.vertices].mean(axis=0)
    tri = verts[hull.simplices]  # (f, 3, 3)
    vols = np.abs(np.einsum("ij,ij->i", tri[:, 0] - inner, np.cross(tri[:, 1] - inner, tri[:, 2] - inner))) / 6
    centroids = (tri.sum(axis=1) + inner) / 4
    return float(vols.sum()), vols @ centroids / vols.sum()


# -- quadrature (independent of transfer.quadrature) -------------------------
def gauss01(n: int):
    x, w = np.polynomial.legendre.leggauss(n)
    return 0.5 * (x + 1.0), 0.5 * w


def tet_rule(n: int = 6):
    """Collapsed (Duffy) Gauss rule on the reference tet {x, y, z >= 0, x + y + z <= 1},
    weights summing to 1/6; exact for polynomials of degree <= 2n - 3."""
    g, w = gauss01(n)
    pts, wts = [], []
    for a, wa in zip(g, w):
        for b, wb in zip(g, w):
            for c, wc in zip(g, w):
                x = a
                y = b * (1 - a)
                z = c * (1 - a) * (1 - b)
                pts.append((x, y, z))
                wts.append(wa * wb * wc * (1 - a) ** 2 * (1 - b))
    return np.array(pts), np.array(wts)


def tri_rule(n: int = 6):
    """Collapsed Gauss rule on the reference triangle, weights summing to 1/2."""
    g, w = gauss01(n)
    pts, wts = [], []
    for a, wa in zip(g, w):
        for b, wb in zip(g, w):
            pts.append((a, b * (1 - a)))
            wts.append(wa * wb * (1 - a))
    return np.array(pts), np.array(wts)


def tensor_rule(dim: int, n: int = 4):
    g, w = gauss01(n)
    grids = np.meshgrid(*([g] * dim), indexing="ij")
    wgrids = np.meshgrid(*([w] * dim), indexing="ij")
    return (np.stack([x.ravel() for x in grids], axis=1),
            np.prod(np.stack([x.ravel() for x in wgrids], axis=1), axis=1))


def q1_values(xi: np.ndarray) -> np.ndarray:
    """Bi/trilinear basis on [0, 1]^d in VTK vertex order, (q, 2^d)."""
    x, y = xi[:, 0], xi[:, 1]
    quad = np.stack([(1 - x) * (1 - y), x * (1 - y), x * y, (1 - x) * y], axis=1)
    if xi.shape[1] == 2:
        return quad
    z = xi[:, 2:3]
    return np.concatenate([quad * (1 - z), quad * z], axis=1)


def q1_gradients(xi: np.ndarray) -> np.ndarray:
    """Reference gradients of the Q1 basis, (q, 2^d, d)."""
    x, y = xi[:, 0], xi[:, 1]
    dx = np.stack([-(1 - y), 1 - y, y, -y], axis=1)
    dy = np.stack([-(1 - x), -x, x, 1 - x], axis=1)
    if xi.shape[1] == 2:
        return np.stack([dx, dy], axis=2)
    z = xi[:, 2:3]
    quad = q1_values(xi[:, :2])
    return np.stack([np.concatenate([dx * (1 - z), dx * z], axis=1),
                     np.concatenate([dy * (1 - z), dy * z], axis=1),
                     np.concatenate([-quad, quad], axis=1)], axis=2)


def q1_jacobians(vertices: np.ndarray, xi: np.ndarray) -> np.ndarray:
    """d x / d xi of the Q1 map of one cell (vertices (2^d, 3)) at points xi: (q, 3, d)."""
    return np.einsum("kd,qke->qde", vertices, q1_gradients(xi))


def q1_map(vertices: np.ndarray, xi: np.ndarray) -> np.ndarray:
    return q1_values(xi) @ vertices


def p1_l2_error(mesh: Mesh, values: np.ndarray, f, rule) -> float:
    """True L2 error of the P1 field `values` on tet `mesh` against f, with a
    simplex rule (barycentric points, weights summing to 1)."""
    bary, w = rule
    p = mesh.points[mesh.cells]
    x = np.einsum("qk,mkd->mqd", bary, p)
    vh = np.einsum("qk,mk->mq", bary, values[mesh.cells])
    fx = f(x.reshape(-1, 3)).reshape(x.shape[:2])
    return float(np.sqrt(np.sum(mesh.cell_measures()[:, None] * w[None, :] * (vh - fx) ** 2)))


# -- meshes with very flat cells ----------------------------------------------
def split_tet(cells: list, index: int, points: list, bary) -> list[int]:
    """Split cell `index` of a tet list by a new point at barycentric `bary`:
    four tets, each with one vertex replaced by the new point (orientation kept).
    Returns the indices of the new cells."""
    tet = list(cells[index])
    p = np.asarray(bary) @ np.asarray([points[v] for v in tet])
    points.append(p)
    new = len(points) - 1
    out = []
    for k in range(4):
        t = tet.copy()
        t[k] = new
        if k == 0:
            cells[index] = t
            out.append(index)
        else:
            cells.append(t)
            out.append(len(cells) - 1)
    return out


def q1_inverse(vertices: np.ndarray, x: np.ndarray, iterations: int = 50) -> np.ndarray:
    """Reference coordinates of physical points x (n, 3) in the trilinear cell
    `vertices` (8, 3), by Newton's method (vectorised)."""
    xi = np.full((len(x), 3), 0.5)
    for _ in range(iterations):
        r = q1_map(vertices, xi) - x
        J = q1_jacobians(vertices, xi)
        step = np.linalg.solve(J, r[..., None])[..., 0]
        xi = xi - step
        if np.max(np.abs(step)) < 1e-15:
            break
    return xi


#: the six tetrahedra of a hexahedron around its 0-6 diagonal (as documented for the kernels)
HEX_SIX_TETS = np.array([[0, 1, 2, 6], [0, 2, 3, 6], [0, 3, 7, 6], [0, 7, 4, 6], [0, 4, 5, 6], [0, 5, 1, 6]])


# -- cases -------------------------------------------------------------------
def copy_case(source, directory, replace=None):
    """A copy of the case directory `source` in `directory`/case, with the text
    replacements {old: new} applied to its scene.toml (each `old` must occur)."""
    import shutil
    from pathlib import Path

    case = Path(directory) / "case"
    shutil.copytree(source, case, ignore=shutil.ignore_patterns("results"))
    scene = (case / "scene.toml").read_text()
    for old, new in (replace or {}).items():
        assert old in scene, old
        scene = scene.replace(old, new)
    (case / "scene.toml").write_text(scene)
    return case


#: gmsh present, found without importing it (imported, it breaks VTK's offscreen rendering: hertz_mesh_file)
NEEDS_GMSH = pytest.mark.skipif(importlib.util.find_spec("gmsh") is None, reason="gmsh not installed")


def hertz_mesh_file(path, **params) -> None:
    """transfer.generators.hertz.hertz_mesh(path, **params) in a child process: gmsh loaded in
    the test process makes VTK's later offscreen rendering abort (tests/coupler/test_pictures.py)."""
    import subprocess
    import sys

    code = f"from transfer.generators.hertz import hertz_mesh; hertz_mesh({str(path)!r}, **{params!r})"
    subprocess.run([sys.executable, "-c", code], check=True, capture_output=True)


def write_xdmf(path, points, cells, topology_rows=None, elements=None) -> None:
    """A tet mesh as XDMF + HDF5 in dolfinx's layout (what ``solid_fenicsx.convert`` writes),
    its points and cells in the order given; `topology_rows` / `elements` declare another row
    count or NumberOfElements in the XML (bad input)."""
    import h5py

    path = Path(path)
    with h5py.File(path.with_suffix(".h5"), "w") as f:
        f["/Mesh/mesh/topology"] = np.asarray(cells, np.int64)
        f["/Mesh/mesh/geometry"] = np.asarray(points, np.float64)
    n, m = len(cells), len(points)
    h5 = f"{path.stem}.h5:/Mesh/mesh"
    path.write_text(f"""<?xml version="1.0"?>
<Xdmf Version="3.0"><Domain><Grid Name="mesh" GridType="Uniform">
<Topology TopologyType="Tetrahedron" NumberOfElements="{elements or n}" NodesPerElement="4">
<DataItem Dimensions="{topology_rows or n} 4" NumberType="Int" Format="HDF">{h5}/topology</DataItem>
</Topology><Geometry GeometryType="XYZ">
<DataItem Dimensions="{m} 3" Format="HDF">{h5}/geometry</DataItem>
</Geometry></Grid></Domain></Xdmf>
""")


def run_mpi(script, ranks: int, *args, timeout: float = 300):
    """``mpirun -n ranks python script args`` from the project root (Open MPI allowed to run as
    root, one thread per rank); its stdout's last line parsed as JSON. A failed run fails the test
    with the end of its stderr."""
    import json
    import os
    import shutil
    import subprocess
    import sys

    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1", OMP_NUM_THREADS="1",
               PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    cmd = [shutil.which("mpirun") or "mpirun", "-n", str(ranks), "--oversubscribe", sys.executable, str(script),
           *map(str, args)]
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=timeout, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


def deliver_stopping_signals() -> None:
    """SIGINT and SIGTERM neither ignored nor blocked in the calling process (Python's own
    handler for SIGINT, the default for SIGTERM): the `preexec_fn` of a test that signals a run,
    whatever the test process inherited."""
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT, signal.SIGTERM})
    signal.signal(signal.SIGINT, signal.default_int_handler)  # also where C code ignored it
    signal.signal(signal.SIGTERM, signal.SIG_DFL)


def stopping_signals_not_delivered(pid: str = "self") -> list[str]:
    """SIGINT and SIGTERM if ignored or blocked in process `pid` (its /proc status: what C code
    did too, which Python's signal.getsignal does not see); both are inherited by the processes
    it starts."""
    status = dict(line.split(":\t", 1) for line in Path(f"/proc/{pid}/status").read_text().splitlines()
                  if ":\t" in line)
    found = []
    for name, number in (("SIGINT", 2), ("SIGTERM", 15)):
        for field, how in (("SigIgn", "ignored"), ("SigBlk", "blocked")):
            if int(status.get(field, "0"), 16) & (1 << (number - 1)):
                found.append(f"{name} {how}")
    return found
