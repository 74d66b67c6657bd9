"""Contact of one body with a rigid plane (paper 4.3, the obstacle problem): eq. 11 with
T = 0. There is no master face and no mortar projection: at every slave node k the
displacement along the plane's normal n (pointing into the body) may not close the
distance to the plane,

    -n . u_k  <=  g_k = n . X_k + d,

exact for P1 (a linear function above a plane at the nodes is above it everywhere).
The "mortar weight" of a node is its lumped area ``int phi_k`` on the slave face, so that
the contact pressure is the nodal contact force over it, as for two-body contact.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .mortar import ContactSetupError, Face, Mortar


@dataclass(frozen=True)
class Plane:
    """The rigid plane ``n . x + d = 0``; the body stays where ``n . x + d >= 0``."""

    normal: np.ndarray  # (3,) unit, pointing into the body's side
    offset: float  # d

    @classmethod
    def from_config(cls, spec: dict, slave: Face) -> "Plane":
        """``{"plane": [a, b, c, d]}`` (a x + b y + c z + d = 0, the body where it is positive)
        or ``{"normal": [a, b, c], "gap": g}``: the plane ``g`` beyond the slave face's
        nearest point along ``-n`` (gap 0: touching it)."""
        if "plane" in spec:
            a = np.asarray(spec["plane"], float)
            length = np.linalg.norm(a[:3])
            if not length > 0:
                raise ContactSetupError(f"obstacle plane {list(a)}: its normal (a, b, c) is zero")
            plane = cls(a[:3] / length, float(a[3] / length))
            below = plane.distance(slave.points) < 0
            if below.all():
                raise ContactSetupError(f"obstacle plane {list(a)}: the whole slave face {slave.name!r} is behind it "
                                        f"(the body must lie where a x + b y + c z + d >= 0)")
            return plane
        n = np.asarray(spec["normal"], float)
        n = n / np.linalg.norm(n)
        return cls(n, float(-(slave.points @ n).min() + spec.get("gap", 0.0)))

    def distance(self, points: np.ndarray) -> np.ndarray:
        """Signed distance of points (k, 3) from the plane (positive on the body's side)."""
        return points @ self.normal + self.offset

    def coupling(self, slave: Face) -> Mortar:
        """The slave face against the plane as a :class:`Mortar` without master (T = 0):
        every node covered, normal -n, gap its distance, weight its lumped area."""
        k = len(slave.nodes)
        weights = np.zeros(k)
        area = 0.5 * np.linalg.norm(slave.area_normals(), axis=1)
        for c in range(3):
            np.add.at(weights, slave.triangles[:, c], area / 3.0)
        normals = np.tile(-self.normal, (k, 1))
        stats = {"slave_nodes": k, "master_nodes": 0, "covered_nodes": k,
                 "plane": [*self.normal.tolist(), self.offset]}
        return Mortar(slave, None, sp.csr_matrix((k, 0)), weights, np.ones(k, bool), normals,
                      self.distance(slave.points), stats)
