"""Errors of the coupler that the CLI prints as one line (``varcouple: error: ...``).

Like :mod:`transfer.errors`, every message names the file (and the scene key)
and the reason, so that no traceback is needed to act on it.
"""


class CouplerError(Exception):
    """A user-facing error: bad input file, field, option or scene."""


class SceneError(CouplerError, ValueError):
    """A scene file is invalid: message reads ``<scene.toml>: [table] key: reason``."""


class NotConverged(CouplerError):
    """The coupling iteration, or an inner solve of a participant, did not converge: the run
    stops with status ``not_converged`` (its results so far kept) instead of claiming a
    result it does not have."""


class RunFailed(CouplerError):
    """A run that had started failed (a participant died or answered an error, NaN in a
    field, an output that could not be written): status ``failed``, exit code 4."""


class Terminated(BaseException):
    """SIGTERM (``timeout``, batch schedulers) received: handled like Ctrl-C, status ``terminated``."""

    def __init__(self, signum: int = 15):
        self.signum = signum
        super().__init__(f"terminated by signal {signum}")


#: Exit code of ``varcouple run`` for each final status of summary.json (README: "When a run fails").
EXIT_CODES = {"completed": 0, "check_failed": 1, "invalid": 2, "not_converged": 3, "failed": 4,
              "interrupted": 130, "terminated": 143}


def one_line(exc: BaseException, message: str | None = None) -> str:
    """An error (or `message` about it) as one line; an OSError as ``<file>: <reason>``; its notes
    (``add_note``: what else went wrong while it ended the run) after it, separated by ``;``."""
    if message is not None:
        text = message
    elif isinstance(exc, OSError) and exc.strerror:
        text = f"{exc.filename}: {exc.strerror}" if exc.filename else exc.strerror
    else:
        text = " ".join(str(exc).split()) or type(exc).__name__
    return "; ".join([text, *(" ".join(note.split()) for note in getattr(exc, "__notes__", ()))])


def run_status(exc: BaseException | None) -> str:
    """The status a run that ended with ``exc`` (None: no exception) records."""
    if exc is None:
        return "completed"
    if isinstance(exc, KeyboardInterrupt):
        return "interrupted"
    if isinstance(exc, Terminated):
        return "terminated"
    if isinstance(exc, NotConverged):
        return "not_converged"
    if isinstance(exc, SceneError):
        return "invalid"
    return "failed"
