"""Freed heap memory given back to the system. An operator's assembly frees far more than it
keeps (the kernel's row pieces, the CSR copies, the matrices' intermediates); glibc's malloc
keeps the freed pages of its heap resident for later allocations, so without this every
rebuilt transfer would leave the process at the peak of its assembly (docs/scaling.md)."""

from __future__ import annotations

import ctypes
import ctypes.util


def _malloc_trim():
    try:
        return ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6").malloc_trim
    except (OSError, AttributeError):  # not glibc: nothing to trim
        return None


_TRIM = _malloc_trim()


def give_back() -> None:
    """Return the free pages of every malloc arena to the system (glibc's ``malloc_trim(0)``;
    nothing elsewhere)."""
    if _TRIM is not None:
        _TRIM(0)
