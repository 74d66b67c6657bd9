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
reads its neighbours at most one index away), 27 colours per component; the pressure
gradient, the divergence, the drag and the open faces' rows are assembled directly. Each
Newton step solves its linear system by GMRES preconditioned with a sparse LU of the
(regularized) Jacobian (:class:`Saddle`): a fresh Jacobian when the last step contracted by
less than :data:`CONTRACTION`, the factorization kept over steps and over solves (the next
coupling iteration's solid is close to this one's) while GMRES converges in :data:`KRYLOV`
iterations, warm-started from the current state. At creeping flow a solve takes two or three
steps; the factorization is its cost, and it grows faster than linearly with the unknowns: slower
than the march on the shipped hm_fracture grid (bench/hm.py --steady).
"""

from __future__ import annotations

import itertools
import logging
import math
import time

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from coupler.protocol.wire import SolveReport

from .staggered import AXIS, along

log = logging.getLogger("varcouple.fluid_chorin")
#: between progress lines of a long Newton solve (the coupler's timeout counts from the latest)
PROGRESS_SECONDS = 5.0

#: a chord step whose update shrank by less than this factor gets a fresh Jacobian
CONTRACTION = 0.2
#: GMRES's relative residual per Newton step at most
LINEAR_TOLERANCE = 1e-8
#: GMRES iterations per Newton step at most (beyond, the Jacobian is factorized afresh)
KRYLOV = 40
#: a linear residual below this fraction of the solve's first one is rounding error
ROUNDING = 1e-13
#: the pressure diagonal of the preconditioner's factorization, relative to the Schur complement's
REGULARIZATION = 1e-8


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
        #: the preconditioner, kept over solves while it makes GMRES converge
        self.linear: Saddle | None = None

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
    def jacobian(self, x: np.ndarray, base: list) -> sp.csc_matrix:
        s, g = self.solver, self.g
        q0, _ = self.unpack(x, base)
        rows, cols, vals = [], [], []

        def add(r, c, v):
            keep = (r >= 0) & (c >= 0)
            rows.append(np.broadcast_to(r, keep.shape)[keep])
            cols.append(np.broadcast_to(c, keep.shape)[keep])
            vals.append(np.broadcast_to(v, keep.shape)[keep])

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
        r, c, v = (np.concatenate(a) for a in (rows, cols, vals))
        n = self.nq + self.ncell
        if self.singular:  # the first cell's continuity row pins its pressure
            keep = r != self.nq
            r, c, v = (np.concatenate([a[keep], [b]]) for a, b in zip((r, c, v), (self.nq, self.nq, 1.0)))
        return sp.csc_matrix((v, (r, c)), shape=(n, n))

    # ------------------------------------------------------------------ the solve
    def solve(self, tolerance: float, max_iterations: int) -> tuple[SolveReport, list, np.ndarray]:
        """Newton from the solver's state until the relative change of (u, p) in one step is
        below ``tolerance``; returns the report and the new face velocities and pressure."""
        s = self.solver
        base = [a.copy() for a in s.state.q]
        self.g.set_normal(base)
        pin, mean = float(s.state.p.flat[0]), float(s.state.p.mean())
        x = self.pack(base, s.state.p)
        jacobians, factorizations, krylov, residual, last = 0, 0, 0, math.inf, math.inf
        rtol, fresh, it, shown = min(LINEAR_TOLERANCE, 0.1 * tolerance), True, 0, time.monotonic()
        for it in range(1, max_iterations + 1):
            if fresh:
                J = self.jacobian(x, base).tocsr()
                jacobians += 1
                if self.linear is None:
                    self.linear, factorizations = Saddle(J, self.nq), factorizations + 1
                self.linear.J = J  # an earlier factorization preconditions while GMRES converges
            F = -self.residual(x, base, pin)
            floor = ROUNDING * float(np.linalg.norm(F)) if it == 1 else floor  # near it, a step is rounding
            dx, iterations, solved = self.linear.solve(F, rtol, floor)
            krylov += iterations
            if not solved and self.linear.lu_of is not J:  # precondition with the LU of this Jacobian
                self.linear.destroy()
                self.linear, factorizations = Saddle(J, self.nq), factorizations + 1
                dx, iterations, solved = self.linear.solve(F, rtol, floor)
                krylov += iterations
            x = x + dx
            q, p = self.unpack(x, base)
            step, _ = self.unpack(dx, [np.zeros_like(a) for a in base])
            residual = max(s.relative(step, q), s.relative([dx[self.nq:].reshape(p.shape)], [p], cells=True))
            if not np.isfinite(residual):
                raise FloatingPointError(f"the steady Newton solve diverged at step {it}")
            if time.monotonic() - shown >= PROGRESS_SECONDS:  # a long solve shows it moves
                shown = time.monotonic()
                log.info("steady Newton step %d of at most %d: change %.3g (tolerance %g), %d LU factorizations",
                         it, max_iterations, residual, tolerance, factorizations)
            if residual < tolerance and solved:  # (a small step of an unsolved system proves nothing)
                break
            fresh = residual > CONTRACTION * last  # a fresh Jacobian at the new state
            last = residual
        q, p = self.unpack(x, base)
        if self.singular:
            p = p + (mean - p.mean())
        converged = residual < tolerance and solved
        why = ("" if converged else f"; its last linear solve missed {rtol:g} even with the LU of its Jacobian"
               if residual < tolerance else f"; limit of {max_iterations} Newton steps reached")
        report = SolveReport("chorin steady Newton", converged, it, residual, tolerance,
                             f"{jacobians} Jacobians, {factorizations} LU factorizations, {krylov} GMRES iterations "
                             f"on {self.nq + self.ncell} unknowns" + why)
        return report, q, p


class Saddle:
    """The Newton system ``[[A, B], [C, 0]]`` (velocity rows first, ``nq`` of them; ``C`` about
    ``-B^T``) by GMRES preconditioned with a sparse LU of the quasi-definite ``[[A, B], [-C, e]]``:
    the continuity rows negated and a small ``e`` (:data:`REGULARIZATION` of the Schur
    complement's diagonal ``C diag(A)^-1 B``) on the pressure diagonal, so the factorization
    needs no pivoting and keeps the fill of a symmetric ordering."""

    def __init__(self, J: sp.csr_matrix, nq: int):
        self.J = self.lu_of = J  # the system solved, and the one whose LU preconditions it
        self.nq = nq
        A, B, C = J[:nq, :nq], J[:nq, nq:], J[nq:, :nq]
        schur = (abs(C) @ sp.diags(1.0 / np.abs(A.diagonal())) @ abs(B)).diagonal()
        n = J.shape[0]
        flip = np.concatenate([np.ones(nq), -np.ones(n - nq)])
        K = (sp.diags(flip) @ J + sp.diags(np.concatenate([np.zeros(nq), REGULARIZATION * schur]))).tocsr()
        from petsc4py import PETSc

        K.sort_indices()
        self.K = PETSc.Mat().createAIJ(size=K.shape, csr=(K.indptr.astype(PETSc.IntType),
                                                          K.indices.astype(PETSc.IntType), K.data),
                                       comm=PETSc.COMM_SELF)
        self.K.assemble()
        self.ksp = PETSc.KSP().create(comm=PETSc.COMM_SELF)
        self.ksp.setOperators(self.K)
        self.ksp.setType("preonly")
        pc = self.ksp.getPC()
        pc.setType("lu")
        pc.setFactorOrdering("nd")
        self.ksp.setUp()
        self.x, self.b = self.K.createVecs()
        self.M = spla.LinearOperator((n, n), matvec=lambda r: self.factored(flip * np.asarray(r).ravel()))

    def factored(self, r: np.ndarray) -> np.ndarray:
        self.b.array[:] = r
        self.ksp.solve(self.b, self.x)
        return self.x.array.copy()

    def destroy(self) -> None:
        for obj in (self.ksp, self.K, self.x, self.b):
            obj.destroy()

    def solve(self, b: np.ndarray, rtol: float, atol: float) -> tuple[np.ndarray, int, bool]:
        """``J x = b`` to the residual ``max(rtol |b|, atol)`` in at most :data:`KRYLOV` iterations:
        the solution, the iterations and whether it got there, by the true residual (scipy's
        ``info`` misjudges it both ways: its preconditioned estimate)."""
        count = [0]

        def counted(_):
            count[0] += 1

        x, _ = spla.gmres(self.J, b, M=self.M, tol=rtol, atol=atol, restart=KRYLOV, maxiter=1,
                          callback=counted, callback_type="pr_norm")
        return x, count[0], float(np.linalg.norm(self.J @ x - b)) <= max(rtol * float(np.linalg.norm(b)), atol)
