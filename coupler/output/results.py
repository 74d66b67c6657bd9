"""What a coupled run writes: VTU series with .pvd files for ParaView, summary.json
(rewritten atomically after every step), the residual plot, and the comparison with
a known solution (``[check]``)."""

from __future__ import annotations

import json
from pathlib import Path

import meshio
import numpy as np

from transfer import StructuredGrid

from coupler.errors import CouplerError

SUMMARY = "summary.json"


class Series:
    """VTU files per output step and a .pvd collection for ParaView."""

    def __init__(self, directory: Path, name: str, mesh):
        self.directory, self.name, self.mesh = directory, name, mesh
        self.entries: list[tuple[float, str]] = []

    def write(self, step: int, t: float, point_data=None, cell_data=None) -> Path:
        file = f"{self.name}_{step:04d}.vtu"
        cell_type = "hexahedron" if isinstance(self.mesh, StructuredGrid) else self.mesh.cell_type
        meshio.write(self.directory / file, meshio.Mesh(
            self.mesh.points, [(cell_type, self.mesh.cells)], point_data=point_data or {},
            cell_data={k: [v] for k, v in (cell_data or {}).items()}))
        self.entries.append((t, file))
        rows = "\n".join(f'    <DataSet timestep="{t:.9g}" file="{f}"/>' for t, f in self.entries)
        (self.directory / f"{self.name}.pvd").write_text(
            f'<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1">\n  <Collection>\n{rows}\n'
            f'  </Collection>\n</VTKFile>\n')
        return self.directory / file


def write_summary(out: Path, summary: dict) -> None:
    tmp = out / (SUMMARY + ".tmp")
    tmp.write_text(json.dumps(summary, indent=2, default=float))
    tmp.replace(out / SUMMARY)


def check_displacement(check: dict, points: np.ndarray, u: np.ndarray) -> dict:
    """Compare the displacement with the scene's expected one ([check]): the largest
    error over the selected vertices relative to the largest expected value."""
    from coupler.protocol.expressions import evaluate_expression

    selected = np.ones(len(points), bool)
    if "where" in check:
        selected = evaluate_expression(check["where"], points) > 0.5
    if not selected.any():
        raise CouplerError(f"[check] where: {check['where']!r} selects no vertex of the solid")
    error = scale = 0.0
    for axis, c in enumerate("xyz"):
        if c in check:
            exact = evaluate_expression(check[c], points[selected])
            error = max(error, float(np.max(np.abs(u[selected, axis] - exact))))
            scale = max(scale, float(np.max(np.abs(exact))))
    relative = error / scale if scale > 0 else error
    return {"error": relative, "absolute_error": error, "tolerance": check["tolerance"],
            "passed": bool(relative <= check["tolerance"]), "vertices": int(selected.sum())}


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
