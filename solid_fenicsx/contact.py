"""Frictionless contact for :class:`Elasticity` (paper 2.2, eq. 7-11): two bodies by mortar
coupling, or one body and a rigid plane (:mod:`solid_fenicsx.obstacle`, T = 0).

The unknowns are transformed as in eq. 10-11, ``u = O Q x``:

* ``O`` adds the mortar projection of the master displacement to the slave
  nodes (``u_S = x_S + T x_M``, per component), so the slave unknowns become
  the jump ``u_S - T u_M`` (the identity against an obstacle);
* ``Q`` rotates each constrained slave node to coordinates of its normal and two
  tangents (:func:`tangent_frames`).

The stiffness matrix becomes ``A = (OQ)^T K (OQ)`` (eq. 10), and
non-penetration (eq. 11) the nodewise bound ``x_normal <= g`` (the weighted gap
of :mod:`solid_fenicsx.mortar`): a :class:`nonsmooth.BoundConstrainedQP`
solved by any solver of :mod:`nonsmooth.solvers`. Dirichlet dofs become fixed
components (lower = upper). The multiplier ``b - A x`` at a normal component is
the nodal contact force; divided by ``D_kk`` it is the contact pressure, the
coefficient of the dual-basis multiplier. Tangential components are free
(frictionless). On several MPI ranks the faces and the mortar coupling are gathered on every
rank and the system stays distributed (:mod:`solid_fenicsx.contact_mpi`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from mpi4py import MPI
from scipy.sparse.csgraph import connected_components

from nonsmooth import BoundConstrainedQP, Solution
from nonsmooth import solvers as nonsmooth_solvers
from nonsmooth.distributed import DistributedQP
from nonsmooth.obstacle import rigid_body_modes as body_modes

from .contact_mpi import DistributedTransform
from .mortar import ContactSetupError, Mortar, boundary_face, mortar, tangent_frames
from .obstacle import Plane


def transformation(m: Mortar, num_dofs: int) -> tuple[sp.csr_matrix, sp.csr_matrix]:
    """``O`` and ``Q`` of eq. 10-11 for block size 3 (u = O Q x), in the numbering of the
    mortar's faces; without a master (an obstacle) ``O`` is the identity."""
    s_nodes = m.slave.nodes
    T = m.T.tocoo()
    rows, cols, vals = [np.arange(num_dofs)], [np.arange(num_dofs)], [np.ones(num_dofs)]
    if m.master is not None:
        for c in range(3):  # O: u_S += T x_M, per component
            rows.append(3 * s_nodes[T.row] + c)
            cols.append(3 * m.master.nodes[T.col] + c)
            vals.append(T.data)
    O = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), (num_dofs, num_dofs))
    R, _ = tangent_frames(m.normals)  # Q: x_S = R^T u_S at every slave node
    keep = np.ones(num_dofs, bool)
    qr, qc, qv = [], [], []
    for i in range(3):
        for j in range(3):
            qr.append(3 * s_nodes + i)
            qc.append(3 * s_nodes + j)
            qv.append(R[:, i, j])
    keep[(3 * s_nodes[:, None] + np.arange(3)).ravel()] = False
    idx = np.flatnonzero(keep)
    Q = sp.csr_matrix((np.concatenate(qv + [np.ones(idx.size)]), (np.concatenate(qr + [idx]), np.concatenate(qc + [idx]))),
                      (num_dofs, num_dofs))
    return O, Q


def rigid_body_modes(points: np.ndarray, K: sp.csr_matrix) -> np.ndarray:
    """(3 n, 6 b) translations and rotations (:func:`nonsmooth.obstacle.rigid_body_modes`,
    about each body's centroid) of each of the b bodies (connected components of the
    matrix graph) at nodes ``points`` (n, 3)."""
    n = len(points)
    rows = np.repeat(np.arange(K.shape[0]), np.diff(K.indptr)) // 3
    graph = sp.csr_matrix((np.ones(rows.size), (rows, K.indices // 3)), (n, n))
    count, label = connected_components(graph, directed=False)
    Z = np.zeros((3 * n, 6 * count))
    for b in range(count):
        nodes = np.flatnonzero(label == b)
        dofs = (3 * nodes[:, None] + np.arange(3)).ravel()
        Z[dofs, 6 * b:6 * b + 6] = body_modes(points[nodes] - points[nodes].mean(axis=0))
    return Z


@dataclass
class ContactState:
    """The result of one contact solve (arrays on the slave nodes unless said)."""

    u: np.ndarray  # (num_dofs,) displacement, dof numbering
    pressure: np.ndarray  # contact pressure (dual multiplier coefficient), > 0 only where active, exactly 0 elsewhere
    gap: np.ndarray  # current gap g - x_n (NaN where not covered)
    active: np.ndarray  # nodes in contact
    force: np.ndarray  # (3,) total contact force on the slave body (sum of nodal forces)
    area_fraction: float  # active weight / covered weight of the slave face
    mean_gap: float  # the weighted mean of the gap over the covered slave nodes
    solution: Solution
    seconds: dict = field(default_factory=dict)  # assemble, amg_setup, solve (without it), total; setup (once)

    def summary(self) -> dict:
        covered = np.isfinite(self.gap)
        return {**self.solution.as_dict(), "active_nodes": int(self.active.sum()), "area_fraction": self.area_fraction,
                "max_pressure": float(np.max(self.pressure, initial=0.0)),
                "min_gap": float(np.min(self.gap[covered], initial=np.inf)), "mean_gap": self.mean_gap,
                "contact_force": self.force.tolist(), "phase_seconds": self.seconds}


class Contact:
    """Frictionless contact on an :class:`Elasticity` (P1): two bodies of one mesh
    (mortar, a ``master`` face) or one body and a rigid plane (``obstacle``).

    elasticity : the solid with its loads and Dirichlet conditions
    slave : name (or tag) of the boundary carrying the contact pressure (with a master: the
        finer or curved side; it carries the dual multiplier)
    master : name (or tag) of the other body's contact boundary; or
    obstacle : a rigid plane instead (then no master): ``{"plane": [a, b, c, d]}`` or
        ``{"normal": [a, b, c], "gap": g}`` (:meth:`solid_fenicsx.obstacle.Plane.from_config`)
    solver : a name of :data:`nonsmooth.solvers.SOLVERS`; ``options`` go to it (the multilevel
        solver's hierarchy is built from ``levels``, ``coarse_shape``, ``margin``, ``threads``)
    search_distance, max_normal_angle : of the mortar segmentation
        (:func:`solid_fenicsx.mortar.mortar`)
    near_nullspace : give the solver the rigid body modes of each body (transformed; one rank).
        Off by default: on the Hertz case GAMG with them was slower per active-set solve
        than without (block size 3 only)

    The unknowns x of the QP are numbered like the mesh's input vertices (the order of the
    generator's or the file's points, whatever dolfinx's own numbering), so that
    order-dependent solvers (Gauss-Seidel sweeps of the multilevel method) do the same
    work for the same mesh. On several ranks (solver ``active_set`` only) each rank holds
    the x of the vertices it owns, in that order; ``x`` and ``ContactState.u`` are then the
    local parts, the slave-face arrays of :class:`ContactState` whole on every rank.

    Each solve starts from the last solution ``x`` (a warm start: the active sets the
    solver predicts at it are the last ones, moved by the change of the loads).
    """

    def __init__(self, elasticity, slave, master=None, solver: str = "active_set",
                 search_distance: float | None = None, max_normal_angle: float = 45.0, obstacle=None,
                 near_nullspace: bool = False, **options):
        comm = elasticity.mesh.comm
        if comm.size > 1 and (solver != "active_set" or near_nullspace):
            raise ContactSetupError(f"contact on {comm.size} ranks: solver {solver!r}"
                                    f"{' with near_nullspace' if near_nullspace else ''} assembles serial matrices; "
                                    f"use solver 'active_set' (without near_nullspace) or one rank")
        if (master is None) == (obstacle is None):
            raise ContactSetupError("contact needs either a master face or an obstacle, not both")
        nonsmooth_solvers.get(solver)  # unknown names fail here, before any assembly
        t0 = time.perf_counter()
        self.elasticity = elasticity
        self.slave_boundary, self.master_boundary = slave, master
        V = elasticity.V
        self.solver, self.options, self.near_nullspace = solver, options, near_nullspace
        self.num_dofs = V.dofmap.index_map.size_global * V.dofmap.index_map_bs
        vio = elasticity.vertices
        self.ids = vio.dof_input_ids(V)  # input vertex id of each local dof block (owned, then ghosts)
        coordinates = vio.dof_points(V)
        faces = {"numbering": self.ids, "coordinates": coordinates}
        slave_face = boundary_face(elasticity.solid, V, slave, name=f"slave:{slave}", **faces)
        if obstacle is not None:
            self.mortar = Plane.from_config(obstacle, slave_face).coupling(slave_face)
        else:
            master_face = boundary_face(elasticity.solid, V, master, name=f"master:{master}", **faces)
            self.mortar = mortar(slave_face, master_face, search_distance, max_normal_angle)
        m = self.mortar
        if not m.covered.any():
            raise ContactSetupError(f"no slave node of {slave!r} faces the master {master!r} within the search "
                                    f"distance and normal angle: nothing can come into contact")
        fixed = np.asarray(elasticity.dirichlet_dofs, np.int64)
        on_slave = comm.allreduce(np.intersect1d(self.ids[fixed // 3], m.slave.nodes).size)
        if on_slave:
            raise ContactSetupError(f"{on_slave} slave contact nodes of {slave!r} carry Dirichlet conditions; "
                                    f"constrain the master side or move the Dirichlet boundary")
        self.distributed = DistributedTransform(elasticity, self.ids, m, fixed) if comm.size > 1 else None
        if self.distributed is None:
            self._serial_transformation(coordinates, fixed)
        self.x: np.ndarray | None = None  # the last transformed solution (the next solve's start)
        self.monitor = None  # progress callback given to the contact solver (``monitor(**values)``)
        self._nullspace = None
        if solver == "multilevel" and "hierarchy" not in options:
            keys = ("levels", "coarse_shape", "margin", "threads")
            options["hierarchy"] = self.multilevel_hierarchy(**{k: options.pop(k) for k in keys if k in options})
        self.initial_mean_gap = self.mean(m.gap)
        self.setup_seconds = time.perf_counter() - t0

    def _serial_transformation(self, coordinates: np.ndarray, fixed: np.ndarray) -> None:
        """P = Pi^T O Q (u in dof numbering = P x, x in input numbering), its inverse and the
        Dirichlet components of x, in scipy (one rank)."""
        n = len(self.ids)
        self.dofs = np.empty(n, np.int64)
        self.dofs[self.ids] = np.arange(n)  # dof block of each input vertex
        self.points = coordinates[self.dofs]  # by input vertex id
        m = self.mortar
        O, Q = transformation(m, self.num_dofs)
        block = (3 * self.ids[:, None] + np.arange(3)).ravel()
        Pi = sp.csr_matrix((np.ones(self.num_dofs), (block, np.arange(self.num_dofs))), (self.num_dofs,) * 2)
        self.P = sp.csr_matrix(Pi.T @ O @ Q)  # u (dof numbering) = P x
        # O = I + N with N^2 = 0 (slave rows, master columns): O^-1 = 2 I - O
        self.to_x = sp.csr_matrix(Q.T @ (2 * sp.identity(self.num_dofs, format="csr") - O))  # input numbering u -> x
        self.P_inverse = sp.csr_matrix(self.to_x @ Pi)
        self.fixed_dofs, self.fixed = fixed, 3 * self.ids[fixed // 3] + fixed % 3
        _, slot = tangent_frames(m.normals)
        self.normal_dofs = (3 * m.slave.nodes + slot)[m.covered]
        self.normal_of_node = 3 * m.slave.nodes + slot  # the normal unknown of every slave node

    def mean(self, values: np.ndarray) -> float:
        """The mean of slave-node values over the covered part of the slave face (weighted by D_kk)."""
        m = self.mortar
        return float(np.sum(m.weights[m.covered] * values[m.covered]) / np.sum(m.weights[m.covered]))

    def slave_dofs(self) -> tuple[np.ndarray, np.ndarray]:
        """The local block dofs (owned and ghost) on the slave face and their slave node index."""
        nodes = self.mortar.slave.nodes
        at = np.searchsorted(nodes, self.ids).clip(max=len(nodes) - 1)
        local = np.flatnonzero(nodes[at] == self.ids)
        return local, at[local]

    def problem(self) -> BoundConstrainedQP | DistributedQP:
        """The transformed QP of eq. 10-11 with the current loads (distributed on several ranks)."""
        if self.distributed is not None:
            return self.distributed.problem()
        K, F = self.elasticity.static_system()
        indptr, indices, data = K.getValuesCSR()
        Ks = sp.csr_matrix((data, indices, indptr), shape=(self.num_dofs,) * 2)
        f = F.getArray().copy()
        F.destroy()
        P = self.P
        A = sp.csr_matrix(P.T @ Ks @ P)
        b = P.T @ f
        lower, upper = np.full(self.num_dofs, -np.inf), np.full(self.num_dofs, np.inf)
        upper[self.normal_dofs] = self.mortar.gap[self.mortar.covered]
        lower[self.fixed] = upper[self.fixed] = f[self.fixed_dofs]  # Dirichlet values (set_bc put them into F)
        if self.near_nullspace and self._nullspace is None:  # rigid body modes of each body, transformed
            self._nullspace = self.P_inverse @ rigid_body_modes(self.points[self.ids], Ks)
        return BoundConstrainedQP(A, b, lower, upper, block_size=3, near_nullspace=self._nullspace)

    def multilevel_hierarchy(self, levels: int = 3, coarse_shape=(2, 2, 2), margin: float = 0.0, threads: int = 1):
        """The semi-geometric hierarchy (paper 2.4, :mod:`nonsmooth.hierarchy`), one set of
        grids per body, for the transformed unknowns: its finest prolongation (input
        numbering) mapped to x."""
        from dataclasses import replace

        from nonsmooth.hierarchy import per_body_hierarchy

        tets = self.ids[np.asarray(self.elasticity.V.dofmap.list.array).reshape(-1, 4)]
        p = self.points[tets]
        negative = np.einsum("ij,ij->i", p[:, 1] - p[:, 0], np.cross(p[:, 2] - p[:, 0], p[:, 3] - p[:, 0])) < 0
        tets[negative] = tets[negative][:, [0, 2, 1, 3]]
        h = per_body_hierarchy(self.points, tets, levels, coarse_shape, margin=margin, block_size=3, nthreads=threads)
        return replace(h, prolongations=h.prolongations[:-1] + [sp.csr_matrix(self.to_x @ h.prolongations[-1])])

    def transposed(self, values: np.ndarray) -> np.ndarray:
        """``P^T v`` of an owned u-space vector (dof numbering): the x-space vector g with
        ``g . x = v . u`` (a load or a gradient in the unknowns of the QP)."""
        if self.distributed is None:
            return self.P.T @ values
        P = self.distributed.P
        v, out = P.createVecLeft(), P.createVecRight()
        v.getArray()[:] = values
        P.multTranspose(v, out)
        result = out.getArray().copy()
        v.destroy()
        out.destroy()
        return result

    def fixed_components(self) -> tuple[np.ndarray, np.ndarray]:
        """The owned Dirichlet dofs (u-space, unrolled) and their components of x."""
        where = self if self.distributed is None else self.distributed
        return where.fixed_dofs, where.fixed

    def solve(self, control=None) -> ContactState:
        """Solve with the current loads, starting from the last solution (load stepping);
        `control`: one more unknown (:class:`nonsmooth.Control`, solver ``active_set``: a platen's
        displacement under its mean stress, :meth:`solid_fenicsx.platen.Platen.control`), its
        change in ``solution.info["control"]``. The state of an unconverged solve is returned
        too (``solution.converged`` False, the last iterate): the caller reports or refuses it."""
        if control is not None and self.solver != "active_set":
            raise ContactSetupError(f"a platen's displacement as an unknown of the contact problem needs solver "
                                    f"'active_set', not {self.solver!r}")
        t0 = time.perf_counter()
        qp = self.problem()
        t1 = time.perf_counter()
        extra = {} if control is None else {"control": control}
        sol = nonsmooth_solvers.solve(qp, self.solver, x0=self.x, monitor=self.monitor, **self.options, **extra)
        t2 = time.perf_counter()
        self.x = sol.x
        owned = self.elasticity.V.dofmap.index_map.size_local * 3
        u = self.P @ sol.x if self.distributed is None else self.distributed.displacement(sol.x)
        self.elasticity.u.x.array[:owned] = u
        self.elasticity.u.x.scatter_forward()
        m = self.mortar
        gap = np.full(len(m.slave.nodes), np.nan)
        gap[m.covered] = m.gap[m.covered] - self._at_normals(sol.x)[m.covered]
        largest = self.elasticity.mesh.comm.allreduce(np.max(np.abs(u), initial=0.0), op=MPI.MAX)
        tol = 1e-9 * max(largest, np.nanmax(np.abs(m.gap), initial=0.0), 1e-300)
        active = np.zeros(len(m.slave.nodes), bool)
        active[m.covered] = gap[m.covered] <= tol
        # the nodal contact force: the multiplier at the normal dof of a closed node, zero at an open
        # one (where b - A x is only the Krylov error); the pressure its dual-basis coefficient
        force_n = np.zeros(len(m.slave.nodes))
        force_n[active] = np.maximum(self._at_normals(qp.multiplier(sol.x))[active], 0.0)
        pressure = np.divide(force_n, m.weights, out=np.zeros_like(force_n), where=active)
        force = -(force_n[:, None] * m.normals).sum(axis=0)  # the master pushes the slave along -n
        area = float(m.weights[active].sum() / m.weights[m.covered].sum())
        amg = sol.info.get("amg_setup_seconds", 0.0)
        return ContactState(u, pressure, gap, active, force, area, self.mean(gap), sol,
                            {"assemble": t1 - t0, "amg_setup": amg, "solve": t2 - t1 - amg,
                             "total": time.perf_counter() - t0, "setup": self.setup_seconds})

    def _at_normals(self, values: np.ndarray) -> np.ndarray:
        """(slave nodes,) an x-vector at the normal unknown of every slave node (on every rank)."""
        if self.distributed is not None:
            return self.distributed.at_normals(values)
        return values[self.normal_of_node]
