"""Each run's own Open MPI session directory (coupler/protocol/mpi_session.py): what Open MPI
writes goes there and is removed however the run ends; a coupler killed with SIGKILL leaves only
its session directories, which the next start removes (and no one else's)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from coupler.protocol import mpi_session
from coupler.protocol.mpi import mpi_environment
from coupler.protocol.mpi_session import PREFIX, SESSION_VAR, shared_memory_dir
from coupler.run.launch import alive, descendants
from vc_helpers import CASES, copy_case


def varcouple(tmp_path, *argv, **kwargs):
    return subprocess.Popen([sys.executable, "-m", "coupler.cli", *map(str, argv)], stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True, env=dict(os.environ, TMPDIR=str(tmp_path / "tmp")),
                            **kwargs)


def test_a_coupler_killed_leaves_its_session_only_and_the_next_start_removes_it(tmp_path):
    """SIGKILL of a one-rank coupler mid-run left $TMPDIR/ompi.<host>.<uid>; now all Open MPI wrote
    is in the run's session directory, and the next varcouple start removes it."""
    (tmp_path / "tmp").mkdir()
    case = copy_case(CASES / "standin_flow", tmp_path / "case", {"steps = 4": "steps = 400"})
    out = tmp_path / "out"
    proc = varcouple(tmp_path, "run", case, "--output", out)
    t0 = time.monotonic()
    while not (out / "summary.json").exists() or not json.loads((out / "summary.json").read_text())["steps"]:
        assert proc.poll() is None and time.monotonic() - t0 < 120, proc.communicate()[1]
        time.sleep(0.1)
    tree = descendants(proc.pid)
    written = [p.relative_to(tmp_path / "tmp") for p in (tmp_path / "tmp").rglob("*")]
    assert any(p.name.startswith("ompi.") for p in written), written  # Open MPI is in use: its session directory
    proc.kill()
    proc.wait()
    while any(alive(pid) for pid in tree):  # the participants see the coupler gone and end
        assert time.monotonic() - t0 < 120
        time.sleep(0.1)
    left = sorted(p.name for p in (tmp_path / "tmp").iterdir())
    assert len(left) == 1 and left[0].startswith(f"{PREFIX}{proc.pid}-"), left
    shm = Path(shared_memory_dir(str(tmp_path / "tmp" / left[0])))
    assert shm.is_dir()
    nxt = varcouple(tmp_path, "check", "--quick", case)
    assert nxt.wait(60) == 0, nxt.communicate()[1]
    assert list((tmp_path / "tmp").iterdir()) == [] and not shm.exists()


def test_a_run_that_ends_leaves_nothing(tmp_path):
    (tmp_path / "tmp").mkdir()
    case = copy_case(CASES / "standin_flow", tmp_path / "case")
    proc = varcouple(tmp_path, "run", case, "--output", tmp_path / "out")
    assert proc.wait(120) == 0, proc.communicate()[1]
    assert list((tmp_path / "tmp").iterdir()) == []
    assert list(Path(shared_memory_dir(str(tmp_path))).parent.glob(f"{PREFIX}{proc.pid}-*")) == []


def test_the_sweep_removes_the_sessions_of_dead_owners_only(tmp_path, monkeypatch):
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    monkeypatch.setattr(mpi_session.tempfile, "tempdir", None)  # gettempdir() reads TMPDIR again
    monkeypatch.setattr(mpi_session, "SHM", tmp_path / "shm")
    (tmp_path / "shm").mkdir()
    dead = subprocess.Popen(["true"])
    dead.wait()
    names = {"dead": f"{PREFIX}{dead.pid}-abcd1234", "alive": f"{PREFIX}{os.getpid()}-abcd1234",
             "other": f"{PREFIX}{dead.pid}-not-ours"}
    for name in names.values():
        (tmp_path / name).mkdir()
        (tmp_path / "shm" / name).mkdir()
    removed = mpi_session.sweep()
    assert sorted(removed) == sorted([tmp_path / names["dead"], tmp_path / "shm" / names["dead"]])
    assert sorted(p.name for p in tmp_path.glob(f"{PREFIX}*")) == sorted([names["alive"], names["other"]])


def test_the_session_is_named_to_every_mpi_process_and_removed(tmp_path, monkeypatch):
    monkeypatch.setattr(mpi_session.tempfile, "tempdir", str(tmp_path))
    monkeypatch.setattr(mpi_session, "SHM", tmp_path / "shm")
    (tmp_path / "shm").mkdir()
    env = {}
    with mpi_session.mpi_session(env) as session:
        assert env[SESSION_VAR] == session and Path(session).parent == tmp_path
        settings = mpi_environment(env=env)
        assert settings["OMPI_MCA_orte_tmpdir_base"] == session
        assert settings["OMPI_MCA_btl_vader_backing_directory"] == str(tmp_path / "shm" / Path(session).name)
        job = mpi_environment(env=dict(env, OMPI_COMM_WORLD_SIZE="2", OMPI_MCA_orte_tmpdir_base="/elsewhere"))
        assert job["OMPI_MCA_orte_tmpdir_base"] == session  # a coupler rank's participants: the run's too
        env.update(settings)
        with mpi_session.mpi_session(env) as inner:  # a process of the run: the run's, not removed
            assert inner == session
        assert Path(session).is_dir()
    assert not Path(session).exists() and not (tmp_path / "shm" / Path(session).name).exists()
    assert SESSION_VAR not in env and "OMPI_MCA_orte_tmpdir_base" not in env
