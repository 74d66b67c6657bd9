"""Result files of the solid: an XDMF time series (dolfinx) and VTU snapshots (meshio).

XDMF (dolfinx.io.XDMFFile, parallel HDF5): displacement, velocity (P1; P2 fields
are interpolated to their vertex values) and the von Mises stress (DG0, cell
data). VTU (meshio, written on rank 0 in input numbering): the vertex fields
and von Mises per cell, one file per time plus a ParaView ``.pvd`` collection.
"""

from __future__ import annotations

from pathlib import Path

import dolfinx
import dolfinx.fem
import dolfinx.io

from transfer.meshfile import write_pvd

from .elasticity import Elasticity
from .vertex_io import write_vtu


class XDMFSeries:
    """``with XDMFSeries(path, solver) as out: out.write(t)`` writes the mesh once
    and, per call, displacement, velocity and von Mises at time ``t``."""

    def __init__(self, path, solver: Elasticity, fields=("displacement", "velocity", "von_mises")):
        self.path = Path(path)
        self.solver = solver
        self.fields = tuple(fields)
        mesh = solver.mesh
        if mesh.comm.rank == 0:
            self.path.parent.mkdir(parents=True, exist_ok=True)
        mesh.comm.barrier()
        self._file = dolfinx.io.XDMFFile(mesh.comm, str(self.path), "w")
        self._file.write_mesh(mesh)
        self._p1 = {}

    def _p1_of(self, f: dolfinx.fem.Function) -> dolfinx.fem.Function:
        element = f.function_space.ufl_element()
        if element.degree() == 1 and element.family() == "Lagrange":
            return f
        if f.name not in self._p1:
            V = dolfinx.fem.VectorFunctionSpace(self.solver.mesh, ("Lagrange", 1))
            self._p1[f.name] = dolfinx.fem.Function(V, name=f.name)
        g = self._p1[f.name]
        g.interpolate(f)
        return g

    def write(self, t: float | None = None) -> None:
        t = self.solver.t if t is None else t
        for name in self.fields:
            if name == "von_mises":
                self._file.write_function(self.solver.von_mises("DG0"), t)
            else:
                self._file.write_function(self._p1_of(self.solver.output(name)), t)

    def close(self) -> None:
        self._file.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


class VTUSeries:
    """VTU files ``<stem>_<k>.vtu`` (meshio, rank 0) of the vertex fields and
    a ``<stem>.pvd`` collection listing them with their times."""

    def __init__(self, directory, solver: Elasticity, stem: str = "solid",
                 fields=("displacement", "velocity")):
        self.dir = Path(directory)
        self.solver = solver
        self.stem = stem
        self.fields = tuple(fields)
        self.entries: list[tuple[float, str]] = []
        if solver.mesh.comm.rank == 0:
            self.dir.mkdir(parents=True, exist_ok=True)

    def write(self, t: float | None = None) -> Path:
        s = self.solver
        t = s.t if t is None else t
        name = f"{self.stem}_{len(self.entries):05d}.vtu"
        point_data = {f: s.output(f) for f in self.fields}
        write_vtu(self.dir / name, s.vertices, point_data=point_data,
                  cell_data={"von_mises": s.von_mises("DG0")})
        self.entries.append((float(t), name))
        if s.mesh.comm.rank == 0:
            write_pvd(self.dir / f"{self.stem}.pvd", self.entries)
        return self.dir / name
