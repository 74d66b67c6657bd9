"""The Hertz contact problem (paper 4.1, figure 5) with :class:`Contact`: a half-sphere
pushed onto a block (:func:`transfer.generators.hertz.hertz_mesh`), compared with
Hertz theory for the measured contact force. Used by bench/contact.py (the case's own
comparison: ``[check] kind = "hertz"``, coupler/checks/hertz.py)."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from transfer.generators.hertz import hertz_mesh

from .contact import Contact
from .elasticity import Elasticity
from .mesh import read_mesh

#: the case's parameters (cases/hertz/scene.toml)
RADIUS, E, NU, PUSH = 1.0, 1.0e9, 0.3, 0.02


def hertz_boundaries(radius: float = 1.0, cap: float = 0.3) -> dict:
    """Predicates for :func:`solid_fenicsx.read_mesh`: ``slave`` = the half-sphere's
    curved face below z = cap * radius (where contact can happen)."""
    R = float(radius)

    def slave(x):
        d = np.sqrt(x[0] ** 2 + x[1] ** 2 + (x[2] - R) ** 2)
        return (x[2] > 1e-12 * R) & (x[2] < cap * R) & (np.abs(d - R) < 0.05 * R)

    return {"slave": slave}


def hertz_solution(force: float, radius: float, E: float, nu: float) -> dict:
    """Hertz theory for a sphere on a half-space of the same material:
    E* = E / (2 (1 - nu^2)), a = (3 F R / (4 E*))^(1/3), p0 = 3 F / (2 pi a^2)."""
    E_star = E / (2.0 * (1.0 - nu * nu))
    a = (3.0 * force * radius / (4.0 * E_star)) ** (1.0 / 3.0)
    return {"E_star": E_star, "a": a, "p0": 3.0 * force / (2.0 * np.pi * a * a),
            "approach": a * a / radius}


def hertz_contact(directory, h: float, solver: str = "active_set", push: float = PUSH, **options):
    """The Contact of the Hertz case with contact cells of size h (mesh written to
    `directory` unless there already) and the platen's displacement (a Constant)."""
    path = Path(directory) / f"hertz_h{h:g}.msh"
    if not path.exists():
        hertz_mesh(path, radius=RADIUS, h_contact=h, h_far=0.3, refine_radius=0.25)
    s = Elasticity(read_mesh(path, boundaries=hertz_boundaries(RADIUS)), E=E, nu=NU)
    s.add_dirichlet("block_bottom", 0.0)
    platen = s.add_dirichlet("load", [0.0, 0.0, -push])
    return Contact(s, "slave", "block_top", solver=solver, search_distance=0.1, **options), platen


def compare(contact: Contact, state) -> dict:
    """Hertz figures: contact radius a and peak pressure p0 from the elliptic fit
    p^2 = p0^2 (1 - r^2/a^2) of the nodal pressures above 20 % of the peak, the
    largest nodal pressure, the contact radius from the area in contact, and the
    weighted L2 error of the pressure profile, all against Hertz for the measured force."""
    m = contact.mortar
    r = np.hypot(m.slave.points[:, 0], m.slave.points[:, 1])
    p = state.pressure
    force = float(state.force[2])
    ref = hertz_solution(force, RADIUS, E, NU)
    sel = p > 0.2 * p.max()
    slope, intercept = np.polyfit(r[sel] ** 2, p[sel] ** 2, 1)
    a_fit, p0_fit = float(np.sqrt(-intercept / slope)), float(np.sqrt(intercept))
    a_area = float(np.sqrt(m.weights[state.active].sum() / np.pi))
    exact = ref["p0"] * np.sqrt(np.clip(1 - (r / ref["a"]) ** 2, 0, None))
    w = m.weights
    profile = float(np.sqrt(np.sum(w * (p - exact) ** 2) / np.sum(w * exact ** 2)))
    return {"force": force, "a_hertz": ref["a"], "p0_hertz": ref["p0"], "a_fit": a_fit, "p0_fit": p0_fit,
            "p_max": float(p.max()), "a_area": a_area,
            "error_a": abs(a_fit / ref["a"] - 1), "error_p0": abs(p0_fit / ref["p0"] - 1),
            "error_p_max": abs(p.max() / ref["p0"] - 1), "error_a_area": abs(a_area / ref["a"] - 1),
            "error_profile": profile}


def run(directory, h: float, solver: str = "active_set", steps: int = 1, **options) -> dict:
    """Solve the Hertz case in `steps` load steps; the comparison, sizes and solver figures."""
    t0 = time.perf_counter()
    contact, holder = hertz_contact(directory, h, solver, **options)
    setup = time.perf_counter() - t0
    per_step = []
    for k in range(1, steps + 1):
        holder.value[:] = [0.0, 0.0, -PUSH * k / steps]
        state = contact.solve()
        state.solution.raise_if_unconverged(f"Hertz load step {k} of {steps}")
        per_step.append({"iterations": state.solution.iterations, "krylov_iterations": state.solution.krylov_iterations,
                         "seconds": state.seconds["total"]})
    out = {"h": h, "dofs": contact.num_dofs, "slave_nodes": len(contact.mortar.slave.nodes),
           "master_nodes": len(contact.mortar.master.nodes), "active_nodes": int(state.active.sum()),
           "setup_seconds": setup, "steps": per_step, **compare(contact, state)}
    out["reaction_balance"] = float(abs(contact.elasticity.boundary_force("load")[2] + state.force[2]) / abs(state.force[2]))
    return out, contact, state
