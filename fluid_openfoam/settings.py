"""The OpenFOAM fluid participant's settings, declared once (``[solvers.fluid]`` with
``participant = "openfoam"``; cases/README.md's reference is generated from it). Imports no
solver: the coupler reads it to validate scenes (entry point ``varcouple.participants``)."""

from coupler.protocol.penalization import PENALIZATION
from coupler.protocol.settings import ParticipantSpec, Setting, Settings, When

#: decomposePar methods of a fluid on several ranks (scotch is a dummy library in Debian's v1912)
DECOMPOSITIONS = ("simple",)
#: how the solid's velocity reaches the fluid (:mod:`fluid_openfoam.zones`)
SOLID_VELOCITIES = ("bodies", "none")

PARTICIPANT = ParticipantSpec(
    kind="openfoam", module="fluid_openfoam", role="fluid", needs=("flow",),
    # per rank: this participant's process and simpleFoam's (bench/ranks.py: 90 + 108 MB on 2,541
    # cells, 112 + 132 MB on 20,328; simpleFoam alone 188 MB on 64k cells, 735 MB on 512k)
    memory=(220 * 2**20, 1400),
    description="incompressible flow on the structured grid by stock OpenFOAM v1912 (simpleFoam, pimpleFoam with "
                "dynamics), the solid immersed by volume penalization",
    settings=Settings(
        Setting("decomposition", "string", "decomposePar's method (N = nx ny nz blocks with the "
                "fewest cut faces; Debian's v1912 ships only a dummy scotch library); the participant runs as one "
                "process per processor, the solver as mpirun -np N simpleFoam -parallel (fluid_openfoam/parallel.py)",
                default="simple", choices=DECOMPOSITIONS, only=When.above("ranks", 1))) + PENALIZATION + Settings(
        Setting("max_iterations", "integer", "simpleFoam iterations per coupling iteration at most (a warning in "
                "the fluid's log when they run out)", default=2000, minimum=1),
        Setting("tolerance", "number", "simpleFoam's residualControl of p and U (with dynamics: PIMPLE's, the "
                "initial residuals per outer iteration); on 3D grids whose flow is nearly 2D the almost-zero "
                "velocity components stall near 1e-6: use 1e-6", default=1e-7, positive=True),
        Setting("substeps", "integer", "with dynamics: pimpleFoam time steps (Euler) per coupling step",
                default=1, minimum=1),
        Setting("outer_correctors", "integer", "with dynamics: PIMPLE outer iterations per time step at most",
                default=50, minimum=1),
        Setting("solid_velocity", "string", "bodies: every solid body (connected cells of solid fraction >= 1/2) "
                "moves rigidly with the fraction-weighted mean velocity of its wetted cell layer "
                "(fluid_openfoam/zones.py; rotation and deformation within a body are not represented; a body cut "
                "by the grid's boundary needs an open face there); none: the solid is penalized towards rest. A "
                "solid at rest (quasi-static) adds nothing", default="bodies", choices=SOLID_VELOCITIES),
        Setting("keep_case", "boolean", "keep the OpenFOAM case in logs/fluid_case of the output directory for "
                "inspection (false: a temporary directory, removed on every exit path)", default=False)))
