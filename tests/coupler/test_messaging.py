"""Messaging integration tests: real participant processes (the stand-ins of
coupler/standins.py) started through the Launcher, talking real zenoh to this process.

Every test has its own run id and its own OS-chosen port, so several runs of this file
can go on in parallel on one machine.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import signal
import threading
import time
import uuid
from pathlib import Path

import numpy as np
import pytest

from coupler.protocol.errors import ParticipantDied, ParticipantError, ParticipantStopped, ParticipantTimeout
from transfer import FieldError
from coupler.run.launch import Launcher, descendants
from coupler.run.client import CouplerSession, ParticipantClient
from coupler.protocol.wire import Field
from transfer.generate import box_tetrahedra

BOX = {"box": {"lower": [0, 0, 0], "upper": [1, 2, 3], "shape": [3, 4, 5]}, "stiffness": 4.0}
N_BOX = 4 * 5 * 6


class Run:
    def __init__(self, tmp_path: Path):
        self.dir = tmp_path
        self.coupler = CouplerSession(f"test-{uuid.uuid4().hex[:12]}")
        self.launcher = Launcher(self.coupler.run_id, tmp_path, self.coupler.endpoints)

    def start(self, name: str, kind: str, config: dict | None = None, timeout: float = 20.0,
              ranks: int = 1, extra=()) -> ParticipantClient:
        self.launcher.start(name, "coupler.standins", ranks=ranks, extra_args=["--kind", kind, *extra])
        client = self.coupler.client(name, timeout, process_check=lambda: self.launcher.check(name))
        client.wait_alive(30.0)
        if config is not None:
            client.configure(config)
        return client

    def log(self, name: str) -> str:
        return (self.dir / "logs" / f"{name}.log").read_text()

    def close(self):
        self.launcher.stop_all(timeout=3.0)
        self.coupler.close()


@pytest.fixture
def run(tmp_path):
    r = Run(tmp_path)
    try:
        yield r
    finally:
        r.close()


def group_members(pgid: int) -> list[int]:
    """Live processes of process group ``pgid`` (from /proc, zombies excluded)."""
    out = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            stat = Path(f"/proc/{entry}/stat").read_text()
        except OSError:
            continue
        fields = stat[stat.rindex(")") + 2:].split()
        if int(fields[2]) == pgid and fields[0] != "Z":
            out.append(int(entry))
    return out


def is_running(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    # a zombie still answers kill(pid, 0): look at its state
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


def traction(n, seed=0):
    return np.random.default_rng(seed).random((n, 3)) * 1e3


def test_spring_solid_speaks_the_protocol(run):
    solid = run.start("solid", "spring_solid")
    info = solid.announce()
    assert info["kind"] == "spring_solid" and info["name"] == "solid" and info["ranks"] == 1
    assert info["accepts"] == ["traction", "pressure"] and info["provides"] == ["displacement", "velocity"]
    assert info["pid"] == run.launcher.processes["solid"].pid

    solid.configure(BOX)
    header, geo = solid.geometry()
    assert header["cell_type"] == "tetra"
    points = geo["points"].data
    assert points.shape == (N_BOX, 3) and geo["points"].units == "m"
    assert points.min(axis=0).tolist() == [0, 0, 0] and points.max(axis=0).tolist() == [1, 2, 3]
    cells = geo["cells"].data
    assert cells.dtype == np.int64 and cells.shape[1] == 4 and cells.max() == N_BOX - 1

    f = traction(N_BOX)
    solid.save_state(0)
    out = solid.advance(0, 0, 0.0, 0.5, {"traction": Field("traction", f, "Pa")})
    np.testing.assert_allclose(out["displacement"].data, f / 4.0, rtol=1e-15)
    np.testing.assert_allclose(out["velocity"].data, f / 4.0 / 0.5, rtol=1e-15)
    assert out["displacement"].units == "m" and out["velocity"].units == "m/s"
    solid.restore_state(0)

    proc = run.launcher.processes["solid"]
    solid.finish()
    assert run.launcher.wait("solid", 10.0) == 0
    assert solid.stats["calls"] == 7
    assert run.launcher.poll()[0].returncode == 0
    assert not is_running(proc.pid)
    assert "finished" in run.log("solid")


def test_restore_gives_identical_fields(run):
    solid = run.start("solid", "spring_solid", BOX)
    dt = 0.1
    solid.save_state(0)
    solid.advance(0, 0, 0.0, dt, {"traction": traction(N_BOX, 1)})
    solid.save_state(1)
    first = solid.advance(1, 0, dt, dt, {"traction": traction(N_BOX, 2)})
    first = {k: f.data.copy() for k, f in first.items()}
    # another iteration of window 1 with other inputs changes the state ...
    solid.restore_state(1)
    other = solid.advance(1, 1, dt, dt, {"traction": traction(N_BOX, 3)})
    assert not np.allclose(other["velocity"].data, first["velocity"])
    # ... and repeating window 1 after restore_state gives the same fields again
    solid.restore_state(1)
    again = solid.advance(1, 2, dt, dt, {"traction": traction(N_BOX, 2)})
    for name in ("displacement", "velocity"):
        np.testing.assert_allclose(again[name].data, first[name], rtol=0, atol=1e-12)
        assert np.array_equal(again[name].data, first[name])
    with pytest.raises(ParticipantError, match="no state saved for window 7"):
        solid.restore_state(7)


def test_replay_fluid_serves_prescribed_fields(run, tmp_path):
    grid = {"origin": [0, 0, 0], "spacing": [0.5, 0.5, 0.5], "shape": [2, 3, 4]}
    n = 3 * 4 * 5
    fluid = run.start("fluid", "replay_fluid", {"grid": grid, "pressure": 1e6, "velocity": [1, 2, 3]})
    header, arrays = fluid.geometry()
    assert header["grid"] == {"origin": [0.0, 0.0, 0.0], "spacing": [0.5, 0.5, 0.5], "shape": [2, 3, 4]}
    assert arrays == {}
    out = fluid.advance(0, 0, 0.0, 1.0, {"solid_velocity": np.zeros((n, 3))})
    assert out["pressure"].data.shape == (n,) and np.all(out["pressure"].data == 1e6)
    assert out["pressure"].units == "Pa"
    assert np.all(out["velocity"].data == [1, 2, 3])
    # replayed per window from an .npz file, on cells
    p = np.arange(3 * 24, dtype=float).reshape(3, 24)
    np.savez(tmp_path / "replay.npz", pressure=p)
    fluid.configure({"grid": grid, "location": "cells", "npz": str(tmp_path / "replay.npz")})
    for window in (0, 1, 2, 5):
        got = fluid.advance(window, 0, window * 1.0, 1.0, {})
        np.testing.assert_array_equal(got["pressure"].data, p[min(window, 2)])
    with pytest.raises(ParticipantError, match="grid"):
        fluid.configure({})


def test_100mb_field_arrives_intact(run):
    echo = run.start("echo", "echo", {})
    data = np.random.default_rng(5).random(100_000_000 // 8)
    digest = hashlib.sha256(data.tobytes()).hexdigest()
    t0 = time.perf_counter()
    out = echo.advance(0, 0, 0.0, 1.0, {"big": Field("big", data, "Pa")}, timeout=60)
    elapsed = time.perf_counter() - t0
    got = out["big"].data
    assert got.shape == data.shape and got.dtype == data.dtype and out["big"].units == "Pa"
    assert hashlib.sha256(got.tobytes()).hexdigest() == digest
    assert echo.stats["bytes_out"] > 100_000_000 and echo.stats["bytes_in"] > 100_000_000
    assert elapsed < 30


def test_100mb_field_over_tcp_without_shared_memory(tmp_path):
    coupler = CouplerSession(f"test-{uuid.uuid4().hex[:12]}", shared_memory=False)
    with coupler, Launcher(coupler.run_id, tmp_path, coupler.endpoints) as launcher:
        launcher.start("echo", "coupler.standins", extra_args=["--kind", "echo", "--no-shm"])
        echo = coupler.client("echo", 60.0, process_check=lambda: launcher.check("echo"))
        echo.wait_alive(30)
        data = np.arange(100_000_000 // 8, dtype=np.float64)
        out = echo.advance(0, 0, 0.0, 1.0, {"big": data})
        assert hashlib.sha256(out["big"].data.tobytes()).digest() == hashlib.sha256(data.tobytes()).digest()
        assert echo.stats["shm_in"] == 0 and echo.stats["shm_out"] == 0


class _LateEvent(threading.Event):
    """An event whose first look after it is set still says unset: a reply that lands between two
    looks of the loop that waits for it."""

    def __init__(self):
        super().__init__()
        self.late = True

    def is_set(self):
        if super().is_set() and self.late:
            self.late = False
            return False
        return super().is_set()


def test_a_reply_landing_between_two_looks_is_taken(run, monkeypatch):
    """The wait for the replies looked at the calls twice (all done? then which one is not?): a
    reply that landed between the two looks ended a run with StopIteration (standin_flow, after 90
    steps, twice in a row under a /proc sampler)."""
    import coupler.run.client as client_module

    class LateCall(client_module._Call):
        def __init__(self, query_key):
            super().__init__(query_key)
            self.done = _LateEvent()

    echo = run.start("echo", "echo")
    monkeypatch.setattr(client_module, "_Call", LateCall)
    out = echo.advance(0, 0, 0.0, 1.0, {"x": np.arange(3.0)})
    assert np.array_equal(out["x"].data, np.arange(3.0))


def test_sigkill_during_a_call_is_detected(run):
    echo = run.start("victim", "echo", {"delay": 30})
    pid = run.launcher.processes["victim"].pid
    threading.Timer(0.5, os.kill, (pid, signal.SIGKILL)).start()
    t0 = time.monotonic()
    with pytest.raises(ParticipantDied) as info:
        echo.advance(0, 0, 0.0, 1.0, {"x": np.ones(3)}, timeout=60)
    assert time.monotonic() - t0 < 5
    assert info.value.name == "victim"
    assert "'victim'" in str(info.value)


def test_sigkill_while_idle_is_detected(run):
    solid = run.start("solid", "spring_solid", BOX)
    os.kill(run.launcher.processes["solid"].pid, signal.SIGKILL)
    t0 = time.monotonic()
    while solid.alive and time.monotonic() - t0 < 5:
        time.sleep(0.02)
    assert not solid.alive, "liveliness token still there 5 s after SIGKILL"
    t1 = time.monotonic()
    with pytest.raises(ParticipantDied, match="solid.*SIGKILL"):
        solid.advance(0, 0, 0.0, 1.0, {"traction": traction(N_BOX)})
    assert time.monotonic() - t1 < 1
    exited = run.launcher.poll()
    assert [(e.name, e.returncode) for e in exited] == [("solid", -signal.SIGKILL)]


def test_handler_error_becomes_participant_error(run):
    solid = run.start("solid", "spring_solid", BOX)
    with pytest.raises(ParticipantError) as info:
        solid.advance(0, 0, 0.0, 1.0, {"traction": np.ones((2, 3))})
    assert info.value.name == "solid"
    assert "traction has shape (2, 3), expected (120, 3)" in info.value.message
    assert "ValueError" in info.value.message
    # the participant logged it and goes on serving
    assert "advance failed" in run.log("solid")
    out = solid.advance(0, 0, 0.0, 1.0, {"traction": traction(N_BOX)})
    assert out["displacement"].data.shape == (N_BOX, 3)
    with pytest.raises(ParticipantError, match="boom"):
        run.start("echo", "echo", {"fail": "boom"}).advance(0, 0, 0.0, 1.0, {})


def test_nan_input_is_refused_before_sending(run):
    solid = run.start("solid", "spring_solid", BOX)
    bad = traction(N_BOX)
    bad[7, 2] = np.nan
    with pytest.raises(FieldError, match="traction"):
        solid.advance(0, 0, 0.0, 1.0, {"traction": bad})
    assert solid.stats["calls"] == 1  # only configure went out


def test_timeout(run):
    slow = run.start("slow", "echo", {"delay": 5})
    t0 = time.monotonic()
    with pytest.raises(ParticipantTimeout) as info:
        slow.advance(0, 0, 0.0, 1.0, {"x": np.ones(2)}, timeout=0.5)
    assert 0.5 <= time.monotonic() - t0 < 3
    assert (info.value.name, info.value.verb, info.value.seconds) == ("slow", "advance", 0.5)
    assert "did not answer 'advance' within 0.5 s ([messaging] timeout = 0.5: raise it" in str(info.value)


def test_process_that_cannot_start_is_reported(run):
    run.launcher.start("broken", "coupler.standins", extra_args=["--kind", "no_such_kind"])
    client = run.coupler.client("broken", 20.0, process_check=lambda: run.launcher.check("broken"))
    t0 = time.monotonic()
    with pytest.raises(ParticipantDied, match="(?s)exited with code 2.*unknown kind"):
        client.wait_alive(20)
    assert time.monotonic() - t0 < 10


def test_participant_that_cannot_connect_exits_with_a_message(tmp_path):
    from coupler.protocol.transport import free_tcp_port

    launcher = Launcher(f"test-{uuid.uuid4().hex[:12]}", tmp_path, [f"tcp/127.0.0.1:{free_tcp_port()}"])
    with launcher:
        launcher.start("lost", "coupler.standins", extra_args=["--kind", "echo", "--connect-timeout", "1"])
        assert launcher.wait("lost", 15) == 1
    log = (tmp_path / "logs" / "lost.log").read_text()
    assert "participant 'lost': error:" in log and "cannot reach tcp/127.0.0.1:" in log


def test_participant_exits_when_the_coupler_goes(run):
    run.start("solid", "spring_solid", BOX)
    run.coupler.close()
    assert run.launcher.wait("solid", 15) == 1
    assert "coupler" in run.log("solid")


def test_sigterm_ends_a_participant_promptly(run):
    run.start("solid", "spring_solid", BOX)
    proc = run.launcher.processes["solid"]
    t0 = time.monotonic()
    run.launcher.stop_all(timeout=5)
    assert time.monotonic() - t0 < 3
    assert proc.returncode == 128 + signal.SIGTERM
    assert "SIGTERM received" in run.log("solid")


@pytest.mark.skipif(shutil.which("mpirun") is None, reason="no mpirun")
def test_mpi_participant_answers_per_rank(run):
    """Each rank of a 2-rank spring_solid answers its own points (r, r + 2, ...; docs/protocol.md,
    "Parts"): the client joins them into the serial arrays, exactly, and sends each rank its rows."""
    solid = run.start("solid", "spring_solid", BOX, ranks=2, timeout=60)
    assert solid.announce()["ranks"] == 2 and solid.parts == 2
    _, geo = solid.geometry()
    serial = box_tetrahedra(BOX["box"]["shape"], BOX["box"]["lower"], BOX["box"]["upper"])
    assert np.array_equal(geo["points"].data, serial.points) and np.array_equal(geo["cells"].data, serial.cells)
    assert sorted(geo) == ["cells", "points"]  # the ids placed the rows and are gone
    assert [len(ids) for ids in solid.layout.ids] == [N_BOX // 2, N_BOX // 2]
    out = solid.advance(0, 0, 0.0, 1.0, {"traction": traction(N_BOX)})
    assert np.array_equal(out["displacement"].data, traction(N_BOX) / 4.0)
    # rank 1's reply travelled on its own key, half the field
    assert solid.stats["bytes_in"] > N_BOX * 3 * 8 * 2
    solid.finish()
    assert run.launcher.wait("solid", 30) == 0


def test_launcher_stops_every_process_on_an_exception(tmp_path):
    coupler = CouplerSession(f"test-{uuid.uuid4().hex[:12]}")
    groups = []
    with coupler, pytest.raises(RuntimeError, match="coupler failed"):
        with Launcher(coupler.run_id, tmp_path, coupler.endpoints) as launcher:
            launcher.start("a", "coupler.standins", extra_args=["--kind", "echo"])
            ranks = 2 if shutil.which("mpirun") else 1
            launcher.start("b", "coupler.standins", ranks=ranks, extra_args=["--kind", "spring_solid"])
            for name in ("a", "b"):
                coupler.client(name, 60, process_check=lambda n=name: launcher.check(n)).wait_alive(60)
            groups = [p.pid for p in launcher.processes.values()]
            pids = groups + [d for g in groups for d in descendants(g)]
            assert all(group_members(g) for g in groups)
            if ranks == 2:  # mpirun and its two python ranks (in process groups of their own)
                assert len(descendants(groups[1])) >= 2
            raise RuntimeError("coupler failed")
    for pid in pids:
        assert not is_running(pid), f"leftover process {pid}"
    for pgid in groups:
        assert group_members(pgid) == [], f"leftover processes in group {pgid}"


def test_nan_in_a_participant_output_is_an_error_naming_the_field(run, tmp_path):
    p = np.zeros((2, 24))
    p[1, 5] = np.nan
    np.savez(tmp_path / "nan.npz", pressure=p)
    grid = {"origin": [0, 0, 0], "spacing": [1, 1, 1], "shape": [2, 3, 4]}
    fluid = run.start("fluid", "replay_fluid", {"grid": grid, "location": "cells", "npz": str(tmp_path / "nan.npz")})
    assert np.all(fluid.advance(0, 0, 0.0, 1.0, {})["pressure"].data == 0)
    with pytest.raises(ParticipantError, match="FieldError: field 'pressure': 1 non-finite"):
        fluid.advance(1, 0, 1.0, 1.0, {})


def test_a_call_that_waits_says_so_naming_the_participant_and_the_request(run):
    said = []
    run.launcher.start("slow", "coupler.standins", extra_args=["--kind", "echo"])
    slow = run.coupler.client("slow", 20.0, waiting=said.append, note_every=0.5)
    slow.wait_alive(30.0)
    slow.configure({"delay": 1.8})
    slow.advance(3, 1, 0.0, 1.0, {"x": np.ones(2)})
    assert len(said) >= 2, said
    assert said[0] == ("waiting for participant 'slow': no answer to 'advance' (window 3, iteration 1) for 1 s; "
                       "no progress reported (the wait ends at 20 s without progress: [messaging] timeout)")


def test_the_timeout_follows_the_work(run):
    """A solve 6.5 times longer than the timeout that reports progress every 0.2 s is waited for
    (it was cut off at the timeout; then zenoh's own limit on the query, the timeout + 5 s, ended
    it as an error reply); the same solve silent is timed out (test_timeout)."""
    said = []
    run.launcher.start("busy", "coupler.standins", extra_args=["--kind", "echo"])
    busy = run.coupler.client("busy", 1.0, waiting=said.append, note_every=1.0)
    busy.wait_alive(30.0)
    busy.configure({"delay": 6.5, "progress": 0.2})
    t0 = time.monotonic()
    out = busy.advance(0, 2, 0.0, 1.0, {"x": np.ones(2)})
    assert time.monotonic() - t0 >= 6.5 and np.array_equal(out["x"].data, np.ones(2))
    assert len(said) >= 2 and all("(window 0, iteration 2)" in line and "; working, " in line and
                                  "s slept (the wait ends 1 s after its last progress" in line for line in said), said
    busy.configure({"delay": 3.0, "progress": 0.0})
    with pytest.raises(ParticipantTimeout, match=r"did not answer 'advance' within 1 s \(\[messaging\] timeout = 1"):
        busy.advance(1, 0, 0.0, 1.0, {"x": np.ones(2)})


def test_a_stopped_participant_is_reported_as_stopped_not_died(run):
    run.launcher.start("paused", "coupler.standins", extra_args=["--kind", "echo"])
    said = []
    paused = run.coupler.client("paused", 120.0, process_check=lambda: run.launcher.check("paused"),
                                process_stopped=lambda: run.launcher.stopped("paused"), waiting=said.append,
                                note_every=5.0)
    paused.wait_alive(30.0)
    paused.configure({"delay": 1.0})
    pid = run.launcher.processes["paused"].pid
    threading.Timer(0.3, os.kill, (pid, signal.SIGSTOP)).start()
    try:
        with pytest.raises(ParticipantStopped) as info:
            paused.advance(0, 0, 0.0, 1.0, {"x": np.ones(2)})
    finally:
        os.kill(pid, signal.SIGCONT)
    assert str(info.value) == (f"participant 'paused' is stopped: process {pid} is stopped (state T: SIGSTOP or "
                               f"SIGTSTP); kill -CONT {pid} resumes it")
    assert said and f"it is stopped: process {pid} is stopped" in said[0]
