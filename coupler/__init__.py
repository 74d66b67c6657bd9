"""varcouple.coupler: the part that runs a coupled simulation.

It reads and validates a case's ``scene.toml``, plans which participants and
fields a scene needs, launches the participants as their own processes, talks
to them over zenoh (messaging) and carries fields between their meshes with the
operators of :mod:`transfer`. It owns all output and the ``varcouple``
command-line interface (:mod:`coupler.cli`).

For now it holds the CLI, mesh-file input/output and the transfer scene
(``varcouple transfer``, ``varcouple run`` on a ``[transfer]`` scene); the
coupled parts (planning, participants, messaging, Steps 1-6) come in later
issues.
"""

from .errors import CouplerError, SceneError

__all__ = ["CouplerError", "SceneError"]
