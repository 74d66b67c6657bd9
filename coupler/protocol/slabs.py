"""How a grid fluid on several MPI ranks cuts its structured grid into slabs, one per rank
(the Chorin fluid's ``slab_axis`` and ``ranks``): the direction, the cells of each slab, and
what makes a cut impossible. Shared by the participant (:mod:`fluid_chorin.slabs`) and the
flow rule, which refuses such a scene before anything starts. Imports nothing: the participant's
settings module declares its keys from it."""

from __future__ import annotations

#: the ``slab_axis`` setting: a direction, or the one of the most cells (the first of them)
SLAB_AXES = ("longest", "x", "y", "z")
#: cells each slab needs at least (a ghost layer of one cell on each side, two owned faces sent down)
MIN_CELLS = 2


def slab_direction(shape, setting: str) -> int:
    """0, 1 or 2 (x, y, z) for ``setting`` (one of :data:`SLAB_AXES`) on a grid of ``shape`` (nx, ny, nz)."""
    if setting == "longest":
        return max(range(3), key=lambda d: int(shape[d]))
    return "xyz".index(setting)


def slab_bounds(shape, ranks: int, setting: str, whole: int | None = None) -> tuple[int, list[int]]:
    """(direction, bounds): slab r holds the cells ``bounds[r]`` to ``bounds[r + 1] - 1`` along the
    direction; ValueError (one line, the reason) when a slab would have fewer than :data:`MIN_CELLS`,
    or (:func:`check_whole`) when the slabs would cut the lines along ``whole`` each rank must hold."""
    d = slab_direction(shape, setting)
    n = int(shape[d])
    if ranks > 1 and n < MIN_CELLS * ranks:
        raise ValueError(f"{ranks} ranks need at least {MIN_CELLS} cells each along {'xyz'[d]} (slab_axis "
                         f"{setting!r}), the grid has {n}")
    check_whole(d, ranks, whole)
    return d, [n * r // ranks for r in range(ranks + 1)]


def check_whole(d: int, ranks: int, whole: int | None) -> None:
    """ValueError when slabs along direction ``d`` on ``ranks`` ranks cut the lines of cells along
    ``whole`` (None: none) that a drag reads whole (the lines across a gap of a lubrication drag)."""
    if ranks > 1 and d == whole:
        raise ValueError(f"its drag reads whole lines of cells along {'xyz'[d]} (across the gap), the slabs "
                         f"along {'xyz'[d]} of {ranks} ranks would cut them: set slab_axis to an axis in the "
                         f"gap's plane")
