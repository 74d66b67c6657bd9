"""Figures of a transfer run, drawn with matplotlib's Agg backend (no display needed).

Volume fields are shown on a horizontal slice: each field is projected (with
:mod:`transfer` itself, exactly) onto a thin slab of box cells around the
plane z = slice_z, so a pixel is the field's mean over a small box, the same
way for every mesh and cell type. Surface meshes are shown as their dofs
coloured by value, seen from above.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from pathlib import Path

import numpy as np

from transfer import FunctionSpace, NoOverlapError, OverlapWarning, StructuredGrid, Transfer

#: slab thickness as a fraction of the largest extent of the meshes
SLAB_THICKNESS = 0.005


def _magnitude(values: np.ndarray) -> np.ndarray:
    v = np.asarray(values, dtype=np.float64)
    return v if v.ndim == 1 else np.linalg.norm(v.reshape(len(v), -1), axis=1)


def default_slice_z(*spaces: FunctionSpace) -> float:
    """Middle of the z-range the meshes have in common (of the last one if none)."""
    lo = max(s.mesh.bounding_box()[0][2] for s in spaces)
    hi = min(s.mesh.bounding_box()[1][2] for s in spaces)
    if lo > hi:
        lo, hi = spaces[-1].mesh.bounding_box()[0][2], spaces[-1].mesh.bounding_box()[1][2]
    return 0.5 * (lo + hi)


def slice_grid(spaces, z: float, resolution: int = 160) -> StructuredGrid:
    """One layer of box cells over the xy-extent of all meshes, centred on z."""
    lo = np.min([s.mesh.bounding_box()[0] for s in spaces], axis=0)
    hi = np.max([s.mesh.bounding_box()[1] for s in spaces], axis=0)
    extent = np.maximum(hi - lo, 1e-12 * max(np.max(hi - lo), 1.0))
    h = max(extent[0], extent[1]) / resolution
    shape = (max(1, int(round(extent[0] / h))), max(1, int(round(extent[1] / h))), 1)
    dz = SLAB_THICKNESS * float(np.max(extent))
    return StructuredGrid.from_bounds((lo[0], lo[1], z - dz / 2), (hi[0], hi[1], z + dz / 2), shape, name="slice")


def sampler(space: FunctionSpace, grid: StructuredGrid) -> Callable[[np.ndarray], np.ndarray]:
    """A function: dof values on `space` (scalars; NaN allowed) -> (ny, nx) image on
    the slab, NaN where the mesh does not reach or the values are NaN."""
    nx, ny = grid.shape[0], grid.shape[1]
    # Q1 on general hexahedra is not polynomial: the kernel integrates it with a rule on each
    # intersection piece, whose cost grows with the points. The pieces are smaller than a
    # pixel, so one point per piece draws the same picture several times faster.
    qdeg = 1 if space.family == "Q1" else None
    try:  # the slab spans all meshes: meshes of different sizes are the run's warning, not the plot's
        with warnings.catch_warnings(action="ignore", category=OverlapWarning):
            op = Transfer.assemble(space, FunctionSpace(grid, "Q0"), "pseudo_l2", quadrature_degree=qdeg)
    except NoOverlapError:
        return lambda values: np.full((ny, nx), np.nan)

    def sample(values):
        values = np.asarray(values, dtype=np.float64)
        ok = np.isfinite(values)
        image = op(np.where(ok, values, 0.0))
        if not ok.all():  # blank the pixels that see a NaN dof
            weight = op(ok.astype(np.float64))
            image[~(weight > 1 - 1e-9)] = np.nan
        return image.reshape(ny, nx)

    return sample


def transfer_figure(path, *, field: str, source: FunctionSpace, source_values: np.ndarray,
                    target: FunctionSpace, results: list[dict], exact: Callable | None = None,
                    slice_z: float | None = None, title: str = "") -> float | None:
    """Save a PNG: top row the source field and the transferred field of each
    method, bottom row the timings and each method's error (vs `exact` if given,
    else vs the source on the slice). `results` items have keys ``method``,
    ``values``, ``assembly_seconds``, ``apply_seconds``, ``covered_fraction``,
    ``conservation_error``. Returns the slice height (None for surfaces)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ncols = 1 + len(results)
    fig, axes = plt.subplots(2, ncols, figsize=(4.2 * ncols, 7.6), squeeze=False, constrained_layout=True)
    vector = np.asarray(source_values).ndim > 1
    label = f"|{field}|" if vector else field
    src = _magnitude(source_values)
    targets = [_magnitude(r["values"]) for r in results]
    volume = source.mesh.tdim == 3 and target.mesh.tdim == 3

    if volume:
        z = default_slice_z(source, target) if slice_z is None else slice_z
        grid = slice_grid([source, target], z)
        lo, hi = grid.bounding_box()
        extent = (lo[0], hi[0], lo[1], hi[1])
        sample_target = sampler(target, grid)
        top = [sampler(source, grid)(src)] + [sample_target(t) for t in targets]
        if exact is not None:
            reference = exact(grid.cell_centers()).reshape(top[0].shape)
        else:
            reference = top[0]
        bottom = [image - reference for image in top[1:]]
        where, at = f"on the slice z = {z:.4g}", "on the slice"
    else:
        z = None
        ref_target = exact(target.dof_coordinates) if exact is not None else None
        top, bottom = [src] + targets, [t - ref_target if ref_target is not None else None for t in targets]
        where, at = "at the dofs, seen from above", "at the dofs"

    finite = np.concatenate([np.ravel(a)[np.isfinite(np.ravel(a))] for a in top] + [np.zeros(0)])
    vmin, vmax = (float(finite.min()), float(finite.max())) if finite.size else (0.0, 1.0)
    errs = np.concatenate([np.ravel(a)[np.isfinite(np.ravel(a))] for a in bottom if a is not None]
                          + [np.zeros(0)])
    emax = float(np.max(np.abs(errs))) if errs.size and np.max(np.abs(errs)) > 0 else 1.0

    def draw(ax, data, points, **kw):
        if volume:
            return ax.imshow(data, origin="lower", extent=extent, interpolation="nearest", **kw)
        return ax.scatter(points[:, 0], points[:, 1], c=data, s=10, **kw)

    names = [f"source ({source.family}, {source.num_dofs} dofs)"] + \
            [f"{r['method']} ({target.family}, {target.num_dofs} dofs)" for r in results]
    points = [source.dof_coordinates] + [target.dof_coordinates] * len(results)
    for ax, data, name, pts in zip(axes[0], top, names, points):
        im = draw(ax, data, pts, cmap="viridis", vmin=vmin, vmax=vmax)
        ax.set_title(name, fontsize=10)
    fig.colorbar(im, ax=list(axes[0]), shrink=0.85, label=label)

    against = "exact" if exact is not None else "source"
    im = None
    for ax, data, r in zip(axes[1, 1:], bottom, results):
        if data is None:
            ax.set_axis_off()
            continue
        im = draw(ax, data, target.dof_coordinates, cmap="RdBu_r", vmin=-emax, vmax=emax)
        finite_err = np.abs(data[np.isfinite(data)])
        worst = f"{finite_err.max():.2e}" if finite_err.size else "n/a"
        ax.set_title(f"{r['method']} - {against}: max {worst} {at}\nconservation error "
                     f"{r['conservation_error']:.1e}", fontsize=10)
    if im is not None:
        fig.colorbar(im, ax=list(axes[1, 1:]), shrink=0.85, label=f"{label} - {against}")
    if not volume:  # same window for all panels
        both = np.vstack([source.dof_coordinates, target.dof_coordinates])
        pad = 0.03 * max(np.ptp(both[:, 0]), np.ptp(both[:, 1]), 1e-12)
        for ax in list(axes[0]) + list(axes[1, 1:]):
            ax.set_xlim(both[:, 0].min() - pad, both[:, 0].max() + pad)
            ax.set_ylim(both[:, 1].min() - pad, both[:, 1].max() + pad)
    for ax in list(axes[0]) + list(axes[1, 1:]):
        ax.set_aspect("equal")
        ax.set_xlabel("x")
        ax.set_ylabel("y")

    ax = axes[1, 0]
    methods = [r["method"] for r in results]
    pos = np.arange(len(results))
    assembly = [1e3 * r["assembly_seconds"] for r in results]
    apply = [1e3 * r["apply_seconds"] for r in results]
    ax.bar(pos - 0.2, assembly, 0.4, label="assemble", color="tab:blue")
    ax.bar(pos + 0.2, apply, 0.4, label="apply", color="tab:orange")
    for x, a, b in zip(pos, assembly, apply):
        ax.annotate(f"{a:.3g}", (x - 0.2, a), ha="center", va="bottom", fontsize=8)
        ax.annotate(f"{b:.2g}", (x + 0.2, b), ha="center", va="bottom", fontsize=8)
    ax.set_xticks(pos, [f"{m}\n{100 * r['covered_fraction']:.1f}% covered" for m, r in zip(methods, results)],
                  fontsize=9)
    ax.set_ylabel("wall time [ms]")
    ax.set_title("timings", fontsize=10)
    ax.margins(y=0.15)
    ax.legend(fontsize=8)

    fig.suptitle(f"{title}\n{label} {where}" if title else f"{label} {where}", fontsize=11)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return z


def residual_plot(path: Path, result) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    for step in result.steps:
        ax.semilogy(range(1, len(step.residuals) + 1), step.residuals, marker="o", ms=3,
                    label=f"step {step.window}" if len(result.steps) <= 10 else None)
    ax.axhline(result.tolerance, color="k", ls="--", lw=0.8, label="tolerance")
    ax.set_xlabel("coupling iteration")
    ax.set_ylabel("relative interface residual (mass-weighted L2)")
    ax.set_title(f"fixed-point residuals ({result.accelerator.get('name', '')})")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def solver_convergence(path: Path, steps: list[dict]) -> bool:
    """The criterion of every inner solve that reports its history, per iteration, one line per
    step (e.g. the nonsmooth multilevel method's step length); False when none does."""
    curves = [(f"{name}: {r['solver']}, step {s['step']}", r["history"], r["tolerance"])
              for s in steps for name, reports in s.get("solves", {}).items() for r in reports if r.get("history")]
    if not curves:
        return False
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    for label, history, _ in curves:
        ax.semilogy(range(1, len(history) + 1), np.abs(np.asarray(history, float)), marker="o", ms=2,
                    label=label if len(curves) <= 10 else None)
    for tolerance in sorted({t for _, _, t in curves if isinstance(t, float)}):
        ax.axhline(tolerance, color="k", ls="--", lw=0.8)
    ax.set_xlabel("iteration")
    ax.set_ylabel("the solver's criterion")
    ax.set_title("inner solver convergence (dashed: tolerance)")
    if len(curves) <= 10:
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return True

