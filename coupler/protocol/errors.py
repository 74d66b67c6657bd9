"""Errors of the participant protocol (docs/protocol.md): malformed or mismatched messages,
and participants that fail, die or do not answer. Each is a :class:`coupler.errors.CouplerError`:
the CLI prints it as one line. A field that cannot travel (NaN/inf, dtype, name) is the
project's one :class:`transfer.errors.FieldError`."""

from coupler.errors import CouplerError, SceneError


class ProtocolError(CouplerError):
    """A message breaks the participant protocol: malformed payload, or a reply that does
    not answer the request (stale or mismatched run id, participant, verb, window,
    iteration). Such data is rejected, never used."""


class RanksError(CouplerError):
    """A failure that every rank of a participant on several MPI ranks raises together, once the
    ranks agreed on it (:func:`coupler.protocol.participant.agree`): each rank answers it as its
    error reply and keeps serving, where another exception on a rank other than 0 aborts the job."""


class ParticipantFailure(CouplerError):
    """Base class of the errors that name the participant that failed (``name``)."""

    def __init__(self, name: str, message: str):
        self.name = name
        super().__init__(message)

    def at(self, where: str) -> "ParticipantFailure":
        """This error, its message prefixed by where in the run it happened (a time step)."""
        self.args = (f"{where}: {self.args[0]}",)
        return self

    def __reduce__(self):  # travels between the coupler's ranks as it was raised: type, text, notes
        return _rebuilt, (type(self), self.args, dict(self.__dict__))


def _rebuilt(cls, args: tuple, state: dict) -> ParticipantFailure:
    """A :class:`ParticipantFailure` unpickled without its constructor (whose arguments differ
    by subclass): its message (``args``, with any :meth:`~ParticipantFailure.at` prefix) and
    attributes (``name``, the notes added to it) as they were."""
    error = cls.__new__(cls)
    error.args = args
    error.__dict__.update(state)
    return error


class ParticipantError(ParticipantFailure):
    """The participant answered with an error (its handler raised): ``message`` is its text."""

    def __init__(self, name: str, message: str):
        self.message = message
        super().__init__(name, f"participant {name!r} failed: {message}")


class InputError(ValueError):
    """Bad input a participant finds in what it was given at set-up (a boundary that selects no
    facet, a tag its mesh file lacks, a mesh or generator parameters it cannot use): its error
    reply is marked ``"input": true`` and the coupler raises :class:`ParticipantInputError`."""


class ParticipantInputError(ParticipantError, SceneError):
    """A participant refused its input (:class:`InputError`): bad input like a scene error,
    status ``invalid`` and exit code 2 wherever it is found."""

    def __init__(self, name: str, message: str):
        self.message = message
        ParticipantFailure.__init__(self, name, f"participant {name!r} refused its input: {message}")


class ParticipantDied(ParticipantFailure):
    """The participant's process is gone (liveliness token lost, process exited)."""

    def __init__(self, name: str, reason: str):
        self.reason = reason
        super().__init__(name, f"participant {name!r} died: {reason}")


class ParticipantStopped(ParticipantFailure):
    """The participant's process is there but stopped (SIGSTOP, SIGTSTP): it answers nothing."""

    def __init__(self, name: str, reason: str):
        self.reason = reason
        super().__init__(name, f"participant {name!r} is stopped: {reason}")


class ParticipantTimeout(ParticipantFailure):
    """The participant is alive but did not answer ``verb``, nor report progress on it, within
    ``seconds`` (the scene's ``[messaging] timeout``); ``progressed``: it had reported some before."""

    def __init__(self, name: str, verb: str, seconds: float, progressed: bool = False):
        self.verb = verb
        self.seconds = seconds
        silent = f"and reported no progress on it for {seconds:g} s" if progressed else f"within {seconds:g} s"
        super().__init__(name, f"participant {name!r} did not answer {verb!r} {silent} ([messaging] timeout = "
                               f"{seconds:g}: raise it for longer solves)")
