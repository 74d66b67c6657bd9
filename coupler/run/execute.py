"""One scene run into its output directory: what
``varcouple run`` does and what ``varcouple study`` does for each of its runs."""

from __future__ import annotations

from coupler.errors import CouplerError, NotConverged, RunFailed, SceneError, one_line
from coupler.protocol.transport import new_run_id
from coupler.run.outdir import OutputLock, prepare
from transfer import TransferError


def execute(scene, origin: str, log=print) -> dict:
    """Run `scene` into ``scene.output_dir`` (`origin` names where that directory comes from),
    locked for the run; its summary. A failure once the run started is a :class:`RunFailed`;
    not converging stays :class:`NotConverged` and a scene key found wrong while running a
    :class:`SceneError`."""
    run_id = new_run_id()
    lock = OutputLock(scene.output_dir, run_id)
    out = prepare(scene.output_dir, origin)
    with lock:
        if lock.note:
            log(f"note: {out}: {lock.note}")
        try:
            from coupler.run.runner import run as run_coupled_case

            return run_coupled_case(scene, log=log, run_id=run_id)
        except (NotConverged, SceneError):
            raise
        except (CouplerError, TransferError, OSError) as exc:  # the run started: a failure, not bad input
            raise RunFailed(one_line(exc)) from exc
