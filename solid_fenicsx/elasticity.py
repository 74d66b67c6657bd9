"""Linear elasticity on tetrahedra with dolfinx 0.5: static and dynamic solves.

Static problem (paper eq. 7, without the contact boundary): find u with

    -div sigma(u) = f        in Omega
    u = g                    on Gamma_D   (all components, or some: rollers)
    sigma(u) n = t           on Gamma_N   (t given, or t = -p n for a pressure p)

with Hooke's law sigma of eq. 5 (:mod:`solid_fenicsx.constitutive`).
Dynamic problem (eq. 13, with a body force and the same boundary loads):

    (rho_s0 - rho_f) u_tt - div sigma(u) = f

integrated in time by Newmark's average acceleration rule or the
generalized-alpha method (:mod:`solid_fenicsx.timestepping`). ``rho_f`` is the
``fluid_density`` of an immersed solid (paper 2.3), 0 by default.

Loads are declared once (they define the variational forms, compiled at the
first solve) and their values changed any time after: constant loads return a
dolfinx ``Constant`` (set ``.value``), field loads a P1 ``Function`` the coupler
fills each step (:meth:`Elasticity.set_vertex_field`).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
import ufl
from petsc4py import PETSc

import dolfinx
import dolfinx.fem
import dolfinx.fem.petsc
import dolfinx.geometry

from . import constitutive
from .constitutive import Material
from .linear_solver import LinearSolve, SolverOptions, make_ksp, mass_ksp, solve
from .mesh import SolidMesh
from .timestepping import Scheme, make_scheme

log = logging.getLogger(__name__)

Boundary = str | int | Sequence[str | int]

_COMPONENTS = {"x": 0, "y": 1, "z": 2}


@dataclass
class _Dirichlet:
    boundary: Boundary
    components: tuple[int, ...] | None
    value: object  # Constant or Function (the handle returned to the user)
    bcs: list
    dofs: np.ndarray  # local (unrolled) dof indices of the parent space, owned and ghost


@dataclass
class StepInfo:
    """The linear solves of the last static solve or time step, in order (a first time
    step solves for the initial acceleration before the step), and their timings."""

    solves: list[LinearSolve] = field(default_factory=list)
    assemble_seconds: float = 0.0
    solve_seconds: float = 0.0

    @property
    def iterations(self) -> int:
        """Krylov iterations of the last solve (the displacement's)."""
        return self.solves[-1].iterations if self.solves else 0


class Elasticity:
    """Linear isotropic elasticity, static (:meth:`solve_static`) and dynamic (:meth:`step`).

    Parameters
    ----------
    solid : :class:`solid_fenicsx.mesh.SolidMesh` (mesh, facet tags, boundary names)
    material : :class:`Material` (or give ``E``, ``nu``, ``density``)
    degree : polynomial degree of the displacement (1 or 2)
    locking_free : use quadratic (P2) displacements, which remove the volumetric
        locking of P1 tetrahedra for nearly incompressible materials (nu -> 0.5)
    scheme : None (static only), ``"newmark"`` (average acceleration,
        beta = 1/4, gamma = 1/2) or ``"generalized_alpha"`` (with ``rho_inf``), or a
        :class:`Scheme`
    dt : time step (dynamic)
    fluid_density : rho_f of eq. 13; the inertia uses rho_s0 - rho_f
    solver : ``"cg"`` (CG + GAMG with rigid body near-nullspace) or ``"lu"``, or
        :class:`SolverOptions`; ``rtol``, ``atol``, ``max_it``, ``petsc_options`` tune it
    """

    def __init__(self, solid: SolidMesh, material: Material | None = None, *, E: float | None = None,
                 nu: float | None = None, density: float = 0.0, degree: int = 1, locking_free: bool = False,
                 scheme: str | Scheme | None = None, dt: float | None = None, rho_inf: float = 0.8,
                 fluid_density: float = 0.0, solver: str | SolverOptions = "cg", rtol: float = 1e-10,
                 atol: float = 1e-50, max_it: int = 1000, petsc_options: dict | None = None):
        if material is None:
            if E is None or nu is None:
                raise ValueError("give a Material or both E and nu")
            material = Material(E, nu, density)
        if degree not in (1, 2):
            raise ValueError(f"degree must be 1 or 2, got {degree}")
        self.solid = solid
        self.mesh = solid.mesh
        self.material = material
        self.locking_free = bool(locking_free)
        self.degree = 2 if locking_free else degree
        self.locking_warned = material.check_locking(self.degree)
        self.fluid_density = float(fluid_density)
        self.scheme = scheme if isinstance(scheme, Scheme) or scheme is None else make_scheme(scheme, rho_inf)
        self.dt = None if dt is None else float(dt)
        if self.scheme is not None:
            if material.density - self.fluid_density <= 0:
                raise ValueError(f"dynamic solid needs density > fluid_density (eq. 13: rho_s - rho_f > 0), "
                                 f"got {material.density} - {self.fluid_density}")
        if isinstance(solver, str):
            solver = SolverOptions(solver, rtol, atol, max_it, dict(petsc_options or {}))
        self.solver_options = solver

        mesh = self.mesh
        self.V = dolfinx.fem.VectorFunctionSpace(mesh, ("Lagrange", self.degree))
        self._fdim = mesh.topology.dim - 1
        self.ds = ufl.Measure("ds", domain=mesh, subdomain_data=solid.facet_tags)
        self.n = ufl.FacetNormal(mesh)

        # state: u, v, a at t; the assembled load F at t (generalized-alpha)
        self.u = dolfinx.fem.Function(self.V, name="displacement")
        self.v = dolfinx.fem.Function(self.V, name="velocity")
        self.a = dolfinx.fem.Function(self.V, name="acceleration")
        self._u_old = dolfinx.fem.Function(self.V)
        self.t = 0.0
        self.step_count = 0
        self._F_old: PETSc.Vec | None = None
        self._initialized = False

        # loads
        self._dirichlet: list[_Dirichlet] = []
        self._neumann: list[tuple[str, Boundary, object]] = []  # (kind, boundary, Constant/Function)
        self._body: list[object] = []
        self.fields: dict[str, dolfinx.fem.Function] = {}
        self._P1 = None
        self._P1s = None

        # constants of the step matrix c_m M + c_k K and of the history terms
        self._cm = dolfinx.fem.Constant(mesh, 0.0)
        self._ck = dolfinx.fem.Constant(mesh, 1.0)
        self._hu = dolfinx.fem.Constant(mesh, 0.0)
        self._hv = dolfinx.fem.Constant(mesh, 0.0)
        self._ha = dolfinx.fem.Constant(mesh, 0.0)
        self._haf = dolfinx.fem.Constant(mesh, 0.0)
        self._mu = dolfinx.fem.Constant(mesh, float(material.mu))
        self._lmbda = dolfinx.fem.Constant(mesh, float(material.lmbda))
        self._rho = dolfinx.fem.Constant(mesh, float(material.density - self.fluid_density))

        self._forms = None
        self._matrix_key = None
        self._A = None
        self._ksp = None
        self._mass = None
        self.info = StepInfo()
        self._vm_cache: dict = {}
        self._vertex = None
        self._internal = None  # the internal force form of boundary_force

    # -- loads ----------------------------------------------------------------
    def _components(self, components) -> tuple[int, ...] | None:
        if components is None:
            return None
        if isinstance(components, (str, int)):
            components = [components]
        out = tuple(sorted({_COMPONENTS[c] if isinstance(c, str) else int(c) for c in components}))
        if any(c not in (0, 1, 2) for c in out):
            raise ValueError(f"components must be among 0, 1, 2 / 'x', 'y', 'z'; got {components}")
        return out

    def add_dirichlet(self, boundary: Boundary, value=0.0, components=None):
        """Prescribe the displacement on a boundary (name, tag or list of them).

        ``components=None`` fixes all components to ``value`` (a 3-vector, a
        scalar broadcast to all, or a callable ``x -> (3, n)`` array);
        ``components="z"`` (or ``[0, 2]``, ...) fixes only those (a roller),
        ``value`` is then a scalar or a callable ``x -> (3, n)`` of which the
        chosen components are used. Returns the value holder: a ``Constant``
        (set ``.value``) or, for callables, the interpolated ``Function``.
        """
        comps = self._components(components)
        facets = self.solid.facets(boundary)
        mesh, V, fdim = self.mesh, self.V, self._fdim
        if comps is None:
            if callable(value):
                holder = dolfinx.fem.Function(V)
                holder.interpolate(value)
                dofs = dolfinx.fem.locate_dofs_topological(V, fdim, facets)
                bcs = [dolfinx.fem.dirichletbc(holder, dofs)]
            else:
                holder = dolfinx.fem.Constant(mesh, np.broadcast_to(np.asarray(value, float), (3,)).copy())
                dofs = dolfinx.fem.locate_dofs_topological(V, fdim, facets)
                bcs = [dolfinx.fem.dirichletbc(holder, dofs, V)]
            bs = V.dofmap.index_map_bs
            unrolled = (bs * np.asarray(dofs)[:, None] + np.arange(bs)[None, :]).ravel()
        else:
            bcs, parts = [], []
            if callable(value):
                holder = dolfinx.fem.Function(V)
                holder.interpolate(value)
                for c in comps:
                    Vc, _ = V.sub(c).collapse()
                    dofs = dolfinx.fem.locate_dofs_topological((V.sub(c), Vc), fdim, facets)
                    gc = dolfinx.fem.Function(Vc)
                    gc.interpolate(holder.sub(c))
                    bcs.append(dolfinx.fem.dirichletbc(gc, dofs, V.sub(c)))
                    parts.append(np.asarray(dofs[0]))
            else:
                holder = dolfinx.fem.Constant(mesh, float(value))
                for c in comps:
                    dofs = dolfinx.fem.locate_dofs_topological(V.sub(c), fdim, facets)
                    bcs.append(dolfinx.fem.dirichletbc(holder, dofs, V.sub(c)))
                    parts.append(np.asarray(dofs))
            unrolled = np.concatenate(parts) if parts else np.empty(0, np.int32)
        self._dirichlet.append(_Dirichlet(boundary, comps, holder, bcs, np.asarray(unrolled, np.int64)))
        self._matrix_key = None
        return holder

    def add_traction(self, boundary: Boundary, value) -> dolfinx.fem.Constant:
        """A constant traction vector sigma n = t on a boundary; returns its Constant."""
        c = dolfinx.fem.Constant(self.mesh, np.asarray(value, float).reshape(3))
        self._neumann.append(("traction", boundary, c))
        self._forms = None
        return c

    def add_pressure(self, boundary: Boundary, p: float) -> dolfinx.fem.Constant:
        """A constant normal pressure (traction -p n, n the outward normal); returns its Constant."""
        c = dolfinx.fem.Constant(self.mesh, float(p))
        self._neumann.append(("pressure", boundary, c))
        self._forms = None
        return c

    def add_body_force(self, value) -> dolfinx.fem.Constant:
        """A constant body force density f (N/m^3); returns its Constant."""
        c = dolfinx.fem.Constant(self.mesh, np.asarray(value, float).reshape(3))
        self._body.append(c)
        self._forms = None
        return c

    def _p1(self, vector: bool):
        if vector:
            if self._P1 is None:
                self._P1 = dolfinx.fem.VectorFunctionSpace(self.mesh, ("Lagrange", 1))
            return self._P1
        if self._P1s is None:
            self._P1s = dolfinx.fem.FunctionSpace(self.mesh, ("Lagrange", 1))
        return self._P1s

    def _new_field(self, name: str, vector: bool) -> dolfinx.fem.Function:
        if name in self.fields:
            raise ValueError(f"field {name!r} already exists")
        f = dolfinx.fem.Function(self._p1(vector), name=name)
        self.fields[name] = f
        self._forms = None
        return f

    def add_traction_field(self, boundary: Boundary, name: str = "traction") -> dolfinx.fem.Function:
        """A traction given by its values at the vertices (a P1 vector field,
        used on ``boundary`` only); fill it with :meth:`set_vertex_field`."""
        f = self._new_field(name, True)
        self._neumann.append(("traction", boundary, f))
        return f

    def add_pressure_field(self, boundary: Boundary, name: str = "pressure") -> dolfinx.fem.Function:
        """A normal pressure (traction -p n) given at the vertices (P1 scalar field)."""
        f = self._new_field(name, False)
        self._neumann.append(("pressure", boundary, f))
        return f

    def add_body_force_field(self, name: str = "body_force") -> dolfinx.fem.Function:
        """A body force density given at the vertices (P1 vector field), e.g. the
        fluid force on an immersed solid (paper 2.3, Step 3)."""
        f = self._new_field(name, True)
        self._body.append(f)
        return f

    # -- vertex-level access (the coupler's side) -----------------------------
    @property
    def vertices(self):
        """:class:`solid_fenicsx.vertex_io.VertexIO` of this mesh (built on first use)."""
        if self._vertex is None:
            from .vertex_io import VertexIO

            self._vertex = VertexIO(self.solid)
        return self._vertex

    def set_vertex_field(self, name: str, values, root: int | None = 0, vertex_ids=None) -> None:
        """Set a field load from vertex values in input numbering, (num_points,)
        or (num_points, 3) on ``root`` (``root=None``: every rank passes the full
        array); with ``vertex_ids``, values at those vertices only (others 0)."""
        self.vertices.scatter(self.fields[name], values, root=root, vertex_ids=vertex_ids)

    def vertex_values(self, what: str = "displacement", root: int | None = 0) -> np.ndarray | None:
        """An output (see :meth:`output`: displacement, velocity, acceleration,
        von_mises, a field) at the vertices, gathered on ``root`` in input
        numbering: (num_points, 3) or (num_points,); None on other ranks
        (``root=None``: on all ranks)."""
        return self.vertices.gather(self.output(what), root=root)

    def output(self, what: str):
        """The Function of an output: ``displacement``, ``velocity``,
        ``acceleration``, ``von_mises`` (lumped P1 projection), ``von_mises_dg0``, or
        the name of a field load."""
        if what in ("displacement", "u"):
            return self.u
        if what in ("velocity", "v"):
            return self.v
        if what in ("acceleration", "a"):
            return self.a
        if what in ("von_mises", "von_mises_p1"):
            return self.von_mises("P1")
        if what == "von_mises_dg0":
            return self.von_mises("DG0")
        if what in self.fields:
            return self.fields[what]
        raise ValueError(f"unknown output {what!r}")

    # -- forms ----------------------------------------------------------------
    def sigma(self, u):
        """Stress of eq. 5 for a displacement (UFL)."""
        return constitutive.sigma(u, self._mu, self._lmbda)

    def _build_forms(self):
        V = self.V
        u, w = ufl.TrialFunction(V), ufl.TestFunction(V)
        dx = ufl.dx(domain=self.mesh)
        eps = constitutive.epsilon
        k = ufl.inner(self.sigma(u), eps(w)) * dx
        m = self._rho * ufl.inner(u, w) * dx
        load = ufl.inner(dolfinx.fem.Constant(self.mesh, np.zeros(3)), w) * dx
        for f in self._body:
            load += ufl.inner(f, w) * dx
        for kind, boundary, value in self._neumann:
            ds = self.ds(self.solid.tags_of(boundary))
            if kind == "traction":
                load += ufl.inner(value, w) * ds
            else:
                load += -value * ufl.inner(self.n, w) * ds
        un, vn, an = self._u_old, self.v, self.a
        history = (self._rho * ufl.inner(self._hu * un + self._hv * vn + self._ha * an, w) * dx
                   - self._haf * ufl.inner(self.sigma(un), eps(w)) * dx)
        residual0 = load - ufl.inner(self.sigma(un), eps(w)) * dx  # F - K u (initial acceleration)
        self._forms = _LazyForms({
            "a": self._cm * m + self._ck * k,
            "m": m,
            "load": load,
            "history": history,
            "residual0": residual0,
            "energy_k": 0.5 * self._rho * ufl.inner(self.v, self.v) * dx,
            "energy_s": 0.5 * ufl.inner(self.sigma(self.u), eps(self.u)) * dx,
        })
        self._matrix_key = None

    @property
    def bcs(self) -> list:
        return [bc for d in self._dirichlet for bc in d.bcs]

    def _bc_dofs_owned(self) -> np.ndarray:
        n_owned = self.V.dofmap.index_map.size_local * self.V.dofmap.index_map_bs
        dofs = np.unique(np.concatenate([d.dofs for d in self._dirichlet])) if self._dirichlet else np.empty(0, int)
        return dofs[dofs < n_owned]

    def _operator(self, cm: float, ck: float):
        """Assemble (once per (c_m, c_k, bcs)) the step matrix and its solver."""
        if self._forms is None:
            self._build_forms()
        key = (cm, ck, len(self._dirichlet))
        if key != self._matrix_key:
            self._cm.value, self._ck.value = cm, ck
            t0 = time.perf_counter()
            if self._A is not None:
                self._A.destroy()
                self._ksp.destroy()
            self._A = dolfinx.fem.petsc.assemble_matrix(self._forms["a"], bcs=self.bcs)
            self._A.assemble()
            self._ksp = make_ksp(self._A, self.solver_options, V=self.V)
            self._matrix_key = key
            log.debug("assembled step matrix in %.3f s", time.perf_counter() - t0)
        return self._A, self._ksp

    def _assemble(self, form) -> PETSc.Vec:
        """Assemble a vector: owned entries complete, ghost entries zero (so
        that later lifting and reverse scatters add nothing twice)."""
        b = dolfinx.fem.petsc.assemble_vector(form)
        b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        with b.localForm() as local:
            local.array[b.getLocalSize():] = 0.0
        return b

    def _solve(self, rhs: PETSc.Vec, cm: float, ck: float, what: str) -> None:
        """Solve (c_m M + c_k K) u = rhs (Dirichlet values lifted) into ``self.u``."""
        A, ksp = self._operator(cm, ck)
        dolfinx.fem.petsc.apply_lifting(rhs, [self._forms["a"]], bcs=[self.bcs])
        rhs.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        dolfinx.fem.petsc.set_bc(rhs, self.bcs)
        t0 = time.perf_counter()
        ksp.setInitialGuessNonzero(self.solver_options.kind != "lu")
        self.info.solves.append(solve(ksp, rhs, self.u.vector, what))
        self.info.solve_seconds = time.perf_counter() - t0
        self.u.x.scatter_forward()

    def _check_ready(self):
        if not self._dirichlet:
            log.warning("no Dirichlet condition: the static problem is singular unless the loads balance")

    # -- static ---------------------------------------------------------------
    def solve_static(self) -> dolfinx.fem.Function:
        """Solve -div sigma(u) = f with the current loads; returns ``u`` (also
        ``self.u``). The velocity and acceleration are left unchanged (zero
        unless set)."""
        self._check_ready()
        if self._forms is None:
            self._build_forms()
        t0 = time.perf_counter()
        b = self._assemble(self._forms["load"])
        self.info = StepInfo(assemble_seconds=time.perf_counter() - t0)
        self._solve(b, 0.0, 1.0, "static")
        b.destroy()
        return self.u

    solve = solve_static

    @property
    def dirichlet_dofs(self) -> np.ndarray:
        """Owned (unrolled) dof indices with a Dirichlet condition."""
        return self._bc_dofs_owned()

    def static_system(self) -> tuple[PETSc.Mat, PETSc.Vec]:
        """The static stiffness matrix K and load vector F with the Dirichlet
        conditions applied (their rows and columns identity, values lifted into
        F), for solvers that work on the algebraic system (contact). K belongs to
        this object and changes with it; F is new (destroy it)."""
        self._check_ready()
        K, _ = self._operator(0.0, 1.0)
        F = self._assemble(self._forms["load"])
        dolfinx.fem.petsc.apply_lifting(F, [self._forms["a"]], bcs=[self.bcs])
        F.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        dolfinx.fem.petsc.set_bc(F, self.bcs)
        return K, F

    def internal_force(self, values: np.ndarray | None = None) -> np.ndarray:
        """The owned entries of the internal force ``int sigma(u) : eps(w)`` (dof numbering) of
        the current u, or of the displacement `values` (u's local array, ghosts included)."""
        if self._internal is None:
            w = ufl.TestFunction(self.V)
            self._internal = dolfinx.fem.form(ufl.inner(self.sigma(self.u), constitutive.epsilon(w))
                                              * ufl.dx(domain=self.mesh))
        kept = None if values is None else self.u.x.array.copy()
        if kept is not None:
            self.u.x.array[:] = values
        f = self._assemble(self._internal)
        out = f.array[:f.getLocalSize()].copy()
        f.destroy()
        if kept is not None:
            self.u.x.array[:] = kept
        return out

    def boundary_dofs(self, boundary: Boundary) -> np.ndarray:
        """The local (owned and ghost) block dofs of a boundary."""
        return dolfinx.fem.locate_dofs_topological(self.V, self._fdim, self.solid.facets(boundary))

    def boundary_force(self, boundary: Boundary) -> np.ndarray:
        """(3,) the sum over the dofs of a boundary of the internal force ``int sigma(u) : eps(w)``
        of the current u: on a Dirichlet boundary without loads, the force the body exerts on
        its support (a loaded boundary needs its load added), on every rank."""
        from mpi4py import MPI

        dofs = self.boundary_dofs(boundary)
        owned = dofs[dofs < self.V.dofmap.index_map.size_local]
        local = self.internal_force().reshape(-1, 3)[owned].sum(axis=0)
        return self.mesh.comm.allreduce(local, op=MPI.SUM)

    def pressure_resultant(self, boundary: Boundary, p) -> np.ndarray:
        """(3,) the force of a pressure p on a boundary, ``int -p n ds``, on every rank: p a
        number (uniform) or a field (a P1 Function, e.g. the coupled fluid pressure)."""
        from mpi4py import MPI

        ds = self.ds(self.solid.tags_of(boundary))
        field = isinstance(p, dolfinx.fem.Function)
        local = [dolfinx.fem.assemble_scalar(dolfinx.fem.form(-(p if field else 1.0) * self.n[i] * ds))
                 for i in range(3)]
        return (1.0 if field else float(p)) * self.mesh.comm.allreduce(np.array(local), op=MPI.SUM)

    # -- dynamic --------------------------------------------------------------
    def _require_dynamic(self, dt):
        if self.scheme is None:
            raise RuntimeError("this Elasticity is static: pass scheme='newmark' or 'generalized_alpha' and dt")
        dt = self.dt if dt is None else float(dt)
        if dt is None or dt <= 0:
            raise ValueError("a positive time step dt is needed")
        return dt

    def initialize(self) -> None:
        """Start the time integration from the current u, v and loads: the
        initial acceleration solves M a0 = F(t0) - K u0 (zero on Dirichlet dofs).
        Called by the first :meth:`step` if not called before."""
        if self.scheme is None:
            raise RuntimeError("initialize() is for dynamic problems")
        if self._forms is None:
            self._build_forms()
        self._u_old.x.array[:] = self.u.x.array
        if self._mass is None:
            M = dolfinx.fem.petsc.assemble_matrix(self._forms["m"], bcs=self.bcs)
            M.assemble()
            self._mass = (M, mass_ksp(M, self.solver_options))
        M, ksp = self._mass
        r = self._assemble(self._forms["residual0"])
        r.array_w[self._bc_dofs_owned()] = 0.0
        self.info.solves.append(solve(ksp, r, self.a.vector, "initial acceleration"))
        self.a.x.scatter_forward()
        r.destroy()
        if self._F_old is not None:
            self._F_old.destroy()
        self._F_old = self._assemble(self._forms["load"])
        self._initialized = True

    def step(self, dt: float | None = None) -> dolfinx.fem.Function:
        """Advance from t to t + dt with the loads currently set (they are the
        loads at t + dt); returns ``u`` (``v``, ``a`` and ``t`` are updated)."""
        dt = self._require_dynamic(dt)
        if self._forms is None:
            self._build_forms()
        self.info = StepInfo()
        if not self._initialized:
            self.initialize()
        s = self.scheme
        self._u_old.x.array[:] = self.u.x.array
        self._hu.value, self._hv.value, self._ha.value = s.history_factors(dt)
        self._haf.value = s.alpha_f

        t0 = time.perf_counter()
        F_new = self._assemble(self._forms["load"])
        rhs = self._assemble(self._forms["history"])
        rhs.axpy(1.0 - s.alpha_f, F_new)
        if s.alpha_f:
            rhs.axpy(s.alpha_f, self._F_old)
        self.info.assemble_seconds = time.perf_counter() - t0
        self._solve(rhs, s.mass_factor(dt), s.stiffness_factor, "time step")
        rhs.destroy()

        u_new, u_old = self.u.x.array, self._u_old.x.array
        a_new, v_new = s.update(dt, u_new, u_old, self.v.x.array, self.a.x.array)
        self.a.x.array[:] = a_new
        self.v.x.array[:] = v_new
        self._F_old.destroy()
        self._F_old = F_new
        self.t += dt
        self.step_count += 1
        return self.u

    # -- checkpoints ----------------------------------------------------------
    def save_state(self) -> dict:
        """Copies of the time-stepping state (u, v, a, t, step count, previous
        load vector); restore with :meth:`restore_state`."""
        return {
            "u": self.u.x.array.copy(), "v": self.v.x.array.copy(), "a": self.a.x.array.copy(),
            "t": self.t, "step_count": self.step_count, "initialized": self._initialized,
            "F_old": None if self._F_old is None else self._F_old.getArray(readonly=True).copy(),
        }

    def restore_state(self, state: dict) -> None:
        """Restore a state from :meth:`save_state` (the state is copied, it can be reused)."""
        self.u.x.array[:] = state["u"]
        self.v.x.array[:] = state["v"]
        self.a.x.array[:] = state["a"]
        self.t = float(state["t"])
        self.step_count = int(state["step_count"])
        self._initialized = bool(state["initialized"])
        if state["F_old"] is not None:
            if self._F_old is None:
                if self._forms is None:
                    self._build_forms()
                self._F_old = dolfinx.fem.petsc.create_vector(self._forms["load"])
            self._F_old.getArray()[:] = state["F_old"]

    # -- derived quantities ---------------------------------------------------
    def energy(self) -> tuple[float, float]:
        """(kinetic, strain) energy: 1/2 int (rho_s - rho_f) v.v and 1/2 int sigma(u):eps(u)."""
        if self._forms is None:
            self._build_forms()
        comm = self.mesh.comm
        from mpi4py import MPI

        kin = comm.allreduce(dolfinx.fem.assemble_scalar(self._forms["energy_k"]), op=MPI.SUM)
        strain = comm.allreduce(dolfinx.fem.assemble_scalar(self._forms["energy_s"]), op=MPI.SUM)
        return float(kin), float(strain)

    def stress(self):
        """The stress tensor of the current displacement (UFL expression)."""
        return self.sigma(self.u)

    def von_mises(self, kind: str = "DG0") -> dolfinx.fem.Function:
        """Von Mises stress of the current displacement: ``"DG0"`` (cellwise, at the cell
        midpoint; exact for P1) or ``"P1"`` (vertex values for output): the lumped-mass
        (row-sum) L2 projection ``vm_i = int vm phi_i / int phi_i``, a weighted mean of the
        values around vertex i. It never undershoots (vm >= 0, phi_i >= 0), is exact for a
        uniform stress, keeps the integral and needs no linear solve; the consistent
        projection overshoots below zero beside stress concentrations (-1.3 MPa on cases/hertz)."""
        kind = kind.upper()
        vm = constitutive.von_mises(self.stress())
        if kind == "DG0":
            if "DG0" not in self._vm_cache:
                W = dolfinx.fem.FunctionSpace(self.mesh, ("DG", 0))
                f = dolfinx.fem.Function(W, name="von_mises")
                expr = dolfinx.fem.Expression(vm, W.element.interpolation_points())
                self._vm_cache["DG0"] = (f, expr)
            f, expr = self._vm_cache["DG0"]
            f.interpolate(expr)
        elif kind == "P1":
            if "P1" not in self._vm_cache:
                q = ufl.TestFunction(self._p1(False))
                dx = ufl.dx(domain=self.mesh)
                lumped = self._assemble(dolfinx.fem.form(q * dx))  # row sums of the mass matrix
                f = dolfinx.fem.Function(self._p1(False), name="von_mises")
                self._vm_cache["P1"] = (f, (lumped.array.copy(), dolfinx.fem.form(vm * q * dx)))
                lumped.destroy()
            f, (lumped, L) = self._vm_cache["P1"]
            b = self._assemble(L)
            f.x.array[: len(lumped)] = b.array / lumped
            f.x.scatter_forward()
            b.destroy()
        else:
            raise ValueError(f"von Mises kind must be 'DG0' or 'P1', got {kind!r}")
        return self._vm_cache[kind][0]

    def evaluate(self, points, what: str = "displacement") -> np.ndarray:
        """Values of an output (see :meth:`output`; or a Function) at points
        (n, 3), on every rank; NaN where a point is outside the mesh."""
        f = what if isinstance(what, dolfinx.fem.Function) else self.output(what)
        return evaluate(f, points)


class _LazyForms(dict):
    """UFL forms compiled (JIT) on first use: a static solve compiles two forms, not seven."""

    def __init__(self, ufl_forms: dict):
        super().__init__()
        self._ufl = ufl_forms

    def __missing__(self, key):
        compiled = dolfinx.fem.form(self._ufl[key])
        self[key] = compiled
        return compiled


def evaluate(f: dolfinx.fem.Function, points) -> np.ndarray:
    """Point values of a dolfinx Function on every rank ((n, value_size); NaN outside)."""
    from mpi4py import MPI

    mesh = f.function_space.mesh
    pts = np.ascontiguousarray(np.asarray(points, float).reshape(-1, 3))
    tdim = mesh.topology.dim
    tree = dolfinx.geometry.BoundingBoxTree(mesh, tdim)
    candidates = dolfinx.geometry.compute_collisions(tree, pts)
    colliding = dolfinx.geometry.compute_colliding_cells(mesh, candidates, pts)
    size = _value_size(f)
    local = np.zeros((len(pts), size))
    found = np.zeros(len(pts))
    idx, cells = [], []
    for i in range(len(pts)):
        links = colliding.links(i)
        if len(links):
            idx.append(i)
            cells.append(links[0])
    if idx:
        vals = f.eval(pts[idx], np.asarray(cells, np.int32))
        local[idx] = np.asarray(vals).reshape(len(idx), size)
        found[idx] = 1.0
    comm = mesh.comm
    total = comm.allreduce(local, op=MPI.SUM)
    count = comm.allreduce(found, op=MPI.SUM)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = total / count[:, None]
    return out


def _value_size(f) -> int:
    shape = f.ufl_shape
    return int(np.prod(shape)) if shape else 1
