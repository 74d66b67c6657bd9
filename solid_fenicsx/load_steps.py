"""The loads of the solid participant over its steps, and one static load step.

A load's value is constant, ramped over the steps (with contact: at step k of n every
constant load is at (k + 1) / n of its value, each contact solve starting from the last),
or given per step (a list, one value per step: no ramp). A ``platen`` load is a rigid
platen under stress control (:class:`solid_fenicsx.platen.Platen`): one target mean normal
stress per step, the platen's displacement found by a search of full solves.

A ``fluid_pressure`` load is a pressure -p n; on a contact face it is the static fluid in
the fracture. It acts on the whole face, so the solve is the effective-stress problem: the
contact multiplier is the contact stress *beyond* p. That is exactly the problem with the
fluid on the open part of the faces only (figure 12 of the paper): on the contact set the
fluid's load on the slave nodes (p D_kk n_k) and its mortar image on the master cancel,
changing only the normal multiplier there by p D_kk, never the displacement. So this
formulation needs no iteration on the contact set and its solution is unique (the
open-part problem admits, besides it, states with contact stress below p, where the fluid
would wedge the faces open). Reported: the contact pressure as the total normal stress
in the contact (multiplier / D_kk + p), and each fluid load's force on the open part of
its face (the whole face's force minus the contact set's p D_kk n_k).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import numpy as np

from .platen import ContactLost

AXES = {"x": 0, "y": 1, "z": 2}
log = logging.getLogger("varcouple.solid_fenicsx")
PROGRESS_SECONDS = 5.0  # between progress lines of a long step (a line at least every 10 s)


class Progress:
    """The progress lines of a long load step: the latest values of every level of the
    step (platen trial, active-set iteration, CG iteration), logged on rank 0 when
    ``PROGRESS_SECONDS`` have passed since the last line."""

    def __init__(self, rank: int = 0):
        self.rank, self.values, self.step, self.shown = rank, {}, 0, time.monotonic()

    def start(self, step: int) -> None:
        self.step, self.values, self.shown = step, {}, time.monotonic()

    def __call__(self, **values) -> None:
        self.values.update(values)
        if self.rank == 0 and time.monotonic() - self.shown >= PROGRESS_SECONDS:
            self.shown = time.monotonic()
            log.info("load step %d: %s", self.step,
                     ", ".join(f"{k.replace('_', ' ')} {v:.4g}" for k, v in self.values.items()))


@dataclass
class SteppedLoad:
    """A declared load: the dolfinx value holder and its value over the steps."""

    kind: str
    name: str | None  # the scene's name of its boundary (None for a body force)
    boundary: object  # that boundary as the mesh knows it: a name or a tag
    holder: object  # dolfinx Constant
    value: np.ndarray  # the full value (ramped with contact)
    per_step: list | None  # one value per step, or None

    def apply(self, step: int, steps: int, ramp: bool) -> None:
        if self.per_step is not None:
            self.holder.value = self.per_step[step]
        elif ramp:
            self.holder.value = (step + 1) / steps * self.value

    @property
    def current(self) -> np.ndarray:
        return np.array(self.holder.value, dtype=float)


def add_loads(elasticity, configs: list[dict], where) -> tuple[list[SteppedLoad], object | None, list]:
    """Declare the loads of the participant's configuration on `elasticity` (boundary names
    resolved by `where`): (stepped loads, the platen or None, the platen's stresses)."""
    from .platen import Platen

    loads, platen, stresses = [], None, []
    for load in configs:
        kind, value = load["type"], load.get("value")
        per_step = value if isinstance(value, list) and kind in ("dirichlet", "pressure", "fluid_pressure") else None
        first = per_step[0] if per_step is not None else value
        boundary = where(load["boundary"]) if load.get("boundary") is not None else None
        if kind == "platen":
            if platen is not None:
                raise ValueError(f"{load.get('key', 'a load')}: one platen per solid")
            platen = Platen(elasticity, boundary, area=load.get("area"), tolerance=load.get("tolerance", 1e-3),
                            max_solves=load.get("max_iterations", 20), method=load.get("method", "search"))
            stresses = [float(v) for v in value]  # one per step
            continue
        if kind == "dirichlet":
            holder = elasticity.add_dirichlet(boundary, first, components=[AXES[c] for c in load["components"]])
        elif kind in ("pressure", "fluid_pressure"):
            holder = elasticity.add_pressure(boundary, first)
        elif kind == "traction":
            holder = elasticity.add_traction(boundary, first)
        elif kind == "body_force":
            holder = elasticity.add_body_force(first)
        else:
            raise ValueError(f"unknown load type {kind!r}")
        loads.append(SteppedLoad(kind, load.get("boundary"), boundary, holder,
                                 np.array(holder.value, dtype=float, copy=True), per_step))
    return loads, platen, stresses


class StaticStep:
    """One static load step of the solid: the loads set for the step, then one solve, or
    the platen's search of solves; with contact each solve is the contact QP.

    ``run(step)`` returns the reports (``(solver, converged, iterations, residual,
    tolerance, detail, history)`` of the step's final inner solves), the figures and, with
    contact, the slave face's fields (values at the slave nodes). With contact the figures
    split the step's time into ``seconds_assembly``, ``seconds_amg_setup`` and
    ``seconds_solves`` (the rest of the solvers' time); :meth:`timed` adds ``seconds``, the
    step's wall time, and ``seconds_other`` (stresses, gaps, fields); with the step's ``contact_solves``,
    ``step_iterations`` and ``step_krylov_iterations`` (all its solves); with a platen
    ``seconds_platen_search``, the wall time of its search. Progress lines
    (:class:`Progress`) come at least every 10 s of a long step."""

    def __init__(self, elasticity, loads, steps: int, platen=None, stresses=(), contact=None):
        self.elasticity, self.loads, self.steps = elasticity, loads, int(steps)
        self.platen, self.stresses, self.contact = platen, list(stresses), contact
        self.state = None
        self.progress = Progress(elasticity.mesh.comm.rank)
        if contact is not None:
            contact.monitor = self.progress
        self.phases, self.counts = {}, {}
        # fluid loads on a contact face: (load, +1 on the slave / -1 on the master)
        faces = {} if contact is None else {contact.slave_boundary: 1.0, contact.master_boundary: -1.0}
        self.fluid = [(ld, faces[ld.boundary]) for ld in loads if ld.kind == "fluid_pressure" and ld.boundary in faces]

    def _solve_once(self, control=None) -> bool:
        if self.contact is not None:
            self.state = self.contact.solve(control)
            sol, seconds = self.state.solution, self.state.seconds
            for phase, key in (("assembly", "assemble"), ("amg_setup", "amg_setup"), ("solves", "solve")):
                self.phases[phase] += seconds[key]
            for key, n in (("contact_solves", 1), ("step_iterations", sol.iterations),
                           ("step_krylov_iterations", sol.krylov_iterations)):
                self.counts[key] += n
            return sol.converged
        self.elasticity.solve_static()
        return all(r.converged for r in self.elasticity.info.solves)

    def _solve_controlled(self, control) -> tuple[bool, float]:
        """One contact solve with the platen's displacement as one more unknown: converged, and
        how far the displacement moved."""
        converged = self._solve_once(control)
        return converged, self.state.solution.info["control"]

    def run(self, step: int) -> tuple[list, dict, dict]:
        self.progress.start(step)
        self.phases = {"assembly": 0.0, "amg_setup": 0.0, "solves": 0.0}
        self.counts = {"contact_solves": 0, "step_iterations": 0, "step_krylov_iterations": 0}
        reports, figures, fields = self._run(step)
        if self.contact is not None:
            figures.update({f"seconds_{k}": v for k, v in self.phases.items()}, **self.counts)
        return reports, figures, fields

    def timed(self, figures: dict, start: float) -> dict:
        """`figures` with ``seconds`` the wall time since `start` (the step's, taken by the
        caller around everything it does for the step) and ``seconds_other`` the part of it
        outside the solvers; logged as the step's summary line."""
        figures["seconds"] = time.perf_counter() - start
        if self.contact is not None:
            figures["seconds_other"] = figures["seconds"] - sum(self.phases.values())
        if self.progress.rank == 0:
            keys = ("seconds", *(f"seconds_{p}" for p in (*self.phases, "other", "platen_search")), *self.counts)
            log.info("load step %d: %s", self.progress.step,
                     ", ".join(f"{k.replace('_', ' ')} {figures[k]:.4g}" for k in keys if k in figures))
        return figures

    def _run(self, step: int) -> tuple[list, dict, dict]:
        before = [load.current for load in self.loads]
        for load in self.loads:
            load.apply(step, self.steps, ramp=self.contact is not None)
        changed = any(not np.array_equal(b, load.current) for b, load in zip(before, self.loads))
        reports, figures = [], {}
        if self.platen is not None:
            closing = max(float(np.nanmin(self.contact.mortar.gap)), 0.0) if self.contact is not None else 0.0
            search = time.perf_counter()
            try:
                if self.platen.method == "constraint" and self.contact is not None:
                    result = self.platen.hold(self.stresses[step], self.contact, self._solve_controlled, closing)
                else:
                    result = self.platen.load_to(self.stresses[step], self._solve_once, closing=closing,
                                                 stale=changed, monitor=self.progress)
            except ContactLost as exc:
                raise ContactLost(f"load step {step}: {exc}") from None
            seconds = time.perf_counter() - search
            reports.append(("platen", result.converged, result.solves, result.mismatch, self.platen.tolerance,
                            f"{result.reason}: {result.stress:.6g} Pa for {result.target:.6g} Pa", ()))
            figures.update(platen_displacement=result.displacement, stress=result.stress, target_stress=result.target,
                           platen_force=result.force, platen_solves=result.solves, seconds_platen_search=seconds)
        else:
            self._solve_once()
        if self.contact is None:
            reports[:0] = [(f"{r.solver} {r.what}", r.converged, r.iterations, r.residual, r.tolerance, r.reason, ())
                           for r in self.elasticity.info.solves]
            return reports, figures, {}
        fields, contact_figures, report = self._contact(figures)
        reports.insert(0, report)
        return reports, contact_figures, fields

    def _contact(self, platen: dict) -> tuple[dict, dict, tuple]:
        """The last contact solve: its report, figures (the `platen` figures after ``closure``,
        the platen's displacement beside the faces' closure) and slave fields, with the fluid in
        the contact moved from the fluid's load to the contact stress (module docstring)."""
        state, contact = self.state, self.contact
        sol, m = state.solution, contact.mortar
        on_contact = np.where(state.active, m.weights, 0.0)[:, None] * m.normals  # D_kk n_k on the contact set
        pressure, force = state.pressure.copy(), state.force.copy()
        figures = {}
        for load, side in self.fluid:
            p = float(load.current)
            if side > 0:  # the slave's fluid load: part of the contact stress where the faces touch
                pressure[state.active] += p
                force -= p * on_contact.sum(axis=0)
            full = self.elasticity.pressure_resultant(load.boundary, p)
            open_part = full + side * p * on_contact.sum(axis=0)
            figures.update({f"fluid_force_{load.name}_{c}": open_part[i] for c, i in AXES.items()})
        stats = state.summary()
        figures.update(iterations=sol.iterations, krylov_iterations=sol.krylov_iterations,
                       active_nodes=stats["active_nodes"],
                       area_fraction=state.area_fraction, max_pressure=float(np.max(pressure, initial=0.0)),
                       **{f"force_{c}": force[i] for c, i in AXES.items()}, min_gap=stats["min_gap"],
                       mean_gap=state.mean_gap, closure=contact.initial_mean_gap - state.mean_gap, **platen,
                       dofs=contact.num_dofs)
        if "asymptotic_rate" in sol.info:
            figures["asymptotic_rate"] = sol.info["asymptotic_rate"]
            figures.update({f"dofs_level_{k}": n for k, n in enumerate(sol.info["level_sizes"])})
        fields = {"contact_pressure": pressure, "gap": np.nan_to_num(state.gap, nan=0.0),
                  "in_contact": state.active.astype(float), "slave": np.ones(len(m.slave.nodes)),
                  "mortar_weight": m.weights}
        report = (f"contact {sol.solver}", sol.converged, sol.iterations, sol.residual, sol.tolerance, sol.reason,
                  tuple(sol.history))
        return fields, figures, report
