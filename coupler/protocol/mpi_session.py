"""A run's own Open MPI session directory, removed however the run ends.

Open MPI 4 keeps a session directory per host and user (``$TMPDIR/ompi.<host>.<uid>``: the
jobs' contact files and PMIx's store) and the ranks' shared-memory segments
(``/dev/shm/vader_segment.*``); a job or a singleton killed with SIGKILL leaves them behind.
The first ``varcouple`` process of a run (:func:`mpi_session`, from :func:`coupler.cli.main`)
makes ``$TMPDIR/varcouple-mpi-<pid>-XXXXXXXX`` and a directory of the same name in /dev/shm,
names them in ``VARCOUPLE_MPI_SESSION`` (which :func:`coupler.protocol.mpi.mpi_environment`
turns into ``orte_tmpdir_base`` and ``btl_vader_backing_directory`` for every MPI process of the
run: this one, the coupler's ranks, the participants and their mpiruns), and removes both when
it ends. A process killed with SIGKILL cannot: the next start removes the directories whose
owner (the pid in the name) is gone.
"""

from __future__ import annotations

import os
import re
import shutil
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import MutableMapping

SESSION_VAR = "VARCOUPLE_MPI_SESSION"
PREFIX = "varcouple-mpi-"
SHM = Path("/dev/shm")


def shared_memory_dir(session: str) -> str:
    """Where the ranks of `session` keep their shared-memory segments: ``/dev/shm/<its name>``
    (the session directory itself on a system without /dev/shm)."""
    return str(SHM / Path(session).name) if SHM.is_dir() else session


def _owner_gone(path: Path) -> bool:
    found = re.fullmatch(rf"{PREFIX}(\d+)-[a-z0-9_]{{8}}", path.name)
    if found is None:
        return False
    try:
        os.kill(int(found.group(1)), 0)
    except ProcessLookupError:
        return True
    except PermissionError:
        return False
    return False


def sweep() -> list[Path]:
    """Remove the session directories (in ``TMPDIR`` and /dev/shm) whose owner is gone; them."""
    removed = []
    for where in {Path(tempfile.gettempdir()), SHM}:
        try:
            candidates = list(where.glob(f"{PREFIX}*"))
        except OSError:
            continue
        for path in candidates:
            if path.is_dir() and _owner_gone(path):
                shutil.rmtree(path, ignore_errors=True)
                removed.append(path)
    return removed


@contextmanager
def mpi_session(env: MutableMapping[str, str] | None = None):
    """``with mpi_session():`` this run's session directory (its path), named in ``env``
    (default ``os.environ``) for the processes below; removed at the end. In a process of a run
    that has one already (a coupler rank, a participant) the run's, which its owner removes."""
    env = os.environ if env is None else env
    if env.get(SESSION_VAR):
        yield env[SESSION_VAR]
        return
    sweep()
    session = tempfile.mkdtemp(prefix=f"{PREFIX}{os.getpid()}-")
    shm = shared_memory_dir(session)
    if shm != session:
        os.mkdir(shm, 0o700)
    env[SESSION_VAR] = session
    try:
        yield session
    finally:
        if env.get(SESSION_VAR) == session:
            del env[SESSION_VAR]
        for key in [k for k, v in env.items() if k.startswith("OMPI_MCA_") and v in (session, shm)]:
            del env[key]  # what confine() derived from it
        shutil.rmtree(session, ignore_errors=True)
        shutil.rmtree(shm, ignore_errors=True)
