"""Output files written whole or not at all.

A writer writes under a temporary name in the file's own directory (hidden, with the
file's extension, so that meshio, matplotlib or VTK pick the same format), which is then
renamed over the file (``os.replace``, atomic within one file system). A failure while
writing (a full disk, a directory made read-only, an interrupt) removes the temporary
file: the file is the previous version or absent, never truncated. An OSError names the
file, not the temporary one (a writer's own ``write`` error names no file at all).
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

#: what a temporary name holds between the file's stem and its extension
PARTIAL = ".partial-"


def partial_name(path: Path, pid: int | None = None) -> Path:
    """The temporary name process `pid` (default: this one) writes `path` under."""
    return path.with_name(f".{path.stem}{PARTIAL}{os.getpid() if pid is None else pid}{path.suffix}")


@contextmanager
def atomic_path(path) -> Iterator[Path]:
    """``with atomic_path(path) as tmp: write(tmp)``: `path` replaced by what was written to
    `tmp` when the block ends normally; otherwise `tmp` removed and `path` left as it was."""
    path = Path(path)
    tmp = partial_name(path)
    try:
        yield tmp
        os.replace(tmp, path)
    except BaseException as exc:
        try:
            tmp.unlink(missing_ok=True)
        except OSError:
            pass
        if isinstance(exc, OSError):
            raise OSError(exc.errno, exc.strerror or str(exc), str(path)) from exc
        raise


def write_text(path, text: str) -> None:
    """`text` written atomically to `path`."""
    with atomic_path(path) as tmp:
        tmp.write_text(text)
