"""The output directory of a run: created, checked writable, and locked for the run.

Two runs writing into one directory would mix their files (the summary of one, the VTU
steps of the other) without a word. :class:`OutputLock` holds ``.varcouple.lock`` in the
directory for the length of a run: it names the run id, process, host and start time; a
second run refuses with that name; a lock whose process is gone (same host) is stale and
taken over with a note, and the partial files of killed writers (:mod:`transfer.atomic`) are
removed.
"""

from __future__ import annotations

import json
import os
import socket
import time
from pathlib import Path

from coupler.errors import CouplerError
from transfer.atomic import PARTIAL

LOCK = ".varcouple.lock"


class OutputBusy(CouplerError):
    """The output directory is locked by another run that is still alive."""


def prepare(directory, origin: str) -> Path:
    """Create `directory` (and its parents) and make sure files can be written there;
    `origin` names where it comes from (``--output``, ``[output] directory``)."""
    directory = Path(directory)
    if directory.exists() and not directory.is_dir():
        raise CouplerError(f"{origin}: {str(directory)!r} exists and is not a directory")
    try:
        directory.mkdir(parents=True, exist_ok=True)
        probe = directory / f".varcouple-write-test-{os.getpid()}"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        raise CouplerError(f"{origin}: cannot write to the output directory {str(directory)!r}: "
                           f"{exc.strerror or exc}") from None
    return directory


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _remove_partials(directory: Path) -> None:
    """Remove the temporary files of :mod:`transfer.atomic` left by processes that are gone
    (a run killed while writing): the directory holds whole files only."""
    for file in directory.glob(f".*{PARTIAL}*"):
        pid = file.stem.rpartition(PARTIAL)[2]
        if pid.isdigit() and not _alive(int(pid)):
            file.unlink(missing_ok=True)


class OutputLock:
    """``with OutputLock(directory, run_id): ...``: the directory is this run's until the end.

    Raises :class:`OutputBusy` naming the run that holds it. ``note`` says when a stale
    lock (its process gone) was taken over."""

    def __init__(self, directory, run_id: str):
        self.path = Path(directory) / LOCK
        self.run_id = run_id
        self.note = ""
        self._held = False
        self._new = not Path(directory).exists()  # made for this run: removed again if it stays empty

    def _holder(self) -> dict | None:
        try:
            return json.loads(self.path.read_text())
        except (OSError, ValueError):
            return None

    def acquire(self) -> None:
        me = {"run_id": self.run_id, "pid": os.getpid(), "host": socket.gethostname(),
              "started": time.strftime("%Y-%m-%d %H:%M:%S")}
        for _ in range(3):
            try:
                fd = os.open(self.path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
            except FileExistsError:
                holder = self._holder()
                if holder is None:  # being written right now, or unreadable: look again
                    time.sleep(0.1)
                    holder = self._holder()
                if holder is not None and (holder.get("host") != me["host"] or _alive(int(holder.get("pid", -1)))):
                    raise OutputBusy(
                        f"{self.path.parent}: in use by run {holder.get('run_id')} (pid {holder.get('pid')} on "
                        f"{holder.get('host')}, started {holder.get('started')}); wait for it to end or give "
                        f"another --output (delete {self.path} if that run is gone on another host)") from None
                self.note = (f"took over the stale lock of run {holder.get('run_id')} (pid {holder.get('pid')}, "
                             f"no longer running)" if holder else "took over an unreadable lock")
                self.path.unlink(missing_ok=True)
                continue
            with os.fdopen(fd, "w") as f:
                json.dump(me, f)
            self._held = True
            _remove_partials(self.path.parent)
            return
        raise OutputBusy(f"{self.path}: could not take the output directory's lock")

    def release(self) -> None:
        """Remove the lock. A directory that no longer lets it be removed (made read-only
        during the run) keeps it: the run's own error says what happened, and the next run
        takes the stale lock over."""
        if self._held:
            self._held = False
            try:
                holder = self._holder()
                if holder is None or holder.get("run_id") == self.run_id:
                    self.path.unlink(missing_ok=True)
                if self._new and not any(self.path.parent.iterdir()):  # a run that wrote nothing leaves nothing
                    self.path.parent.rmdir()
            except OSError:
                pass

    def __enter__(self):
        self.acquire()
        return self

    def __exit__(self, *exc):
        self.release()
