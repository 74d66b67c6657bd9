"""The fluid participant's temporary OpenFOAM case (``<TMPDIR>/varcouple-<run_id>-<name>-*``)
is gone however the participant ends: finish, SIGTERM, SIGINT, a coupler that dies, a failing
configure; after SIGKILL the Launcher removes it. A ``case_dir`` given in the config is kept.
Each test has a TMPDIR of its own, so a leftover found there is this run's."""

from __future__ import annotations

import os
import shutil
import signal
import threading
import uuid
from pathlib import Path

import numpy as np
import pytest

from coupler.protocol.errors import ParticipantDied, ParticipantError
from coupler.run.launch import Launcher
from coupler.run.client import CouplerSession
from coupler.protocol.wire import Field

pytestmark = pytest.mark.skipif(shutil.which("blockMesh") is None, reason="OpenFOAM not installed")

CONFIG = {"grid": {"origin": [0.0, 0.0, 0.0], "spacing": [1e-3, 1e-3, 1e-3], "shape": [4, 3, 1]},
          "inlet": {"pressure": 1e-2}, "outlet": {"pressure": 0.0},
          "boundaries": {"zmin": "empty", "zmax": "empty"}, "max_iterations": 20}


class Run:
    """A coupler session and a launcher whose participants have ``tmp`` as TMPDIR."""

    def __init__(self, tmp_path: Path, **env):
        self.tmp = tmp_path / "tmp"
        self.tmp.mkdir()
        self.coupler = CouplerSession(f"test-{uuid.uuid4().hex[:12]}")
        self.launcher = Launcher(self.coupler.run_id, tmp_path, self.coupler.endpoints,
                                 env=dict(os.environ, TMPDIR=str(self.tmp), **env))

    def start_fluid(self, config=None):
        self.launcher.start("fluid", "fluid_openfoam")
        fluid = self.coupler.client("fluid", 60.0, process_check=lambda: self.launcher.check("fluid"))
        fluid.wait_alive(30.0)
        fluid.configure(CONFIG if config is None else config)
        return fluid

    def cases(self) -> list[Path]:
        return sorted(self.tmp.iterdir())

    def wait(self, code: int) -> None:
        assert self.launcher.wait("fluid", 30.0) == code, self.launcher.check("fluid")

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.launcher.stop_all(timeout=3.0)
        self.coupler.close()


@pytest.fixture
def run(tmp_path):
    with Run(tmp_path) as r:
        yield r


def test_the_case_is_named_after_the_run_and_removed_by_finish(run):
    fluid = run.start_fluid()
    [case] = run.cases()
    assert case.name.startswith(f"varcouple-{run.coupler.run_id}-fluid-") and (case / "case" / "system").is_dir()
    fluid.finish()
    run.wait(0)
    assert run.cases() == []


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_a_signal_removes_the_case(run, sig):
    run.start_fluid()
    assert len(run.cases()) == 1
    os.kill(run.launcher.processes["fluid"].pid, sig)
    run.wait(128 + sig)
    assert run.cases() == []


def processes_in(directory: Path) -> list[str]:
    """Command lines of the live processes that name ``directory`` (OpenFOAM's ``-case``)."""
    found = []
    for entry in os.listdir("/proc"):
        try:
            cmd = Path(f"/proc/{entry}/cmdline").read_bytes().replace(b"\0", b" ").decode()
            state = Path(f"/proc/{entry}/stat").read_text().rsplit(")", 1)[1].split()[0]
        except (OSError, ValueError):
            continue
        if str(directory) in cmd and state != "Z":
            found.append(cmd)
    return found


@pytest.mark.parametrize("ranks", [1, pytest.param(2, marks=pytest.mark.skipif(shutil.which("mpirun") is None,
                                                                                   reason="no mpirun"))])
def test_a_signal_during_an_advance_stops_the_solver_and_removes_the_case(run, ranks):
    """SIGTERM while simpleFoam runs (on 2 ranks: under mpirun, which must get to stop its ranks
    and remove its own session directory from TMPDIR, ompi.*): nothing is left running or on disk."""
    config = dict(CONFIG, max_iterations=100000, tolerance=1e-30, ranks=ranks)
    config["grid"] = dict(CONFIG["grid"], shape=[4, 4, 1])
    fluid = run.start_fluid(config)
    pid = run.launcher.processes["fluid"].pid
    threading.Timer(1.5, os.kill, (pid, signal.SIGTERM)).start()
    with pytest.raises(ParticipantDied):
        fluid.advance(0, 0, 0.0, 1.0, {"solid_fraction": Field("solid_fraction", np.zeros(16))}, timeout=60)
    run.wait(128 + signal.SIGTERM)
    assert processes_in(run.tmp) == []
    assert run.cases() == []


def test_a_coupler_that_goes_away_removes_the_case(run):
    run.start_fluid()
    assert len(run.cases()) == 1
    run.coupler.close()
    run.wait(1)
    assert run.cases() == []


def test_after_sigkill_the_launcher_removes_the_case(run):
    run.start_fluid()
    os.kill(run.launcher.processes["fluid"].pid, signal.SIGKILL)
    run.wait(-signal.SIGKILL)
    assert len(run.cases()) == 1  # nobody could remove it yet
    run.launcher.stop_all()
    assert run.cases() == []


def test_a_failing_configure_removes_its_case_at_once(tmp_path):
    """blockMesh fails (a stand-in on PATH): the error reaches the coupler and the case is
    gone while the participant still serves."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    (bin_dir / "blockMesh").write_text("#!/bin/sh\necho 'FOAM FATAL ERROR: no mesh today'\nexit 1\n")
    (bin_dir / "blockMesh").chmod(0o755)
    with Run(tmp_path, PATH=f"{bin_dir}{os.pathsep}{os.environ['PATH']}") as r:
        with pytest.raises(ParticipantError, match="blockMesh failed"):
            r.start_fluid()
        assert r.launcher.processes["fluid"].returncode is None
        assert r.cases() == []


def test_a_failing_advance_keeps_the_state_until_the_run_stops(run):
    fluid = run.start_fluid()
    with pytest.raises(ParticipantError, match="solid_fraction"):
        fluid.advance(0, 0, 0.0, 1.0, {"solid_fraction": Field("solid_fraction", np.zeros(5))})
    assert len(run.cases()) == 1  # still serving: the coupler may restore and retry
    run.launcher.stop_all(timeout=10.0)
    assert run.launcher.processes["fluid"].returncode == 128 + signal.SIGTERM
    assert run.cases() == []


def test_a_given_case_dir_is_never_removed(run, tmp_path):
    kept = tmp_path / "results" / "logs" / "fluid_case"
    fluid = run.start_fluid(dict(CONFIG, case_dir=str(kept)))
    assert run.cases() == [] and (kept / "system").is_dir()
    fluid.finish()
    run.wait(0)
    run.launcher.stop_all()
    assert (kept / "system").is_dir() and (kept / "log.blockMesh").exists()


def test_the_launcher_leaves_other_runs_alone(run):
    """Directories of another run (or of a run id that merely starts like this one) stay."""
    others = [run.tmp / f"varcouple-other-fluid-{'a' * 8}", run.tmp / f"varcouple-{run.coupler.run_id}-fluid-x-abcdefgh"]
    for d in others:
        d.mkdir()
    run.launcher.start("fluid", "fluid_openfoam")
    run.launcher.stop_all()
    assert run.cases() == sorted(others)
