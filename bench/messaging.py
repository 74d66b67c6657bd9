"""Latency and throughput of the participant protocol (docs/protocol.md) on one host.

An ``advance`` round trip between this process (the coupler side) and an ``echo``
stand-in participant started as its own process (:mod:`coupler.standins`): one float64
array out, the same array back, through the whole stack (encode with the NaN check,
zenoh query/reply, decode). Transports: loopback TCP (shared memory disabled on both
sides) and zenoh's shared-memory transport. ``one_way``: the echo replies without
arrays, so the time is one crossing of the array plus a tiny reply.

Goal: a 10^6-double field (8 MB) crosses in under 10 ms one way, a round trip
in under 20 ms.

    python bench/messaging.py [--quick] [-o bench/results/messaging.json]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from coupler.run.launch import Launcher  # noqa: E402
from coupler.run.client import CouplerSession
from coupler.protocol.transport import new_run_id  # noqa: E402
from coupler.protocol.wire import Field  # noqa: E402

SIZES = [8_000, 80_000, 800_000, 8_000_000, 80_000_000, 100_000_000]
GOAL_BYTES = 8_000_000
GOAL_ONE_WAY_MS = 10.0
GOAL_ROUND_TRIP_MS = 20.0


def repeats_for(nbytes: int, quick: bool) -> int:
    if nbytes <= 1_000_000:
        return 10 if quick else 50
    if nbytes <= 10_000_000:
        return 8 if quick else 30
    return 2 if quick else 5


def measure(client, nbytes: int, repeats: int, kind: str, rng) -> dict:
    data = rng.random(nbytes // 8)
    field = {"data": Field("data", data, "1")}
    times = []
    for r in range(repeats + 1):  # the first call warms up (page faults, SHM pool)
        t0 = time.perf_counter()
        out = client.advance(0, r, 0.0, 1.0, field)
        dt = time.perf_counter() - t0
        if r == 0:
            if kind == "round_trip" and not np.array_equal(out["data"].data, data):
                raise RuntimeError(f"{nbytes} bytes: the echoed array differs")
            continue
        times.append(dt)
        del out
    med, best = statistics.median(times), min(times)
    moved = nbytes * (2 if kind == "round_trip" else 1)
    return {
        "kind": kind, "size_bytes": nbytes, "n_doubles": nbytes // 8, "repeats": repeats,
        "min_ms": best * 1e3, "median_ms": med * 1e3,
        "MB_per_s": moved / med / 1e6,
    }


def run_transport(transport: str, sizes, quick: bool, workdir: Path, rng) -> list[dict]:
    shm = transport == "shm"
    rows = []
    with CouplerSession(new_run_id(), shared_memory=shm) as cs, \
            Launcher(cs.run_id, workdir / transport, cs.endpoints) as launcher:
        extra = ["--kind", "echo"] + ([] if shm else ["--no-shm"])
        launcher.start("echo", "coupler.standins", extra_args=extra)
        client = cs.client("echo", timeout=120.0, process_check=lambda: launcher.check("echo"))
        client.wait_alive(30.0)
        for kind in ("round_trip", "one_way"):
            client.configure({"reply": "same" if kind == "round_trip" else "empty"})
            for nbytes in sizes:
                before = client.stats["shm_out"] + client.stats["shm_in"]
                row = measure(client, nbytes, repeats_for(nbytes, quick), kind, rng)
                row["transport"] = transport
                # whether the arrays actually went through shared memory (either way)
                row["shm_used"] = client.stats["shm_out"] + client.stats["shm_in"] > before
                rows.append(row)
                print(f"  {transport:4s} {kind:10s} {nbytes / 1e6:8.3f} MB  min {row['min_ms']:9.3f} ms  "
                      f"median {row['median_ms']:9.3f} ms  {row['MB_per_s']:9.1f} MB/s", flush=True)
        client.finish()
        launcher.wait("echo", 10.0)
    return rows


def shm_available() -> bool:
    try:
        import zenoh.shm  # noqa: F401
    except ImportError:
        return False
    return os.path.isdir("/dev/shm") and os.access("/dev/shm", os.W_OK)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--quick", action="store_true", help="fewer repeats, no 100 MB array")
    p.add_argument("-o", "--output", default=str(ROOT / "bench" / "results" / "messaging.json"))
    p.add_argument("--transports", default="tcp,shm", help="comma-separated: tcp, shm (default both)")
    p.add_argument("--sizes", help="comma-separated array sizes in bytes (default 8 kB ... 100 MB)")
    args = p.parse_args(argv)

    sizes = SIZES[:-1] if args.quick else SIZES
    if args.sizes:
        sizes = sorted({int(float(s)) // 8 * 8 for s in args.sizes.split(",")} | {GOAL_BYTES})
    transports = [t for t in args.transports.split(",") if t]
    if "shm" in transports and not shm_available():
        print("shared memory unavailable: skipping the shm transport")
        transports.remove("shm")
    rng = np.random.default_rng(0)
    rows = []
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="vc-bench-msg-") as tmp:
        for transport in transports:
            print(f"{transport}: echo participant over {'shared memory' if transport == 'shm' else 'loopback TCP'}")
            rows += run_transport(transport, sizes, args.quick, Path(tmp), rng)

    goal = {}
    for transport in transports:
        rt = next(r for r in rows if r["transport"] == transport and r["kind"] == "round_trip" and r["size_bytes"] == GOAL_BYTES)
        ow = next(r for r in rows if r["transport"] == transport and r["kind"] == "one_way" and r["size_bytes"] == GOAL_BYTES)
        ok = ow["median_ms"] < GOAL_ONE_WAY_MS and rt["median_ms"] < GOAL_ROUND_TRIP_MS
        goal[transport] = {"one_way_median_ms": ow["median_ms"], "round_trip_median_ms": rt["median_ms"],
                           "status": "PASS" if ok else "MISS"}
    best = "PASS" if any(g["status"] == "PASS" for g in goal.values()) else "MISS"

    print()
    print(f"{'transport':9s} {'kind':10s} {'size':>10s} {'min ms':>9s} {'median ms':>10s} {'MB/s':>9s}")
    for r in rows:
        print(f"{r['transport']:9s} {r['kind']:10s} {r['size_bytes'] / 1e6:8.3f}MB {r['min_ms']:9.3f} "
              f"{r['median_ms']:10.3f} {r['MB_per_s']:9.1f}")
    print()
    for t, g in goal.items():
        print(f"goal 8 MB ({GOAL_BYTES // 8} doubles) one way < {GOAL_ONE_WAY_MS:g} ms, round trip < "
              f"{GOAL_ROUND_TRIP_MS:g} ms, {t}: one way {g['one_way_median_ms']:.2f} ms, round trip "
              f"{g['round_trip_median_ms']:.2f} ms: {g['status']}")
    print(f"goal (best transport): {best}")

    import zenoh

    result = {
        "benchmark": "messaging",
        "quick": args.quick,
        "meta": {
            "host": platform.node(), "cpus": os.cpu_count(), "python": platform.python_version(),
            "numpy": np.__version__, "zenoh": getattr(zenoh, "__version__", "1.x"),
            "seconds": time.perf_counter() - t0,
        },
        "transports": transports,
        "results": rows,
        "goal": {"size_bytes": GOAL_BYTES, "one_way_ms": GOAL_ONE_WAY_MS, "round_trip_ms": GOAL_ROUND_TRIP_MS,
                 "per_transport": goal, "status": best},
    }
    out = Path(args.output)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=2) + "\n")
    print(f"saved {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
