"""The fluid's traction on the rock with its viscous part (paper 2.3, Steps 2-3;
``[coupling] traction = "full"``): ``t = (-p I + tau) n`` at the interface vertices,
``tau = mu (grad u + grad u^T)``, n the solid's outward normal (into the fluid).

Two ways to get ``tau n`` from the grid's cell-centred velocity (both measured in
tests/test_viscous_traction.py against plane Poiseuille flow):

``"wall"`` (default)
    At a no-slip wall the viscous traction is the wall shear ``mu du_t/dn`` (the
    normal part vanishes there: ``du_n/dn = -div_t u_t = 0``). The velocity relative
    to the wall's is sampled on the pressure's surface (half a cell diagonal into the
    fluid) and on the deeper ones of :class:`coupler.interface.SolidOnGrid` (about a
    cell apart), each at its effective distance from the wall (the same trace applied
    to the cell centres), and only where the sample reads fluid-centred cells alone.
    The quadratic through the three samples gives ``du_t/dn`` at the wall without
    assuming where the discrete flow's wall is: with OpenFOAM's immersed plates it
    matches the analytical wall shear to 1e-5 where the quadratic through the no-slip
    wall and two samples is 3 % off at 8 cells across (the penalized solution's
    effective wall is a fraction of a cell from the geometric one). Fallbacks per
    vertex (counted): the quadratic through the wall and two samples, then the line
    through the wall and one (narrow gaps, where deeper samples reach the other wall).
``"stress"``
    ``tau`` on the grid (:func:`velocity_gradient`: central differences, one-sided at
    the grid's faces, and next to a solid-centred cell a three-point difference through
    the wall at its sub-cell distance, as :mod:`transfer.penalization` places it),
    traced to the pressure's surface. ``tau`` there is the stress half a cell or more
    from the wall: first order in the cell size (``1 - 2 d / w`` of the wall shear in a
    channel of aperture w).

On a coupler of P ranks (:class:`coupler.fsi.ranks.SolidOnSlabs`, docs/scaling.md step 3) the
``"wall"`` method runs on each rank's rows of the interface, the fits and figures summed over the
ranks; ``"stress"``, which differentiates the velocity across the grid, is refused there.
"""

from __future__ import annotations

import numpy as np

from transfer.grid import wall_distance

from coupler.coupling.row_sums import RowSums
from coupler.errors import CouplerError
from coupler.fsi.interface import DEPTHS

METHODS = ("wall", "stress")


def _shift(a: np.ndarray, axis: int, step: int, fill) -> np.ndarray:
    """``a`` moved by ``step`` cells along ``axis``: out[i] = a[i + step] (``fill`` off the grid)."""
    out = np.full_like(a, fill)
    src = [slice(None)] * a.ndim
    dst = [slice(None)] * a.ndim
    n = a.shape[axis]
    src[axis] = slice(max(step, 0), n + min(step, 0))
    dst[axis] = slice(max(-step, 0), n - max(step, 0))
    out[tuple(dst)] = a[tuple(src)]
    return out


def velocity_gradient(velocity, shape, spacing, fraction=None) -> np.ndarray:
    """``grad u`` per cell (n, 3, 3), ``[c, i, j] = du_i/dx_j``, of cell-centred velocities
    (n, 3), x fastest, on a structured grid.

    Fluid cells are those whose centre is outside the solid (solid fraction below 1/2,
    as in the ``wall`` penalization). Along each axis (spacing h) a fluid cell c uses the
    three-point difference through its neighbours at distances ``d-`` and ``d+``: a fluid
    neighbour at h, a solid-centred neighbour s as the wall at ``d = h (3/2 - f_c - f_s)``
    (clipped to [h/50, h]; :func:`transfer.grid.wall_distance`) carrying s's
    (penalized) velocity, which is the wall's. At the grid's faces the difference is one-sided (two points).
    Solid-centred cells get zero.
    """
    shape = tuple(int(n) for n in shape)
    nx, ny, nz = shape
    u = np.asarray(velocity, float).reshape(nz, ny, nx, 3)
    f = np.zeros((nz, ny, nx)) if fraction is None else np.asarray(fraction, float).reshape(nz, ny, nx)
    fluid = f < 0.5
    grad = np.zeros((nz, ny, nx, 3, 3))
    for j, h in enumerate(np.asarray(spacing, float)):
        axis = 2 - j  # the array is (z, y, x)
        sides = []
        for step in (-1, 1):
            inside = _shift(np.ones_like(fluid), axis, step, False)
            f_n = _shift(f, axis, step, 0.0)
            wall = inside & (f_n >= 0.5)
            d = np.where(wall, wall_distance(f, f_n, h), h)
            sides.append((inside, d[..., None], _shift(u, axis, step, 0.0)))
        (in_m, dm, um), (in_p, dp, up) = sides
        both = (in_m & in_p)[..., None]
        central = (-dp / (dm * (dm + dp)) * um + (dp - dm) / (dm * dp) * u + dm / (dp * (dm + dp)) * up)
        one_sided = np.where(in_p[..., None], (up - u) / dp, np.where(in_m[..., None], (u - um) / dm, 0.0))
        grad[..., j] = np.where(both, central, one_sided)
    grad[~fluid] = 0.0
    return grad.reshape(-1, 3, 3)


def viscous_stress(velocity, shape, spacing, mu: float, fraction=None) -> np.ndarray:
    """``tau = mu (grad u + grad u^T)`` per cell (n, 3, 3) (:func:`velocity_gradient`)."""
    g = velocity_gradient(velocity, shape, spacing, fraction)
    return mu * (g + np.swapaxes(g, 1, 2))


def _tangential(v: np.ndarray, n: np.ndarray) -> np.ndarray:
    return v - np.sum(v * n, axis=1)[:, None] * n


#: how each vertex's wall shear was found (:func:`wall_shear`)
FITS = ("three samples", "wall and two samples", "wall and one sample", "unresolved")


def wall_shear(samples, normals, mu: float, spacing: float | np.ndarray, comm=None) -> tuple[np.ndarray, dict]:
    """``mu du_t/dn`` at the wall (nv, 3) from velocity samples ``[(v, d, valid), ...]`` in
    order of depth: velocities relative to the wall (nv, 3), their distances from the wall
    (nv,), whether each reads fluid cells only (nv,). Per vertex, the first that applies:
    the quadratic through three valid samples; the quadratic through the wall (no slip)
    and the first two; the line through the wall and the first valid one; the line
    through the wall and the nearest sample (``unresolved``: no sample reads fluid
    alone, e.g. an aperture of about a cell). Samples count as separate when at least
    ``spacing / 2`` (nv,) apart, the nearest at least ``spacing / 4`` from the wall.
    Returns the shear and how many vertices took each way (:data:`FITS`; with `comm`, the
    vertices of the rows every rank gave)."""
    (v1, d1, ok1), (v2, d2, ok2), (v3, d3, ok3) = [
        (_tangential(np.asarray(v, float), normals), np.asarray(d, float), np.asarray(ok, bool))
        for v, d, ok in samples]
    h = np.broadcast_to(np.asarray(spacing, float), d1.shape)
    near = ok1 & (d1 >= h / 4)
    two = near & ok2 & (d2 - d1 >= h / 2)
    three = two & ok3 & (d3 - d2 >= h / 2)

    def used(d, where):  # NaN off the vertices of a branch (np.where below keeps the branch's own)
        return np.where(where, d, np.nan)

    a, b, c = used(d1, three), used(d2, three), used(d3, three)
    slope3 = (-(b + c) / ((a - b) * (a - c)))[:, None] * v1 + (-(a + c) / ((b - a) * (b - c)))[:, None] * v2 \
        + (-(a + b) / ((c - a) * (c - b)))[:, None] * v3
    a, b = used(d1, two)[:, None], used(d2, two)[:, None]
    slope2 = (v1 * b ** 2 - v2 * a ** 2) / (a * b * (b - a))
    linear = near | (ok2 & (d2 >= h / 4))
    # the line through the wall and the first valid sample (unresolved: the nearest one)
    nearest = (near | ~linear)[:, None]
    slope1 = np.where(nearest, v1 / np.maximum(d1, h / 4)[:, None], v2 / np.maximum(d2, h / 4)[:, None])
    slope = np.where(three[:, None], slope3, np.where(two[:, None], slope2, slope1))
    counts = RowSums(comm).sum(np.array([np.count_nonzero(c) for c in (three, two & ~three, linear & ~two, ~linear)],
                                        float))
    return mu * slope, dict(zip(FITS, (int(c) for c in counts)))


class FluidTraction:
    """``t = -p n + tau n`` at the interface vertices of a :class:`coupler.interface.SolidOnGrid`
    built with ``traction="full"`` (its ``interface`` and the ``deeper`` sampling surfaces); of a
    :class:`coupler.fsi.ranks.SolidOnSlabs` (its ``comm``) at this rank's rows of the interface, the
    fluid's fields given at its grid slab and ``fits`` counted over the ranks."""

    def __init__(self, mu: float, method: str = "wall"):
        if method not in METHODS:
            raise CouplerError(f"viscous traction: method must be one of {METHODS}, got {method!r}")
        self.mu, self.method = float(mu), method
        self.fits: dict = {}  # of the last call: vertices per way of :func:`wall_shear`

    def parts(self, on_grid, pressure, velocity, wall_velocity=None) -> tuple[np.ndarray, np.ndarray]:
        """(pressure part ``-p n``, viscous part ``tau n``), each (nv, 3)."""
        near, n = on_grid.interface, on_grid.interface.normals
        p = near.from_fluid(pressure)
        if self.method == "stress":
            if on_grid.comm is not None:
                raise CouplerError("viscous traction: method 'stress' differentiates the velocity on the whole "
                                   "grid: not on several coupler ranks; use 'wall'")
            G = on_grid.G
            tau = viscous_stress(velocity, G.shape, G.spacing, self.mu, on_grid.fraction)
            tau_n = np.einsum("vij,vj->vi", near.from_fluid(tau.reshape(-1, 9)).reshape(-1, 3, 3), n)
            return -p[:, None] * n, tau_n
        if len(on_grid.deeper) != 2:
            raise CouplerError("viscous traction 'wall' needs the deeper sampling surfaces "
                               "(SolidOnGrid(..., traction='full'))")
        centres, fluid = on_grid.cell_centres(), (on_grid.fraction < 0.5).astype(float)
        wall = np.zeros_like(n) if wall_velocity is None else np.asarray(wall_velocity, float)
        samples = []
        for surface in (near, *on_grid.deeper):
            if surface is None:  # a deeper surface entirely outside the grid (a thin channel): no sample
                samples.append((np.full_like(n, np.nan), np.full(len(n), np.nan), np.zeros(len(n), bool)))
                continue
            distance = np.sum((surface.from_fluid(centres) - surface.points) * n, axis=1)
            # a vertex outside the grid (partial surface) reads NaN: not valid
            samples.append((surface.from_fluid(velocity) - wall, distance,
                            np.abs(surface.from_fluid(fluid) - 1.0) < 1e-9))
        # the samples' intended spacing along the normal (DEPTHS in units of the pressure surface's offset)
        shear, self.fits = wall_shear(samples, n, self.mu, (DEPTHS[1] - DEPTHS[0]) * near.offsets, on_grid.comm)
        return -p[:, None] * n, shear

    def __call__(self, on_grid, pressure, velocity, wall_velocity=None) -> np.ndarray:
        t_p, t_v = self.parts(on_grid, pressure, velocity, wall_velocity)
        return t_p + t_v


def traction_figures(weights, t_pressure, t_viscous, comm=None) -> dict:
    """How much the viscous part matters: the forces of both parts on the interface
    (lumped surface mass ``weights``) and the ratio of their L2 norms; with `comm`, of the rows
    every rank gives (the sums over the ranks, then the roots and the ratio: one allreduce)."""
    w = np.asarray(weights, float)
    sums = RowSums(comm).sum(np.concatenate([w @ t_pressure, w @ t_viscous,
                                             [w @ np.sum(t ** 2, axis=1) for t in (t_pressure, t_viscous)]]))
    norm = [float(np.sqrt(s)) for s in sums[6:]]
    return {"pressure_force": sums[:3].tolist(), "viscous_force": sums[3:6].tolist(),
            "shear_to_pressure": norm[1] / norm[0] if norm[0] > 0 else None}
