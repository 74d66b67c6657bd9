"""The solid participant's settings, declared once (``[solvers.solid]`` with ``participant =
"solid_fenicsx"``; cases/README.md's reference is generated from it). Imports no solver (no
dolfinx): the coupler reads it to validate scenes (entry point ``varcouple.participants``)."""

from coupler.protocol.settings import ParticipantSpec, Setting, Settings

#: linear solvers of the elasticity system (:mod:`solid_fenicsx.linear_solver`)
LINEAR_SOLVERS = ("cg", "lu")

PARTICIPANT = ParticipantSpec(
    kind="solid_fenicsx", module="solid_fenicsx", role="solid",
    memory=(120 * 2**20, 1000),  # P1 elasticity with CG + GAMG: 25k tets 130 MB, 197k tets 298 MB
    contact_step=(5.7, 2.05),  # bench/first_step.py: 9.6k to 38k tets, measured / rule 0.70 .. 1.75
    description="linear elasticity on tetrahedra with dolfinx 0.5.2 (static, elastodynamics, frictionless mortar "
                "contact of two bodies or with a rigid plane, platen loads under stress control)",
    settings=Settings(
        Setting("degree", "integer", "polynomial degree of the displacement", default=1, choices=(1, 2)),
        Setting("linear_solver", "string", "cg: CG with GAMG; lu: a direct solver", default="cg",
                choices=LINEAR_SOLVERS),
        Setting("rtol", "number", "relative tolerance of CG", default=1e-10, positive=True),
        Setting("max_iterations", "integer", "Krylov iterations per solve at most", default=1000, minimum=1)))
