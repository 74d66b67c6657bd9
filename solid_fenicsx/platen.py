"""A rigid platen under stress control: the uniform displacement of a flat boundary that
gives a target mean normal stress (paper 4.1, the closure test's load steps).

The platen is a Dirichlet condition on its boundary, ``u = -d n`` (all components: a rigid
platen also holds the face laterally), with ``n`` the boundary's outward normal. The mean
normal stress is the force the body exerts on the platen along ``-n`` over the platen's
area, ``sigma = -F . n / A``, and grows monotonically with ``d`` for an elastic body with
frictionless contact. :meth:`Platen.load_to` finds ``d`` for a target ``sigma`` by secant
steps from the last solve, in ``log sigma`` while the stresses are positive (rough contact
stiffens about exponentially with closure), each trial a full solve (with contact: from the
last contact state): the first with the slope of the previous search's last two solves
(near its target) or, for the first search, of the body's elastic column (``E / H`` with
``H`` its extent along ``n``), the next through the last two trials, at most twice the last
step until the target is bracketed, then kept inside the bracket (regula falsi when a secant
step leaves it).
The search is an inner solve: converged when ``|sigma / target - 1| <= tolerance``. When the
stress no longer changes as the platen opens, the block is free of contact and its other
loads (a fluid's pressure on a fracture face) alone push it onto the platen with more than the
target: no displacement reaches it, :class:`ContactLost`.

With contact, :meth:`hold` reaches a stress in one contact solve instead (``method =
"constraint"``): the platen's displacement is one more unknown of the contact problem, its mean
force the constraint; each active-set iteration takes a Newton step on the displacement with
the tangent of its own linear system (exact for its active sets), from the last stress's
displacement.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from nonsmooth import Control



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
    max_solves : trial solves per target at most (``method = "search"``)
    method : ``"search"`` (:meth:`load_to`) or ``"constraint"`` (:meth:`hold`, with contact)
    """

    def __init__(self, elasticity, boundary, area: float | None = None, tolerance: float = 1e-3,
                 max_solves: int = 20, method: str = "search"):
        self.elasticity, self.boundary = elasticity, boundary
        self.tolerance, self.max_solves, self.method = float(tolerance), int(max_solves), method
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
        lo = hi = None  # the trials nearest the target from below and from above: (d, s)
        (d, s), previous = self.history[-1], None
        while abs(s - target) > self.tolerance * abs(target):
            if s < target:
                lo = (d, s)
            else:
                if lo is None and hi is not None and d < hi[0] and abs(s - hi[1]) <= 1e-6 * abs(hi[1]):
                    raise ContactLost(f"the mean normal stress on the platen stays at {s:.6g} Pa however far it opens "
                                      f"(to {d:.3g} m): free of contact, the block is pushed onto the platen by its "
                                      f"other loads (a fluid's pressure on the fracture faces) with more than the "
                                      f"target {target:.6g} Pa: the faces separate (loss of contact)")
                hi = (d, s)
            if exhausted():
                return result(False, f"target not bracketed in {self.max_solves} solves" if lo is None or hi is None
                              else f"iteration limit: {self.max_solves} solves")
            new = None
            if previous is None and first >= 2:  # the first step: the slope of the last search's last two solves
                new = _secant(self.history[first - 2], self.history[first - 1], target, (d, s))
            elif previous is not None:  # a secant step through the last two trials
                new = _secant(previous, (d, s), target, (d, s))
            if new is None and previous is None:  # the first search: the elastic column's slope
                new = d + (target - s) * self.compliance + (closing if s <= 0 else 0.0)
            elif new is None:  # no stress change yet (the faces still apart): twice the last step
                new = d + 2 * abs(d - previous[0]) * np.sign(target - s)
            if (lo is None or hi is None) and previous is not None:  # unbracketed: at most twice the last step
                new = d + np.clip(new - d, -2 * abs(d - previous[0]), 2 * abs(d - previous[0]))
            if lo is not None and hi is not None:  # inside the bracket, away from its ends
                width = hi[0] - lo[0]
                if not lo[0] + 0.01 * width <= new <= hi[0] - 0.01 * width:
                    new = min(max(_secant(lo, hi, target, lo), lo[0] + 0.05 * width), hi[0] - 0.05 * width)
            previous = (d, s)
            ok, s = trial(new)
            d = new
            if not ok:
                return result(False, f"the solve at displacement {d:g} m did not converge")
        return result(True, "mean normal stress within the tolerance")

    def control(self, contact, target: float):
        """The platen's displacement d as one more unknown of `contact`'s problem
        (:class:`nonsmooth.Control`): the load and the fixed components' values per unit of d
        (the difference of the static system at d + 1 and d: the lifting of ``u = -d n``), the
        mean normal stress as ``g . x`` (``g = -P^T K w / area``, w the normal n on the
        platen's dofs: the force the body exerts on the platen, as :meth:`stress`), the
        target, and the elastic column's stiffness for when no contact carries the platen."""
        el = self.elasticity
        d = float(-self.holder.value @ self.normal)
        loads = []
        for at in (d + 1.0, d):
            self.set(at)
            _, F = el.static_system()
            loads.append(F.getArray().copy())
            F.destroy()
        per_unit = loads[0] - loads[1]
        fixed_dofs, fixed = contact.fixed_components()
        bounds = np.zeros(len(per_unit))
        bounds[fixed] = per_unit[fixed_dofs]
        w = np.zeros(len(el.u.x.array))
        w.reshape(-1, 3)[el.boundary_dofs(self.boundary)] = self.normal
        gradient = -el.internal_force(w) / self.area
        return Control(contact.transposed(per_unit), bounds, contact.transposed(gradient), float(target),
                       1.0 / self.compliance)

    def hold(self, target: float, contact, solve: Callable, closing: float = 0.0) -> PlatenResult:
        """The mean normal stress `target` in one contact solve: ``solve(control)`` solves with
        the platen's displacement one more unknown (:meth:`control`) and returns whether it
        converged and how far the displacement moved; it starts where the last stress left it
        (the first at `closing`, the faces touching at their nearest point). Converged when the
        solve did and the stress is within the tolerance."""
        start = self.history[-1][0] if self.history else closing
        self.set(start)
        ok, moved = solve(self.control(contact, target))
        d = start + moved
        self.set(d)
        s = self.stress()
        self.history.append((d, s))
        within = abs(s - target) <= self.tolerance * abs(target)
        reason = ("mean normal stress within the tolerance" if ok and within else
                  "the contact solve with the platen's displacement as an unknown did not converge" if not ok else
                  "the contact solve converged off the target stress")
        return PlatenResult(ok and within, target, s, d, s * self.area, 1, reason, [(d, s)])

    def save_state(self) -> list:
        return list(self.history)

    def restore_state(self, history: list) -> None:
        self.history = list(history)
        if history:
            self.set(history[-1][0])


def _secant(p: tuple, q: tuple, target: float, at: tuple) -> float | None:
    """The displacement where the secant of the trials `p` and `q` ((d, sigma) each), drawn
    through the trial `at`, reaches `target`; in log(sigma) when all the stresses are positive
    (contact stiffens about exponentially with closure: a straight line there), else in sigma.
    None without a positive slope."""
    (d0, s0), (d1, s1) = p, q
    g = np.log if min(s0, s1, at[1], target) > 0 else (lambda v: v)
    slope = (g(s1) - g(s0)) / (d1 - d0) if d1 != d0 else 0.0
    return at[0] + (g(target) - g(at[1])) / slope if slope > 0 and np.isfinite(slope) else None


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
