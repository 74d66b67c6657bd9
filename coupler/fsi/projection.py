"""The ``l2`` and ``pseudo_l2`` exchange operators: a field of one participant carried to another's
mesh by the variational transfer of paper 2.1 (``T = D^-1 B``, eq. 3-4), in one process
(:class:`Projection`, on the participants' whole meshes) or on the coupler's P ranks
(:class:`ProjectionRanks`, on the cells of the parts each rank holds: the operator distributed,
nothing gathered). One code path: the two differ only in the spaces they assemble, where the
source values come from and where the result goes."""

from __future__ import annotations

import time
import warnings

import numpy as np

from transfer import FunctionSpace, OverlapWarning, StructuredGrid, Transfer
from transfer.distributed import Part


class Projection:
    """A field of one participant carried to another's mesh (paper 2.1, eq. 3-4): P1/Q1 at a
    mesh's points or P0/Q0 in its cells on the source side (option ``kind``, else by the field's
    length), the same family on a target mesh and Q0 in the cells of a grid. Where the source does
    not reach, the target gets zero, or NaN with option ``fill = "nan"`` (a mesh file that records
    the transfer). Options ``quadrature_degree`` and ``threads`` go to the assembly; a ``kind``
    given is assembled with the operators, before the first step. Figures of a step: the covered
    fraction, the uncovered dofs and the conservation error over the overlap (``projections``)."""

    #: the coupler's ranks the operator is distributed over (None: one process)
    comm = None

    def __init__(self, ctx, exchange, method: str):
        (source,) = exchange.sources
        self.participant, self.field = source.split(".", 1)
        self.target_participant = exchange.target_participant
        self.ctx, self.method, self.name = ctx, method, exchange.target
        options = exchange.options
        self.fill = np.nan if options.get("fill") == "nan" else 0.0
        self.assembly = {"quadrature_degree": options.get("quadrature_degree"), "nthreads": options.get("threads", 1)}
        self.units = ""
        self._transfers: dict = {}
        self._last = None  # (transfer, source values) of the last evaluation
        if "kind" in options:
            self._transfer(options["kind"])

    def spaces(self, kind: str) -> tuple:
        """The source and target spaces of a point or cell field."""
        S, G = (self.ctx.meshes[name] for name in (self.participant, self.target_participant))
        return FunctionSpace(S, _family(S, kind)), FunctionSpace(G, _family(G, kind, grid="Q0"))

    def source_values(self, outputs) -> tuple[np.ndarray, str]:
        """The source field's values at the source dofs and their kind (point or cell)."""
        values = np.asarray(outputs[self.participant][self.field])
        return values, "point" if len(values) == self.ctx.meshes[self.participant].num_points else "cell"

    def _transfer(self, kind: str):
        if kind not in self._transfers:
            source, target = self.spaces(kind)
            start = time.perf_counter()
            with warnings.catch_warnings(action="ignore", category=OverlapWarning):  # reported once, below
                T = Transfer.assemble(source, target, self.method, comm=self.comm, **self.assembly)
            self.ctx.phases.add("transfer", time.perf_counter() - start)
            self.ctx.warn(T.warnings)
            self._transfers[kind] = T
        return self._transfers[kind]

    def evaluate(self, outputs) -> np.ndarray:
        values, kind = self.source_values(outputs)
        T = self._transfer(kind)
        flat = values.reshape(len(values), -1) if values.ndim > 1 else values
        self._last = T, flat
        out = T.apply(flat, fill=self.fill)
        return out.reshape((len(out),) + values.shape[1:])

    def deliver(self, value):
        return value

    def figures(self) -> dict:
        """The last evaluation's figures, from global counts and integrals (on ranks: the
        distributed operator's allreduced sums, then the ratios). Collective on ranks."""
        if self._last is None:
            return {}
        T, u = self._last
        return {"projections": {self.name: {"method": self.method, "covered_fraction": T.covered_fraction,
                                            "uncovered_dofs": int(T.num_target_dofs - T.num_covered),
                                            "conservation_error": T.conservation_error(u)}}}


class ProjectionRanks(Projection):
    """:class:`Projection` on the coupler's ranks: between the cells of the parts this rank holds
    of each participant (:meth:`coupler.fsi.held.Held.mesh`), the global ids of their rows the dofs
    of a :class:`transfer.distributed.Part` (vertices for P1/Q1, cells for P0/Q0: the participants'
    ``location``), the source values fetched at those rows, the result delivered at the input rows
    of the target's parts held here."""

    def __init__(self, ctx, exchange, method: str):
        self.comm = ctx.comm
        names = (exchange.sources[0].split(".", 1)[0], exchange.target_participant)
        self.held = {name: ctx.held[name] for name in names}
        self.parts = {name: self.held[name].mesh(ctx.parts[name]) for name in names}  # (rows, mesh)
        super().__init__(ctx, exchange, method)

    def spaces(self, kind: str) -> tuple:
        return tuple(Part(mesh, _family(mesh, kind), rows)
                     for rows, mesh in (self.parts[self.participant], self.parts[self.target_participant]))

    def source_values(self, outputs=None) -> tuple[np.ndarray, str]:
        rows, _ = self.parts[self.participant]
        held = self.held[self.participant]
        return held.fetch(self.field, rows), "cell" if held.location == "cells" else "point"

    def deliver(self, value) -> list[np.ndarray]:
        rows, _ = self.parts[self.target_participant]
        return self.held[self.target_participant].inputs(rows, value)


def _family(mesh, kind: str, grid: str | None = None) -> str:
    """The Lagrange family of a point (degree 1) or cell (degree 0) field on `mesh`; on a grid
    `grid` when given (the fluid's cells)."""
    if isinstance(mesh, StructuredGrid):
        return grid or ("Q1" if kind == "point" else "Q0")
    return ("P" if mesh.is_simplex else "Q") + ("1" if kind == "point" else "0")
