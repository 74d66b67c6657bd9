"""Frictionless two-body mortar contact for :class:`Elasticity` (paper 2.2, eq. 7-11).

The unknowns are transformed as in eq. 10-11, ``u = O Q x``:

* ``O`` adds the mortar projection of the master displacement to the slave
  nodes (``u_S = x_S + T x_M``, per component), so the slave unknowns become
  the jump ``u_S - T u_M``;
* ``Q`` rotates each constrained slave node to (normal, tangent, tangent)
  coordinates of its normal.

The stiffness matrix becomes ``A = (OQ)^T K (OQ)`` (eq. 10), and
non-penetration (eq. 11) the nodewise bound ``x_normal <= g`` (the weighted gap
of :mod:`solid_fenicsx.mortar`): a :class:`nonsmooth.BoundConstrainedQP`
solved by any solver of :mod:`nonsmooth.solvers`. Dirichlet dofs become fixed
components (lower = upper). The multiplier ``b - A x`` at a normal component is
the nodal contact force; divided by ``D_kk`` it is the contact pressure, the
coefficient of the dual-basis multiplier. Tangential components are free
(frictionless). Serial: one process.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from nonsmooth import BoundConstrainedQP, Solution
from nonsmooth import solvers as nonsmooth_solvers
from nonsmooth.obstacle import rigid_body_modes as body_modes

from .mortar import ContactSetupError, Mortar, boundary_face, mortar


def tangent_frames(normals: np.ndarray) -> np.ndarray:
    """(k, 3, 3) orthonormal frames with columns (n, t1, t2)."""
    n = normals / np.linalg.norm(normals, axis=1)[:, None]
    helper = np.where(np.abs(n[:, [0]]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    t1 = np.cross(n, helper)
    t1 /= np.linalg.norm(t1, axis=1)[:, None]
    t2 = np.cross(n, t1)
    return np.stack([n, t1, t2], axis=2)


def transformation(m: Mortar, num_dofs: int) -> tuple[sp.csr_matrix, sp.csr_matrix]:
    """``O`` and ``Q`` of eq. 10-11 for block size 3 (u = O Q x)."""
    s_nodes, m_nodes = m.slave.nodes, m.master.nodes
    T = m.T.tocoo()
    rows, cols, vals = [np.arange(num_dofs)], [np.arange(num_dofs)], [np.ones(num_dofs)]
    for c in range(3):  # O: u_S += T x_M, per component
        rows.append(3 * s_nodes[T.row] + c)
        cols.append(3 * m_nodes[T.col] + c)
        vals.append(T.data)
    O = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), (num_dofs, num_dofs))
    R = tangent_frames(m.normals)  # Q: x_S = R^T w_S at every slave node
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

    u: np.ndarray  # (num_dofs,) displacement
    pressure: np.ndarray  # contact pressure (dual multiplier coefficient), > 0 only where active, exactly 0 elsewhere
    gap: np.ndarray  # current gap g - x_n (NaN where not covered)
    active: np.ndarray  # nodes in contact
    force: np.ndarray  # (3,) total contact force on the slave body (sum of nodal forces)
    area_fraction: float  # active weight / covered weight of the slave face
    solution: Solution
    seconds: dict = field(default_factory=dict)

    def summary(self) -> dict:
        covered = np.isfinite(self.gap)
        return {**self.solution.as_dict(), "active_nodes": int(self.active.sum()), "area_fraction": self.area_fraction,
                "max_pressure": float(np.max(self.pressure, initial=0.0)),
                "min_gap": float(np.min(self.gap[covered], initial=np.inf)),
                "contact_force": self.force.tolist(), "phase_seconds": self.seconds}


class Contact:
    """Two-body frictionless mortar contact on an :class:`Elasticity` (P1, serial).

    elasticity : the solid with its loads and Dirichlet conditions; both bodies in one mesh
    slave, master : names (or tags) of the contact boundaries; the slave carries
        the dual multiplier (take the finer or the curved side)
    solver : a name of :data:`nonsmooth.solvers.SOLVERS`; ``options`` go to it
    search_distance, max_normal_angle : of the mortar segmentation
        (:func:`solid_fenicsx.mortar.mortar`)
    near_nullspace : give the solver the rigid body modes of each body (transformed).
        Off by default: measured on the Hertz case (6.5k dofs), GAMG with them took
        2.5-6 s per active-set solve against 0.85 s without (block size 3 only)
    """

    def __init__(self, elasticity, slave, master, solver: str = "active_set", search_distance: float | None = None,
                 max_normal_angle: float = 45.0, near_nullspace: bool = False, **options):
        if elasticity.mesh.comm.size > 1:
            raise ContactSetupError("contact runs on one process (the transformed system is assembled in scipy)")
        nonsmooth_solvers.get(solver)  # unknown names fail here, before any assembly
        t0 = time.perf_counter()
        self.elasticity = elasticity
        V = elasticity.V
        self.solver, self.options, self.near_nullspace = solver, options, near_nullspace
        slave_face = boundary_face(elasticity.solid, V, slave, name=f"slave:{slave}")
        master_face = boundary_face(elasticity.solid, V, master, name=f"master:{master}")
        self.mortar = mortar(slave_face, master_face, search_distance, max_normal_angle)
        m = self.mortar
        if not m.covered.any():
            raise ContactSetupError(f"no slave node of {slave!r} faces the master {master!r} within the search "
                                    f"distance and normal angle: nothing can come into contact")
        self.num_dofs = V.dofmap.index_map.size_local * V.dofmap.index_map_bs
        O, Q = transformation(m, self.num_dofs)
        self.P = sp.csr_matrix(O @ Q)  # u = P x
        # O = I + N with N^2 = 0 (slave rows, master columns): O^-1 = 2 I - O
        self.P_inverse = sp.csr_matrix(Q.T @ (2 * sp.identity(self.num_dofs, format="csr") - O))
        fixed = np.asarray(elasticity.dirichlet_dofs, np.int64)
        on_slave = np.intersect1d(fixed // 3, m.slave.nodes)
        if on_slave.size:
            raise ContactSetupError(f"{on_slave.size} slave contact nodes of {slave!r} carry Dirichlet conditions; "
                                    f"constrain the master side or move the Dirichlet boundary")
        self.fixed = fixed
        self.normal_dofs = 3 * m.slave.nodes[m.covered]
        self.points = V.tabulate_dof_coordinates()[: self.num_dofs // 3]
        self.x: np.ndarray | None = None  # the last transformed solution (next step's start)
        self._nullspace = None
        if solver == "multilevel" and "hierarchy" not in options:
            options["hierarchy"] = self.multilevel_hierarchy(options.pop("levels", 3))
        self.setup_seconds = time.perf_counter() - t0
        self._internal = None

    def problem(self) -> BoundConstrainedQP:
        """The transformed QP of eq. 10-11 with the current loads."""
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
        lower[self.fixed] = upper[self.fixed] = f[self.fixed]  # Dirichlet values (set_bc put them into F)
        if self.near_nullspace and self._nullspace is None:  # rigid body modes of each body, transformed
            self._nullspace = self.P_inverse @ rigid_body_modes(self.points, Ks)
        return BoundConstrainedQP(A, b, lower, upper, block_size=3, near_nullspace=self._nullspace)

    def multilevel_hierarchy(self, levels: int = 3, coarse_shape=(2, 2, 2)):
        """The semi-geometric hierarchy (paper 2.4, :mod:`nonsmooth.hierarchy`), one set of
        grids per body, for the transformed unknowns: its finest prolongation times P^-1
        (x = P^-1 u)."""
        from dataclasses import replace

        from nonsmooth.hierarchy import per_body_hierarchy

        tets = np.asarray(self.elasticity.V.dofmap.list.array).reshape(-1, 4)
        h = per_body_hierarchy(self.points, tets, levels, coarse_shape, block_size=3)
        return replace(h, prolongations=h.prolongations[:-1] + [sp.csr_matrix(self.P_inverse @ h.prolongations[-1])])

    def solve(self) -> ContactState:
        """Solve with the current loads, starting from the last solution (load stepping).
        The state of an unconverged solve is returned too (``solution.converged`` False,
        the last iterate): the caller reports or refuses it."""
        t0 = time.perf_counter()
        qp = self.problem()
        t1 = time.perf_counter()
        sol = nonsmooth_solvers.solve(qp, self.solver, x0=self.x, **self.options)
        t2 = time.perf_counter()
        self.x = sol.x
        u = self.P @ sol.x
        self.elasticity.u.x.array[: self.num_dofs] = u
        self.elasticity.u.x.scatter_forward()
        m = self.mortar
        gap = np.full(len(m.slave.nodes), np.nan)
        gap[m.covered] = m.gap[m.covered] - sol.x[self.normal_dofs]
        tol = 1e-9 * max(np.max(np.abs(u), initial=0.0), np.nanmax(np.abs(m.gap), initial=0.0), 1e-300)
        active = np.zeros(len(m.slave.nodes), bool)
        active[m.covered] = gap[m.covered] <= tol
        # the nodal contact force: the multiplier at the normal dof of a closed node, zero at an open
        # one (where b - A x is only the Krylov error); the pressure its dual-basis coefficient
        force_n = np.zeros(len(m.slave.nodes))
        force_n[active] = np.maximum(qp.multiplier(sol.x)[3 * m.slave.nodes[active]], 0.0)
        pressure = np.divide(force_n, m.weights, out=np.zeros_like(force_n), where=active)
        force = -(force_n[:, None] * m.normals).sum(axis=0)  # the master pushes the slave along -n
        area = float(m.weights[active].sum() / m.weights[m.covered].sum())
        return ContactState(u, pressure, gap, active, force, area, sol,
                            {"assemble": t1 - t0, "solve": t2 - t1, "setup": self.setup_seconds})

    def reaction(self, boundary) -> np.ndarray:
        """(3,) the force the body exerts on a Dirichlet boundary: the sum over its
        nodes of the internal force ``int sigma(u) : eps(w)`` of the current u (a
        loaded boundary needs its traction added)."""
        import dolfinx.fem
        import dolfinx.fem.petsc
        import ufl

        from .constitutive import epsilon

        el = self.elasticity
        if self._internal is None:
            w = ufl.TestFunction(el.V)
            self._internal = dolfinx.fem.form(ufl.inner(el.sigma(el.u), epsilon(w)) * ufl.dx(domain=el.mesh))
        vec = dolfinx.fem.petsc.assemble_vector(self._internal)
        f = vec.getArray().copy().reshape(-1, 3)
        vec.destroy()
        nodes = boundary_face(el.solid, el.V, boundary).nodes
        return f[nodes].sum(axis=0)

    def write_face(self, path, state: ContactState) -> None:
        """The slave face with pressure, gap, contact flag and normal as a VTU file (deformed coordinates in
        the point data ``displacement``)."""
        import meshio

        m = self.mortar
        u = state.u.reshape(-1, 3)[m.slave.nodes]
        meshio.write(str(path), meshio.Mesh(m.slave.points, [("triangle", m.slave.triangles)], point_data={
            "contact_pressure": state.pressure, "gap": np.nan_to_num(state.gap, nan=-1.0),
            "in_contact": state.active.astype(np.int32), "normal": m.normals, "displacement": u,
            "covered": m.covered.astype(np.int32)}))
