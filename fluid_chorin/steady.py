"""The steady penalized Navier-Stokes equations of the MAC grid solved as steady (paper eq. 12
without the time derivative): Newton's method on the coupled velocity-pressure system,
instead of marching pseudo-time to the steady state
(:meth:`fluid_chorin.solver.ChorinSolver.steady`, whose fixed point this is):

    nu lap u - div(u u) - grad p - D (u - u_s) = 0    on the interior faces,
    div u = s                                          in the cells,

with the march's operators (:meth:`fluid_chorin.staggered.Staggered.momentum_terms`), drag
``D``, solid velocity ``u_s``, source ``s`` and boundary conditions, and on a fixed-pressure
face the march's steady open-face equation: the explicit terms of the inner face, the
pressure gradient to the face's value, the face's drag and a pull ``r_o (u_b - u_i)`` towards
the inner face at the pseudo-time rate ``r_o`` (:meth:`ChorinSolver.open_rate`). Without a
fixed-pressure face the pressure is fixed up to a constant: one cell's continuity row pins it,
and the result keeps the start's mean, as the march does.

The Jacobian of the momentum terms is probed: central differences, exact for the quadratic
convection, with the unknowns coloured by their index modulo 3 in each direction (every term
reads its neighbours at most one index away), 27 colours per component; it depends on the state
through the convection only, so it is kept over steps and over solves while each Newton step
shrinks the change to :data:`CONTRACTION` of the last. The pressure gradient, the divergence,
the drag and the open faces' rows are assembled directly, anew for each solve (the solid moves
between them). Each Newton step solves its linear system by GMRES, right-preconditioned by a
block factorization (:class:`Block`: line solves of the velocity block along the finest
direction and a Schur complement with the lines' lumped inverse, by a multigrid cycle while
GMRES converges with it in half of :data:`KRYLOV` iterations, else by LU from then on), built
once per solid and kept over the steps while GMRES converges; the first step to
:data:`LINEAR_TOLERANCE`, the later ones inexactly (:data:`FORCING`). Measured against the
march: docs/benchmarks.md (bench/hm.py --steady).
"""

from __future__ import annotations

import itertools
import logging
import math
import time

import numpy as np
import scipy.sparse as sp

from coupler.protocol.wire import SolveReport

from .petsc import Factor, gmres, has_multigrid
from .staggered import AXIS, along

log = logging.getLogger("varcouple.fluid_chorin")
#: between progress lines of a long Newton solve (the coupler's timeout counts from the latest)
PROGRESS_SECONDS = 5.0

#: a chord step whose update shrank by less than this factor gets a fresh Jacobian
CONTRACTION = 0.2
#: GMRES's relative residual in a solve's first Newton step at most
LINEAR_TOLERANCE = 1e-10
#: GMRES's relative residual in the later steps (inexact Newton: a step's error is this fraction
#: of the step, itself near the solve's tolerance when the solve ends)
FORCING = 0.1
#: GMRES iterations per Newton step at most (beyond, the preconditioner is built afresh; with its
#: Schur complement by multigrid half as many, beyond: by LU)
KRYLOV = 120
#: a linear residual below this fraction of the solve's first one is rounding error
ROUNDING = 1e-13


def triplets():
    """Lists of rows, columns and values of a sparse matrix and ``add(r, c, v)``, which appends
    the entries of broadcast arrays where both indices are unknowns (>= 0)."""
    rows, cols, vals = [], [], []

    def add(r, c, v):
        keep = (r >= 0) & (c >= 0)
        rows.append(np.broadcast_to(r, keep.shape)[keep])
        cols.append(np.broadcast_to(c, keep.shape)[keep])
        vals.append(np.broadcast_to(v, keep.shape)[keep])

    return rows, cols, vals, add


class SteadyNewton:
    """Newton on the steady equations of ``solver`` (a :class:`fluid_chorin.solver.ChorinSolver`
    on one rank), its drag, solid velocity and face conditions as set."""

    def __init__(self, solver):
        if solver.slabs.size > 1:
            raise ValueError(f"steady = 'newton' needs the fluid on one rank, got ranks = {solver.slabs.size}: "
                             f"use steady = 'march' with ranks > 1")
        self.solver, g = solver, solver.grid
        self.g = g
        #: the unknown faces of each component: the interior ones and those of fixed-pressure faces
        self.free = []
        for c in range(3):
            m = np.zeros(g.face_shape(c), dtype=bool)
            m[g.interior(c)] = True
            for d, side in g.pressure_faces:
                if d == c:
                    m[along(AXIS[c], -1 if side else 0)] = True
            self.free.append(m)
        counts = [int(m.sum()) for m in self.free]
        self.offsets = np.concatenate([[0], np.cumsum(counts)])
        self.nq = int(self.offsets[-1])
        self.ncell = int(np.prod(g.cells))
        #: the unknown number of every face (-1: a fixed face)
        self.number = []
        for c in range(3):
            n = np.full(g.face_shape(c), -1, dtype=np.int64)
            n[self.free[c]] = self.offsets[c] + np.arange(counts[c])
            self.number.append(n)
        self.cell_number = self.nq + np.arange(self.ncell).reshape(g.cells)
        self.singular = not g.pressure_faces
        #: the line of each velocity unknown: its component and its face's indices but along the
        #: direction of the finest spacing (the thin gap's across)
        axis = AXIS[min((d for d in range(3) if g.active[d]), key=lambda d: g.h[d])]
        span = sum(m.size for m in self.free)
        self.lines = np.concatenate([
            c * span + np.ravel_multi_index(tuple(np.delete(np.indices(m.shape), axis, axis=0)),
                                            tuple(np.delete(m.shape, axis)))[m] for c, m in enumerate(self.free)])
        #: the probed momentum terms' Jacobian, kept over steps and solves while Newton contracts
        self.terms: sp.csr_matrix | None = None
        #: the preconditioner, kept over steps while it makes GMRES converge
        self.linear: Block | None = None
        #: its Schur complement by multigrid (if PETSc has hypre), until GMRES misses with it: by LU
        #: from then on
        self.multigrid = has_multigrid()

    # ------------------------------------------------------------------ the equations
    def unpack(self, x: np.ndarray, base: list) -> tuple[list, np.ndarray]:
        q = [a.copy() for a in base]
        for c in range(3):
            q[c][self.free[c]] = x[self.offsets[c]:self.offsets[c + 1]]
        return q, x[self.nq:].reshape(self.g.cells)

    def pack(self, q: list, p: np.ndarray) -> np.ndarray:
        return np.concatenate([q[c][self.free[c]] for c in range(3)] + [p.ravel()])

    def residual(self, x: np.ndarray, base: list, pin: float) -> np.ndarray:
        """The steady equations at ``x`` (momentum per unknown face, continuity per cell)."""
        s, g = self.solver, self.g
        q, p = self.unpack(x, base)
        terms = g.momentum_terms(q, s.spec.nu)
        rows = []
        for c in range(3):
            r = np.zeros(g.face_shape(c))
            inner = g.interior(c)
            r[inner] = terms[c] - g.gradient(c, p) - s.drag[c][inner] * (q[c][inner] - s.target[c][inner])
            rows.append(r)
        for (d, side), value in s.pressure_values.items():
            A = AXIS[d]
            last = along(A, slice(-1, None) if side else slice(0, 1))
            inner = along(A, slice(-2, -1) if side else slice(1, 2))
            t = terms[d][along(A, slice(-1, None) if side else slice(0, 1))]
            rows[d][last] = (t - g.boundary_gradient(d, side, p, value)
                             - s.drag[d][last] * (q[d][last] - s.target[d][last])
                             - s.open_rate() * (q[d][last] - q[d][inner]))
        continuity = s.source - g.divergence(q)
        if self.singular:
            continuity.flat[0] = p.flat[0] - pin
        return np.concatenate([rows[c][self.free[c]] for c in range(3)] + [continuity.ravel()])

    # ------------------------------------------------------------------ the Jacobian
    def jacobian(self, x: np.ndarray, base: list) -> sp.csr_matrix:
        """The Jacobian of :meth:`residual` at ``x``."""
        return (self.probed(x, base) + self.assembled()).tocsr()

    def probed(self, x: np.ndarray, base: list) -> sp.csr_matrix:
        """The momentum terms' part of the Jacobian at ``x`` (it depends on ``x`` through the
        convection only, not on the solid)."""
        s, g = self.solver, self.g
        q0, _ = self.unpack(x, base)
        rows, cols, vals, add = triplets()

        # d terms / d q by coloured central differences: terms[c] row at face index (k, j, i) of
        # component c reads component e within one index in each array direction
        step = max(1.0, *(float(np.abs(a).max(initial=0.0)) for a in q0))
        term_rows = [self.number[c][g.interior(c)] for c in range(3)]
        position = [np.indices(r.shape) for r in term_rows]
        for c in range(3):  # the terms' interior positions in the full face array of component c
            position[c][AXIS[c]] += 1
        opens = [np.full(r.shape, -1, dtype=np.int64) for r in term_rows]
        for d, side in s.pressure_values:  # an open face's row takes the terms of its inner face
            A = AXIS[d]
            opens[d][along(A, slice(-1, None) if side else slice(0, 1))] = \
                self.number[d][along(A, slice(-1, None) if side else slice(0, 1))]
        for e in range(3):
            shape = g.face_shape(e)
            index = np.indices(shape)
            for colour in itertools.product(range(3), repeat=3):
                hit = self.free[e] & (index[0] % 3 == colour[0]) & (index[1] % 3 == colour[1]) & \
                    (index[2] % 3 == colour[2])
                if not hit.any():
                    continue
                plus = [a.copy() for a in q0]
                minus = [a.copy() for a in q0]
                plus[e][hit] += step
                minus[e][hit] -= step
                tp, tm = g.momentum_terms(plus, s.spec.nu), g.momentum_terms(minus, s.spec.nu)
                for c in range(3):
                    dv = (tp[c] - tm[c]) / (2.0 * step)
                    nz = dv != 0.0
                    if not nz.any():
                        continue
                    pos = [a[nz] for a in position[c]]
                    # the one index within one of the row's with this colour, per array direction
                    cand = [p - 1 + (k - (p - 1)) % 3 for p, k in zip(pos, colour)]
                    inside = np.all([(a >= 0) & (a < n) for a, n in zip(cand, shape)], axis=0)
                    col = np.full(inside.shape, -1, dtype=np.int64)
                    col[inside] = self.number[e][tuple(a[inside] for a in cand)]
                    add(term_rows[c][nz], col, dv[nz])
                    add(opens[c][nz], col, dv[nz])
        return self.matrix(rows, cols, vals)

    def assembled(self) -> sp.csr_matrix:
        """The drag's, the pressure gradient's, the divergence's and the open faces' part of the
        Jacobian (and the pinned pressure): constant but for the solid's drag."""
        s, g = self.solver, self.g
        rows, cols, vals, add = triplets()
        # the drag, the pressure gradient and the divergence
        for c in range(3):
            A, h = AXIS[c], g.h[c]
            inner = g.interior(c)
            r = self.number[c][inner]
            add(r, r, -s.drag[c][inner])
            lo, hi = self.cell_number[along(A, slice(None, -1))], self.cell_number[along(A, slice(1, None))]
            add(r, hi, -1.0 / h)
            add(r, lo, 1.0 / h)
            # continuity -div q: cell k has faces k (-) and k + 1 (+)
            n = self.number[c]
            add(self.cell_number, n[along(A, slice(1, None))], -1.0 / h)
            add(self.cell_number, n[along(A, slice(None, -1))], 1.0 / h)
        for (d, side) in s.pressure_values:
            A, h = AXIS[d], g.h[d]
            last = self.number[d][along(A, -1 if side else 0)]
            inner = self.number[d][along(A, -2 if side else 1)]
            cell = self.cell_number[along(A, -1 if side else 0)]
            D = s.drag[d][along(A, -1 if side else 0)]
            rate = s.open_rate()
            add(last, last, -D - rate)
            add(last, inner, rate)
            add(last, cell, (2.0 / h) if side else (-2.0 / h))
        if self.singular:  # the first cell's continuity row pins its pressure
            r, c, v = (np.concatenate(a) for a in (rows, cols, vals))
            keep = r != self.nq
            rows, cols, vals = [r[keep], [self.nq]], [c[keep], [self.nq]], [v[keep], [1.0]]
        return self.matrix(rows, cols, vals)

    def matrix(self, rows: list, cols: list, vals: list) -> sp.csr_matrix:
        n = self.nq + self.ncell
        return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n))

    # ------------------------------------------------------------------ the solve
    def solve(self, tolerance: float, max_iterations: int) -> tuple[SolveReport, list, np.ndarray]:
        """Newton from the solver's state until the relative change of (u, p) in one step is
        below ``tolerance``; returns the report and the new face velocities and pressure."""
        s = self.solver
        base = [a.copy() for a in s.state.q]
        self.g.set_normal(base)
        pin, mean = float(s.state.p.flat[0]), float(s.state.p.mean())
        x = self.pack(base, s.state.p)
        jacobians, probes, builds, krylov, residual, last = 0, 0, 0, 0, math.inf, math.inf
        rtol, it, shown = min(LINEAR_TOLERANCE, 0.1 * tolerance), 0, time.monotonic()
        fresh, J = self.terms is None, None
        for it in range(1, max_iterations + 1):
            if fresh or J is None:  # the solid's part anew at a solve's start, the probed one when stale
                if fresh:
                    self.terms, probes = self.probed(x, base), probes + 1
                J, jacobians = (self.terms + self.assembled()).tocsr(), jacobians + 1
                if self.linear is None or not self.linear.serves(s.drag):  # built for another solid
                    if self.linear is not None:
                        self.linear.destroy()
                    self.linear, builds = Block(J, self.nq, self.lines, s.drag, self.multigrid), builds + 1
                self.linear.J = J  # over Newton steps the preconditioner serves while GMRES converges
            F = -self.residual(x, base, pin)
            floor = ROUNDING * float(np.linalg.norm(F)) if it == 1 else floor  # near it, a step is rounding
            eta = rtol if it == 1 else max(rtol, FORCING)
            dx, iterations, solved = self.linear.solve(F, eta, floor)
            krylov += iterations
            # missed: precondition with this Jacobian's blocks, and if that missed, by LU
            while not solved and (self.linear.built_for is not J or self.linear.multigrid):
                self.multigrid = self.multigrid and self.linear.built_for is not J
                self.linear.destroy()
                self.linear, builds = Block(J, self.nq, self.lines, s.drag, self.multigrid), builds + 1
                dx, iterations, solved = self.linear.solve(F, eta, floor)
                krylov += iterations
            x = x + dx
            q, p = self.unpack(x, base)
            step, _ = self.unpack(dx, [np.zeros_like(a) for a in base])
            residual = max(s.relative(step, q), s.relative([dx[self.nq:].reshape(p.shape)], [p], cells=True))
            if not np.isfinite(residual):
                raise FloatingPointError(f"the steady Newton solve diverged at step {it}")
            if time.monotonic() - shown >= PROGRESS_SECONDS:  # a long solve shows it moves
                shown = time.monotonic()
                log.info("steady Newton step %d of at most %d: change %.3g (tolerance %g), %d preconditioners built",
                         it, max_iterations, residual, tolerance, builds)
            if residual < tolerance and solved:  # (a small step of an unsolved system proves nothing)
                break
            fresh = residual > CONTRACTION * last  # the momentum terms probed afresh at the new state
            last = residual
        q, p = self.unpack(x, base)
        if self.singular:
            p = p + (mean - p.mean())
        converged = residual < tolerance and solved
        why = ("" if converged else f"; its last linear solve missed {eta:g} even with its Jacobian's preconditioner"
               if residual < tolerance else f"; limit of {max_iterations} Newton steps reached")
        report = SolveReport("chorin steady Newton", converged, it, residual, tolerance,
                             f"{jacobians} Jacobians ({probes} probed), {builds} preconditioners (Schur complement by "
                             f"{'multigrid' if self.multigrid else 'LU'}), {krylov} GMRES iterations on "
                             f"{self.nq + self.ncell} unknowns" + why)
        return report, q, p


class Block:
    """The Newton system ``[[A, B], [C, E]]`` (velocity rows first, ``nq`` of them; ``E`` the pinned
    pressure, if any) by GMRES preconditioned with a block factorization (SIMPLE-like):

        u* = Ah^-1 f,   S p = g - C u*,   u = Ah^-1 (f - B p),   S = E - C L B,

    ``Ah`` the velocity block's couplings along ``lines`` (the direction of the finest spacing:
    across a thin gap, where viscosity and drag dominate; one tridiagonal system per line) and
    ``L`` its lumped inverse ``diag(Ah^-1 1)``: a line's response to a uniform pressure gradient,
    the column's Poiseuille conductance in a gap (``diag(A)^-1`` would take a cell's, too small by
    about ``n^2 / 6`` at ``n`` cells across). ``Ah`` by its LU factors, ``S`` by one V-cycle of
    algebraic multigrid (``multigrid``; a tenth of the LU's set-up on the shipped hm_fracture grid,
    about as many GMRES iterations) or its LU factors (:class:`fluid_chorin.petsc.Factor`). With
    the LU GMRES takes about as many iterations at 8 as at 32 cells across a gap; with the V-cycle
    (``S`` is very anisotropic there: its coupling across the gap about ``12 (n h_x / H)^2`` times
    the one along) 2 and 10 times as many as with the LU on a duct."""

    def __init__(self, J: sp.csr_matrix, nq: int, lines: np.ndarray, drag: list, multigrid: bool = False):
        self.J = self.built_for = J  # the system solved, and the one whose blocks precondition it
        self.multigrid = multigrid
        self.drag = [a.copy() for a in drag]
        self.nq = nq
        A = J[:nq, :nq].tocoo()
        keep = lines[A.row] == lines[A.col]
        self.B, self.C = J[:nq, nq:].tocsr(), J[nq:, :nq].tocsr()
        self.line = Factor(sp.csr_matrix((A.data[keep], (A.row[keep], A.col[keep])), shape=A.shape))
        # -S = B^T |L| B + (open faces) -E: symmetric positive definite; a pinned pressure (E's
        # identity row) made an identity row and column, the cell held in the preconditioner
        S = (self.C @ sp.diags(self.lumped()) @ self.B - J[nq:, nq:]).tocsr()
        pinned = J[nq:, nq:].nnz > 0
        if pinned:
            keep = sp.diags(np.r_[0.0, np.ones(S.shape[0] - 1)])
            S = keep @ S @ keep + sp.diags(np.r_[1.0, np.zeros(S.shape[0] - 1)])
        self.schur = Factor(S, multigrid)
        self.sign = np.r_[1.0 if pinned else -1.0, -np.ones(S.shape[0] - 1)]  # S^-1 = -(-S)^-1 but the pin

    def lumped(self) -> np.ndarray:
        """``L``: each velocity unknown's response to a unit force on its whole line."""
        return self.line.solve(np.ones(self.nq))

    def serves(self, drag: list) -> bool:
        """Whether it was built for this drag (a solid moved since: GMRES stalls with it)."""
        return all(np.array_equal(a, b) for a, b in zip(self.drag, drag))

    def apply(self, r: np.ndarray) -> np.ndarray:
        r = np.asarray(r).ravel()
        f, g = r[:self.nq], r[self.nq:]
        p = self.sign * self.schur.solve(g - self.C @ self.line.solve(f))
        return np.concatenate([self.line.solve(f - self.B @ p), p])

    def destroy(self) -> None:
        self.line.destroy()
        self.schur.destroy()

    def solve(self, b: np.ndarray, rtol: float, atol: float) -> tuple[np.ndarray, int, bool]:
        """``J x = b`` to the residual ``max(rtol |b|, atol)`` in at most :data:`KRYLOV` iterations,
        half as many with the multigrid cycle (:func:`fluid_chorin.petsc.gmres`, right-preconditioned):
        the solution, the iterations and whether it got there, by the true residual."""
        x, count = gmres(self.J, b, self.apply, rtol, atol, KRYLOV // 2 if self.multigrid else KRYLOV)
        return x, count, float(np.linalg.norm(self.J @ x - b)) <= max(rtol * float(np.linalg.norm(b)), atol)
