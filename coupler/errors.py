"""Errors of the coupler that the CLI prints as one line (``varcouple: error: ...``).

Like :mod:`transfer.errors`, every message names the file (and the scene key)
and the reason, so that no traceback is needed to act on it.
"""


class CouplerError(Exception):
    """A user-facing error: bad input file, field, option or scene."""


class SceneError(CouplerError, ValueError):
    """A scene file is invalid: message reads ``<scene.toml>: [table] key: reason``."""
