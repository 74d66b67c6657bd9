"""One scene run into its output directory: what
``varcouple run`` does and what ``varcouple study`` does for each of its runs."""

from __future__ import annotations

import os
from contextlib import ExitStack, nullcontext

from coupler.errors import CouplerError, NotConverged, RunFailed, SceneError, one_line
from coupler.protocol.transport import new_run_id
from coupler.run.outdir import OutputLock, prepare
from transfer import TransferError


def job_size() -> int:
    """The ranks of the MPI job mpirun started this process in (1 outside one)."""
    for size in ("OMPI_COMM_WORLD_SIZE", "PMI_SIZE"):
        if size in os.environ:
            return int(os.environ[size])
    return 1


def coupler_ranks(scene) -> int:
    """P, the coupler's ranks: those of this process's MPI job, or ``[coupling] ranks``; SceneError
    when both are given and differ."""
    key, job = scene.coupling["ranks"], job_size()
    if job > 1 and key > 1 and key != job:
        raise SceneError(f"{scene.path}: [coupling] ranks: {key}, but this coupler runs on {job} MPI ranks "
                         f"(mpirun -n {job}): give one of them, or the same number")
    return job if job > 1 else key


def execute(scene, origin: str, log=print, run_id: str | None = None) -> dict:
    """Run `scene` into ``scene.output_dir`` (`origin` names where that directory comes from),
    locked for the run, as run `run_id` (default a new one: its summary's ``run_id``); its summary. A failure once the run started is a :class:`RunFailed`;
    not converging stays :class:`NotConverged` and a scene key found wrong while running a
    :class:`SceneError`. In an MPI job of P > 1 ranks every rank runs the coupler
    (:mod:`coupler.run.ranks`); rank 0 locks the directory and logs."""
    comm = run_class = None
    if coupler_ranks(scene) > 1 and job_size() > 1:
        from mpi4py import MPI

        from coupler.run.ranks import RanksRun, agree

        comm, run_class = MPI.COMM_WORLD, RanksRun
        run_id = comm.bcast(run_id or new_run_id())
        if comm.rank:
            log = lambda line: None  # noqa: E731
        out = agree(comm, prepare, scene.output_dir, origin) if comm.rank == 0 else agree(comm, lambda: None)
        lock = OutputLock(scene.output_dir, run_id) if comm.rank == 0 else nullcontext()
    else:
        run_id = run_id or new_run_id()
        lock = OutputLock(scene.output_dir, run_id)
        out = prepare(scene.output_dir, origin)
    with ExitStack() as stack:
        if comm is None:
            stack.enter_context(lock)
        else:  # rank 0's lock refused (another run writes there): every rank raises it
            agree(comm, stack.enter_context, lock)
        if getattr(lock, "note", None):
            log(f"note: {out}: {lock.note}")
        try:
            from coupler.run.runner import run as run_coupled_case

            return run_coupled_case(scene, log=log, run_id=run_id, comm=comm, run_class=run_class)
        except (NotConverged, SceneError):
            raise
        except (CouplerError, TransferError, OSError) as exc:  # the run started: a failure, not bad input
            raise RunFailed(one_line(exc)) from exc
