"""The settings of the Chorin fluid participant (``[solvers.fluid] participant = "chorin"``):
their defaults and choices, in one place (the scene and :mod:`fluid_chorin.spec` read them)."""

from transfer.penalization import PENALIZATIONS  # noqa: F401 (how solid fractions become drag)

#: pressure Poisson solvers (:mod:`fluid_chorin.poisson`)
POISSON_METHODS = ("auto", "direct", "gamg")

#: key -> default; ``drag`` None: :func:`transfer.penalization.default_drag`
DEFAULTS = {
    "penalization": "wall",        # solid fractions -> drag (transfer/penalization.py)
    "penalization_exponent": 2.0,  # of penalization "power"
    "drag": None,                  # maximum drag [1/s]
    "max_iterations": 20000,       # pseudo-time steps per advance (steady)
    "tolerance": 1.0e-7,           # steady: relative change per pseudo-time step; transient: per outer iteration
    "substeps": 1,                 # transient: at least this many time steps per coupling step
    "outer_correctors": 50,        # transient: outer iterations per time step at most
    "cfl": 0.5,                    # Courant number of the explicit convection
    "poisson": "auto",             # pressure solver: "direct" (Cholesky), "gamg" (CG + GAMG), "auto" (by size)
}
