"""Time integration of the elastodynamic equation (paper eq. 13).

``(rho_s0 - rho_f) u_tt - div sigma(u) = f``: the solid is accelerated with the
effective density ``rho_s0 - rho_f`` (the fluid mass displaced by an immersed
solid, paper 2.3). Discretised with the generalized-alpha method of Chung and
Hulbert (1993); Newmark's average acceleration rule (beta = 1/4, gamma = 1/2,
unconditionally stable, energy conserving for linear problems) is the case
alpha_m = alpha_f = 0:

    M a_{n+1-am} + K u_{n+1-af} = F_{n+1-af},   x_{n+1-a} = (1-a) x_{n+1} + a x_n
    u_{n+1} = u_n + dt v_n + dt^2 ((1/2 - beta) a_n + beta a_{n+1})
    v_{n+1} = v_n + dt ((1 - gamma) a_n + gamma a_{n+1})

solved for u_{n+1}: ``(c_m M + (1 - af) K) u_{n+1} = rhs``.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Scheme:
    """Coefficients of a Newmark / generalized-alpha scheme."""

    beta: float
    gamma: float
    alpha_m: float = 0.0
    alpha_f: float = 0.0
    name: str = "newmark"

    @classmethod
    def newmark(cls, beta: float = 0.25, gamma: float = 0.5) -> "Scheme":
        """Newmark; the default is the average acceleration (trapezoidal) rule."""
        return cls(beta, gamma, 0.0, 0.0, "newmark")

    @classmethod
    def generalized_alpha(cls, rho_inf: float = 0.8) -> "Scheme":
        """Chung-Hulbert generalized-alpha with spectral radius ``rho_inf`` at
        infinite frequency (1: no dissipation, 0: asymptotic annihilation)."""
        if not 0.0 <= rho_inf <= 1.0:
            raise ValueError(f"rho_inf must lie in [0, 1], got {rho_inf}")
        am = (2.0 * rho_inf - 1.0) / (rho_inf + 1.0)
        af = rho_inf / (rho_inf + 1.0)
        gamma = 0.5 - am + af
        beta = 0.25 * (1.0 - am + af) ** 2
        return cls(beta, gamma, am, af, "generalized_alpha")

    # coefficients of the u_{n+1} update: a_{n+1} = c0 (u_{n+1} - u_n - dt v_n) - c1 a_n
    def c0(self, dt: float) -> float:
        return 1.0 / (self.beta * dt * dt)

    @property
    def c1(self) -> float:
        return (0.5 - self.beta) / self.beta

    def mass_factor(self, dt: float) -> float:
        """c_m: the factor of M in the step matrix c_m M + (1 - alpha_f) K."""
        return (1.0 - self.alpha_m) * self.c0(dt)

    @property
    def stiffness_factor(self) -> float:
        return 1.0 - self.alpha_f

    def history_factors(self, dt: float) -> tuple[float, float, float]:
        """(f_u, f_v, f_a) with the inertial history M (f_u u_n + f_v v_n + f_a a_n) on the right."""
        cm = self.mass_factor(dt)
        return cm, cm * dt, (1.0 - self.alpha_m) * self.c1 - self.alpha_m

    def update(self, dt: float, u_new, u, v, a):
        """(a_{n+1}, v_{n+1}) from the new displacement (numpy arrays)."""
        a_new = self.c0(dt) * (u_new - u - dt * v) - self.c1 * a
        v_new = v + dt * ((1.0 - self.gamma) * a + self.gamma * a_new)
        return a_new, v_new


def make_scheme(name: str, rho_inf: float = 0.8, beta: float = 0.25, gamma: float = 0.5) -> Scheme:
    """``"newmark"`` (average acceleration by default) or ``"generalized_alpha"``."""
    key = name.lower().replace("-", "_")
    if key == "newmark":
        return Scheme.newmark(beta, gamma)
    if key in ("generalized_alpha", "genalpha", "alpha"):
        return Scheme.generalized_alpha(rho_inf)
    raise ValueError(f"unknown time scheme {name!r}; use 'newmark' or 'generalized_alpha'")
