"""Run under ``mpirun -n P`` by test_acceleration_mpi.py with the rows per rank as argument
("0,13,17": rank 0 holds none, rank 1 the first 13, rank 2 the last 17). Every coupled
problem of :data:`PROBLEMS` runs serially (``comm=None``, every rank the whole vector) and
distributed (each rank its rows); rank 0 prints, as JSON, the largest differences of the
iterates, residuals and factors, whether the counts (iterations, columns used and filtered)
are equal, and whether every rank holds bit for bit the same scalars.
"""

from __future__ import annotations

import json
import sys
import warnings

import numpy as np
from mpi4py import MPI

from coupler.coupling.acceleration import filtered_qr, make_accelerator
from coupler.coupling.loop import NonFiniteInterface, run_coupled

comm = MPI.COMM_WORLD
N = 30  # 10 nodes x 3 components
NODES = 10
TOLERANCE = 1e-6


def operator(seed: int = 7) -> tuple[np.ndarray, np.ndarray]:
    """A symmetric A with eigenvalues in [-1.3, 0.3] (the plain iteration diverges, like a
    strong added mass) and a load b."""
    rng = np.random.default_rng(seed)
    basis = np.linalg.qr(rng.normal(size=(N, N)))[0]
    return basis @ np.diag(np.linspace(-1.3, 0.3, N)) @ basis.T, rng.normal(size=N)


A, B = operator()
MASS = np.repeat(np.linspace(0.2, 3.0, NODES) ** 2, 3)  # lumped mass per node, on its 3 components


def linear(window, x):
    return A @ x + (1.0 + window.index) * B


def nonlinear(window, x):
    return 0.5 * A @ x + 0.3 * np.tanh(x) * np.roll(x, 1) + np.cos(window.index + np.arange(N)) * B


#: name -> (map, accelerator, its options, weighted, extrapolation); each chosen so that the serial
#: run with its rows permuted (the same arithmetic summed in another order) stays within 1e-13 of
#: it: IQN-ILS with QR2 filtering columns out, and any of them to a tighter tolerance, amplify
#: the rounding of a reordered sum to 1e-11..1e-8 in the iterates (QR2's filtering is compared
#: in `qr_case` instead)
PROBLEMS = {
    "constant, linear": (linear, "constant", {"relaxation": 0.5}, True, 0),
    "aitken capped, nonlinear": (nonlinear, "aitken", {"relaxation": 0.4, "omega_max": 0.8}, False, 1),
    "iqn-ils QR2, linear": (linear, "iqn-ils", {"filter": "QR2", "filter_eps": 1e-2}, True, 0),
    "iqn-ils QR2 reuse, linear": (linear, "iqn-ils", {"filter": "QR2", "filter_eps": 1e-1, "reuse": 2}, True, 1),
    "iqn-ils QR1 reuse, linear": (linear, "iqn-ils", {"filter": "QR1", "filter_eps": 1e-10, "reuse": 2}, True, 0),
    "iqn-ils QR1 reuse, nonlinear": (nonlinear, "iqn-ils", {"filter": "QR1", "filter_eps": 1e-3, "reuse": 2},
                                     True, 1),
    "iqn-ils QR1-absolute, nonlinear": (nonlinear, "iqn-ils", {"filter": "QR1-absolute", "filter_eps": 1e-3,
                                                               "reuse": 1}, False, 0),
    "iqn-ils 5 columns, nonlinear": (nonlinear, "iqn-ils", {"max_columns": 5, "filter": "QR1", "filter_eps": 1e-3},
                                     True, 0),
}


def split(counts):
    starts = np.concatenate([[0], np.cumsum(counts)])
    return slice(int(starts[comm.rank]), int(starts[comm.rank + 1]))


def whole(local: np.ndarray, counts) -> np.ndarray:
    """The whole vector from every rank's rows (the test's stand-in for the participants)."""
    out = np.empty(N)
    comm.Allgatherv(np.ascontiguousarray(local), [out, list(counts)])
    return out


def run(problem: str, counts=None) -> dict:
    """One problem, serially (`counts` None) or on this rank's rows; the log of every
    iteration (residuals, factors, columns) and the accepted vectors (whole)."""
    H, kind, options, weighted, extrapolation = PROBLEMS[problem]
    rows = slice(None) if counts is None else split(counts)
    c = None if counts is None else comm
    acc = make_accelerator(kind, **options, comm=c)
    log = {"x": [], "omega": [], "used": [], "filtered": [], "columns": []}
    update = acc.update

    def logged(x, Hx):
        out = update(x, Hx)
        log["x"].append(out if counts is None else whole(out, counts))
        log["omega"].append(getattr(acc, "omega", np.nan))
        for key, attr in (("used", "used_columns"), ("filtered", "filtered_columns"), ("columns", "columns")):
            log[key].append(getattr(acc, attr, -1))
        return out

    acc.update = logged
    accepted = []

    def iterate(window, k, x):
        full = x if counts is None else whole(x, counts)
        return H(window, full)[rows]

    def on_converged(window, x, step):
        accepted.append(x if counts is None else whole(x, counts))

    result = run_coupled(4, 0.1, iterate, np.zeros(N)[rows], acc, tolerance=TOLERANCE, max_iterations=80,
                         on_converged=on_converged, weights=MASS[rows] if weighted else None,
                         extrapolation=extrapolation, comm=c)
    return {"x": np.concatenate(accepted), "iterates": np.concatenate(log["x"]), "residuals": np.concatenate(result.residual_histories),
            "abs_residuals": np.concatenate([s.abs_residuals for s in result.steps]),
            "iterations": result.iterations, "omega": np.array(log["omega"]),
            "counts": [log["used"], log["filtered"], log["columns"]], "info": result.accelerator}


def relative(a, b) -> float:
    a, b = np.asarray(a, float), np.asarray(b, float)
    if a.shape != b.shape:
        return float("inf")
    scale = max(1.0, float(np.max(np.abs(b)))) if b.size else 1.0
    return float(np.max(np.abs(a - b), initial=0.0) / scale)


def same_on_every_rank(values) -> bool:
    """The scalars every rank derived (residuals, factors, counts) are bit for bit rank 0's."""
    gathered = comm.allgather(values)
    return all(repr(g) == repr(gathered[0]) for g in gathered)


#: Aitken's factor from residuals at least this small (relative) is compared apart: their
#: differences r_k - r_{k-1} cancel all but ~ -log10(residual) digits, so a rounding of x
#: changes the factor by about 1e-16 / residual (also between two serial runs in another order)
EARLY = 1e-4


def _updated(run: dict) -> np.ndarray:
    """The relative residual of each iteration followed by an update (not the last of a window)."""
    out, start = [], 0
    for its in run["iterations"]:
        out.extend(run["residuals"][start:start + its - 1])
        start += its
    return np.array(out)


def compare(problem: str, counts) -> dict:
    serial, distributed = run(problem), run(problem, counts)
    scalars = [distributed[k].tolist() for k in ("residuals", "abs_residuals", "omega")]
    omega = np.abs(np.nan_to_num(distributed["omega"] - serial["omega"]))
    early = _updated(serial) >= EARLY
    return {"x": relative(distributed["x"], serial["x"]),
            "iterates": relative(distributed["iterates"], serial["iterates"]),
            "residuals": relative(distributed["residuals"], serial["residuals"]),
            "abs_residuals": relative(distributed["abs_residuals"], serial["abs_residuals"]),
            "omega": float(np.max(omega, initial=0.0)), "omega_early": float(np.max(omega[early], initial=0.0)),
            "iterations": [serial["iterations"], distributed["iterations"]],
            "counts_equal": serial["counts"] == distributed["counts"],
            "info_equal": serial["info"] == distributed["info"],
            "filtered": serial["info"].get("filtered_columns", 0),
            "ranks_agree": same_on_every_rank([scalars, distributed["counts"], distributed["iterations"]])}


def qr_case(kind: str, weighted: bool, counts) -> dict:
    """filtered_qr of columns with two nearly dependent ones and a zero one, serial and distributed."""
    rng = np.random.default_rng(3)
    V = rng.normal(size=(N, 8))
    V[:, 3] = V[:, 1] - 2 * V[:, 2] + 1e-9 * rng.normal(size=N)
    V[:, 5] = 0.0
    V[:, 6] = 3 * V[:, 0] + 1e-2 * rng.normal(size=N)
    if kind == "none":  # no filter: Q's column of a nearly dependent one is rounding noise
        V = V[:, [0, 1, 2, 4, 5, 7]]
    w = MASS if weighted else None
    rows = split(counts)
    serial = filtered_qr(V, kind, 1e-3, w)
    part = filtered_qr(V[rows], kind, 1e-3, None if w is None else w[rows], comm)
    Q = np.empty((N, part.Q.shape[1]))
    for j in range(Q.shape[1]):
        Q[:, j] = whole(part.Q[:, j], counts)
    signs = np.sign(np.diag(serial.R)) * np.sign(np.diag(part.R)) if serial.kept == part.kept else 1.0
    return {"kept": [serial.kept, part.kept], "removed": [serial.removed, part.removed],
            "R": relative(signs[:, None] * part.R if serial.kept == part.kept else part.R, serial.R),
            "Q": relative(Q * signs, serial.Q), "ranks_agree": same_on_every_rank([part.R.tolist(), part.kept])}


def nan_message(counts) -> list[str]:
    """The NonFiniteInterface message, serial and distributed, when H(x) has NaN at dofs 17 and 20."""
    messages = []
    for c in (None, counts):
        rows = slice(None) if c is None else split(c)

        def iterate(window, k, x):
            out = np.ones(N)
            out[[17, 20]] = np.nan
            return out[rows]

        try:
            run_coupled(1, 0.1, iterate, np.zeros(N)[rows], comm=None if c is None else comm)
        except NonFiniteInterface as exc:
            messages.append(str(exc))
    return messages


def main():
    counts = [int(c) for c in sys.argv[1].split(",")]
    assert len(counts) == comm.size and sum(counts) == N, (counts, comm.size, N)
    warnings.simplefilter("error")
    out = {"ranks": comm.size, "counts": counts,
           "problems": {p: compare(p, counts) for p in PROBLEMS},
           "qr": {f"{k} {'weighted' if w else 'euclidean'}": qr_case(k, w, counts)
                  for k in ("QR1", "QR1-absolute", "QR2", "none") for w in (False, True)},
           "nan": nan_message(counts)}
    if comm.rank == 0:
        print(json.dumps(out))


if __name__ == "__main__":
    main()
