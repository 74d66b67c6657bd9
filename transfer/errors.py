"""Typed errors and warnings of the transfer library.

Every error names what was wrong with which input, so that command-line tools
can print it as one line instead of a traceback.
"""

import re

#: a quoted fragment of a message: 'text', "text", b'bytes'
QUOTED = re.compile(r"b?'(?:[^'\\]|\\.)*'" + r'|b?"(?:[^"\\]|\\.)*"')


def without_content(message: str) -> str:
    """A file reader's message (numpy, meshio: ``could not convert string to float: '<a line>'``)
    with its quoted fragments, which are the file's content, shown as ``'...'``: no error
    quotes a file."""
    return QUOTED.sub("'...'", message)


class TransferError(Exception):
    """Base class of all errors raised by :mod:`transfer`."""


class MeshError(TransferError, ValueError):
    """A mesh is malformed: bad arrays, unknown cell type, inverted or degenerate cells."""


class SpaceError(TransferError, ValueError):
    """A function space does not fit its mesh (e.g. P1 on a hexahedral mesh)."""


class NoOverlapError(TransferError):
    """Source and target do not overlap: nothing can be transferred."""


class QuadratureError(TransferError, ValueError):
    """A quadrature degree outside [1, :data:`transfer.quadrature.MAX_DEGREE`]."""


class FieldError(TransferError, ValueError):
    """A field that cannot be used: the wrong shape, NaN/inf values, or (between processes,
    :mod:`coupler.protocol.wire`) a dtype or name that cannot travel. ``field`` is its name
    when known (the message then starts with it)."""

    def __init__(self, message: str, field: str | None = None):
        self.field = field
        super().__init__(message if field is None else f"field {field!r}: {message}")


class MeshFileError(TransferError):
    """A mesh file cannot be read or written as asked (missing, unreadable, no such field,
    a format that would drop the fields, an output that would overwrite an input)."""


class OverlapWarning(UserWarning):
    """Source and target look like different length units or places (sizes far apart, or
    boxes that barely overlap): the transfer runs, but its result is probably not meant."""
