"""The choices of the OpenFOAM fluid participant's settings, in one place (the case writer,
the penalization and the decomposition check against them)."""

#: how solid volume fractions become drag in the fluid cells (:mod:`fluid_openfoam.penalization`)
PENALIZATIONS = ("wall", "linear", "power")
#: decomposePar methods of a fluid on several ranks (scotch is a dummy library in Debian's v1912)
DECOMPOSITIONS = ("simple",)
#: how the solid's velocity reaches the fluid (:mod:`fluid_openfoam.zones`)
SOLID_VELOCITIES = ("bodies", "none")
