"""The transformed contact system of eq. 10-11 on several MPI ranks, for
:class:`solid_fenicsx.contact.Contact`.

What is gathered and what stays distributed: the two contact faces are surfaces, small
beside the volume, so every rank holds both whole faces and the whole mortar coupling
(``T = D^-1 B`` of eq. 9, computed identically on every rank from the gathered faces,
:func:`solid_fenicsx.mortar.boundary_face`). The volume stays distributed: the stiffness
``K`` is dolfinx's MPI AIJ matrix, and ``P = O Q`` (eq. 10) is an MPI AIJ matrix in the
solid's dof ownership whose rows each rank fills for the dofs it owns (the slave rows
``u_S = R x_S + T x_M`` with the columns of master nodes owned elsewhere), so
``A = P^T K P`` (PETSc's PtAP) and ``b = P^T F`` are distributed and the active set
solver runs on a :class:`nonsmooth.distributed.DistributedQP`.

The unknowns x: each rank owns the x of the dof blocks it owns, ordered by input vertex
id, numbered after the ranks before it. On one rank that is the input numbering of the
serial :class:`~solid_fenicsx.contact.Contact`.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from mpi4py import MPI
from petsc4py import PETSc

from nonsmooth.distributed import DistributedQP

from .mortar import Mortar, tangent_frames


class DistributedTransform:
    """``u = P x`` (eq. 10) and the bounds of eq. 11 on distributed matrices.

    elasticity : the solid; ids : the input vertex id of each local block dof (owned first)
    mortar : the whole coupling, the same on every rank
    fixed_dofs : the owned (unrolled, local) dofs with a Dirichlet condition
    """

    def __init__(self, elasticity, ids: np.ndarray, mortar: Mortar, fixed_dofs: np.ndarray):
        self.elasticity, self.mortar = elasticity, mortar
        imap = elasticity.V.dofmap.index_map
        self.comm: MPI.Comm = elasticity.mesh.comm
        n, start = imap.size_local, imap.local_range[0]
        owned = ids[:n]
        self.x_block = np.empty(n, np.int64)  # the local x block of each owned dof block
        self.x_block[np.argsort(owned)] = np.arange(n)
        slave = mortar.slave.nodes
        at = np.searchsorted(slave, owned).clip(max=len(slave) - 1)
        on_slave = slave[at] == owned
        self.owned_slave = np.flatnonzero(on_slave)  # owned dof blocks on the slave face
        self.slave_at = at[on_slave]  # their slave node index
        frames, self.slot = tangent_frames(mortar.normals)
        # the global x block of every master node, from the rank owning it
        master = mortar.master.nodes if mortar.master is not None else np.empty(0, np.int64)
        mine = np.isin(owned, master)
        pairs = self.comm.allgather((owned[mine], start + self.x_block[mine]))
        master_x = np.empty(len(master), np.int64)
        for node_ids, blocks in pairs:
            master_x[np.searchsorted(master, node_ids)] = blocks
        self.P = self._transformation(n, start, on_slave, frames, master_x)
        x_of_dof = 3 * self.x_block[fixed_dofs // 3] + fixed_dofs % 3
        self.fixed_dofs, self.fixed = fixed_dofs, x_of_dof

    def _transformation(self, n, start, on_slave, frames, master_x) -> PETSc.Mat:
        """P = O Q: the rows of the owned dofs, the identity at nodes off the slave face; at a
        slave node s ``u_s = R_s x_s + sum_m T_sm x_m`` (per component)."""
        m, N = self.mortar, self.elasticity.V.dofmap.index_map.size_global
        rows, cols, vals = [], [], []
        plain = np.flatnonzero(~on_slave)
        for c in range(3):
            rows.append(3 * plain + c)
            cols.append(3 * (start + self.x_block[plain]) + c)
            vals.append(np.ones(len(plain)))
        blocks, s = self.owned_slave, self.slave_at
        for i in range(3):
            for j in range(3):
                rows.append(3 * blocks + i)
                cols.append(3 * (start + self.x_block[blocks]) + j)
                vals.append(frames[s, i, j])
        T = m.T[s].tocoo()
        for c in range(3):
            rows.append(3 * blocks[T.row] + c)
            cols.append(3 * master_x[T.col] + c)
            vals.append(T.data)
        local = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), (3 * n, 3 * N))
        local.sort_indices()
        P = PETSc.Mat().createAIJ(((3 * n, 3 * N), (3 * n, 3 * N)), bsize=3, comm=self.comm,
                                  csr=(local.indptr.astype(PETSc.IntType), local.indices.astype(PETSc.IntType),
                                       local.data))
        P.assemble()
        return P

    def problem(self) -> DistributedQP:
        """The QP of eq. 10-11 with the current loads: A = P^T K P, b = P^T F, the normal
        unknowns of the covered slave nodes below their gap, Dirichlet components fixed."""
        K, F = self.elasticity.static_system()
        A = K.PtAP(self.P)
        b = self.P.createVecRight()
        self.P.multTranspose(F, b)
        f = F.getArray().copy()
        F.destroy()
        local = len(f)
        lower, upper = np.full(local, -np.inf), np.full(local, np.inf)
        covered = self.mortar.covered[self.slave_at]
        normal = 3 * self.x_block[self.owned_slave] + self.slot[self.slave_at]
        upper[normal[covered]] = self.mortar.gap[self.slave_at[covered]]
        lower[self.fixed] = upper[self.fixed] = f[self.fixed_dofs]
        return DistributedQP(A, b, lower, upper, block_size=3)

    def displacement(self, x: np.ndarray) -> np.ndarray:
        """The owned part of u = P x (dof numbering)."""
        xv, u = self.P.createVecRight(), self.P.createVecLeft()
        xv.getArray()[:] = x
        self.P.mult(xv, u)
        out = u.getArray().copy()
        xv.destroy()
        u.destroy()
        return out

    def at_normals(self, values: np.ndarray) -> np.ndarray:
        """(slave nodes,) the local x-vector `values` at the normal unknown of every slave
        node, on every rank."""
        out = np.zeros(len(self.mortar.slave.nodes))
        out[self.slave_at] = values[3 * self.x_block[self.owned_slave] + self.slot[self.slave_at]]
        return self.comm.allreduce(out, op=MPI.SUM)
