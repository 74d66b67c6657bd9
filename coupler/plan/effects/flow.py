"""Effect ``flow``: fluid flow on a structured grid around the rock, coupled to it by the
immersed-boundary scheme of paper 2.3 (Steps 1-6): a fluid participant on the grid and the
exchanges between it and the solid.

Per coupling iteration, in the order the participants advance: the solid advances under the
fluid's load on its wetted boundary (``[coupling] interface``: the pressure, or with
``traction = "full"`` the traction (-p I + tau) n; Steps 2-4), which is the accelerated
interface quantity; the fluid advances in the grid cells the deformed solid fills (the solid
fraction, before Step 1) and, when the solid moves in time (``dynamics``), with the solid's
velocity on the grid (Step 6). A quasi-static scene sends no velocity: the solid is at rest
in each step.
"""

NAME = "flow"
DESCRIPTION = "fluid flow on a structured grid, coupled to the solid (fluid participant, paper 2.3)"
ORDER = 3


def fluid_config(scene) -> dict:
    """What the fluid participant is configured with: its grid, the fluid, the boundary
    conditions ([flow]) and its solver settings."""
    solver = scene.solvers["fluid"]
    g = scene.fluid
    config = {"grid": {"origin": g.origin, "spacing": g.spacing, "shape": g.shape}, "location": "cells",
              "rho": scene.fluid_material["density"], "mu": scene.fluid_material["viscosity"]}
    if solver["participant"] == "replay_fluid":
        config.update(pressure=solver["pressure"], feedback=solver["feedback"], unconverged=solver["unconverged"])
    if solver["participant"] == "openfoam":
        from pathlib import Path

        config.update({k: solver[k] for k in ("penalization", "penalization_exponent", "drag", "max_iterations",
                                              "tolerance", "decomposition", "substeps", "outer_correctors",
                                              "solid_velocity")}, ranks=solver["solver_ranks"])
        config.update(transient="dynamics" in scene.effects, dt=scene.time["dt"])
        if solver["keep_case"]:
            config["case_dir"] = str((Path(scene.output_dir) / "logs" / "fluid_case").resolve())
        if scene.flow:
            f = scene.flow
            config.update(inlet=f["inlet"], outlet=f["outlet"], walls=f["walls"], boundaries=dict(f["faces"]))
    return config


def plan(scene, plan) -> None:
    from coupler.plan.plan import Exchange, PlannedParticipant

    solver = scene.solvers["fluid"]
    c = scene.coupling
    solid = plan.participant("solid")
    solid.config.update(wetted=c["interface"], traction=c["traction"])
    plan.participants.append(PlannedParticipant("fluid", solver["participant"], solver["module"], solver["ranks"],
                                                fluid_config(scene), solver["allow_unconverged"]))
    dynamic = "dynamics" in scene.effects
    interface = c["interface"] if isinstance(c["interface"], str) else ", ".join(c["interface"])
    if c["traction"] == "full":
        plan.exchanges.append(Exchange(
            ["fluid.pressure", "fluid.velocity", "solid.velocity"], "solid.traction", "viscous_traction", "2-3",
            accelerated=True, description=f"(-p I + tau) n on the wetted boundary '{interface}': the Q0 pressure "
                                          f"traced half a cell into the fluid, the wall shear from three velocity "
                                          f"samples (coupler/fsi/viscous.py)"))
    else:
        plan.exchanges.append(Exchange(
            ["fluid.pressure"], "solid.pressure", "pressure_trace", "2-3", accelerated=True,
            description=f"Q0 (grid) -> P1 on the wetted boundary '{interface}' moved half a fluid cell into the "
                        f"fluid, pseudo_l2 trace (solids without boundary triangles: onto all solid vertices)"))
    deformed = "the deformed solid" if c["deformation"] else "the undeformed solid ([coupling] deformation = false)"
    plan.exchanges.append(Exchange(["solid.displacement"], "fluid.solid_fraction", "solid_fraction", "before 1",
                                   description=f"P0 indicator of {deformed} -> Q0, exact volume fractions"))
    if dynamic:
        plan.exchanges.append(Exchange(["solid.displacement", "solid.velocity"], "fluid.solid_velocity",
                                       "solid_velocity", "6",
                                       description=f"P1 (solid mesh) -> Q0 (fluid cells) of {deformed}, pseudo_l2"))
    quasi = ""
    if solver["participant"] == "openfoam":
        quasi = (f", transient: pimpleFoam over each step ({solver['substeps']} time step"
                 f"{'s' * (solver['substeps'] > 1)}) and an elastodynamic solid" if dynamic
                 else ", quasi-static: steady simpleFoam and a static solid per step")
        if dynamic:
            plan.notes.append("openfoam: the solid velocity is applied per solid body (a rigid translation with the "
                              "mean velocity of its wetted cells; rotation and deformation within a body are not)"
                              if solver["solid_velocity"] == "bodies" else
                              "openfoam: the solid velocity is not applied (penalization towards rest)")
        if solver["solver_ranks"] > 1:
            plan.tasks.append(f"fluid: openfoam on {solver['solver_ranks']} MPI ranks ({solver['decomposition']} "
                              f"decomposition by decomposePar once; fields written and read per processor, no "
                              f"reconstructPar)")
    plan.iteration = (f"{scene.time['steps']} time steps of {scene.time['dt']:g} s{quasi}; implicit fixed point per "
                      f"step ({c['acceleration']}, tolerance {c['tolerance']:g}, at most {c['max_iterations']} "
                      f"iterations)")
