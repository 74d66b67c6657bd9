"""A rigid platen under stress control: the uniform displacement of a flat boundary that
gives a target mean normal stress (paper 4.1, the closure test's load steps).

The platen is a Dirichlet condition on its boundary, ``u = -d n`` (all components: a rigid
platen also holds the face laterally), with ``n`` the boundary's outward normal. The mean
normal stress is the force the body exerts on the platen along ``-n`` over the platen's
area, ``sigma = -F . n / A``, and grows monotonically with ``d`` for an elastic body with
frictionless contact. :meth:`Platen.load_to` finds ``d`` for a target ``sigma`` by
bracketing from the last solve (steps of the body's elastic column, ``H sigma / E`` with
``H`` its extent along ``n``, doubling until the target is bracketed) and regula falsi
inside the bracket, each trial a full solve (with contact: from the last contact state).
The search is an inner solve: converged when ``|sigma / target - 1| <= tolerance``. When the
stress no longer changes as the platen opens, the block is free of contact and its other
loads (a fluid's pressure on a fracture face) alone push it onto the platen with more than the
target: no displacement reaches it, :class:`ContactLost`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np



class PlatenError(ValueError):
    """A platen boundary that is not flat."""


class ContactLost(ValueError):
    """The target stress is below the push of the block's other loads with its contact open."""


@dataclass
class PlatenResult:
    """One :meth:`Platen.load_to`: converged or not, and why."""

    converged: bool
    target: float  # the mean normal stress asked for [Pa]
    stress: float  # the one reached [Pa]
    displacement: float  # the platen's displacement along -n [m]
    force: float  # the normal force on the platen [N]: the stress times the area it is taken over
    solves: int  # trial solves of this search
    reason: str = ""
    trials: list = field(default_factory=list)  # (displacement, stress) of each trial

    @property
    def mismatch(self) -> float:
        """|stress / target - 1| (|stress| for a zero target)."""
        return abs(self.stress / self.target - 1) if self.target else abs(self.stress)


class Platen:
    """A rigid platen on `boundary` of an :class:`~solid_fenicsx.elasticity.Elasticity`.

    area : the area the mean stress is taken over (default: the boundary's, projected on n)
    tolerance : relative tolerance on each target stress
    max_solves : trial solves per target at most
    """

    def __init__(self, elasticity, boundary, area: float | None = None, tolerance: float = 1e-3,
                 max_solves: int = 20):
        self.elasticity, self.boundary = elasticity, boundary
        self.tolerance, self.max_solves = float(tolerance), int(max_solves)
        self.normal, projected = _flat_face(elasticity, boundary)
        self.area = float(area) if area is not None else projected
        x = elasticity.V.tabulate_dof_coordinates() @ self.normal
        comm = elasticity.mesh.comm
        from mpi4py import MPI

        extent = comm.allreduce(x.max(initial=-np.inf), op=MPI.MAX) - comm.allreduce(x.min(initial=np.inf), op=MPI.MIN)
        self.compliance = extent / elasticity.material.E  # displacement per stress of the elastic column
        self.holder = elasticity.add_dirichlet(boundary, [0.0, 0.0, 0.0])
        self.history: list[tuple[float, float]] = []  # (displacement, stress) of every solve so far

    def set(self, displacement: float) -> None:
        self.holder.value[:] = -displacement * self.normal

    def stress(self) -> float:
        """The mean normal stress on the platen of the current displacement field."""
        return -float(self.elasticity.boundary_force(self.boundary) @ self.normal) / self.area

    def load_to(self, target: float, solve: Callable[[], bool], closing: float = 0.0,
                stale: bool = False, monitor: Callable[..., None] | None = None) -> PlatenResult:
        """Move the platen until the mean normal stress is `target`: ``solve()`` solves with
        the platen where it is set and returns whether that solve converged; `closing` (a
        contact's smallest initial gap) is added to the first step from an unloaded state.
        The first search starts with a solve at zero displacement, a later one from the last
        solve, or, when other loads changed since (`stale`), from a solve where the platen is."""
        first = len(self.history)
        trials = []

        def trial(d):
            if monitor is not None:
                monitor(platen_trial=len(trials) + 1, platen_displacement=d, target_stress=target)
            self.set(d)
            ok = solve()
            s = self.stress()
            self.history.append((d, s))
            trials.append((d, s))
            if monitor is not None:
                monitor(last_trial_stress=s)
            return ok, s

        def result(converged, reason):
            d, s = self.history[-1]
            return PlatenResult(converged, target, s, d, s * self.area, len(self.history) - first, reason, trials)

        def exhausted():
            return len(self.history) - first >= self.max_solves

        start = self.history[-1][0] if self.history else 0.0
        if (stale or not self.history) and not trial(start)[0]:
            return result(False, f"the solve at displacement {start:g} m did not converge")
        d0, s0 = self.history[-1]
        step = (target - s0) * self.compliance + (closing if s0 <= 0 else 0.0)
        lo, s_lo, hi, s_hi = (d0, s0, None, None) if s0 < target else (None, None, d0, s0)
        s1 = s0
        while lo is None or hi is None:  # bracket: steps of the elastic column, doubling
            if exhausted():
                return result(False, f"target not bracketed in {self.max_solves} solves")
            d = (lo if hi is None else hi) + step
            ok, s1 = trial(d)
            if not ok:
                return result(False, f"the solve at displacement {d:g} m did not converge")
            if abs(s1 - target) <= self.tolerance * abs(target):
                break
            if lo is None and abs(s1 - s_hi) <= 1e-6 * abs(s_hi):  # opened, and the stress did not change
                raise ContactLost(f"the mean normal stress on the platen stays at {s1:.6g} Pa however far it opens "
                                  f"(to {d:.3g} m): free of contact, the block is pushed onto the platen by its other "
                                  f"loads (a fluid's pressure on the fracture faces) with more than the target "
                                  f"{target:.6g} Pa: the faces separate (loss of contact)")
            if s1 < target:
                lo, s_lo = d, s1
            else:
                hi, s_hi = d, s1
            step *= 2
        while abs(s1 - target) > self.tolerance * abs(target):  # regula falsi in the bracket
            if exhausted():
                return result(False, f"iteration limit: {self.max_solves} solves")
            d = lo + (target - s_lo) * (hi - lo) / (s_hi - s_lo)
            d = min(max(d, lo + 0.05 * (hi - lo)), hi - 0.05 * (hi - lo))  # inside, away from the ends
            ok, s1 = trial(d)
            if not ok:
                return result(False, f"the solve at displacement {d:g} m did not converge")
            if s1 < target:
                lo, s_lo = d, s1
            else:
                hi, s_hi = d, s1
        return result(True, "mean normal stress within the tolerance")

    def save_state(self) -> list:
        return list(self.history)

    def restore_state(self, history: list) -> None:
        self.history = list(history)
        if history:
            self.set(history[-1][0])


def _flat_face(elasticity, boundary) -> tuple[np.ndarray, float]:
    """The unit outward normal of a flat boundary and its area; PlatenError if it is not flat
    (its mean normal more than 1 degree off the facets' on average)."""
    import dolfinx.fem
    import ufl
    from mpi4py import MPI

    ds = elasticity.ds(elasticity.solid.tags_of(boundary))
    n = ufl.FacetNormal(elasticity.mesh)
    comm = elasticity.mesh.comm

    def integral(f):
        return comm.allreduce(dolfinx.fem.assemble_scalar(dolfinx.fem.form(f * ds)), op=MPI.SUM)

    total = np.array([integral(n[i]) for i in range(3)])
    area = integral(dolfinx.fem.Constant(elasticity.mesh, 1.0))
    if not area > 0:
        raise PlatenError(f"platen boundary {boundary!r} has no facets")
    projected = float(np.linalg.norm(total))
    if not projected >= np.cos(np.radians(1.0)) * area:
        raise PlatenError(f"platen boundary {boundary!r} is not flat: its facets' normals are on average "
                          f"{np.degrees(np.arccos(min(projected / area, 1.0))):.1f} degrees off their mean")
    return total / projected, projected
