"""Where the faces of a fracture in contact touch, on the fluid-solid interface: no fluid acts
there (the contact pressure carries the load), so the fluid's pressure is masked."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree


def touching(points: np.ndarray, vertices: np.ndarray, slave: np.ndarray, in_contact: np.ndarray) -> np.ndarray:
    """Per interface vertex (`vertices`, indices into the deformed solid's `points`): whether it
    lies where the faces touch. A slave node is where the contact solve put it (`in_contact`);
    another vertex (the master face's) where its nearest slave node is in contact."""
    slave_nodes = np.flatnonzero(slave)
    if slave_nodes.size == 0:
        return np.zeros(len(vertices), bool)
    _, nearest = cKDTree(points[slave_nodes]).query(points[vertices])
    closed = np.asarray(in_contact, bool)
    return np.where(slave[vertices], closed[vertices], closed[slave_nodes[nearest]])
