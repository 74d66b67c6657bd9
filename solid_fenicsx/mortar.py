"""Mortar coupling of two contact faces of a dolfinx P1 displacement space
(paper 2.2.1, eq. 9): the faces as triangle meshes in dof numbering, the
slave's nodal normals, ``T = D^-1 B`` from :mod:`transfer` with the dual
(biorthogonal) basis on the slave side, and the weighted gap.

With the dual basis ``D`` is diagonal, ``D_kk = int phi_k`` over the part of the
slave face the master covers, and the discrete non-penetration condition at
slave node k (linearized, ``n^m = -n^s``, eq. 8) reads::

    n_k . (u_S - T u_M)_k  <=  g_k = n_k . (T X_M - X_S)_k

with X the node positions: g_k is the gap measured along the slave normal
between the slave node and the mortar projection of the master face.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from transfer import FunctionSpace, Mesh, NoOverlapError, Transfer


class ContactSetupError(ValueError):
    """Contact faces that cannot be coupled (missing, overlapping, not facing each other)."""


@dataclass
class Face:
    """A boundary of the mesh as triangles over its own nodes.

    nodes : (k,) node ids of the face's nodes, sorted: block dof indices of the P1 vector space,
        or another numbering of them (:func:`boundary_face`'s ``numbering``)
    triangles : (t, 3) outward-oriented triangles, indices into ``nodes``
    points : (k, 3) node coordinates
    """

    name: str
    nodes: np.ndarray
    triangles: np.ndarray
    points: np.ndarray

    def mesh(self) -> Mesh:
        return Mesh(self.points, self.triangles, "triangle", name=self.name)

    def area_normals(self) -> np.ndarray:
        """(t, 3) outward normals scaled by twice the triangle areas."""
        p = self.points[self.triangles]
        return np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])

    def nodal_normals(self) -> np.ndarray:
        """(k, 3) unit outward normals at the nodes: the area-weighted mean of the
        normals of the triangles around each node."""
        an = self.area_normals()
        n = np.zeros((len(self.nodes), 3))
        for c in range(3):
            np.add.at(n, self.triangles[:, c], an)
        return n / np.linalg.norm(n, axis=1)[:, None]


def vertex_dofs(V) -> np.ndarray:
    """Block dof index of each local mesh vertex (owned and ghost) of a P1 vector space."""
    mesh = V.mesh
    tdim = mesh.topology.dim
    mesh.topology.create_connectivity(tdim, 0)
    c2v = mesh.topology.connectivity(tdim, 0).array.reshape(-1, tdim + 1)
    dofs = np.asarray(V.dofmap.list.array).reshape(-1, tdim + 1)
    out = np.full(mesh.topology.index_map(0).size_local + mesh.topology.index_map(0).num_ghosts, -1, np.int64)
    out[c2v] = dofs
    return out


def boundary_face(solid, V, boundary, name: str | None = None, numbering: np.ndarray | None = None,
                  coordinates: np.ndarray | None = None) -> Face:
    """The facets of a named boundary as an outward-oriented :class:`Face`, its nodes in dof
    numbering or, with ``numbering`` (local block dof -> node id) and ``coordinates`` (the
    coordinates of each local block dof), in that one. Collective: on several ranks each
    rank contributes the facets it owns and every rank receives the whole face (a contact
    face is a surface, small beside the volume), its triangles in rank order."""
    if V.ufl_element().degree() != 1:
        raise ContactSetupError("contact needs P1 displacements (degree 1)")
    mesh = V.mesh
    comm = mesh.comm
    tdim = mesh.topology.dim
    facets = solid.facets(boundary)
    facets = facets[facets < mesh.topology.index_map(tdim - 1).size_local]  # each facet on one rank
    if comm.allreduce(len(facets)) == 0:
        raise ContactSetupError(f"contact boundary {boundary!r} has no facets")
    for a, b in ((tdim - 1, 0), (tdim - 1, tdim), (tdim, 0)):
        mesh.topology.create_connectivity(a, b)
    f2v = mesh.topology.connectivity(tdim - 1, 0)
    f2c = mesh.topology.connectivity(tdim - 1, tdim)
    c2v = mesh.topology.connectivity(tdim, 0)
    vdofs = vertex_dofs(V)
    dof_coordinates = V.tabulate_dof_coordinates()
    tri = np.array([f2v.links(f) for f in facets], np.int64).reshape(-1, 3)
    opposite = np.array([np.setdiff1d(c2v.links(f2c.links(f)[0]), f2v.links(f))[0] for f in facets], np.int64)
    tri, opposite = vdofs[tri], vdofs[opposite]
    p = dof_coordinates[tri]
    normal = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    inward = np.einsum("ij,ij->i", normal, dof_coordinates[opposite] - p[:, 0]) > 0
    tri[inward] = tri[inward][:, [0, 2, 1]]
    if numbering is None:
        numbering, coordinates = np.arange(len(dof_coordinates)), dof_coordinates
    ids, xyz = np.asarray(numbering)[tri], np.asarray(coordinates)[tri]
    if comm.size > 1:
        ids, xyz = np.concatenate(comm.allgather(ids)), np.concatenate(comm.allgather(xyz))
    nodes, first, local = np.unique(ids, return_index=True, return_inverse=True)
    return Face(name or str(boundary), nodes, local.reshape(-1, 3), xyz.reshape(-1, 3)[first])


def tangent_frames(normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(k, 3, 3) orthonormal frames and (k,) the column of each that is its normal n: the
    normal takes the place of its largest component, the tangents are the other two axes
    made orthogonal to it (Gram-Schmidt), so a normal along a coordinate axis leaves the
    components where they are (only the normal's sign may flip)."""
    n = normals / np.linalg.norm(normals, axis=1)[:, None]
    slot = np.argmax(np.abs(n), axis=1)
    frames = np.zeros((len(n), 3, 3))
    frames[np.arange(len(n)), :, slot] = n
    for shift in (1, 2):
        column = (slot + shift) % 3
        t = np.zeros_like(n)
        t[np.arange(len(n)), column] = 1.0
        for done in range(shift):  # against the normal and the tangents already made
            prev = frames[np.arange(len(n)), :, (slot + done) % 3]
            t -= np.einsum("ij,ij->i", t, prev)[:, None] * prev
        frames[np.arange(len(n)), :, column] = t / np.linalg.norm(t, axis=1)[:, None]
    return frames, slot


@dataclass
class Mortar:
    """The mortar coupling of a slave and a master face (paper eq. 9, dual basis), or of a
    slave face and a rigid obstacle (no master: T has no columns, eq. 11 with T = 0).

    T : (ns, nm) ``D^-1 B`` on the slave nodes the master covers (zero rows elsewhere)
    weights : (ns,) diagonal of D (``int phi_k`` over the covered part)
    covered : (ns,) slave nodes the master face (or the obstacle) reaches
    normals : (ns, 3) unit slave normals (pointing at the master or the obstacle)
    gap : (ns,) weighted gap g_k (NaN where not covered)
    """

    slave: Face
    master: Face | None
    T: sp.csr_matrix
    weights: np.ndarray
    covered: np.ndarray
    normals: np.ndarray
    gap: np.ndarray
    stats: dict


def mortar(slave: Face, master: Face, search_distance: float | None = None,
           max_normal_angle: float = 45.0) -> Mortar:
    """Assemble ``T = D^-1 B`` from the master face to the slave face with the dual
    basis on the slave (``pseudo_l2``), the slave normals and the weighted gap.

    search_distance : how far along the slave normal master triangles are
        looked for; default 0.5 x the slave's mean edge (give at least the largest
        initial gap that may close)
    """
    if np.intersect1d(slave.nodes, master.nodes).size:
        raise ContactSetupError(f"contact faces {slave.name!r} and {master.name!r} share nodes: the two "
                                f"bodies must be meshed separately (non-matching faces)")
    kwargs = {"max_normal_angle": max_normal_angle}
    if search_distance is not None:
        kwargs["search_distance"] = float(search_distance)
    try:
        transfer = Transfer.assemble(FunctionSpace(master.mesh(), "P1"), FunctionSpace(slave.mesh(), "P1"),
                                     "pseudo_l2", **kwargs)
    except NoOverlapError as exc:
        raise ContactSetupError(f"no slave node of {slave.name!r} faces the master {master.name!r} within the "
                                f"search distance and normal angle: nothing can come into contact ({exc})") from exc
    covered = transfer.covered
    T = transfer.matrix()
    normals = slave.nodal_normals()
    projected = T @ master.points
    gap = np.where(covered, np.einsum("ij,ij->i", normals, projected - slave.points), np.nan)
    stats = dict(transfer.stats, slave_nodes=len(slave.nodes), master_nodes=len(master.nodes),
                 covered_nodes=int(covered.sum()))
    return Mortar(slave, master, T, np.where(covered, transfer.D.diagonal(), 0.0), covered, normals, gap, stats)
