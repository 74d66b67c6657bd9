"""The dual (biorthogonal) basis of paper eq. 4.

On each target element the dual basis functions are combinations of the
standard ones, psi_a = sum_c A[a, c] phi_c, with A = diag(M 1) M^{-1} for the
element mass matrix M. Then int psi_a phi_c = delta_ac int phi_c: the mass
matrix of the pseudo-L2 projection is diagonal (the lumped mass). On affine
simplices A is the same on every element: (d + 2) I - 1 1^T.
"""

from __future__ import annotations

import numpy as np

from .spaces import FunctionSpace


def dual_coefficients(space: FunctionSpace) -> np.ndarray:
    """(m, nb, nb) coefficients A of the dual basis on every cell of `space`."""
    local = space.element_mass_matrices()
    lumped = local.sum(axis=2)  # (m, nb): int phi_a
    # A = diag(lumped) M^{-1}; M is symmetric, so solve M X = diag(lumped) and transpose.
    eye = np.broadcast_to(np.eye(local.shape[1]), local.shape) * lumped[:, None, :]
    return np.ascontiguousarray(np.linalg.solve(local, eye).transpose(0, 2, 1))
