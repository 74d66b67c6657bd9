"""A child killed by SIGKILL that we did not kill is blamed on the kernel's out-of-memory killer
only when the kernel says so: its out-of-memory count rose while the child ran, or (without a
count) its log names the child; a count that did not rise rules it out, and without either the
message says that it is not known (coupler/protocol/exits.py), for participants
(coupler/run/launch.py) and OpenFOAM binaries (fluid_openfoam/solver.py)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import uuid
from pathlib import Path

import pytest

from coupler.protocol.exits import describe_exit, oom_kills
from coupler.run.launch import Launcher
from fluid_openfoam.case import CaseSpec
from fluid_openfoam.solver import OpenFOAMError, OpenFOAMSolver
from vc_helpers import ROOT

from coupler.protocol import exits

RULED_OUT = "killed by SIGKILL (signal 9): not the kernel's out-of-memory killer ("
UNKNOWN = "which is not known"


def self_killing_child() -> int:
    return subprocess.run(["sh", "-c", "kill -9 $$"]).returncode


def test_a_sigkill_the_kernel_did_not_count_is_not_blamed_on_memory():
    before = oom_kills()
    assert self_killing_child() == -signal.SIGKILL
    text = describe_exit(-signal.SIGKILL, before)
    assert text.startswith(RULED_OUT) and "another process sent it" in text and "probably" not in text, text


@pytest.mark.parametrize("log_line, words", [
    ("[ 12.3] Out of memory: Killed process 4242 (python3) total-vm:1048576kB", "the kernel's out-of-memory killer "
                                                                               "(kernel log: [ 12.3] Out of memory"),
    (None, UNKNOWN)], ids=["kernel_log", "nothing_readable"])
def test_without_a_count_only_the_kernel_log_blames_memory(monkeypatch, log_line, words):
    monkeypatch.setattr(exits, "oom_kills", lambda: None)
    monkeypatch.setattr(exits, "kernel_log_kill", lambda pid: log_line if pid == 4242 else None)
    text = describe_exit(-signal.SIGKILL, None, pid=4242)
    assert text.startswith("killed by SIGKILL (signal 9): ") and words in text and "probably" not in text, text


def test_the_kernel_log_names_the_pid_it_killed(monkeypatch):
    log = ("[ 5.1] oom-kill:constraint=CONSTRAINT_MEMCG,task=python3,pid=777,uid=0\n"
           "[ 5.2] Memory cgroup out of memory: Killed process 777 (python3)\n")
    monkeypatch.setattr(exits.subprocess, "run", lambda *a, **k: subprocess.CompletedProcess(a, 0, log, ""))
    assert exits.kernel_log_kill(777) == "[ 5.2] Memory cgroup out of memory: Killed process 777 (python3)"
    assert exits.kernel_log_kill(77) is None
    monkeypatch.setattr(exits.subprocess, "run", lambda *a, **k: subprocess.CompletedProcess(a, 1, "", "denied"))
    assert exits.kernel_log_kill(777) is None  # an unreadable log says nothing


def test_exit_code_137_names_sigkill_of_a_process_under_it():
    """mpirun (and a shell) exit with 128 + 9 when a process they ran was killed by SIGKILL."""
    rc = subprocess.run(["sh", "-c", "sh -c 'kill -9 $$'"]).returncode
    assert rc == 137
    text = describe_exit(rc)
    assert text.startswith("exited with code 137") and "SIGKILL" in text and UNKNOWN in text


@pytest.mark.parametrize("code, words", [(0, "exited with code 0"), (1, "exited with code 1"),
                                         (-signal.SIGTERM, "killed by SIGTERM (signal 15)"),
                                         (128 + signal.SIGTERM, "exited with code 143 (128 + SIGTERM")])
def test_other_exits_claim_nothing_about_memory(code, words):
    assert describe_exit(code).startswith(words)
    assert "memory" not in describe_exit(code)


def test_a_kill_the_caller_sent_is_not_blamed_on_memory():
    assert describe_exit(-signal.SIGKILL, sender="the launcher") == "killed by SIGKILL (signal 9), stopped by the launcher"


def test_the_kernel_counter_is_read():
    """On Linux the kernel counts its out-of-memory kills (this cgroup's or the machine's)."""
    where, count = oom_kills()
    assert Path(where).exists() and count >= 0


# ------------------------------------------------------------------ participants (Launcher)

def module_env(directory: Path, name: str, body: str) -> dict:
    """Write module ``name`` into ``directory``; an environment in which it imports."""
    (directory / f"{name}.py").write_text(textwrap.dedent(body))
    return dict(os.environ, PYTHONPATH=f"{directory}{os.pathsep}{os.environ.get('PYTHONPATH', '')}")


def test_participant_killed_by_sigkill_is_not_blamed_on_memory_the_kernel_did_not_count(tmp_path):
    env = module_env(tmp_path, "vc_selfkill", "import os, signal\nos.kill(os.getpid(), signal.SIGKILL)\n")
    with Launcher(f"t-{uuid.uuid4().hex[:8]}", tmp_path, env=env) as launcher:
        launcher.start("solid", "vc_selfkill")
        assert launcher.wait("solid", 30) == -signal.SIGKILL
        assert RULED_OUT in launcher.check("solid")
        assert RULED_OUT in str(launcher.poll()[0])


def test_participant_the_launcher_kills_is_not_blamed_on_memory(tmp_path):
    env = module_env(tmp_path, "vc_stubborn", """\
        import signal, sys, time
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        print("ready", flush=True)
        time.sleep(60)
        """)
    launcher = Launcher(f"t-{uuid.uuid4().hex[:8]}", tmp_path, env=env)
    proc = launcher.start("fluid", "vc_stubborn")
    while "ready" not in proc.log_path.read_text():
        assert proc.returncode is None
    launcher.stop_all(timeout=0.5)
    assert proc.returncode == -signal.SIGKILL
    text = launcher.check("fluid")
    assert "killed by SIGKILL (signal 9), stopped by the launcher" in text and "memory" not in text


# ------------------------------------------------------------------ OpenFOAM binaries

def fake_blockmesh(tmp_path, monkeypatch, script: str) -> OpenFOAMSolver:
    """An OpenFOAMSolver on a 2 x 2 x 2 grid case whose ``blockMesh`` is the shell `script`."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    fake = bin_dir / "blockMesh"
    fake.write_text("#!/bin/sh\n" + script)
    fake.chmod(0o755)
    monkeypatch.setenv("PATH", f"{bin_dir}{os.pathsep}{os.environ['PATH']}")
    (tmp_path / "case").mkdir()
    spec = CaseSpec.from_config({"grid": {"origin": [0, 0, 0], "spacing": [1, 1, 1], "shape": [2, 2, 2]}})
    return OpenFOAMSolver(tmp_path / "case", spec)


def test_openfoam_binary_killed_by_sigkill(tmp_path, monkeypatch):
    """OpenFOAMSolver.run names a SIGKILL and what the kernel says of it, not 'exit code -9'."""
    solver = fake_blockmesh(tmp_path, monkeypatch, "kill -9 $$\n")
    with pytest.raises(OpenFOAMError) as info:
        solver.run("blockMesh")
    assert RULED_OUT in str(info.value) and "exit code" not in str(info.value)


def test_a_running_openfoam_binary_logs_its_progress(tmp_path, monkeypatch, caplog):
    """While a binary writes its log, its last line is logged every PROGRESS_SECONDS (the fluid
    participant's progress, which keeps the coupler's [messaging] timeout from cutting a long solve
    off: docs/protocol.md); a binary whose log stands still is silent."""
    import logging

    import fluid_openfoam.solver as solver_module

    solver = fake_blockmesh(tmp_path, monkeypatch, 'for i in 1 2 3 4 5 6; do echo "Time = $i"; sleep 0.2; done\n'
                                                   "sleep 1\n")
    monkeypatch.setattr(solver_module, "PROGRESS_SECONDS", 0.3)
    with caplog.at_level(logging.INFO, logger="varcouple.fluid_openfoam"):
        solver.run("blockMesh")
    lines = [r.getMessage() for r in caplog.records if r.getMessage().startswith("blockMesh running: ")]
    assert len(lines) >= 2 and all(line.startswith("blockMesh running: Time = ") for line in lines), lines
    assert len(lines) <= 5  # none in the last second, when the log stood still


# ------------------------------------------------------------------ a real out-of-memory kill

def memory_cgroup(limit: int) -> Path | None:
    """A new memory cgroup below this process's (cgroup v1 or v2) limited to ``limit`` bytes
    without swap, or None when this machine does not let us make one."""
    for line in Path("/proc/self/cgroup").read_text().splitlines():
        _, controllers, path = line.split(":", 2)
        if "memory" in controllers.split(","):  # v1
            group = Path("/sys/fs/cgroup/memory") / path.lstrip("/") / f"varcouple-test-{uuid.uuid4().hex[:8]}"
            files = {"memory.limit_in_bytes": limit, "memory.memsw.limit_in_bytes": limit}
        elif controllers == "":  # v2
            group = Path("/sys/fs/cgroup") / path.lstrip("/") / f"varcouple-test-{uuid.uuid4().hex[:8]}"
            files = {"memory.max": limit, "memory.swap.max": 0}
        else:
            continue
        try:
            group.mkdir()
        except OSError:
            continue
        try:
            for name, value in files.items():
                if (group / name).exists():
                    (group / name).write_text(str(value))
            if not any((group / name).exists() for name in files):
                raise OSError("no memory limit in this cgroup")
            return group
        except OSError:
            group.rmdir()
    return None


def test_a_real_out_of_memory_kill_is_named_as_such(tmp_path):
    """A child that allocates 1 GiB inside a 96 MiB memory cgroup: the kernel's OOM killer
    ends it (only inside that cgroup: the machine's memory is never at risk) and counts it."""
    group = memory_cgroup(96 << 20)
    if group is None:
        pytest.skip("cannot create a memory-limited cgroup here (needs root and a writable cgroup fs)")
    driver = textwrap.dedent("""\
        import os, subprocess, sys
        open(sys.argv[1], "w").write(str(os.getpid()))  # into the limited cgroup, with the child
        from coupler.protocol.exits import describe_exit, oom_kills
        before = oom_kills()
        hog = subprocess.run([sys.executable, "-c", "b = bytearray(b'1') * (1 << 30)"]).returncode
        print(describe_exit(hog, before))
        """)
    try:
        out = subprocess.run([sys.executable, "-c", driver, str(group / "cgroup.procs")], capture_output=True,
                             text=True, timeout=120, cwd=ROOT)
    finally:
        group.rmdir()
    assert out.returncode == 0, out.stderr
    text = out.stdout.strip()
    assert text.startswith("killed by SIGKILL (signal 9): the kernel's out-of-memory killer ("), text
    assert "probably" not in text
