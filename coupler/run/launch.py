"""Start participant processes and make sure every one of them ends.

:class:`Launcher` starts ``[mpirun -n N --oversubscribe] python -m MODULE --run-id R
--name NAME --connect ENDPOINT ...`` per participant, each in its own process group with
its output in ``<results_dir>/logs/<name>.log``. Used as a context manager, it stops
every process it started (SIGTERM to the whole group, SIGKILL after a grace period) on
any exit: normal end, exception, Ctrl-C, and then removes the temporary directories
(:func:`coupler.protocol.participant.scratch_dir`) its participants could not remove themselves.
"""

from __future__ import annotations

import logging
import os
import re
import shlex
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable

from coupler.protocol.exits import describe_exit, oom_kills
from coupler.protocol.transport import check_name
from coupler.protocol.mpi import mpi_environment

log = logging.getLogger("varcouple.launch")


def tail(path: Path, lines: int = 15, max_bytes: int = 64 * 1024) -> str:
    """The last ``lines`` lines of a text file ("" if it does not exist)."""
    try:
        with open(path, "rb") as f:
            f.seek(0, os.SEEK_END)
            size = f.tell()
            f.seek(max(0, size - max_bytes))
            text = f.read().decode("utf-8", "replace")
    except OSError:
        return ""
    return "\n".join(text.rstrip("\n").splitlines()[-lines:])


def proc_stat(pid: int) -> tuple[str, int, int, str] | None:
    """(state, ppid, pgid, start time) of a process from /proc, or None if it is gone (the start
    time tells it from a later process of the same pid)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    fields = stat[stat.rindex(")") + 2:].split()
    return fields[0], int(fields[1]), int(fields[2]), fields[19]


def alive(pid: int) -> bool:
    """``pid`` exists and is not a zombie."""
    st = proc_stat(pid)
    return st is not None and st[0] not in ("Z", "X")


def descendants(pid: int) -> list[int]:
    """Every live descendant of ``pid`` (children, grandchildren, ...), from /proc.

    mpirun puts each rank in a process group of its own, so signalling mpirun's group
    does not reach the ranks: :meth:`Launcher.stop_all` signals these pids as well."""
    children: dict[int, list[int]] = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            st = proc_stat(int(entry))
            if st is not None and st[0] not in ("Z", "X"):
                children.setdefault(st[1], []).append(int(entry))
    out, todo = [], [pid]
    while todo:
        for c in children.get(todo.pop(), []):
            out.append(c)
            todo.append(c)
    return out


@dataclass
class Process:
    """One started participant."""

    name: str
    argv: list[str]
    popen: subprocess.Popen
    log_path: Path
    started: float = field(default_factory=time.monotonic)
    reported: bool = False
    oom_before: tuple[str, int] | None = None  # coupler.exits.oom_kills() before it started
    killed: bool = False  # signalled by Launcher.stop_all

    @property
    def pid(self) -> int:
        return self.popen.pid

    @property
    def returncode(self) -> int | None:
        return self.popen.poll()

    def how(self) -> str:
        """How it ended (:func:`coupler.exits.describe_exit`); call once it has."""
        return describe_exit(self.popen.poll(), self.oom_before, "the launcher" if self.killed else None, self.pid)

    def describe_exit(self, lines: int = 15) -> str:
        if self.popen.poll() is None:
            return f"{self.name} is running (pid {self.pid})"
        last = tail(self.log_path, lines)
        text = f"process {self.how()} (log {self.log_path})"
        if last:
            text += "; last lines:\n" + "\n".join("    " + ln for ln in last.splitlines())
        return text


@dataclass
class Exited:
    """What :meth:`Launcher.poll` reports about a process that ended."""

    name: str
    pid: int
    returncode: int
    log_tail: str
    log_path: Path
    how: str  # coupler.exits.describe_exit

    def __str__(self):
        return f"{self.name} (pid {self.pid}) {self.how}"


class Launcher:
    """Start and stop the participant processes of run ``run_id``.

    ``connect``: the zenoh endpoints every participant connects to (the coupler's,
    :attr:`coupler.messaging.CouplerSession.endpoints`); ``coupler_ranks``: those of each rank
    of a coupler on several ranks (``--coupler-rank``: each participant rank links to the
    coupler ranks it talks to, :func:`coupler.protocol.transport.part_links`). ``python``: the interpreter
    (default: this one). ``mpirun``: the MPI launcher for ``ranks > 1``. ``env``: the
    participants' environment (default: this one's), with Open MPI's settings for
    ``mpi_interfaces`` added (:func:`coupler.mpi_env.mpi_environment`: None reads
    ``VARCOUPLE_MPI_INTERFACES``, none means this host only); the participants' own mpiruns
    (the fluid's OpenFOAM) inherit them.
    """

    def __init__(self, run_id: str, results_dir, connect: Iterable[str] = (), *,
                 coupler_ranks: Iterable[str] = (), python: str | None = None, mpirun: str = "mpirun", env: dict | None = None,
                 mpi_interfaces: list[str] | None = None):
        self.run_id = check_name("run id", run_id)
        self.results_dir = Path(results_dir)
        self.log_dir = self.results_dir / "logs"
        self.connect = list(connect)
        self.coupler_ranks = list(coupler_ranks)
        self.python = python or sys.executable
        self.mpirun = mpirun
        self.env = env
        self.mpi_interfaces = mpi_interfaces
        self.processes: dict[str, Process] = {}

    def command(self, name: str, module: str, ranks: int = 1, extra_args: Iterable[str] = ()) -> list[str]:
        argv = [self.python, "-m", module, "--run-id", self.run_id, "--name", name]
        for ep in self.connect:
            argv += ["--connect", ep]
        for ep in self.coupler_ranks:
            argv += ["--coupler-rank", ep]
        argv += [str(a) for a in extra_args]
        if ranks > 1:
            mpirun = shutil.which(self.mpirun) or self.mpirun
            argv = [mpirun, "-n", str(int(ranks)), "--oversubscribe"] + argv
        return argv

    def start(self, name: str, module: str, ranks: int = 1, extra_args: Iterable[str] = ()) -> Process:
        """Start participant ``name`` as ``python -m module`` (under ``mpirun -n ranks``
        when ``ranks > 1``); output to ``<results_dir>/logs/<name>.log``."""
        check_name("participant name", name)
        if name in self.processes and self.processes[name].returncode is None:
            raise RuntimeError(f"participant {name!r} is already running (pid {self.processes[name].pid})")
        if ranks < 1:
            raise ValueError(f"ranks must be >= 1, got {ranks}")
        argv = self.command(name, module, ranks, extra_args)
        self.log_dir.mkdir(parents=True, exist_ok=True)
        log_path = self.log_dir / f"{name}.log"
        env = dict(mpi_environment(self.mpi_interfaces, self.env), PYTHONUNBUFFERED="1")
        oom_before = oom_kills()
        with open(log_path, "ab") as out:
            out.write(f"# {time.strftime('%Y-%m-%d %H:%M:%S')} {shlex.join(argv)}\n".encode())
            out.flush()
            popen = subprocess.Popen(argv, stdin=subprocess.DEVNULL, stdout=out, stderr=subprocess.STDOUT,
                                     env=env, start_new_session=True, close_fds=True)
        proc = Process(name, argv, popen, log_path, oom_before=oom_before)
        self.processes[name] = proc
        log.info("started %s: pid %d, %s", name, popen.pid, shlex.join(argv))
        return proc

    def check(self, name: str) -> str | None:
        """``None`` while ``name`` runs, else why it ended (exit code, last log lines).
        Suitable as :class:`~coupler.messaging.ParticipantClient`'s ``process_check``."""
        proc = self.processes.get(name)
        if proc is None or proc.returncode is None:
            return None
        return proc.describe_exit()

    def stopped(self, name: str) -> str | None:
        """Why ``name`` answers nothing while it runs: which of its processes (it, its MPI ranks)
        is stopped (SIGSTOP or SIGTSTP: state T; a debugger: t), or ``None``. Suitable as
        :class:`~coupler.run.client.ParticipantClient`'s ``process_stopped``."""
        proc = self.processes.get(name)
        if proc is None or proc.returncode is not None:
            return None
        for pid in [proc.pid, *descendants(proc.pid)]:
            st = proc_stat(pid)
            if st is not None and st[0] in ("T", "t"):
                how = "SIGSTOP or SIGTSTP" if st[0] == "T" else "traced by a debugger"
                return f"process {pid} is stopped (state {st[0]}: {how}); kill -CONT {pid} resumes it"
        return None

    def poll(self) -> list[Exited]:
        """The processes that have exited since the last call, with their exit code and
        the last lines of their log."""
        out = []
        for proc in self.processes.values():
            code = proc.returncode
            if code is not None and not proc.reported:
                proc.reported = True
                out.append(Exited(proc.name, proc.pid, code, tail(proc.log_path), proc.log_path, proc.how()))
        return out

    def running(self) -> list[str]:
        return [p.name for p in self.processes.values() if p.returncode is None]

    def wait(self, name: str, timeout: float | None = None) -> int | None:
        """Wait for ``name`` to exit (e.g. after ``finish``); its exit code, or ``None``."""
        try:
            return self.processes[name].popen.wait(timeout)
        except subprocess.TimeoutExpired:
            return None

    @staticmethod
    def _signal(pids_and_groups, sig) -> None:
        for kind, pid in pids_and_groups:
            try:
                if kind == "group":
                    os.killpg(pid, sig)
                else:
                    os.kill(pid, sig)
            except (ProcessLookupError, PermissionError):
                pass

    def stop_all(self, timeout: float = 5.0) -> None:
        """End every process: SIGTERM to each process group and to every descendant
        (mpirun's ranks live in groups of their own), wait up to ``timeout`` seconds,
        then SIGKILL whatever is left."""
        procs = list(self.processes.values())
        # Even when a leader has exited, its group or its children may live on (MPI ranks).
        targets = [("group", p.pid) for p in procs]
        extra = [d for p in procs for d in descendants(p.pid)]
        targets += [("pid", d) for d in extra]
        for proc in procs:
            proc.killed = proc.killed or proc.returncode is None
        self._signal(targets, signal.SIGTERM)
        deadline = time.monotonic() + timeout
        for proc in procs:
            try:
                proc.popen.wait(max(0.0, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                pass
        while any(alive(d) for d in extra) and time.monotonic() < deadline:
            time.sleep(0.02)
        left = [p for p in procs if p.returncode is None] + [d for d in extra if alive(d)]
        for item in left:
            if isinstance(item, Process):
                log.warning("%s (pid %d) did not stop on SIGTERM within %.1f s: SIGKILL", item.name, item.pid, timeout)
        # SIGKILL the groups (cheap, harmless when empty) and the descendants still alive.
        self._signal(targets[:len(procs)] + [("pid", d) for d in extra if alive(d)], signal.SIGKILL)
        for proc in procs:
            try:
                proc.popen.wait(5.0)
            except subprocess.TimeoutExpired:
                log.error("%s (pid %d) survived SIGKILL", proc.name, proc.pid)
        self._remove_scratch()

    def _remove_scratch(self) -> None:
        """Remove the :func:`~coupler.protocol.participant.scratch_dir` directories its ended participants left behind."""
        tmp = Path((os.environ if self.env is None else self.env).get("TMPDIR") or tempfile.gettempdir())
        for proc in self.processes.values():
            if proc.returncode is None:
                continue
            prefix = f"varcouple-{self.run_id}-{proc.name}-"
            for path in tmp.glob(f"{prefix}*"):
                # mkdtemp's 8 random characters: not a longer run id or name that starts the same
                if re.fullmatch(r"[a-z0-9_]{8}", path.name[len(prefix):]) and path.is_dir():
                    log.warning("removing %s, left by %s (%s)", path, proc.name, proc.how())
                    shutil.rmtree(path, ignore_errors=True)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.stop_all()
