"""Effect ``dynamics``: the rock's inertia, elastodynamics in time steps (paper eq. 13)."""

NAME = "dynamics"
DESCRIPTION = "inertia: elastodynamics with time steps (paper eq. 13)"
ORDER = 1
NEEDS = ("elasticity",)  # the inertia of an elastic solid
TIME_STEPS = True  # [time] dt and steps are required


def plan(scene, plan) -> None:
    solid = plan.participant("solid")
    # rho_f of eq. 13 is for a volume-coupled immersed solid; here the fluid loads the rock through
    # its wetted surface only (the penalized fluid inside it passes its inertia to the penalty, not
    # to the surface pressure: tests/fluid_openfoam/test_fluid_transient.py, piston), so the rock
    # keeps its own inertia rho_s: fluid_density stays 0
    solid.config["dynamic"] = True
    plan.iteration = f"{scene.time['steps']} time steps of {scene.time['dt']:g} s, one solve per step"
