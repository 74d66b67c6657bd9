"""The OpenFOAM fluid's error: a binary failed or left output that cannot be used (a log's
tail, a missing or malformed processor directory, non-finite fields)."""


class OpenFOAMError(RuntimeError):
    """An OpenFOAM binary failed or produced unusable output."""
