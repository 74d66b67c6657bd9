"""Where the faces of a fracture in contact touch, on the fluid-solid interface: no fluid acts
there (the contact pressure carries the load), so the fluid's pressure is weighted by the
share of each interface vertex that is open."""

from __future__ import annotations

import numpy as np

from transfer import FunctionSpace, Mesh, NoOverlapError, coupling_operator


def contact_share(points: np.ndarray, triangles: np.ndarray, on_slave: np.ndarray, in_contact: np.ndarray) -> np.ndarray:
    """Per interface vertex (`points`, with the interface `triangles` on them), the share chi in
    [0, 1] of it where the faces touch. A slave node has the contact solve's ``in_contact``; a
    vertex of the other face the L2 projection (eq. 3) of the slave's chi_h with that face's
    lumped mass for D: chi_i = int(phi_i chi_h) / int(phi_i), a convex combination of slave
    values whose integral is the slave's contact area, so both faces lose the same area to
    contact and a uniform fluid pressure pushes them apart with the same force."""
    chi = np.where(on_slave, np.asarray(in_contact, float), 0.0)
    slave = triangles[np.all(on_slave[triangles], axis=1)]
    other = triangles[~np.any(on_slave[triangles], axis=1)]
    if not (len(slave) and len(other) and chi.any()):
        return chi
    spaces = []
    for faces in (slave, other):
        vertices, local = np.unique(faces, return_inverse=True)
        spaces.append((vertices, FunctionSpace(Mesh(points[vertices], local.reshape(-1, 3), "triangle"), "P1")))
    (sv, S), (ov, O) = spaces
    try:
        B = coupling_operator(S, O, "l2").B
    except NoOverlapError:  # the faces do not face each other: nothing on the other face touches
        return chi
    chi[ov] = np.minimum(B @ chi[sv] / np.asarray(O.mass_matrix().sum(axis=1)).ravel(), 1.0)  # round-off above 1
    return chi
