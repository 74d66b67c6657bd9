"""Chorin's projection for the penalized Navier-Stokes equations (paper eq. 12, Step 1), in
kinematic form (``p`` is pressure / rho):

    du/dt + div(u u) = nu lap u - grad p - D (u - u_s),      div u = s

``D`` the penalization drag (:mod:`transfer.penalization`, from the exact solid fractions)
per cell (with penalization ``"lubrication"`` the faces in the gap's plane get their own, from
the larger of their two cells' fractions, each column's gap made plates first:
:func:`transfer.penalization.face_fraction`, :func:`~transfer.penalization.plates_fraction`), else
on a face from the mean of the two cells' conductances ``1 / (r + D)``, ``r`` the
viscous rate of a cell (plus ``1/dt`` when transient): a face between two cells of one drag
keeps it, a face between a fluid cell and a solid-centred one gets about ``r`` (its flow is
set by the solid cell's continuity), as the face conductance of a collocated scheme
(OpenFOAM's interpolated ``1/A``); averaging the drag itself instead seals the solid's
boundary layer against the inlet's flux (measured on small_fracture: pressures of 1400 Pa in
solid cells by the inlet against 600 Pa of flow), ``u_s`` the solid's velocity per cell (Step 6: the L2-projected velocity of the
solid) on the faces as the fraction-weighted mean of the two cells, so a face next to a
solid-centred cell moves with that cell, and ``s`` the solid's dilatation rate
``div u_s`` in the solid-centred cells (zero elsewhere): a compressed or stretched solid
carries the fluid it overlaps with it instead of forcing it through its pores.

One step from ``(u^n, p^n)`` over ``dt`` (incremental pressure correction):

1. predictor, explicit in convection and viscosity, implicit in the drag:
   ``(1 + dt D) u* = u^n + dt (nu lap u^k - div(u^k u^k) - grad p^k) + dt D u_s``;
2. pressure Poisson ``-div(beta grad phi) = s - div u*`` with ``beta = dt / (1 + dt D)``
   (:mod:`fluid_chorin.poisson`);
3. correction ``u = u* - beta grad phi``, ``p = p^k + phi``.

A fixed-pressure face's normal velocity has the predictor of the inner face's explicit terms
(zero gradient) and its own drag, pressure gradient and, transient, its own ``u^n``: taking
the inner face's ``u^n`` there shifted the pressure
of the whole channel of cases/added_mass_heavy by about 130 Pa per step under a constant
acceleration (2 to 4 % of its added-mass pressure), against none with the open face's own.

``(u^k, p^k)`` is ``(u^n, p^n)`` for one pass. Steady problems (:meth:`ChorinSolver.march`)
make pseudo-time steps until the relative change of velocity and pressure in one step is
below the tolerance; there the open face's ``u^n`` is relaxed towards the inner face's at the
rate :meth:`ChorinSolver.open_rate` (at the viscous pseudo-time step, the inner face's), so the
steady state does not depend on the pseudo-time step: it is the solution of the steady
equations that :mod:`fluid_chorin.steady` solves by Newton's method (``steady = "newton"``).
A transient coupling step (:meth:`ChorinSolver.transient`) is cut into
time steps within the explicit stability bound, each iterated on ``(u^k, p^k)`` (outer
iterations, as PIMPLE) until the change is below the tolerance: implicit Euler in time, as
the OpenFOAM fluid's pimpleFoam.

On several MPI ranks (``comm``) each rank steps its slab of the grid (:mod:`fluid_chorin.slabs`):
the predictor and correction on its local grid, the ghost layers exchanged after each
correction, the Poisson equation solved on a distributed matrix, and the norms and step
bounds reduced over the ranks; each rank gives its owned cells' fields (:meth:`ChorinSolver.part_fields`).
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field

import numpy as np

from coupler.protocol.fluid_faces import closed_faces, dropped_velocity
from coupler.protocol.wire import SolveReport
from transfer.bodies import rigid_bodies, rigid_velocity
from transfer.grid import across_axis
from transfer.penalization import LINES, REACH, drag_fraction, face_fraction, plates_fraction

from .poisson import PoissonReport, PressurePoisson
from .slabs import Slabs
from .spec import ChorinSpec
from .steady import SteadyNewton
from .staggered import AXIS, Staggered, along, to_faces

log = logging.getLogger("varcouple.fluid_chorin")
PROGRESS_SECONDS = 10.0  # between progress lines of a long steady solve


@dataclass
class State:
    """Face velocities (one array per component), kinematic pressure per cell, time."""

    q: list
    p: np.ndarray
    t: float = 0.0

    def copy(self) -> "State":
        return State([a.copy() for a in self.q], self.p.copy(), self.t)


@dataclass
class Run:
    """How one steady solve or one transient coupling step ended, and its Poisson solves."""

    report: SolveReport
    poisson: list = field(default_factory=list)  # PoissonReport per solve

    @property
    def converged(self) -> bool:
        return self.report.converged


class ChorinSolver:
    """The projection on the grid of ``spec``, on the ranks of ``comm`` (None: one process)."""

    def __init__(self, spec: ChorinSpec, comm=None):
        self.spec = spec
        # the inputs of a rank: its cells, the ghost layer (which also holds the face neighbours a
        # rigid body's interface layer reads) and the cells the drag of a ghost reads
        #: the axis across the gap (the drag of penalization "lubrication" reads whole lines along it)
        self.across = across_axis(spec.grid.shape, spec.grid.spacing)
        self.slabs = Slabs(spec.grid.shape, spec.faces, comm, spec.slab_axis, 1 + REACH[spec.penalization],
                           self.across if spec.penalization in LINES else None)
        #: this rank's part of the grid, ghosts included (the whole grid on one rank)
        self.grid = Staggered(self.slabs.local_shape, spec.grid.spacing, self.slabs.faces)
        self.state = State(self.grid.zeros(), np.zeros(self.grid.cells))
        self.d_max = spec.drag_value()
        #: (direction, side) of each fixed-pressure face -> its kinematic pressure
        self.pressure_values = {(d, side): self.grid.condition(d, side)["value"] / spec.rho
                                for d, side in self.grid.pressure_faces}
        self._poisson: PressurePoisson | None = None
        self._poisson_dt = None
        self.warned_faces: set[str] = set()
        self._newton: SteadyNewton | None = None
        self.set_solid(np.zeros(int(np.prod(self.slabs.input_shape))), None)

    def set_inlet_pressure(self, pressure: float) -> None:
        """The pressure [Pa] of the inlet face xmin, a fixed-pressure face (on the rank that
        holds it); the Poisson operator does not depend on it."""
        if self.spec.faces["xmin"]["kind"] != "pressure":
            raise ValueError(f"input 'inlet_pressure' needs a fixed-pressure inlet (xmin), got "
                             f"{self.spec.faces['xmin']['kind']!r}")
        if (0, 0) in self.pressure_values:
            self.pressure_values[(0, 0)] = pressure / self.spec.rho

    # ------------------------------------------------------------------ the solid
    def set_solid(self, fraction, velocity=None) -> None:
        """Solid fraction per input cell of this rank (:meth:`fluid_chorin.slabs.Slabs.input_ids`,
        the whole grid on one rank; x fastest, clipped to [0, 1]) and the solid's velocity there
        ((n, 3) m/s, None: at rest): drag, target velocity and dilatation on this rank's grid. The
        velocity as ``solid_velocity`` says: per cell, each body's rigid velocity
        (:func:`transfer.bodies.rigid_bodies`, bodies labelled across the slabs, each rank's
        own cells' velocities and its ghosts' from the neighbours), or none. The drag
        of a cell reads the fractions :data:`transfer.penalization.REACH` cells away, all among
        the input cells for every local cell, so each equals the serial one bit for bit."""
        g, spec, slabs = self.grid, self.spec, self.slabs
        n = int(np.prod(slabs.input_shape))
        f = np.clip(np.asarray(fraction, dtype=float).reshape(-1), 0.0, 1.0)
        if f.size != n:
            raise ValueError(f"the solid fraction has {f.size} values, this rank's input cells {n} (planes "
                             f"{slabs.input_planes[0]} to {slabs.input_planes[1] - 1} along {'xyz'[slabs.d]})")
        if velocity is not None and spec.solid_velocity == "none":
            velocity = None
        rigid = velocity is not None and spec.solid_velocity == "bodies"
        if rigid:
            ids = slabs.input_ids()
            bodies = rigid_bodies(f, velocity, spec.grid.shape, closed_faces(spec.faces), slabs.box, ids, slabs.comm)
            for face, value in ((face, value) for b in bodies for face, value in b.dropped.items()):
                if face not in self.warned_faces and slabs.rank == 0:
                    log.warning("%s", dropped_velocity(face, value))
                self.warned_faces.add(face)
            velocity = rigid_velocity(bodies, ids)  # at the slab's own cells
        T = drag_fraction(f, slabs.input_shape, spec.grid.spacing, spec.nu, self.d_max, spec.penalization,
                          spec.penalization_exponent, self.across)
        drag = slabs.from_inputs(T * self.d_max)
        self.solid_fraction = f
        self.fraction = slabs.from_inputs(f)
        g.set_mask(1.0 - self.fraction)
        rate = self.viscous_rate() + (spec.substeps / spec.dt if spec.transient else 0.0)
        self.drag = [1.0 / to_faces(1.0 / (rate + drag), c) - rate for c in range(3)]
        if spec.penalization in LINES:  # each in-plane face column: the cubic law of its own opening
            # on the input box (the faces of its cells read both neighbours), then the local faces
            plates = plates_fraction(f.reshape(slabs.input_shape[::-1]), 2 - self.across)
            first = slabs.start - slabs.input_planes[0]
            for c in (c for c in range(3) if c != self.across):
                F = face_fraction(plates, AXIS[c])
                D = drag_fraction(F.ravel(), F.shape[::-1], spec.grid.spacing, spec.nu, self.d_max,
                                  spec.penalization, None, self.across).reshape(F.shape)
                local = slice(first, first + slabs.local_shape[slabs.d] + int(c == slabs.d))
                self.drag[c] = self.d_max * D[along(slabs.axis, local)]
        if velocity is None:
            self.target = g.zeros()
            self.source = np.zeros(g.cells)
        else:
            v = slabs.from_inputs(np.asarray(velocity, dtype=float).reshape(n, 3))
            if rigid:
                for c in range(3):
                    slabs.exchange(v[..., c])  # the ghosts' bodies: the neighbours' own cells
            weight = [to_faces(self.fraction, c) for c in range(3)]
            self.target = [np.divide(to_faces(self.fraction * v[..., c], c), weight[c],
                                     out=np.zeros(g.face_shape(c)), where=weight[c] > 0) for c in range(3)]
            self.source = np.where(self.fraction >= 0.5, g.divergence(self.target), 0.0)
        self._poisson = None

    def viscous_rate(self) -> float:
        """``nu sum 2 / h^2`` over the active directions [1/s]: the diagonal of one cell's
        viscous operator."""
        g = self.grid
        return self.spec.nu * float(np.sum(2.0 / g.h[np.asarray(g.active)] ** 2))

    def open_rate(self) -> float:
        """The rate [1/s] at which a steady fixed-pressure face's velocity is pulled towards its
        inner face's: the inverse of the viscous pseudo-time step (:meth:`stable_dt`)."""
        return self.viscous_rate() / 0.9

    # ------------------------------------------------------------------ one step
    def poisson(self, dt: float) -> PressurePoisson:
        if self._poisson is None or self._poisson_dt != dt:
            if self._poisson is not None:
                self._poisson.destroy()
            self.beta = [dt / (1.0 + dt * D) for D in self.drag]
            self._poisson, self._poisson_dt = PressurePoisson(self.grid, self.beta, self.slabs, self.spec.poisson), dt
        return self._poisson

    def step(self, dt: float, start: State, k: State) -> tuple[State, np.ndarray, PoissonReport]:
        """One predictor, Poisson solve and correction from ``start`` over ``dt`` with the
        explicit terms and pressure of ``k``; returns the new state and the increment phi."""
        g, nu = self.grid, self.spec.nu
        poisson = self.poisson(dt)
        beta = self.beta
        terms = g.momentum_terms(k.q, nu)
        star = [a.copy() for a in start.q]
        for c in range(3):
            inner = g.interior(c)
            D = self.drag[c][inner]
            star[c][inner] = (start.q[c][inner] + dt * (terms[c] - g.gradient(c, k.p))
                              + dt * D * self.target[c][inner]) / (1.0 + dt * D)
        g.set_normal(star)
        for (d, side), value in self.pressure_values.items():  # the flow through an open face
            A = AXIS[d]
            last = along(A, slice(-1, None) if side else slice(0, 1))  # also the gradient next to it
            inner = along(A, slice(-2, -1) if side else slice(1, 2))
            D, target = self.drag[d], self.target[d]
            # u^n plus dt (nu lap u - div(u u)) of the inner face, extrapolated (zero gradient),
            # then penalized with the open face's own drag and solid velocity; transient, u^n is
            # the open face's own (the inner face's would add the acceleration rho (u_b - u_i) / dt
            # of a velocity gradient along the face's normal: the module doc)
            # steady, relaxed towards the inner face's at the rate open_rate: a fixed point free of dt
            own = (start.q[d][last] - start.q[d][inner]) * (1.0 if self.spec.transient else 1.0 - dt * self.open_rate())
            free = (own + (star[d][inner] + beta[d][inner] * g.gradient(d, k.p)[last]) * (1.0 + dt * D[inner])
                    - dt * D[inner] * target[inner])
            star[d][last] = ((free + dt * D[last] * target[last]) / (1.0 + dt * D[last])
                             - beta[d][last] * g.boundary_gradient(d, side, k.p, value))
        owned = self.slabs.owned()
        phi = np.zeros(g.cells)
        phi[owned], report = poisson.solve((self.source - g.divergence(star))[owned])
        self.slabs.exchange(phi)
        for c in range(3):
            inner = g.interior(c)
            star[c][inner] -= beta[c][inner] * g.gradient(c, phi)
        for (d, side) in self.pressure_values:
            A = AXIS[d]
            plane = along(A, slice(-1, None) if side else slice(0, 1))
            star[d][plane] -= beta[d][plane] * g.boundary_gradient(d, side, phi, 0.0)
        for c in range(3):
            self.slabs.exchange(star[c], c)
        return State(star, k.p + phi, start.t + dt), phi, report

    def stable_dt(self, state: State, explicit: bool = True) -> float:
        """The largest step: viscous ``0.9 / (2 nu sum 1/h^2)`` and the Courant number ``cfl``
        (active directions), and for one explicit pass (``explicit``: forward Euler with central
        convection) also ``0.9 * 2 nu / sum u^2``; iterated to convergence (implicit Euler) the
        first two bound the outer iteration's contraction instead."""
        g, nu = self.grid, self.spec.nu
        speed = np.zeros(3)
        for c in range(3):
            speed[c] = max(np.abs(state.q[c]).max(initial=0.0), np.abs(self.target[c]).max(initial=0.0),
                           *(abs(f["value"][c]) for f in self.spec.faces.values() if f["kind"] == "velocity"))
        speed = self.slabs.max(speed)
        active = np.asarray(g.active)
        bounds = [1.0 / self.open_rate()]
        u2 = float(np.sum(speed[active] ** 2))
        if u2 > 0 and explicit:
            bounds.append(0.9 * 2.0 * nu / u2)
        courant = float(np.sum(speed[active] / g.h[active]))
        if courant > 0:
            bounds.append(self.spec.cfl / courant)
        return min(bounds)

    # ------------------------------------------------------------------ solves
    def steady(self) -> Run:
        """The steady state from the current one, as ``steady`` says: Newton on the steady
        equations (:mod:`fluid_chorin.steady`, one rank) or the pseudo-time march."""
        if self.spec.steady == "march":
            return self.march()
        if self._newton is None:
            self._newton = SteadyNewton(self)
        report, q, p = self._newton.solve(self.spec.tolerance, self.spec.newton_iterations)
        self.state = State(q, p, self.state.t)
        return Run(report)

    def march(self) -> Run:
        """Pseudo-time steps from the current state until the relative change of (u, p) per
        step is below the tolerance (or ``max_iterations``)."""
        spec = self.spec
        dt = self.stable_dt(self.state)
        residual, reports = math.inf, []
        it = 0
        shown = time.monotonic()
        for it in range(1, spec.max_iterations + 1):
            new, phi, report = self.step(dt, self.state, self.state)
            reports.append(report)
            residual = max(self.relative([a - b for a, b in zip(new.q, self.state.q)], new.q),
                           self.relative([phi], [new.p], cells=True))
            if not np.isfinite(residual):
                raise FloatingPointError(f"chorin: the steady pseudo-time stepping diverged at its iteration {it} "
                                         f"(pseudo time step dt {dt:.3g} s): non-finite velocity or pressure")
            self.state = State(new.q, new.p, self.state.t)
            if residual < spec.tolerance:
                break
            if self.slabs.rank == 0 and time.monotonic() - shown > PROGRESS_SECONDS:  # a long solve shows it moves
                shown = time.monotonic()
                log.info("pseudo-time step %d of at most %d: residual %.3g (tolerance %g), dt %.3g s",
                         it, spec.max_iterations, residual, spec.tolerance, dt)
            bound = self.stable_dt(self.state)
            if bound < dt:
                dt = 0.9 * bound
        converged = residual < spec.tolerance
        return Run(SolveReport("chorin pseudo-time", converged, it, residual, spec.tolerance,
                               "" if converged else f"limit of {spec.max_iterations} pseudo-time steps reached"),
                   reports)

    def transient(self, t: float, dt: float) -> Run:
        """From ``t`` (the state's time) to ``t + dt``: ``n >= substeps`` time steps within the
        explicit bound, each with outer iterations until the change is below the tolerance."""
        spec = self.spec
        if abs(self.state.t - t) > 1e-9 * max(dt, abs(t)):
            raise ValueError(f"the fluid's state is at time {self.state.t!r}, the coupling step starts at {t!r} "
                             f"(restore_state to the step's start first)")
        n = max(spec.substeps, math.ceil(dt / self.stable_dt(self.state, explicit=False) - 1e-9))
        h = dt / n
        reports, iterations, worst, converged = [], 0, 0.0, True
        for _ in range(n):
            start = k = self.state
            residual = math.inf
            for outer in range(1, spec.outer_correctors + 1):
                new, _, report = self.step(h, start, k)
                reports.append(report)
                residual = self.relative([a - b for a, b in zip(new.q, k.q)], new.q)
                k = new
                if outer > 1 and residual < spec.tolerance or residual == 0.0:
                    break
            if not np.isfinite(residual):
                raise FloatingPointError(f"the time stepping diverged at t = {k.t!r}")
            iterations += outer
            worst = max(worst, residual)
            converged &= residual < spec.tolerance
            self.state = k
        self.state.t = t + dt
        return Run(SolveReport("chorin time stepping", converged, iterations, worst, spec.tolerance,
                               f"{n} time steps of {h:.3g} s" + ("" if converged else f"; limit of "
                                                                 f"{spec.outer_correctors} outer iterations reached")),
                   reports)

    def relative(self, change: list, value: list, cells: bool = False) -> float:
        """The norm of ``change`` relative to that of ``value`` over the owned values of every
        rank: lists of the three face components, or (``cells``) of cell arrays."""
        def norm(arrays):
            where = [self.slabs.owned(None if cells else c) for c in range(len(arrays))]
            return float(np.sqrt(self.slabs.sum(sum(float(np.vdot(a[o], a[o])) for a, o in zip(arrays, where)))))

        scale, size = norm(value), norm(change)
        return size / scale if scale > 0 else (0.0 if size == 0 else math.inf)

    # ------------------------------------------------------------------ fields
    def _centre_velocity(self) -> list[np.ndarray]:
        """Each component of the velocity at the local cell centres (mean of the two faces)."""
        q = self.state.q
        return [0.5 * (q[c][along(AXIS[c], slice(None, -1))] + q[c][along(AXIS[c], slice(1, None))]) for c in range(3)]

    def cell_velocity(self) -> np.ndarray | None:
        """(n, 3) m/s at the cell centres, x fastest; on rank 0 (None on the others: every rank
        must call it)."""
        parts = [self.slabs.gather(a) for a in self._centre_velocity()]
        return None if parts[0] is None else np.stack([a.ravel() for a in parts], axis=1)

    def cell_pressure(self) -> np.ndarray | None:
        """(n,) Pa on rank 0 (None on the others: every rank must call it)."""
        p = self.slabs.gather(self.state.p)
        return None if p is None else p.ravel() * self.spec.rho

    def part_fields(self) -> tuple[np.ndarray, np.ndarray]:
        """``(pressure, velocity)`` of this rank's owned cells, in the order of
        :meth:`fluid_chorin.slabs.Slabs.cell_ids`: (k,) Pa and (k, 3) m/s (no communication)."""
        owned = self.slabs.owned()
        velocity = np.stack([a[owned].ravel() for a in self._centre_velocity()], axis=1)
        return self.state.p[owned].ravel() * self.spec.rho, velocity
