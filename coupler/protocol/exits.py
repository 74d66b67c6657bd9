"""How a child process ended, in words, for participants (:mod:`coupler.launch`) and the
OpenFOAM binaries (:mod:`fluid_openfoam.solver`).

A child killed by SIGKILL that nobody here killed was killed by another process (a user, a
batch scheduler) or by the kernel's out-of-memory killer; only the kernel can say which. It
counts those kills (``oom_kill``) per memory cgroup (v2: ``memory.events``, counting the cgroups
below too; v1: ``memory.oom_control``) and for the whole machine (``/proc/vmstat``), and logs
each (``dmesg``: "Killed process PID"). Read the count before starting a child
(:func:`oom_kills`: this process's cgroup, where children start, else the machine) and hand it
to :func:`describe_exit`: a count that rose while the child ran names the out-of-memory killer,
one that did not rules it out; without a count, only a kernel log line naming the child's pid
blames it. Otherwise the message says that it is not known.
"""

from __future__ import annotations

import re
import signal
import subprocess
from pathlib import Path

CGROUP_ROOT = Path("/sys/fs/cgroup")


def _counter_files() -> list[Path]:
    """Where the kernel counts out-of-memory kills that reach this process's children: its
    memory cgroup (v2, then v1), then the machine."""
    files = []
    try:
        lines = Path("/proc/self/cgroup").read_text().splitlines()
    except OSError:
        lines = []
    for line in lines:
        _, controllers, path = line.split(":", 2)
        if controllers == "":
            files.insert(0, CGROUP_ROOT / path.lstrip("/") / "memory.events")
        elif "memory" in controllers.split(","):
            files.append(CGROUP_ROOT / "memory" / path.lstrip("/") / "memory.oom_control")
    return files + [Path("/proc/vmstat")]


def oom_kills() -> tuple[str, int] | None:
    """``(file, count)`` of the kernel's out-of-memory kills from the first readable of
    :func:`_counter_files`, or None when the kernel does not say."""
    for path in _counter_files():
        try:
            text = path.read_text()
        except OSError:
            continue
        for line in text.splitlines():
            key, _, value = line.partition(" ")
            if key == "oom_kill":
                return str(path), int(value)
    return None


def _signal_name(number: int) -> str | None:
    try:
        return signal.Signals(number).name
    except ValueError:
        return None


def kernel_log_kill(pid: int) -> str | None:
    """The kernel log's line on an out-of-memory kill of `pid`, or None (no such line, or a kernel
    log this process may not read)."""
    try:
        out = subprocess.run(["dmesg"], capture_output=True, text=True, timeout=5)
    except (OSError, subprocess.SubprocessError):
        return None
    if out.returncode:
        return None
    said = re.compile(rf"Killed process {pid}\b|[,:\s]pid={pid}[,\s]")
    lines = [line for line in out.stdout.splitlines() if "kill" in line.lower() and said.search(line)]
    return " ".join(lines[-1].split()) if lines else None


def _sigkill_cause(oom_before: tuple[str, int] | None, pid: int | None) -> str:
    """Who sent a SIGKILL that nobody here sent, as far as the kernel says."""
    after = oom_kills()
    if oom_before and after and after[0] == oom_before[0]:
        if after[1] > oom_before[1]:
            return (f"the kernel's out-of-memory killer ({after[0]}: oom_kill {oom_before[1]} -> {after[1]} "
                    f"while it ran)")
        return (f"not the kernel's out-of-memory killer ({after[0]}: oom_kill {after[1]}, unchanged while it ran): "
                f"another process sent it")
    said = kernel_log_kill(pid) if pid is not None else None
    if said:
        return f"the kernel's out-of-memory killer (kernel log: {said})"
    return ("sent by another process or by the kernel's out-of-memory killer; which is not known (no out-of-memory "
            "count from before it started, no kernel log line naming it)")


def describe_exit(returncode: int, oom_before: tuple[str, int] | None = None, sender: str | None = None,
                  pid: int | None = None) -> str:
    """``returncode`` (``Popen.returncode``: negative for a signal) in words. ``oom_before``:
    :func:`oom_kills` read before the child started. ``sender``: who sent the signal when we
    did (then the kernel is not blamed), e.g. ``"the launcher"``. ``pid``: the child's, looked
    up in the kernel log when there is no count.

    128 + N is read as signal N reported by the child (mpirun when a rank was killed, a shell,
    a participant that ended on SIGTERM)."""
    if returncode < 0:
        name = _signal_name(-returncode)
        text = f"killed by {name or 'signal'} (signal {-returncode})"
    else:
        name = _signal_name(returncode - 128) if 128 < returncode < 128 + 65 else None
        text = f"exited with code {returncode}"
        if name:
            text += f" (128 + {name}: it or a process it ran ended by signal {returncode - 128})"
    if sender:
        return f"{text}, stopped by {sender}"
    if name != "SIGKILL":
        return text
    return f"{text}: {_sigkill_cause(oom_before, pid if returncode < 0 else None)}"
