"""The solid participant: :class:`Elasticity` behind the protocol of docs/protocol.md.

Started by the coupler as ``[mpirun -n N] python -m solid_fenicsx --run-id R
--name solid --connect ENDPOINT``. ``configure`` receives the solid's part of the
scene (:func:`coupler.plan.effects.elasticity.solid_config`, completed by the other
effects' rules): the mesh (a file, a box or a generator of :mod:`transfer.generators`),
named boundaries (box faces, expressions in x, y, z on facet midpoints, or tags of the
file or generator), the material, the loads (:mod:`solid_fenicsx.load_steps`: constant,
ramped or per step, a stress-controlled platen), contact (mortar between two faces, or a
rigid plane), the solver and whether the problem is dynamic (paper eq. 13). ``advance``
solves one step (static: one solve, or the platen's search of solves) with the coupler's
inputs (``pressure`` at the vertices, applied on the wetted boundary; with config
``traction = "full"`` the vector ``traction`` instead) and returns the displacement,
velocity and von Mises stress at the vertices, in the numbering of ``geometry``; it
reports every inner solve (``report_solve``: the linear solve, the contact QP, the
platen's search, converged or not; each contact solve starts from the latest one, that of
the previous load step, platen trial or coupling iteration) and the step's figures
(``report_figures``: contact, platen, fluid forces) and, with contact, the vertex fields
``contact_pressure`` (exactly 0 off contact), ``gap``, ``in_contact``, ``slave`` and
``mortar_weight`` (D_kk of eq. 9's dual basis; zero off the slave face), so that
``sum(contact_pressure * mortar_weight)`` is the normal contact force. ``configure``
refuses a load, wetted interface or contact face on a boundary that selects no
facet, naming the scene key. ``geometry`` also returns the
wetted boundary's facets as ``interface_triangles`` (outward oriented), so the
coupler can sample the fluid pressure on that surface (paper 2.3, Steps 2-3).
"""

from __future__ import annotations

import re
import time

import numpy as np
from mpi4py import MPI

from coupler.protocol.participant import Participant
from coupler.protocol.wire import Field
from coupler.protocol.expressions import evaluate_expression
from transfer.generators.lattices import box_lattices

from .elasticity import Elasticity
from .load_steps import StaticStep, add_loads
from .mesh import BOX_FACES, SolidMeshError, exterior_midpoints, generated_mesh, lattice_mesh, read_mesh
from .settings import PARTICIPANT

_AXES = {"x": 0, "y": 1, "z": 2}


def _face_predicate(face: str, lower, upper):
    axis, side = BOX_FACES.index(face) // 2, BOX_FACES.index(face) % 2
    value = (upper if side else lower)[axis]
    tol = 1e-9 * (np.asarray(upper) - np.asarray(lower)).max()
    return lambda x: np.abs(x[axis] - value) <= tol


def _expression_predicate(text: str):
    return lambda x: evaluate_expression(text, x.T) > 0.5


def _why_empty(solid, name, spec, predicate) -> str:
    """Why boundary `name` (scene `spec`: an expression, a box face or a file tag, and its
    `predicate`; None for file tags) has no exterior facet of `solid`."""
    comm = solid.comm
    if predicate is None:
        return f"its tag {solid.tags_of(name)[0]} of the mesh file is on no exterior facet"
    what = f"box face {spec!r}" if spec in BOX_FACES else f"expression {spec!r}"
    exterior, midpoints = exterior_midpoints(solid.mesh)
    owned = exterior < solid.mesh.topology.index_map(solid.mesh.topology.dim - 1).size_local
    hit = exterior[np.asarray(predicate(midpoints), dtype=bool).reshape(-1) & owned]
    count = comm.allreduce(len(hit))
    if count:  # selected, then taken by boundaries given after it
        local = solid.facet_tags.values[np.isin(solid.facet_tags.indices, hit)]
        now = set().union(*comm.allgather(set(local.tolist())))
        owners = [n for n, tag in solid.boundaries.items() if tag in now]
        return (f"the {count} facets {what} selects all carry boundar{'ies' if len(owners) > 1 else 'y'} "
                f"{', '.join(map(repr, owners))}, given after it (a facet has one tag)")
    x = solid.mesh.geometry.x
    # (the pickled allreduce's MIN compares whole arrays: it fails on 3 coordinates)
    lower, upper = np.min(comm.allgather(x.min(axis=0)), axis=0), np.max(comm.allgather(x.max(axis=0)), axis=0)
    axes = sorted(set(re.findall(r"\b[xyz]\b", str(spec)))) or list(_AXES)
    spans = ", ".join(f"{a} in [{lower[_AXES[a]]:g}, {upper[_AXES[a]]:g}]" for a in axes)
    return f"{what} is false on every boundary facet midpoint; the mesh spans {spans}"


def _boundary_uses(config: dict) -> list[tuple[str, str | int]]:
    """(scene key, boundary) of every boundary a load, the wetted interface or contact acts on."""
    uses = [(load.get("key", f"load {i}"), load["boundary"]) for i, load in enumerate(config.get("loads", []), start=1)
            if load.get("boundary") is not None]
    wetted = config.get("wetted")
    uses += [("[coupling] interface", b) for b in ([] if wetted is None else [wetted] if isinstance(wetted, (str, int))
                                                   else wetted)]
    if config.get("contact"):
        uses += [(f"[contact] {side}", config["contact"][side]) for side in ("slave", "master")
                 if config["contact"].get(side) is not None]
    return uses


class SolidParticipant(Participant):
    """Linear elasticity on dolfinx (see :mod:`solid_fenicsx.elasticity`)."""

    kind = PARTICIPANT.kind

    def __init__(self):
        self.solver: Elasticity | None = None
        self.states: dict[int, dict] = {}
        self.dynamic = False

    def announce(self) -> dict:
        return {"kind": self.kind, "provides": ["displacement", "velocity", "von_mises"],
                "accepts": ["pressure", "traction"]}

    def configure(self, config: dict) -> None:
        comm = self.comm or MPI.COMM_WORLD
        boundaries, tags = {}, {}
        box = config.get("box")
        for name, spec in config.get("boundaries", {}).items():
            if isinstance(spec, int):
                tags[name] = spec
            elif spec in BOX_FACES and box is not None:
                boundaries[name] = _face_predicate(spec, box["lower"], box["upper"])
            else:
                boundaries[name] = _expression_predicate(spec)
        if box is not None:  # each rank makes its own cells and points
            lattices = box_lattices(box["shape"], box["lower"], box["upper"], box.get("jitter", 0.0), box.get("seed", 0))
            solid = lattice_mesh(lattices, "[geometry.solid] box", boundaries, comm)
        elif "generator" in config:
            g = config["generator"]
            solid = generated_mesh(g["name"], g.get("parameters"), boundaries, comm)
        else:
            solid = read_mesh(config["mesh"], boundaries=boundaries, comm=comm)
        solid.require_tags(tags, config.get("mesh") or (f"the mesh of generator {config['generator']['name']!r}"
                                                        if "generator" in config else "[geometry.solid] box"))
        for key, name in _boundary_uses(config):  # a load on no facet: a singular system or a lost load
            if solid.comm.allreduce(len(solid.facets(tags.get(name, name)))) == 0:
                why = _why_empty(solid, name, config.get("boundaries", {}).get(name), boundaries.get(name))
                raise SolidMeshError(f"{key} boundary {name!r}: selects no facet of the mesh ({why})")
        material, settings = config["material"], PARTICIPANT.configuration(config)
        self.dynamic = bool(config.get("dynamic"))
        s = Elasticity(solid, E=material["E"], nu=material["nu"], density=material.get("density", 0.0),
                       degree=settings["degree"], scheme="newmark" if self.dynamic else None,
                       fluid_density=float(config.get("fluid_density", 0.0)),
                       solver=settings["linear_solver"], rtol=settings["rtol"], max_it=settings["max_iterations"])

        def where(name):
            return tags.get(name, name)

        loads, platen, stresses = add_loads(s, config.get("loads", []), where)
        self.wetted = config.get("wetted")
        self.wetted_boundary = None
        if self.wetted is not None:
            # one boundary, or a list of them (e.g. both faces of a fracture)
            self.wetted_boundary = (where(self.wetted) if isinstance(self.wetted, (str, int))
                                    else [where(w) for w in self.wetted])
            # the fluid's pressure (-p n), or its full traction (-p I + tau) n as a vector (coupler/viscous.py)
            if config.get("traction", "pressure") == "full":
                s.add_traction_field(self.wetted_boundary, "traction")
            else:
                s.add_pressure_field(self.wetted_boundary, "pressure")
        self.solver, self.states = s, {}
        self.contact, self.steps = None, int(config.get("steps", 1))
        if config.get("contact"):
            from .contact import Contact

            c = config["contact"]
            options = {"active_set": {"tol": c["tolerance"], "max_iter": c["max_iterations"]},
                       "snes_vi": {"rtol": c["tolerance"], "max_iter": c["max_iterations"]},
                       "multilevel": {"tol": c["tolerance"], "maxiter": c["max_iterations"],
                                      **{k: c[k] for k in ("levels", "coarse_shape", "margin", "threads") if k in c},
                                      **({"presmooth": c["smoothing"], "postsmooth": c["smoothing"],
                                          "coarse_smooth": c["smoothing"]} if "smoothing" in c else {})}}[c["solver"]]
            sides = {"obstacle": c["obstacle"]} if c.get("obstacle") else {"master": where(c["master"])}
            self.contact = Contact(s, where(c["slave"]), solver=c["solver"], search_distance=c.get("search_distance"),
                                   max_normal_angle=c.get("max_normal_angle", 45.0), **sides, **options)
        self.loads = loads
        self.static = None if self.dynamic else StaticStep(s, loads, self.steps, platen, stresses, self.contact)

    def geometry(self):
        """This rank's part of the mesh (docs/protocol.md, "Parts"; nothing gathered): its owned
        vertices (``point_ids``, ``points``), its own tetrahedra (``cell_ids``, ``cells`` in input
        vertex ids) and, with a wetted boundary, its facets there as ``interface_triangles``
        (outward oriented, right-hand rule), for the coupler's volume -> surface transfer of the
        fluid pressure. The coupler joins the ranks' parts in input numbering."""
        io = self.solver.vertices
        point_ids, points = io.part_points()
        cell_ids, cells = io.part_tetrahedra()
        fields = {"point_ids": point_ids, "points": Field("points", points, "m"),
                  "cell_ids": cell_ids, "cells": Field("cells", np.asarray(cells, np.int64))}
        header = {"cell_type": "tetra", "boundaries": dict(self.solver.solid.boundaries)}
        if self.wetted_boundary is not None:
            triangles = io.part_boundary_triangles(self.wetted_boundary)[:, :3]
            if io.comm.allreduce(len(triangles)) == 0 and self.rank == 0:
                raise ValueError(f"the wetted boundary {self.wetted!r} has no facets on the mesh boundary")
            fields["interface_triangles"] = Field("interface_triangles", np.ascontiguousarray(triangles))
            header["interface"] = self.wetted
        return header, fields

    def advance(self, window, iteration, t, dt, inputs):
        start = time.perf_counter()
        s = self.solver
        for name in ("pressure", "traction"):
            if name not in inputs:
                continue
            if name not in s.fields:
                raise ValueError(f"input {name!r} needs a wetted boundary (config 'wetted') with "
                                 f"traction = {'full' if name == 'traction' else 'pressure'!r}")
            s.vertices.set_part(s.fields[name], inputs[name].data)
        extra = {}
        if self.static is not None:
            reports, figures, slave = self.static.run(int(window))
            for solver, converged, iterations, residual, tolerance, detail, history in reports:
                self.report_solve(solver, converged, iterations, residual, tolerance, detail=detail, history=history)
            if self.contact is not None and "pressure" in s.fields:
                figures.update(self._wetted_forces())
            extra = self._slave_fields(slave)
        else:
            for load in self.loads:
                load.apply(int(window), self.steps, ramp=False)
            s.step(dt)
            for r in s.info.solves:
                self.report_solve(f"{r.solver} {r.what}", r.converged, r.iterations, r.residual, r.tolerance,
                                  detail=r.reason)
        out = {what: s.vertices.part_values(s.output(what)) for what in ("displacement", "velocity", "von_mises")}
        out.update({k: s.vertices.part_values(f) for k, f in extra.items()})
        if self.static is not None and figures:  # contact or a platen: the step's figures, timed
            self.report_figures(**self.static.timed(figures, start))
        units = {"displacement": "m", "velocity": "m/s", "von_mises": "Pa", "contact_pressure": "Pa", "gap": "m",
                 "in_contact": "1", "slave": "1", "mortar_weight": "m^2"}
        return {k: Field(k, v, units[k]) for k, v in out.items()}

    def _wetted_forces(self) -> dict:
        """The coupled fluid pressure's force on each wetted face (``fluid_force_<face>_<x|y|z>``):
        with contact, the fluid's share of the load the platen carries (its pressure is zero where
        the faces touch)."""
        faces = [self.wetted] if isinstance(self.wetted, (str, int)) else list(self.wetted)
        figures = {}
        for name, boundary in zip(faces, [self.wetted_boundary] if len(faces) == 1 else self.wetted_boundary):
            force = self.solver.pressure_resultant(boundary, self.solver.fields["pressure"])
            figures.update({f"fluid_force_{name}_{c}": float(force[i]) for i, c in enumerate("xyz")})
        return figures

    def _slave_fields(self, values: dict) -> dict:
        """Values at the contact's slave nodes as P1 functions, zero off the slave face."""
        import dolfinx.fem

        if not values:
            return {}
        W = dolfinx.fem.FunctionSpace(self.solver.mesh, ("Lagrange", 1))  # same vertex dofs as the P1 vectors
        dofs, at = self.contact.slave_dofs()  # the local dofs on the slave face (the values: the whole face)
        fields = {}
        for name, v in values.items():
            fields[name] = dolfinx.fem.Function(W)
            fields[name].x.array[dofs] = v[at]
        return fields

    def save_state(self, window):
        platen = self.static.platen if self.static is not None else None
        self.states[int(window)] = {"solid": self.solver.save_state(),
                                    "platen": platen.save_state() if platen else None}
        for w in [w for w in self.states if w < int(window) - 1]:
            del self.states[w]

    def restore_state(self, window):
        state = self.states[int(window)]
        self.solver.restore_state(state["solid"])
        if state["platen"] is not None:
            self.static.platen.restore_state(state["platen"])
        # not the contact's x: it is only the start of the next contact solve (warm start), and
        # the latest solution (the previous coupling iteration's) is the closest one
