"""solid_fenicsx: the solid participant of varcouple on dolfinx 0.5.2.

Linear elasticity on tetrahedra (Hooke's law, paper eq. 5; boundary value
problem eq. 7 without contact), static and dynamic with the effective density
of an immersed solid (eq. 13), P1 or P2, PETSc CG + GAMG, MPI-parallel.

>>> from solid_fenicsx import box_mesh, Elasticity
>>> solid = box_mesh(upper=(1, 1, 1), shape=(8, 8, 8))          # faces xmin..zmax
>>> s = Elasticity(solid, E=1e9, nu=0.3)
>>> s.add_dirichlet("zmin", 0.0, components="z"); s.add_pressure("zmax", 1e6)
>>> u = s.solve_static()

Modules: :mod:`.mesh` (meshes and boundary tags), :mod:`.constitutive`
(material, stress), :mod:`.timestepping` (Newmark, generalized-alpha),
:mod:`.linear_solver` (KSP set-up, how each solve ended), :mod:`.elasticity` (the solver),
:mod:`.vertex_io` (arrays for the coupler), :mod:`.output` (XDMF, VTU),
:mod:`.cases` (block compression, penny crack, bar, cantilever); load steps
(:mod:`.load_steps`: constant, ramped or per step; :mod:`.platen`: a rigid platen under stress
control); frictionless contact (paper 2.2, eq. 7-11): :mod:`.mortar` (contact faces, slave
normals, ``T = D^-1 B`` with the dual basis, weighted gap), :mod:`.obstacle` (a rigid plane,
T = 0), :mod:`.contact` (the transformed system of eq. 10 as a bound-constrained QP, pressure),
:mod:`.contact_hertz` (the Hertz case and its theory), :mod:`.contact_halfspace` (the periodic
half-space of rough contact, tamaas). Case geometry comes from
:mod:`transfer.generators`. :mod:`.settings`: the participant's declared settings, read by the
coupler without dolfinx.
"""

import importlib

#: public name -> the module that defines it, imported on first use (PEP 562): reading the
#: participant's settings (:mod:`.settings`) imports no dolfinx
_EXPORTS = {
    "LockingWarning": ".constitutive", "Material": ".constitutive",
    "Elasticity": ".elasticity", "evaluate": ".elasticity",
    "LinearSolve": ".linear_solver", "LinearSolveError": ".linear_solver", "SolverOptions": ".linear_solver",
    "SolidMesh": ".mesh", "SolidMeshError": ".mesh", "box_mesh": ".mesh", "from_arrays": ".mesh",
    "read_mesh": ".mesh",
    "VTUSeries": ".output", "XDMFSeries": ".output",
    "Scheme": ".timestepping", "make_scheme": ".timestepping",
    "VertexIO": ".vertex_io", "write_vtu": ".vertex_io",
}
__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name not in _EXPORTS:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(_EXPORTS[name], __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *_EXPORTS})
