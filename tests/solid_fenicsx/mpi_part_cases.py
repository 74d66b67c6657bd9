"""The solid participant's parts on the ranks of MPI.COMM_WORLD (tests/solid_fenicsx/test_solid_parts.py):
``mpirun -n N python tests/solid_fenicsx/mpi_part_cases.py`` configures cases/block_compression's solid with
a coupled pressure on its top face, answers geometry and one advance with every gathering method of the
solid made to fail (VertexIO's gathers), then joins the ranks' parts as the coupler does
(:class:`coupler.protocol.parts.Layout`) and prints, as JSON from rank 0, each rank's part sizes against
its owned sizes and whether the joined arrays equal the old gathered ones exactly."""

from __future__ import annotations

import json
from contextlib import contextmanager
from pathlib import Path

import numpy as np
from mpi4py import MPI

from coupler.plan.plan import make_plan
from coupler.protocol.parts import Layout, Part
from coupler.protocol.wire import Field
from coupler.scene import load
from solid_fenicsx.participant import SolidParticipant
from solid_fenicsx.vertex_io import VertexIO

ROOT = Path(__file__).resolve().parents[2]


@contextmanager
def no_gather():
    """VertexIO's gathers raise: whatever the participant calls meanwhile gathers nothing."""
    saved = {name: getattr(VertexIO, name) for name in ("_gatherv", "boundary_triangles")}

    def refuse(*args, **kwargs):
        raise AssertionError("a participant verb gathered a whole field or mesh")

    for name in saved:
        setattr(VertexIO, name, refuse)
    try:
        yield
    finally:
        for name, method in saved.items():
            setattr(VertexIO, name, method)


def pressure_at(points: np.ndarray) -> np.ndarray:
    return 1e5 * (1.0 + points[:, 0] + 2.0 * points[:, 1])


def main() -> None:
    comm = MPI.COMM_WORLD
    config = make_plan(load(ROOT / "cases" / "block_compression")).participant("solid").config
    config["loads"] = config["loads"][:3]  # the top face's pressure comes from the coupler instead
    config["wetted"] = "zmax"
    p = SolidParticipant()
    p.bind("parts", "solid", comm)
    p.configure(config)
    io = p.solver.vertices
    with no_gather():
        header, geometry = p.geometry()
        ids, points = geometry["point_ids"], geometry["points"].data
        out = p.advance(0, 0, 0.0, 1.0, {"pressure": Field("pressure", pressure_at(points), "Pa")})
    tdim = p.solver.mesh.topology.dim
    sizes = {"points": len(ids), "owned_points": io.num_owned, "cells": len(geometry["cell_ids"]),
             "owned_cells": p.solver.mesh.topology.index_map(tdim).size_local,
             "outputs": {k: len(f.data) for k, f in out.items()}, "all_points": io.num_points}
    parts = comm.gather((geometry, out), root=0)  # the test's own gather: what the coupler receives
    old = {"points": io.points(), "cells": io.tetrahedra(), "interface_triangles": io.boundary_triangles("zmax"),
           **{k: p.solver.vertex_values(k) for k in ("displacement", "velocity", "von_mises")}}
    sizes = comm.gather(sizes, root=0)
    if comm.rank != 0:
        return
    geometry_parts = [Part(r, f"rank {r}", header if r == 0 else {}, {k: v if isinstance(v, Field) else Field(k, v)
                                                                      for k, v in g.items()})
                      for r, (g, _) in enumerate(parts)]
    layout, joined = Layout.join_geometry("solid", geometry_parts)
    fields = layout.join([Part(r, f"rank {r}", {}, o) for r, (_, o) in enumerate(parts)])
    same = {"points": np.array_equal(joined["points"].data, old["points"]),
            "cells": np.array_equal(joined["cells"].data, old["cells"]),
            "interface_triangles": np.array_equal(joined["interface_triangles"].data, old["interface_triangles"][0]),
            **{k: np.array_equal(fields[k].data, old[k]) for k in ("displacement", "velocity", "von_mises")}}
    coupled = pressure_at(joined["points"].data)  # the coupler's rows per rank: its inputs exactly
    inputs = layout.split({"pressure": Field("pressure", coupled)})
    same["inputs"] = all(np.array_equal(part["pressure"].data, pressure_at(np.asarray(g["points"].data)))
                         for part, (g, _) in zip(inputs, parts))
    print(json.dumps({"ranks": comm.size, "sizes": sizes, "same": same,
                      "max_displacement": float(np.abs(fields["displacement"].data).max())}))


if __name__ == "__main__":
    main()
