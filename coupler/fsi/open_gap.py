"""Where the faces of a fracture in contact touch, on the fluid-solid interface: no fluid acts
there (the contact pressure carries the load), so the fluid's pressure is weighted by the
share of each interface vertex that is open.

On a coupler of several ranks (`rows`: the interface numbering's :class:`transfer.rows.Rows`,
`ids`: the interface index of each vertex given) each rank gives the interface triangles it
holds and the mortar projection is the distributed one (:func:`transfer.distributed.assemble`);
``rows=None`` is the serial code."""

from __future__ import annotations

import numpy as np

from coupler.coupling.row_sums import RowSums
from transfer import FunctionSpace, Mesh, NoOverlapError, coupling_operator
from transfer.distributed import Part, assemble


def contact_share(points: np.ndarray, triangles: np.ndarray, on_slave: np.ndarray, in_contact: np.ndarray,
                  rows=None, ids=None) -> np.ndarray:
    """Per interface vertex (`points`, with the interface `triangles` on them), the share chi in
    [0, 1] of it where the faces touch. A slave node has the contact solve's ``in_contact``; a
    vertex of the other face the L2 projection (eq. 3) of the slave's chi_h with that face's
    lumped mass for D: chi_i = int(phi_i chi_h) / int(phi_i), a convex combination of slave
    values whose integral is the slave's contact area, so both faces lose the same area to
    contact and a uniform fluid pressure pushes them apart with the same force. Collective with
    `rows`."""
    chi = np.where(on_slave, np.asarray(in_contact, float), 0.0)
    slave = triangles[np.all(on_slave[triangles], axis=1)]
    other = triangles[~np.any(on_slave[triangles], axis=1)]
    anywhere = RowSums(None if rows is None else rows.comm).any
    if not (anywhere(len(slave)) and anywhere(len(other)) and anywhere(chi.any())):
        return chi
    (sv, S), (ov, O) = (_face(points, faces, ids, rows) for faces in (slave, other))
    try:
        covered, mass = _mortar(S, O, chi[sv], rows)
    except NoOverlapError:  # the faces do not face each other: nothing on the other face touches
        return chi
    chi[ov] = np.minimum(covered / mass, 1.0)  # round-off above 1
    return chi


def _face(points, faces, ids, rows):
    """(vertices, space): the P1 space of the triangles `faces` on their `vertices` (a
    :class:`transfer.distributed.Part` in the interface numbering with `rows`)."""
    vertices, local = np.unique(faces, return_inverse=True)
    if rows is None:
        return vertices, FunctionSpace(Mesh(points[vertices], local.reshape(-1, 3), "triangle"), "P1")
    mesh = Mesh(points[vertices], local.reshape(-1, 3), "triangle") if len(faces) else Mesh.empty("triangle", "face")
    index, _ = rows.numbering(ids[vertices])  # the face's vertices numbered 0..m-1 (the serial face's order)
    return vertices, Part(mesh, "P1", rows.move(rows.own, index, ids[vertices]).astype(np.int64))


def _mortar(S, O, chi, rows) -> tuple[np.ndarray, np.ndarray]:
    """(B chi, the lumped mass int(phi_i)) at the vertices of the other face O: the coupling
    matrix B of eq. 3 from the slave face S (l2, mortar pairing)."""
    if rows is None:
        return coupling_operator(S, O, "l2").B @ chi, np.asarray(O.mass_matrix().sum(axis=1)).ravel()
    local = np.asarray(O.space.mass_matrix().sum(axis=1)).ravel() if O.num_cells else np.zeros(0)
    mass = rows.move(O.global_dofs, local, O.global_dofs, add=True)  # a vertex on a cut: its ranks' areas
    return assemble(S, O, "l2", rows.comm).product(chi), mass


def open_share(reference: np.ndarray, triangles: np.ndarray, field, rows=None, ids=None) -> np.ndarray:
    """Per interface vertex (`reference`: undeformed, with the interface `triangles` on them) the
    share of it where the fluid acts (the faces do not touch), 1 - chi of :func:`contact_share`
    on the vertices as the solid's latest displacement moved them; ``field(name)``: the solid's
    output `name` at these vertices (displacement, slave, in_contact). Collective with `rows`."""
    return 1.0 - contact_share(reference + field("displacement"), triangles, field("slave") > 0.5,
                               field("in_contact") > 0.5, rows, ids)
