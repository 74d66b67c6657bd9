"""The choices of the OpenFOAM fluid participant's settings, in one place (the case writer,
the penalization and the decomposition check against them)."""

from transfer.penalization import PENALIZATIONS  # noqa: F401 (how solid fractions become drag)
#: decomposePar methods of a fluid on several ranks (scotch is a dummy library in Debian's v1912)
DECOMPOSITIONS = ("simple",)
#: how the solid's velocity reaches the fluid (:mod:`fluid_openfoam.zones`)
SOLID_VELOCITIES = ("bodies", "none")
