"""Vertex-level exchange between the distributed dolfinx solid and the coupler.

The coupler transfers fields with its own library (``transfer/``, meshes from
arrays), so the solid publishes its mesh as plain arrays and exchanges fields
as values at its vertices, all in the *input numbering* of
:mod:`solid_fenicsx.mesh` (the order of the points the mesh was built from):

- :meth:`VertexIO.part_points`, :meth:`VertexIO.part_tetrahedra`,
  :meth:`VertexIO.part_values`, :meth:`VertexIO.set_part`: this rank's part, with no
  communication (the participant's parts of docs/protocol.md): its owned vertices in
  increasing input id (on one rank the input numbering itself), its own cells in
  increasing input cell index;
- :meth:`VertexIO.points`, :meth:`VertexIO.tetrahedra`,
  :meth:`VertexIO.boundary_triangles` gather the geometry on one rank;
- :meth:`VertexIO.gather` collects a field's vertex values (P1 functions
  directly, other spaces interpolated into P1 first);
- :meth:`VertexIO.scatter` sets a P1 function (e.g. the traction field of
  :meth:`solid_fenicsx.elasticity.Elasticity.add_traction_field`) from values given
  at all vertices on one rank.

Every method but the ``part_`` ones and :meth:`VertexIO.set_part` (which updates the
ghosts) is collective over the mesh communicator.
"""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

import dolfinx
import dolfinx.cpp
import dolfinx.fem

from transfer.atomic import atomic_path

from .mesh import SolidMesh


class VertexIO:
    """Maps between the local geometry nodes of a distributed P1 mesh and the
    input vertex numbering."""

    def __init__(self, solid: SolidMesh):
        self.solid = solid
        mesh = solid.mesh
        self.comm: MPI.Comm = mesh.comm
        geom = mesh.geometry
        self.input_ids = np.asarray(geom.input_global_indices, dtype=np.int64)  # local node -> input id
        self.num_owned = geom.index_map().size_local
        self.num_points = solid.num_points
        #: this rank's owned geometry nodes in increasing input id, and those ids
        self.owned = np.argsort(self.input_ids[: self.num_owned], kind="stable")
        self.owned_ids = self.input_ids[self.owned]
        self._p1_maps: dict = {}
        self._interp: dict = {}

    # -- helpers -------------------------------------------------------------
    def _node_to_dof(self, V) -> np.ndarray:
        """Local geometry node -> local block dof of a P1 space V."""
        key = id(V)
        if key not in self._p1_maps:
            mesh = self.solid.mesh
            geo = mesh.geometry.dofmap.array.reshape(-1, 4)
            dofs = np.asarray(V.dofmap.list.array).reshape(-1, 4)
            m = np.full(len(self.input_ids), -1, np.int64)
            m[geo.ravel()] = dofs.ravel()
            self._p1_maps[key] = (V, m)
        return self._p1_maps[key][1]

    def dof_input_ids(self, V) -> np.ndarray:
        """The input vertex id of each local block dof of a P1 space V (owned and ghost)."""
        out = np.full(V.dofmap.index_map.size_local + V.dofmap.index_map.num_ghosts, -1, np.int64)
        out[self._node_to_dof(V)] = self.input_ids
        return out

    def dof_points(self, V) -> np.ndarray:
        """The input coordinates of each local block dof of a P1 space V (owned and ghost):
        the mesh's geometry, not dolfinx's dof coordinates (those differ by round-off)."""
        out = np.empty((V.dofmap.index_map.size_local + V.dofmap.index_map.num_ghosts, 3))
        out[self._node_to_dof(V)] = self.solid.mesh.geometry.x[:, :3]
        return out

    def _as_p1(self, f: dolfinx.fem.Function) -> dolfinx.fem.Function:
        V = f.function_space
        element = V.ufl_element()
        if element.family() in ("Lagrange", "Q", "P") and element.degree() == 1:
            return f
        shape = f.ufl_shape
        key = (id(f), shape)
        if key not in self._interp:
            mesh = self.solid.mesh
            if shape:
                W = dolfinx.fem.VectorFunctionSpace(mesh, ("Lagrange", 1), dim=shape[0])
            else:
                W = dolfinx.fem.FunctionSpace(mesh, ("Lagrange", 1))
            self._interp[key] = dolfinx.fem.Function(W, name=f.name)
        g = self._interp[key]
        if V.ufl_element().family() in ("Discontinuous Lagrange", "DG"):
            # DG fields: vertex value = average over the cells around the vertex
            return self._dg_average(f, g)
        g.interpolate(f)
        return g

    def _dg_average(self, f, g):
        """Vertex average of a DG0 field (unweighted over incident owned and ghost cells)."""
        mesh = self.solid.mesh
        bs = g.function_space.dofmap.index_map_bs
        cell_vals = f.x.array.reshape(-1, bs)
        cells_dofs = np.asarray(f.function_space.dofmap.list.array).ravel()
        geo = mesh.geometry.dofmap.array.reshape(-1, 4)
        n_cells = geo.shape[0]
        acc = np.zeros((len(self.input_ids), bs))
        cnt = np.zeros(len(self.input_ids))
        for k in range(4):
            np.add.at(acc, geo[:, k], cell_vals[cells_dofs[:n_cells]])
            np.add.at(cnt, geo[:, k], 1.0)
        node_vals = acc / np.maximum(cnt, 1.0)[:, None]
        m = self._node_to_dof(g.function_space)
        g.x.array.reshape(-1, bs)[m] = node_vals
        return g

    def _gatherv(self, ids: np.ndarray, vals: np.ndarray, root: int | None, size: int) -> np.ndarray | None:
        comm = self.comm
        k = vals.shape[1]
        counts = np.asarray(comm.allgather(len(ids)), dtype=np.int64)
        if root is None:
            all_ids = np.empty(counts.sum(), np.int64)
            all_vals = np.empty((counts.sum(), k))
            comm.Allgatherv(np.ascontiguousarray(ids), [all_ids, counts])
            comm.Allgatherv(np.ascontiguousarray(vals), [all_vals, counts * k])
        else:
            all_ids = np.empty(counts.sum(), np.int64) if comm.rank == root else None
            all_vals = np.empty((counts.sum(), k)) if comm.rank == root else None
            comm.Gatherv(np.ascontiguousarray(ids), [all_ids, counts] if comm.rank == root else None, root=root)
            comm.Gatherv(np.ascontiguousarray(vals), [all_vals, counts * k] if comm.rank == root else None,
                         root=root)
            if comm.rank != root:
                return None
        out = np.full((size, k), np.nan)
        out[all_ids] = all_vals
        return out

    # -- this rank's part ------------------------------------------------------------
    def part_points(self) -> tuple[np.ndarray, np.ndarray]:
        """``(ids, points)``: the input ids and coordinates of this rank's owned vertices, in
        increasing input id."""
        return self.owned_ids, self.solid.mesh.geometry.x[self.owned, :3]

    def part_tetrahedra(self) -> tuple[np.ndarray, np.ndarray]:
        """``(ids, cells)``: the input indices of this rank's own tetrahedra (increasing) and their
        vertices in input ids."""
        mesh = self.solid.mesh
        n_owned = mesh.topology.index_map(mesh.topology.dim).size_local
        original = np.asarray(mesh.topology.original_cell_index[:n_owned], dtype=np.int64)
        order = np.argsort(original, kind="stable")
        geo = mesh.geometry.dofmap.array.reshape(-1, 4)[:n_owned]
        return original[order], self.input_ids[geo[order]]

    def part_values(self, f: dolfinx.fem.Function) -> np.ndarray:
        """The values of a field at this rank's owned vertices (the order of :meth:`part_points`):
        (n,) or (n, k); P2 interpolated, DG0 averaged as :meth:`gather`."""
        g = self._as_p1(f)
        bs = g.function_space.dofmap.index_map_bs
        values = g.x.array.reshape(-1, bs)[self._node_to_dof(g.function_space)[self.owned]]
        return values[:, 0] if not f.ufl_shape else values

    def set_part(self, f: dolfinx.fem.Function, values) -> None:
        """Set a P1 function from its values at this rank's owned vertices (the order of
        :meth:`part_points`), the ghosts from their owners (collective)."""
        V = f.function_space
        bs = V.dofmap.index_map_bs
        given = np.asarray(values, dtype=np.float64)
        if given.size != len(self.owned) * bs:
            raise ValueError(f"{f.name}: expected {len(self.owned)} x {bs} values at this rank's vertices, "
                             f"got shape {given.shape}")
        f.x.array.reshape(-1, bs)[self._node_to_dof(V)[self.owned]] = given.reshape(-1, bs)
        f.x.scatter_forward()

    # -- geometry --------------------------------------------------------------
    def points(self, root: int | None = 0) -> np.ndarray | None:
        """(num_points, 3) coordinates in input numbering on ``root`` (all ranks if None)."""
        x = self.solid.mesh.geometry.x[: self.num_owned, :3]
        return self._gatherv(self.input_ids[: self.num_owned], x, root, self.num_points)

    def tetrahedra(self, root: int | None = 0) -> np.ndarray | None:
        """(num_cells, 4) tetrahedra in input vertex numbering and input cell order."""
        mesh = self.solid.mesh
        tdim = mesh.topology.dim
        n_owned = mesh.topology.index_map(tdim).size_local
        geo = mesh.geometry.dofmap.array.reshape(-1, 4)[:n_owned]
        cells = self.input_ids[geo].astype(float)
        original = np.asarray(mesh.topology.original_cell_index[:n_owned], dtype=np.int64)
        out = self._gatherv(original, cells, root, self.solid.num_cells)
        return None if out is None else out.astype(np.int64)

    def part_boundary_triangles(self, boundary=None) -> np.ndarray:
        """This rank's exterior facets as triangles in input numbering, oriented with the
        outward normal (right-hand rule), and their tags (0 for untagged facets): (k, 4) rows
        (three vertices, tag). ``boundary`` (name, tag or list) keeps only those tags."""
        mesh = self.solid.mesh
        tdim = mesh.topology.dim
        mesh.topology.create_connectivity(tdim - 1, tdim)
        exterior = np.sort(dolfinx.mesh.exterior_facet_indices(mesh.topology)).astype(np.int32)
        ft = self.solid.facet_tags
        tag_of = np.zeros(mesh.topology.index_map(tdim - 1).size_local
                          + mesh.topology.index_map(tdim - 1).num_ghosts, np.int64)
        tag_of[ft.indices] = ft.values
        tags = tag_of[exterior]
        if boundary is not None:
            keep = np.isin(tags, self.solid.tags_of(boundary))
            exterior, tags = exterior[keep], tags[keep]
        nodes = dolfinx.cpp.mesh.entities_to_geometry(mesh._mesh, tdim - 1, exterior, True)
        tris = self.input_ids[np.asarray(nodes).reshape(-1, 3)]
        return np.column_stack([tris, tags]).astype(np.int64).reshape(-1, 4)

    def boundary_triangles(self, boundary=None, root: int | None = 0):
        """Every rank's :meth:`part_boundary_triangles` on ``root``: ``(triangles (k, 3), tags
        (k,))`` in a canonical order (sorted by vertex triple, independent of the partition)."""
        gathered = self.comm.gather(self.part_boundary_triangles(boundary), root=root if root is not None else 0)
        if root is None:
            gathered = self.comm.bcast(gathered, root=0)
        elif self.comm.rank != root:
            return None
        data = np.concatenate(gathered)
        key = np.sort(data[:, :3], axis=1)
        data = data[np.lexsort(key.T[::-1])]
        return data[:, :3], data[:, 3]

    def boundary_vertices(self, boundary=None, root: int | None = 0) -> np.ndarray | None:
        """Sorted input ids of the vertices of a boundary's triangles (all
        exterior facets if None), on ``root``."""
        out = self.boundary_triangles(boundary, root)
        return None if out is None else np.unique(out[0])

    # -- fields -------------------------------------------------------------------
    def gather(self, f: dolfinx.fem.Function, root: int | None = 0) -> np.ndarray | None:
        """Vertex values of a field in input numbering on ``root``: (num_points,)
        for scalars, (num_points, k) for vectors. P2 is interpolated (its vertex
        values), DG0 averaged over the cells around each vertex."""
        g = self._as_p1(f)
        V = g.function_space
        bs = V.dofmap.index_map_bs
        m = self._node_to_dof(V)[: self.num_owned]
        vals = g.x.array.reshape(-1, bs)[m]
        out = self._gatherv(self.input_ids[: self.num_owned], vals, root, self.num_points)
        if out is None:
            return None
        return out[:, 0] if not f.ufl_shape else out

    def scatter(self, f: dolfinx.fem.Function, values, root: int | None = 0, vertex_ids=None) -> None:
        """Set a P1 function from values at all vertices (input numbering),
        given on ``root`` ((num_points,) or (num_points, k)); ``root=None``:
        every rank passes the same full array. With ``vertex_ids`` (on the same
        rank(s) as ``values``), ``values`` holds only those vertices (e.g. the
        :meth:`boundary_vertices` of a wetted boundary) and the others get 0."""
        V = f.function_space
        element = V.ufl_element()
        if element.degree() != 1 or element.family() != "Lagrange":
            raise ValueError(f"{f.name}: scatter needs a P1 function, got {element.family()} {element.degree()}")
        bs = V.dofmap.index_map_bs
        if vertex_ids is not None and (root is None or self.comm.rank == root):
            ids = np.asarray(vertex_ids, dtype=np.int64).ravel()
            given = np.asarray(values, dtype=np.float64).reshape(len(ids), -1)
            values = np.zeros((self.num_points, given.shape[1]))
            values[ids] = given
        if root is None:
            arr = np.asarray(values, dtype=np.float64)
            if arr.size != self.num_points * bs:
                raise ValueError(f"{f.name}: expected {self.num_points} x {bs} vertex values, got shape {arr.shape}")
            arr = arr.reshape(self.num_points, bs)
        else:
            arr = np.empty((self.num_points, bs))
            error = None
            if self.comm.rank == root:
                given = np.asarray(values, dtype=np.float64)
                if given.size != arr.size:
                    error = f"{f.name}: expected {self.num_points} x {bs} vertex values, got shape {given.shape}"
                else:
                    arr[:] = given.reshape(self.num_points, bs)
            error = self.comm.bcast(error, root=root)
            if error:
                raise ValueError(error)
            self.comm.Bcast(arr, root=root)
        m = self._node_to_dof(V)
        f.x.array.reshape(-1, bs)[m] = arr[self.input_ids]


def write_vtu(path, vio: VertexIO, point_data: dict | None = None, cell_data: dict | None = None,
              root: int = 0) -> None:
    """Write the mesh and vertex fields (name -> Function or array in input
    numbering) as a VTU file with meshio, on ``root``. ``cell_data`` holds DG0
    Functions (gathered in input cell order) or arrays (num_cells, ...)."""
    import meshio

    pts = vio.points(root)
    tets = vio.tetrahedra(root)
    pdata = {}
    for name, value in (point_data or {}).items():
        pdata[name] = vio.gather(value, root) if isinstance(value, dolfinx.fem.Function) else value
    cdata = {}
    for name, value in (cell_data or {}).items():
        cdata[name] = [_gather_cells(vio, value, root) if isinstance(value, dolfinx.fem.Function) else value]
    if vio.comm.rank == root:
        with atomic_path(path) as tmp:
            meshio.write(str(tmp), meshio.Mesh(pts, [("tetra", tets)], point_data=pdata, cell_data=cdata))


def _gather_cells(vio: VertexIO, f: dolfinx.fem.Function, root: int):
    """Values of a DG0 function in input cell order."""
    mesh = vio.solid.mesh
    tdim = mesh.topology.dim
    n_owned = mesh.topology.index_map(tdim).size_local
    bs = f.function_space.dofmap.index_map_bs
    dofs = np.asarray(f.function_space.dofmap.list.array).ravel()[:n_owned]
    vals = f.x.array.reshape(-1, bs)[dofs]
    original = np.asarray(mesh.topology.original_cell_index[:n_owned], dtype=np.int64)
    out = vio._gatherv(original, vals, root, vio.solid.num_cells)
    if out is None:
        return None
    return out[:, 0] if not f.ufl_shape else out
