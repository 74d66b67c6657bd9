"""Measured fracture surfaces as height maps: one reader (and writer) per file format.

A height map is an array ``heights[j, i]`` (metres), shape (ny, nx): row j at y = y0 + j dy,
column i at x = x0 + i dx, with ``spacing`` = (dx, dy) and ``origin`` = (x0, y0).

- ``.npz``: both faces in one file, arrays ``lower`` and ``upper`` (ny, nx) and ``spacing``
  [dx, dy]; the origin is (0, 0).
- XYZ: one face per plain-text file, one point ``x y z`` per line (spaces, tabs or commas;
  ``#`` starts a comment) on a regular grid, in any order.

The readers raise ``ValueError`` with one line naming the file and the reason (a missing
array, NaN heights, points off a regular grid); the generator that reads them prefixes its
parameter's name.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from transfer.errors import without_content

#: how far a point of an XYZ grid may lie from its grid position, a fraction of the spacing
GRID_TOLERANCE = 1e-6


def _file(path) -> Path:
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{'no file' if not path.exists() else 'not a file:'} {path}")
    return path


def _finite(heights: np.ndarray, what: str) -> np.ndarray:
    """`heights` as floats, refused with the first bad row and column if any is NaN or infinite."""
    bad = ~np.isfinite(heights)
    if bad.any():
        j, i = np.argwhere(bad)[0]
        raise ValueError(f"{what} has {int(bad.sum())} NaN or infinite heights, the first at row {j}, column {i}")
    return heights


def read_npz(path) -> tuple[tuple[np.ndarray, np.ndarray], tuple[float, float]]:
    """``((lower, upper), (dx, dy))`` of an ``.npz`` holding both faces (each (ny, nx), at
    least 2 x 2 nodes, the same shape) and their ``spacing``."""
    path = _file(path)
    try:
        data = np.load(path, allow_pickle=False)
    except Exception as exc:  # noqa: BLE001 - any reader error means the file is not an .npz
        raise ValueError(f"{path} is not a readable .npz file ({without_content(str(exc))})") from None
    with data:
        for name in ("lower", "upper", "spacing"):
            if name not in data.files:
                raise ValueError(f"{path} has no array {name!r} (it holds: {', '.join(data.files) or 'nothing'})")
        faces = [np.asarray(data[name]) for name in ("lower", "upper")]
        spacing = np.asarray(data["spacing"])
    for name, h in zip(("lower", "upper"), faces):
        if h.ndim != 2 or min(h.shape) < 2 or not np.issubdtype(h.dtype, np.number):
            raise ValueError(f"array {name!r} of {path} must be numbers of shape (ny, nx), at least 2 x 2; "
                             f"got {h.dtype} {h.shape}")
        _finite(h.astype(float), f"array {name!r} of {path}")
    if faces[0].shape != faces[1].shape:
        raise ValueError(f"the faces of {path} have different extents: lower {faces[0].shape}, "
                         f"upper {faces[1].shape} nodes (ny, nx)")
    if (spacing.shape != (2,) or not np.issubdtype(spacing.dtype, np.number)
            or not np.all(np.isfinite(spacing)) or not np.all(spacing > 0)):
        raise ValueError(f"array 'spacing' of {path} must be [dx, dy], two positive numbers; got {spacing.tolist()}")
    return (faces[0].astype(float), faces[1].astype(float)), (float(spacing[0]), float(spacing[1]))


def _axis(values: np.ndarray, name: str, path) -> tuple[float, float, np.ndarray]:
    """(origin, spacing, index of each value) of coordinates on a regular axis."""
    distinct = np.unique(values)
    if len(distinct) < 2:
        raise ValueError(f"{path}: every point has the same {name} = {distinct[0]:g}: not a 2D grid")
    step = float(np.median(np.diff(distinct)))  # a stray value does not move it
    index = np.rint((values - distinct[0]) / step).astype(np.int64)
    off = np.abs(values - (distinct[0] + index * step))
    if off.max() > GRID_TOLERANCE * step:
        k = int(np.argmax(off))
        raise ValueError(f"{path}: not a regular grid: {name} = {values[k]:.9g} (point {k + 1} of the file) lies "
                         f"{off[k]:.3g} m off the grid of spacing {step:.9g} m from {distinct[0]:.9g} m")
    return float(distinct[0]), float(step), index


def _bad_line(lines: list[str]) -> str:
    """Where `lines` stop being lines of numbers, without quoting them (a file's content stays
    out of messages)."""
    columns = None
    for number, line in enumerate(lines, start=1):
        words = line.split("#", 1)[0].split()
        if not words:
            continue
        try:
            [float(w) for w in words]
        except ValueError:
            return f"line {number} is not numbers"
        if columns is not None and len(words) != columns:
            return f"line {number} has {len(words)} numbers, the lines before it {columns}"
        columns = len(words)
    return "not lines of numbers"


def read_xyz(path) -> tuple[np.ndarray, tuple[float, float], tuple[float, float]]:
    """``(heights, (dx, dy), (x0, y0))`` of a plain-text XYZ grid: heights (ny, nx), every
    grid node given once."""
    path = _file(path)
    try:
        lines = path.read_text().replace(",", " ").splitlines()
    except UnicodeDecodeError as exc:
        raise ValueError(f"{path} is not a text file of x y z lines (byte {exc.start} is not UTF-8)") from None
    try:
        points = np.loadtxt(lines, comments="#", ndmin=2)
    except ValueError:
        raise ValueError(f"{path} is not a text file of x y z lines ({_bad_line(lines)})") from None
    if points.shape[1] != 3 or len(points) < 4:
        raise ValueError(f"{path} must hold at least 4 lines of three numbers x y z; got {points.shape[0]} "
                         f"lines of {points.shape[1]}")
    if not np.all(np.isfinite(points[:, :2])):
        raise ValueError(f"{path}: a point's x or y is NaN or infinite (line of point "
                         f"{int(np.argwhere(~np.isfinite(points[:, :2]))[0, 0]) + 1})")
    x0, dx, i = _axis(points[:, 0], "x", path)
    y0, dy, j = _axis(points[:, 1], "y", path)
    nx, ny = int(i.max()) + 1, int(j.max()) + 1
    count = np.zeros((ny, nx), np.int64)
    np.add.at(count, (j, i), 1)
    if np.any(count != 1):
        jj, ii = np.argwhere(count != 1)[0]
        raise ValueError(f"{path}: not a regular grid: the node x = {x0 + ii * dx:.9g}, y = {y0 + jj * dy:.9g} "
                         f"is given {count[jj, ii]} times ({len(points)} points for {nx} x {ny} nodes)")
    heights = np.empty((ny, nx))
    heights[j, i] = points[:, 2]
    return _finite(heights, str(path)), (dx, dy), (x0, y0)


def write_npz(path, lower, upper, spacing) -> Path:
    """Write both faces ((ny, nx) each) and their spacing [dx, dy] as :func:`read_npz` reads them."""
    np.savez_compressed(path, lower=np.asarray(lower, float), upper=np.asarray(upper, float),
                        spacing=np.asarray(spacing, float))
    return Path(path)


def write_xyz(path, heights, spacing, origin=(0.0, 0.0)) -> Path:
    """Write one face ((ny, nx)) as ``x y z`` lines, x fastest, to full precision."""
    h = np.asarray(heights, float)
    y, x = np.meshgrid(origin[1] + spacing[1] * np.arange(h.shape[0]), origin[0] + spacing[0] * np.arange(h.shape[1]),
                       indexing="ij")
    np.savetxt(path, np.column_stack([x.ravel(), y.ravel(), h.ravel()]), fmt="%.17g",
               header="x y z [m]: a measured fracture face")
    return Path(path)
