"""Linear isotropic elasticity: Hooke's law (paper eq. 5) and derived quantities.

``sigma_ij(u) = E_ijml u_l,m`` with the isotropic Hooke tensor, i.e.
``sigma = 2 mu eps(u) + lambda tr(eps(u)) I`` with the Lame parameters of
Young's modulus ``E`` and Poisson ratio ``nu``.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import ufl

#: above this Poisson ratio, P1 tetrahedra lock (volumetric locking)
LOCKING_NU = 0.49


class LockingWarning(UserWarning):
    """Nearly incompressible material discretised with locking-prone P1 elements."""


@dataclass(frozen=True)
class Material:
    """Isotropic linear elastic material; ``density`` is the solid density rho_s0 (eq. 13)."""

    E: float
    nu: float
    density: float = 0.0

    def __post_init__(self):
        if not self.E > 0:
            raise ValueError(f"Young's modulus must be positive, got E={self.E}")
        if not -1.0 < self.nu < 0.5:
            raise ValueError(f"Poisson ratio must lie in (-1, 0.5), got nu={self.nu}")
        if self.density < 0:
            raise ValueError(f"density must be >= 0, got {self.density}")

    @property
    def mu(self) -> float:
        """Shear modulus mu = E / (2 (1 + nu))."""
        return self.E / (2.0 * (1.0 + self.nu))

    @property
    def lmbda(self) -> float:
        """First Lame parameter lambda = E nu / ((1 + nu)(1 - 2 nu))."""
        return self.E * self.nu / ((1.0 + self.nu) * (1.0 - 2.0 * self.nu))

    @property
    def bulk(self) -> float:
        return self.E / (3.0 * (1.0 - 2.0 * self.nu))

    def wave_speed(self, fluid_density: float = 0.0) -> float:
        """Bar (1D, nu-free) wave speed sqrt(E / (rho_s - rho_f))."""
        return (self.E / (self.density - fluid_density)) ** 0.5

    def check_locking(self, degree: int) -> bool:
        """Warn (:class:`LockingWarning`) when nu > 0.49 with P1; returns True if it warned."""
        if self.nu > LOCKING_NU and degree < 2:
            warnings.warn(
                f"Poisson ratio nu={self.nu} > {LOCKING_NU}: the material is nearly incompressible and "
                "linear (P1) tetrahedra lock (displacements far too small). Use locking_free=True "
                "(quadratic P2 displacements) or degree=2.", LockingWarning, stacklevel=3)
            return True
        return False


def epsilon(u):
    """Small strain eps(u) = sym(grad u)."""
    return ufl.sym(ufl.grad(u))


def sigma(u, mu, lmbda):
    """Cauchy stress of Hooke's law (eq. 5): 2 mu eps + lambda tr(eps) I."""
    eps = epsilon(u)
    return 2.0 * mu * eps + lmbda * ufl.tr(eps) * ufl.Identity(len(u))


def von_mises(s):
    """Von Mises equivalent stress sqrt(3/2 s_dev : s_dev) of a stress tensor."""
    dev = s - ufl.tr(s) / 3.0 * ufl.Identity(3)
    return ufl.sqrt(1.5 * ufl.inner(dev, dev))
