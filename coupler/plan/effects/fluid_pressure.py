"""Effect ``fluid_pressure``: a fluid at rest in the fracture, its uniform pressure a load on
the faces (its ``[[loads]]`` of type ``fluid_pressure``); no fluid solver is started."""

NAME = "fluid_pressure"
DESCRIPTION = "a static fluid pressure on fracture faces, applied as a load (no fluid solver)"
ORDER = 2
NEEDS = ("elasticity",)  # a load on the elastic solid


def plan(scene, plan) -> None:
    """Nothing to add: the elasticity rule sends the fluid_pressure loads as pressures."""
