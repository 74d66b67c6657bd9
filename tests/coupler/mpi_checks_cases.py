"""Run under ``mpirun -n P`` by test_checks_mpi.py with the share of the rows per rank as argument
("0,3,2": rank 0 holds none, rank 1 three fifths, rank 2 the rest). Each distributed [check] kind
(coupler/checks: hertz, sneddon, uniaxial, expression; exact_transfer has its own) evaluates a known result twice: serially
(every rank the whole result, ``comm=None``) and on the ranks (each rank its rows, shuffled, and
their points, ``comm``). Rank 0 prints, as JSON, per kind the largest relative difference of the
two reports' numbers, whether their keys and texts are equal and whether every rank made the same
report; and the messages of the checks that must fail (serial and distributed)."""

from __future__ import annotations

import json
import sys
from types import SimpleNamespace

import numpy as np
from mpi4py import MPI

from coupler.checks import KINDS, Result
from coupler.errors import CouplerError

comm = MPI.COMM_WORLD
SCENE = SimpleNamespace(path="scene.toml", material={"E": 1.0e9, "nu": 0.3})
rng = np.random.default_rng(5)


def hertz_face() -> tuple[np.ndarray, dict]:
    """A half-sphere's lower cap (R = 1) of scattered vertices, pressed: p = p0 sqrt(1 - r^2/a^2)
    (a = 0.15, p0 = 5e7) with 1 % noise inside the contact, 0 outside; lumped weights; and
    vertices off the slave face."""
    theta, phi = np.sqrt(rng.uniform(0, 0.3**2, 400)), rng.uniform(0, 2 * np.pi, 400)
    cap = np.column_stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), 1 - np.cos(theta)])
    rest = rng.uniform(-1, 1, (100, 3)) + [0, 0, 2]
    points = np.vstack([cap, rest])
    r2 = points[:, 0] ** 2 + points[:, 1] ** 2
    slave = np.r_[np.ones(len(cap)), np.zeros(len(rest))]
    pressure = np.where((r2 < 0.15**2) & (slave > 0), 5e7 * np.sqrt(np.clip(1 - r2 / 0.15**2, 0, 1)), 0.0)
    pressure *= 1 + 0.01 * rng.standard_normal(len(points))
    weight = rng.uniform(1e-4, 3e-4, len(points)) * slave
    return points, {"slave": slave, "contact_pressure": pressure, "mortar_weight": weight,
                    "in_contact": (pressure > 0).astype(float)}


def box_points() -> np.ndarray:
    axes = np.linspace(-0.2, 0.2, 17)
    return np.array(np.meshgrid(axes, axes, np.linspace(-0.1, 0.1, 5), indexing="ij")).reshape(3, -1).T


def displaced(points: np.ndarray, exact) -> dict:
    """`exact(points)` with noise: the field of a solid whose error is known to be non-zero."""
    return {"displacement": exact(points) * (1 + 1e-3 * rng.standard_normal((len(points), 3)))}


def sneddon_u(x):
    s = x[:, 0] ** 2 + x[:, 1] ** 2
    u = np.zeros_like(x)
    u[:, 2] = 0.5 * 2.4e-5 * np.sqrt(np.clip(1 - s / 0.1**2, 0, 1)) + 1e-6 * x[:, 2]
    return u


def uniaxial_u(x):
    return np.column_stack([0.3e-3 * (x[:, 0] + 0.2), 0.3e-3 * (x[:, 1] + 0.2), -1e-3 * (x[:, 2] + 0.1)])


BOX = box_points()
CASES = {
    "hertz": ({"radius": 1.0, "tolerance": 0.1}, *hertz_face()),
    "sneddon": ({"radius": 0.1, "centre": [0.0, 0.0, 0.0], "compared": 0.8, "pressure": 1e6, "tolerance": 0.05},
                BOX, displaced(BOX, sneddon_u)),
    "uniaxial": ({"axis": 2, "pressure": 1e6, "planes": [-0.2, -0.2, -0.1], "tolerance": 1e-6},
                 BOX, displaced(BOX, uniaxial_u)),
    "expression": ({"x": "0.3e-3 * (x + 0.2)", "z": "-1e-3 * (z + 0.1)", "where": "y > 0", "tolerance": 1e-6},
                   BOX, displaced(BOX, uniaxial_u)),
}
FAILING = {  # kind: (settings, points, fields) whose check cannot be made
    "hertz": ({"radius": 1.0, "tolerance": 0.1}, CASES["hertz"][1],
              {**CASES["hertz"][2], "contact_pressure": np.zeros(len(CASES["hertz"][1]))}),
    "sneddon": ({**CASES["sneddon"][0], "centre": [5.0, 0.0, 0.0]}, BOX, CASES["sneddon"][2]),
}


def mine(n: int, shares: list[int]) -> np.ndarray:
    """This rank's rows of n, shuffled (the same permutation on every rank), by `shares`."""
    order = np.random.default_rng(11).permutation(n)
    bounds = np.round(np.cumsum([0] + shares) / sum(shares) * n).astype(int)
    return order[bounds[comm.rank]:bounds[comm.rank + 1]]


def evaluate(kind, settings, points, fields, rows=None):
    """The report of `kind` on the whole result (`rows` None) or on this rank's `rows`; a
    failure's message."""
    if rows is None:
        result = Result({"solid": SimpleNamespace(points=points)}, {"solid": fields})
    else:
        result = Result({}, {}, comm=comm, held={"solid": (points[rows], {k: v[rows] for k, v in fields.items()})})
    try:
        return KINDS[kind].evaluate(settings, SCENE, result)
    except CouplerError as exc:
        return str(exc)


def numbers(report: dict) -> dict:
    return {k: np.asarray(v, float) for k, v in report.items() if not isinstance(v, (str, bool))}


def main(shares: list[int]) -> None:
    found = {}
    for kind, (settings, points, fields) in CASES.items():
        serial, ranks = (evaluate(kind, settings, points, fields, rows)
                         for rows in (None, mine(len(points), shares)))
        a, b = numbers(serial), numbers(ranks)
        found[kind] = {
            "difference": max(float(np.max(np.abs(a[k] - b[k]) / np.maximum(np.abs(a[k]), 1e-300))) for k in a),
            "same_keys": a.keys() == b.keys(),
            "same_text": {k: v for k, v in serial.items() if isinstance(v, (str, bool))}
            == {k: v for k, v in ranks.items() if isinstance(v, (str, bool))},
            "ranks_agree": all(r == ranks for r in comm.allgather(ranks)),
            "passed": serial["passed"], "serial": {k: v for k, v in serial.items() if k != "centre"}}
    failures = {kind: [evaluate(kind, settings, points, fields, rows)
                       for rows in (None, mine(len(points), shares))]
                for kind, (settings, points, fields) in FAILING.items()}
    if comm.rank == 0:
        print(json.dumps({"ranks": comm.size, "checks": found, "failures": failures}, default=float))


if __name__ == "__main__":
    main([int(s) for s in sys.argv[1].split(",")])
