"""The coupler on P ranks seen from its front process (coupler/run/job.py): a rank or mpirun
killed (SIGKILL: no word of its own) ends the run with status failed naming it, one error line and
exit 4, nothing of the job left running; ranks the cores or the memory cannot hold are refused
before any process starts, naming [coupling] ranks."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from coupler.run.job import _rank
from coupler.run.launch import alive, descendants
from vc_helpers import CASES, copy_case

needs_mpi = pytest.mark.skipif(shutil.which("mpirun") is None, reason="mpirun not installed")


def steps_done(out) -> int:
    try:
        return len(json.loads((out / "summary.json").read_text())["steps"])
    except (OSError, ValueError, KeyError):
        return 0


def start_on_two_ranks(tmp_path, steps: int = 400):
    """standin_flow with the coupler on 2 ranks, started and run to its first step; (the front
    process, its output directory, {rank: pid}, every process under the front)."""
    case = copy_case(CASES / "standin_flow", tmp_path / "case",
                     {"steps = 4": f"steps = {steps}", "max_iterations = 30": "max_iterations = 30\nranks = 2"})
    out = tmp_path / "out"
    (tmp_path / "tmp").mkdir()
    proc = subprocess.Popen([sys.executable, "-m", "coupler.cli", "run", str(case), "--output", str(out)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                            env=dict(os.environ, TMPDIR=str(tmp_path / "tmp")))
    t0 = time.monotonic()
    while steps_done(out) < 1:
        assert proc.poll() is None, proc.communicate()[1]
        assert time.monotonic() - t0 < 120, "no step in 120 s"
        time.sleep(0.1)
    tree = descendants(proc.pid)
    ranks = {_rank(pid): pid for pid in tree if _rank(pid) is not None}
    assert sorted(ranks) == [0, 1], tree
    shared = {line.split()[-1] for pid in ranks.values() for line in Path(f"/proc/{pid}/maps").read_text().splitlines()
              if "/vader_segment." in line}
    assert shared, "the ranks share no Open MPI memory segment: nothing to look for after the kill"
    return proc, out, ranks, tree, shared


def left_behind(tmp_path, shared) -> list[str]:
    """Open MPI's files the run left: in its TMPDIR (session directories) and the shared-memory
    segments its ranks had mapped."""
    return sorted(str(p) for p in (tmp_path / "tmp").iterdir()) + sorted(p for p in shared if os.path.exists(p))


def assert_ended_failed(proc, out, tree, shared, words: str):
    """Exit 4, one error line containing `words`, summary.json failed with it, no process of the
    job alive, the output directory's lock gone, no Open MPI file left."""
    err = proc.communicate(timeout=120)[1]
    lines = [line for line in err.splitlines() if line.startswith("varcouple: error:")]
    assert proc.returncode == 4, err
    assert len(lines) == 1 and words in lines[0], err
    assert err.strip().splitlines()[-1] == lines[0], err  # nothing after it: no mpirun banner, no token lost
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "failed" and words in summary["error"] and len(summary["steps"]) >= 1
    left = {pid: Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ")[:200] for pid in tree if alive(pid)}
    assert left == {}, err
    assert not (out / ".varcouple.lock").exists()
    assert left_behind(out.parent, shared) == []


@needs_mpi
@pytest.mark.parametrize("rank", [pytest.param(0, marks=pytest.mark.slow), 1])
def test_a_coupler_rank_killed_is_named(tmp_path, rank):
    """SIGKILL of coupler rank 0 or 1 mid-run (mpirun exited 137 or 247, status stayed "running",
    no error line): status failed naming the rank, one line, exit 4."""
    proc, out, ranks, tree, shared = start_on_two_ranks(tmp_path)
    os.kill(ranks[rank], signal.SIGKILL)
    assert_ended_failed(proc, out, tree, shared, f"coupler rank {rank} (pid {ranks[rank]}) died")


@needs_mpi
@pytest.mark.slow
def test_the_coupler_mpirun_killed_is_named(tmp_path):
    """SIGKILL of the coupler's mpirun: its ranks, left without it, are stopped; failed, mpirun named."""
    proc, out, ranks, tree, shared = start_on_two_ranks(tmp_path)
    mpirun = next(pid for pid in tree if pid not in ranks.values() and _rank(pid) is None
                  and open(f"/proc/{pid}/comm").read().strip() in ("mpirun", "orterun"))
    os.kill(mpirun, signal.SIGKILL)
    assert_ended_failed(proc, out, tree, shared, f"the coupler's mpirun (pid {mpirun}) killed by SIGKILL")


def ranks_case(tmp_path, ranks: int, more: str = ""):
    return copy_case(CASES / "standin_flow", tmp_path / "case",
                     {"max_iterations = 30": f"max_iterations = 30\nranks = {ranks}{more}"})


def refused(tmp_path, capsys, monkeypatch, case) -> str:
    """`varcouple check` and `run` of `case` refused in seconds, exit 2, one line, no process
    started, nothing written; the line."""
    from coupler.cli import main
    from coupler.run import job

    def no_job(*args, **kwargs):
        raise AssertionError("the coupler's ranks were started")

    monkeypatch.setattr(job, "Job", no_job)
    lines = []
    for command in (["check", "--quick", str(case)], ["run", str(case), "--output", str(tmp_path / "out")]):
        t0 = time.monotonic()
        code = main(command)
        err = capsys.readouterr().err
        assert code == 2 and len(err.strip().splitlines()) == 1 and time.monotonic() - t0 < 10, err
        lines.append(err.strip())
    assert lines[0] == lines[1] and f"{case / 'scene.toml'}: [coupling] ranks = " in lines[0], lines
    assert not (tmp_path / "out").exists()
    return lines[0]


def test_ranks_beyond_the_cores_are_refused_before_anything_starts(tmp_path, capsys, monkeypatch):
    """200 coupler ranks on this machine's cores (mpirun started them all; not refused in 120 s,
    about 200 shared-memory segments left): refused at once, naming the key and the override."""
    monkeypatch.delenv("VARCOUPLE_RANKS_PER_CORE", raising=False)
    line = refused(tmp_path, capsys, monkeypatch, ranks_case(tmp_path, 200))
    assert "ranks = 200: more than 4 coupler ranks per core" in line and "VARCOUPLE_RANKS_PER_CORE" in line


def test_ranks_beyond_the_memory_are_refused_before_anything_starts(tmp_path, capsys, monkeypatch):
    """16 coupler ranks over the memory limit (refused after 16.5 s, from the started ranks, blaming
    [geometry.solid] shape): refused at once naming [coupling] ranks, which alone makes it too big."""
    monkeypatch.setenv("VARCOUPLE_RANKS_PER_CORE", "100")
    line = refused(tmp_path, capsys, monkeypatch, ranks_case(tmp_path, 16, "\n[resources]\nmemory_limit = 1e9"))
    assert "ranks = 16: about 150 MB per coupler rank" in line and "[geometry.solid]" not in line, line
    assert "available ([resources] memory_limit)" in line and "check_memory = false" in line


def test_the_ranks_per_core_must_be_a_number(tmp_path, capsys, monkeypatch):
    from coupler.cli import main

    monkeypatch.setenv("VARCOUPLE_RANKS_PER_CORE", "many")
    assert main(["check", "--quick", str(ranks_case(tmp_path, 2))]) == 2
    assert "VARCOUPLE_RANKS_PER_CORE='many': not an integer" in capsys.readouterr().err


def test_a_participants_ranks_under_the_coupler_are_not_taken_for_coupler_ranks(monkeypatch):
    """Under the coupler's mpirun (pid 100) its ranks 0 and 1 (its children) and, below rank 0, a
    solid on 4 ranks under its own mpirun (pid 200), whose processes have ranks 0..3 too: only
    mpirun's children are coupler ranks (before: the solid's ranks 2 and 3 were watched as coupler
    ranks 2 and 3, and their end at the run's close named as a coupler rank that died)."""
    from coupler.run import job

    tree = {101: (100, 0), 102: (100, 1), 200: (101, None), **{300 + r: (200, r) for r in range(4)}}
    monkeypatch.setattr(job, "descendants", lambda pid: list(tree))
    monkeypatch.setattr(job, "proc_stat", lambda pid: ("S", tree[pid][0], pid, "7") if pid in tree else None)
    monkeypatch.setattr(job, "_rank", lambda pid: tree[pid][1])
    watched = job.Job.__new__(job.Job)
    watched.popen = type("Popen", (), {"pid": 100})()
    watched.ranks, watched.seen = {}, {}
    watched.search()
    assert watched.ranks == {0: 101, 1: 102} and set(watched.seen) == set(tree)
