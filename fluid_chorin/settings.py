"""The Chorin fluid participant's settings, declared once (``[solvers.fluid]`` with
``participant = "chorin"``; cases/README.md's reference is generated from it), and what it
cannot run (:func:`refuses`). Imports no solver: the coupler reads it to validate scenes
(entry point ``varcouple.participants``)."""

from coupler.protocol.penalization import PENALIZATION
from coupler.protocol.settings import ParticipantSpec, Setting, Settings
from coupler.protocol.slabs import MIN_CELLS, SLAB_AXES

#: pressure Poisson solvers (:mod:`fluid_chorin.poisson`)
POISSON_METHODS = ("auto", "direct", "gamg")
#: how the solid's velocity reaches the fluid (:meth:`fluid_chorin.solver.ChorinSolver.set_solid`)
SOLID_VELOCITIES = ("cells", "bodies", "none")
#: how a steady scene's flow is solved (:meth:`fluid_chorin.solver.ChorinSolver.steady`)
STEADY_METHODS = ("march", "newton")

def refuses(scene) -> str | None:
    """Why the Chorin fluid cannot run `scene` (None: it can): the steady Newton solve assembles
    and factorizes the whole grid's blocks in one process."""
    solver = scene.solvers["fluid"]
    if solver.settings.get("steady") == "newton" and solver.ranks > 1:
        return f"steady = 'newton' solves on one rank, got ranks = {solver.ranks}: use steady = 'march' on several ranks"
    return None


PARTICIPANT = ParticipantSpec(
    kind="chorin", module="fluid_chorin", role="fluid", needs=("flow",), accepts=("inlet_pressure",),
    memory=(120 * 2**20, 2000), refuses=refuses,
    description="incompressible flow on the structured grid by Chorin's projection on a staggered grid, in memory, "
                "the solid immersed by volume penalization towards its velocity cell by cell",
    settings=PENALIZATION + Settings(
        Setting("max_iterations", "integer", "pseudo-time steps per coupling iteration at most", default=20000,
                minimum=1),
        Setting("tolerance", "number", "the relative change of velocity and pressure in one pseudo-time step (with "
                "dynamics: in one outer iteration) that ends the solve", default=1e-7, positive=True),
        Setting("steady", "string", "without dynamics, how the steady flow is solved: march (pseudo-time steps to the "
                "steady state, up to max_iterations), newton (Newton on the steady velocity-pressure system of the "
                "grid, GMRES preconditioned by line solves along the finest direction and a Schur complement with their "
                "lumped inverse; one rank only; the same steady state; its time grows less with the cells across a "
                "fracture than the march's: bench/hm.py --steady)", default="march", choices=STEADY_METHODS),
        Setting("newton_iterations", "integer", "without dynamics and steady = newton: Newton steps per coupling "
                "iteration at most", default=30, minimum=1),
        Setting("error_estimate", "boolean", "without dynamics: also solve each steady flow on the grid coarsened 2x "
                "across the thin gap (pairs of cells merged, their solid fractions averaged: exact) and report its "
                "flow rate (figure coarse_flow_rate), from which the coupler estimates the error of a fracture's "
                "hydraulic aperture (summary.json fracture.hydraulic_aperture_error); on hm_fracture the coarse solves "
                "cost 0.18 of the fine ones with the march, 0.18 to 0.45 with Newton (bench/eh_error.py); only a fracture "
                "(contact with flow) reads it: the hm_fracture scenes set it", default=False),
        Setting("substeps", "integer", "with dynamics: at least this many time steps per coupling step (more when "
                "the explicit stability bound asks)", default=1, minimum=1),
        Setting("outer_correctors", "integer", "with dynamics: predictor-projection outer iterations per time step "
                "at most", default=50, minimum=1),
        Setting("cfl", "number", "Courant number of the explicit convection", default=0.5, positive=True,
                maximum=1.0),
        Setting("poisson", "string", "the pressure solver: auto (PETSc's sparse Cholesky up to 30000 cells, up to "
                "300000 on anisotropic cells (sides 10:1 or more), CG + GAMG beyond), direct (on several ranks "
                "MUMPS's Cholesky), gamg", default="auto",
                choices=POISSON_METHODS),
        Setting("solid_velocity", "string", "cells: the projected solid velocity per cell (rotating and deforming "
                "solids move the fluid); bodies: every solid body (connected cells of solid fraction >= 1/2) moves "
                "rigidly with the fraction-weighted mean velocity of its wetted cell layer, the velocity normal to a "
                "closed grid face dropped (transfer/bodies.py: the model of the OpenFOAM fluid's bodies, to compare "
                "the two); none: the solid is penalized towards rest", default="cells", choices=SOLID_VELOCITIES),
        Setting("slab_axis", "string", "with ranks > 1: the direction the grid is cut in slabs along, one per MPI "
                f"rank (at least {MIN_CELLS} cells each); longest: the direction of the most cells", default="longest",
                choices=SLAB_AXES)))
