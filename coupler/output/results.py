"""What a run writes for people and scripts: VTU series with .pvd files for ParaView and
summary.json (rewritten atomically after every step)."""

from __future__ import annotations

import json
from pathlib import Path

import meshio

from transfer import StructuredGrid
from transfer.meshfile import write_pvd

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
        write_pvd(self.directory / f"{self.name}.pvd", self.entries)
        return self.directory / file


def write_summary(out: Path, summary: dict, name: str = SUMMARY) -> None:
    """`summary` as JSON in ``out/name``, written atomically."""
    tmp = out / (name + ".tmp")
    tmp.write_text(json.dumps(summary, indent=2, default=float))
    tmp.replace(out / name)
