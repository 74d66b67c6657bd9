"""What one rank of a coupler on several ranks holds of a participant (docs/scaling.md, step 3):
the parts of the participant's ranks assigned to it (round-robin: participant rank r to coupler
rank r mod P), their rows of every output field and the rows of every input they need, in the
participant's input numbering. The cells a coupler rank works on (:meth:`Held.mesh`) are those
of its parts, or any others :meth:`Held.place` gives (in a flow scene the solid cells over its
grid slab: :func:`coupler.fsi.ranks.on_slabs`). :meth:`Held.fetch` carries output rows to whatever
rows a coupler rank works on (its slab of the grid, the vertices of its solid cells) and
:meth:`Held.inputs` the values a coupler rank computed to the input rows of its parts, through
:class:`transfer.rows.Rows`: nothing is gathered."""

from __future__ import annotations

import numpy as np

from coupler.errors import CouplerError
from coupler.protocol.transport import coupler_rank_of
from transfer import Mesh
from transfer.mesh import CELL_TYPES
from transfer.rows import Rows


def assigned(rank: int, coupler_ranks: int, parts: int) -> list[int]:
    """The participant ranks (of `parts`) coupler rank `rank` talks to: round-robin
    (:func:`coupler.protocol.transport.coupler_rank_of`, the rule the participants link by)."""
    return [r for r in range(parts) if coupler_rank_of(r, coupler_ranks) == rank]


class Held:
    """Coupler rank's share of participant `name`: its parts' row ids (``ids``, concatenated in
    part order: ``out_ids``), their input rows (``in_ids``) and the latest output fields at
    ``out_ids`` (:attr:`fields`), and for a mesh the coordinates of those rows (:attr:`points`,
    once :meth:`mesh` made it). ``count``: the rows of the whole participant; ``cell_type``: that
    of the cells of its geometry (:meth:`mesh`); ``location``: what a row is, a point (``points``)
    or a cell (``cells``: P0/Q0 fields, the rows the global cell ids of its geometry)."""

    def __init__(self, comm, name: str, ranks: list[int], ids: list[np.ndarray], inputs: list[np.ndarray],
                 cell_type: str = "tetra", location: str = "points"):
        self.comm, self.name, self.ranks, self.cell_type, self.location = comm, name, ranks, cell_type, location
        self.ids, self.input_rows = ids, inputs
        self.out_ids = np.concatenate(ids).astype(np.int64) if ids else np.zeros(0, np.int64)
        self.in_ids = np.concatenate(inputs).astype(np.int64) if inputs else np.zeros(0, np.int64)
        self.count = comm.allreduce(len(self.out_ids))
        if len(self.out_ids) and (self.out_ids.min() < 0 or self.out_ids.max() >= self.count):
            raise CouplerError(f"participant {name!r}: its parts' row ids reach outside 0..{self.count - 1}")
        self.rows = Rows(comm, self.count)
        once = self.rows.block(self.out_ids, np.ones(len(self.out_ids)), add=True)
        if comm.allreduce(int(np.count_nonzero(once != 1))):
            raise CouplerError(f"participant {name!r}: its parts do not number each of its {self.count} rows once")
        self.fields: dict[str, np.ndarray] = {}
        self.points: np.ndarray | None = None
        self._mesh = self._cells = None

    def fetch(self, field: str, wanted: np.ndarray) -> np.ndarray:
        """The output `field` at the rows `wanted` (any rows of the whole). Collective."""
        return self.rows.move(self.out_ids, self.fields[field], wanted)

    def inputs(self, held: np.ndarray, values) -> list[np.ndarray]:
        """Each of this rank's parts' input rows of a field that every coupler rank gives at its
        rows `held`. Collective."""
        rows = self.rows.move(held, values, self.in_ids)
        return np.split(rows, np.cumsum([len(i) for i in self.input_rows])[:-1]) if self.ranks else []

    def max_norm(self, field: str) -> float:
        """max over this rank's rows of |value| (the Euclidean norm of each row of a vector
        field; 0 without rows)."""
        a = self.fields.get(field)
        return float(np.max(np.linalg.norm(a.reshape(len(a), -1), axis=1))) if a is not None and len(a) else 0.0

    def mesh(self, geometry: list[dict]) -> tuple[np.ndarray, Mesh]:
        """(rows, mesh): the cells of the parts held here (their `geometry`), or those :meth:`place`
        gave, on the global vertices they use, with the coordinates of those owned elsewhere
        fetched, and the global ids of the mesh's rows (its vertices; with ``location`` cells its
        cells, ``out_ids``); made once (the operators and the output share it). Collective the
        first time."""
        if self._mesh is None:
            self._mesh = self._made_mesh(geometry)
        return self._mesh

    def part_cells(self, geometry: list[dict]) -> np.ndarray:
        """The cells of the parts held here (global vertex ids, one row each)."""
        k = CELL_TYPES[self.cell_type][1]
        cells = [np.asarray(g["cells"], np.int64).reshape(-1, k) for g in geometry]
        return np.concatenate(cells) if cells else np.zeros((0, k), np.int64)

    def place(self, cells: np.ndarray) -> None:
        """Work on `cells` (global vertex ids, one row each; over the ranks each of the
        participant's cells once) instead of the cells of the parts held here: :meth:`mesh` is
        made of them from now on."""
        self._cells, self._mesh = cells, None

    def coordinates(self, geometry: list[dict], wanted: np.ndarray, axis: int | None = None) -> np.ndarray:
        """The coordinates (n, 3), or those along `axis` (n,), of the points `wanted` (global point
        ids) from the parts' `geometry`, wherever they are held. Collective."""
        points = [np.asarray(g["points"]).reshape(-1, 3) for g in geometry]
        if self.location == "points":
            rows, ids = self.rows, self.out_ids
        else:  # the coordinates are rows of the points, not of the fields
            ids = [np.asarray(g.get("point_ids", np.arange(len(p))), np.int64) for g, p in zip(geometry, points)]
            ids = np.concatenate(ids) if ids else np.zeros(0, np.int64)
            rows = Rows(self.comm, self.comm.allreduce(len(ids)))
        points = _joined(points)
        if axis is not None:
            return rows.move(ids, points[:, axis], wanted, keep=False)
        return rows.move(ids, points, wanted).reshape(-1, 3)

    def _made_mesh(self, geometry: list[dict]) -> tuple[np.ndarray, Mesh]:
        cells = self.part_cells(geometry) if self._cells is None else self._cells
        vertices, local = np.unique(cells, return_inverse=True)
        reference = self.coordinates(geometry, vertices)
        name = f"{self.name} part"
        mesh = (Mesh(reference, local.reshape(cells.shape), self.cell_type, name=name, reorient=True) if len(cells)
                else Mesh.empty(self.cell_type, name))
        if self.location == "points":
            self.points = _joined([np.asarray(g["points"]).reshape(-1, 3) for g in geometry])
            return vertices, mesh
        self.points = mesh.points[mesh.cells].mean(axis=1)  # the cells' centroids (their P0 dofs)
        return self.out_ids, mesh


def _joined(points: list[np.ndarray]) -> np.ndarray:
    return np.concatenate(points) if points else np.zeros((0, 3))
