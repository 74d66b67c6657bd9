"""The coupler on P ranks seen from the process that starts it: ``varcouple run`` with
``[coupling] ranks = P`` runs itself again under ``mpirun -n P`` and stays, as the front.

Before anything starts, P is held to the cores and the memory (:func:`coupler.run.preflight.check_cores`,
:func:`~coupler.run.preflight.check_memory`): a refusal names ``[coupling] ranks``. While the job
runs the front notes which process is which rank (from ``/proc``); a rank or mpirun that dies
without a word of its own (SIGKILL: mpirun exits with 137 or 247, or is itself killed, and no rank
wrote the summary's end) leaves the front to say so: ``summary.json`` status ``failed`` naming
the rank, one error line, exit 4 (:class:`~coupler.errors.RunFailed`). The ranks and the
processes they started that outlive mpirun are stopped.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

from coupler.errors import EXIT_CODES, CouplerError, RunFailed, Terminated
from coupler.output.results import SUMMARY, read_summary, write_summary
from coupler.protocol.exits import describe_exit
from coupler.protocol.mpi import mpi_environment
from coupler.run.launch import descendants, proc_stat
from coupler.run.outdir import LOCK
from coupler.run.preflight import check_cores, check_memory, estimate

#: seconds between two looks at the ranks, between two searches for the job's processes, and
#: given to them to stop on SIGTERM
LOOK, SEARCH, GRACE = 0.05, 1.0, 10.0


def _rank(pid: int) -> int | None:
    """The MPI rank of process `pid` (its ``OMPI_COMM_WORLD_RANK``), None if it has none."""
    try:
        env = Path(f"/proc/{pid}/environ").read_bytes().split(b"\0")
    except OSError:
        return None
    for item in env:
        if item.startswith(b"OMPI_COMM_WORLD_RANK="):
            return int(item.split(b"=", 1)[1])
    return None


class Job:
    """``mpirun -n ranks`` of `command` (with the one-host or named-interface MPI settings),
    watched: :attr:`ranks` (rank -> pid), every process seen under mpirun (:attr:`seen`), and the
    first rank seen gone while mpirun ran (:attr:`first_gone`)."""

    def __init__(self, command: list[str], ranks: int):
        mpirun = shutil.which("mpirun")
        if mpirun is None:
            raise CouplerError(f"[coupling] ranks = {ranks} needs mpirun (Open MPI), which is not installed")
        # -q: no Open MPI banners after the one error line (the front says what happened)
        self.popen = subprocess.Popen([mpirun, "-q", "-n", str(ranks), "--oversubscribe", *command],
                                      env=dict(mpi_environment(), OMP_NUM_THREADS="1"), stderr=subprocess.PIPE)
        self.errors: list[bytes] = []
        self.relay = threading.Thread(target=self._relay, daemon=True)
        self.relay.start()
        self.ranks: dict[int, int] = {}
        self.seen: dict[int, str] = {}
        self.first_gone: int | None = None

    def _relay(self) -> None:
        """The job's stderr to this process's, but its error lines held back (:meth:`said`)."""
        for line in self.popen.stderr:
            if line.startswith(b"varcouple: error:"):
                self.errors.append(line)
            else:
                sys.stderr.buffer.write(line)
                sys.stderr.flush()

    def said(self) -> None:
        """Write the error lines the ranks wrote: the run's end is theirs to tell."""
        self.relay.join(GRACE)
        for line in self.errors:
            sys.stderr.buffer.write(line)
        sys.stderr.flush()

    def search(self) -> None:
        """Note the processes under mpirun, and which is which rank."""
        known = set(self.ranks.values())
        for pid in descendants(self.popen.pid):
            if (st := proc_stat(pid)) is None:
                continue
            self.seen.setdefault(pid, st[3])
            # the coupler's ranks are mpirun's children; a participant's ranks (under the participant's
            # own mpirun) have a rank too but are not ours (not yet a rank: mpirun's fork before the exec)
            if pid not in known and st[1] == self.popen.pid and (rank := _rank(pid)) is not None:
                self.ranks.setdefault(rank, pid)

    def look(self) -> None:
        """Note the first rank gone while mpirun runs."""
        if self.first_gone is None:
            gone = [r for r, pid in sorted(self.ranks.items()) if not self._alive(pid)]
            if gone and self.popen.poll() is None:
                self.first_gone = gone[0]

    def _alive(self, pid: int) -> bool:
        """`pid` is the process seen under mpirun (not a later one of the same pid) and runs."""
        st = proc_stat(pid)
        return st is not None and st[0] not in ("Z", "X") and st[3] == self.seen[pid]

    def wait(self) -> int:
        searched = -SEARCH
        while self.popen.poll() is None:
            if time.monotonic() - searched >= SEARCH:
                self.search()
                searched = time.monotonic()
            self.look()
            time.sleep(LOOK)
        return self.popen.returncode

    def stop(self, sig=signal.SIGTERM) -> None:
        """`sig` to mpirun; after :data:`GRACE` s SIGKILL to it and to every process seen under it."""
        if self.popen.poll() is None:
            self.popen.send_signal(sig)
            try:
                self.popen.wait(GRACE)
            except subprocess.TimeoutExpired:
                self.popen.kill()
                self.popen.wait()
        self.stop_left()

    def stop_left(self) -> list[int]:
        """Stop the processes seen under mpirun that outlived it (SIGTERM, then SIGKILL after
        :data:`GRACE` s); their pids."""
        left = [pid for pid in self.seen if self._alive(pid)]
        for sig in (signal.SIGTERM, signal.SIGKILL):
            for pid in left:
                try:
                    os.kill(pid, sig)
                except ProcessLookupError:
                    pass
            deadline = time.monotonic() + GRACE
            while any(self._alive(p) for p in left) and time.monotonic() < deadline:
                time.sleep(0.05)
        return left


def relaunch(argv: list[str], scene, ranks: int) -> int:
    """This ``varcouple`` command line (`argv`, running `scene`) under ``mpirun -n ranks``; its
    exit code. SceneError (nothing started) when the ranks are too many for the cores or the
    memory; RunFailed when a rank or mpirun died without ending the run."""
    check_cores(scene, ranks)
    check_memory(scene, estimate(scene, ranks), ranks)
    job = Job([sys.executable, "-m", "coupler.cli", *argv], ranks)
    try:
        code = job.wait()
    except Terminated:
        job.stop(signal.SIGTERM)
        raise
    except KeyboardInterrupt:  # Ctrl-C reached mpirun too (same process group), which passes it to the ranks
        try:
            job.popen.wait(GRACE)
        except subprocess.TimeoutExpired:  # it did not (a SIGINT to this process alone)
            pass
        job.stop(signal.SIGTERM)
        raise
    left = job.stop_left()
    out = Path(scene.output_dir)
    summary = read_summary(out)
    if code in EXIT_CODES.values() and summary.get("status") != "running":
        job.said()
        return code  # the ranks ended the run and said how
    if job.first_gone is not None:
        who = f"coupler rank {job.first_gone} (pid {job.ranks[job.first_gone]}) died while the other ranks ran"
        how = f"mpirun {describe_exit(code)}"
    elif code >= 0:  # mpirun ended by itself, its ranks all gone between two looks
        who, how = "a coupler rank died", f"mpirun {describe_exit(code)}"
    else:
        who = f"the coupler's mpirun (pid {job.popen.pid}) {describe_exit(code)}"
        how = f"its ranks {'were stopped' if left else 'ended with it'}"
    message = f"{who}; {how}; the run is incomplete ({out / SUMMARY} says what was done)"
    if summary or out.is_dir():
        summary.update(status="failed", error=f"RunFailed: {message}")
        write_summary(out, summary)
    _release(out / LOCK, job.ranks.values())
    raise RunFailed(message)


def _release(lock: Path, pids) -> None:
    """Remove the output directory's lock if a rank of this job (now gone) held it."""
    holder = read_summary(lock.parent, lock.name)
    if holder.get("pid") in set(pids):
        lock.unlink(missing_ok=True)
