"""Effect ``elasticity``: the rock deforms elastically (paper eq. 5 and 7): a solid
participant on the rock's mesh, with its loads; static, one solve per step."""

NAME = "elasticity"
DESCRIPTION = "linear elastic deformation of the rock (solid participant)"
ORDER = 0
ROLES = ("solid",)  # the [solvers.X] tables it needs
DOMAINS = ("solid",)  # the [geometry.X] tables it needs


def geometry_config(solid) -> dict:
    """The solid's geometry as a participant is configured with it: a mesh file, a box or a generator."""
    from pathlib import Path

    if solid.generator is not None:
        return {"generator": solid.generator}
    return {"mesh": str(Path(solid.mesh).resolve())} if solid.mesh else {"box": solid.box}


def describe_load(load) -> str:
    where = f" on '{load.boundary}'" if load.boundary else ""
    value = (", ".join(f"{v:g}" for v in load.value) + " per step") if load.per_step else load.value
    if load.type == "platen":
        how = ("one more unknown of the contact solve" if load.settings.get("method") == "constraint"
               else "found by bracketing")
        return (f"platen{where}: rigid, mean normal stress {value} Pa (its displacement {how}, "
                f"tolerance {load.settings['tolerance']:g})")
    if load.type == "dirichlet":
        return f"dirichlet{where}: u_{''.join(load.components)} = {value if load.per_step else f'{value:g}'}"
    if load.type in ("pressure", "fluid_pressure"):
        source = " (static fluid pressure, no fluid solver)" if load.type == "fluid_pressure" else ""
        return f"pressure{where}: {value if load.per_step else f'{value:g}'} Pa{source}"
    return f"{load.type}{where}: {value}"


def solid_config(scene) -> dict:
    """What the solid participant is configured with: its mesh (a file, a box or a generator), named
    boundaries, material, loads (each with its scene key) and its validated ``[solvers.solid]``
    settings."""
    loads = [{"type": load.type, "key": f"[loads.{i}]", "boundary": load.boundary, "value": load.value,
              "components": load.components, **load.settings} for i, load in enumerate(scene.loads, start=1)]
    return {**geometry_config(scene.solid), "boundaries": scene.solid.boundaries, "material": scene.material,
            "loads": loads, **scene.solvers["solid"].settings, "dynamic": False, "fluid_density": 0.0}


def plan(scene, plan) -> None:
    from coupler.plan.plan import PlannedParticipant

    solver = scene.solvers["solid"]
    plan.participants.append(PlannedParticipant.of(solver, solid_config(scene)))
    plan.loads += [describe_load(load) for load in scene.loads]
    steps = scene.time["steps"]
    plan.iteration = "static: one solve" if steps == 1 else \
        f"{steps} time steps of {scene.time['dt']:g} s, one solve per step"
    if scene.material["nu"] > 0.49 and solver.settings.get("degree") == 1:
        plan.notes.append(f"nu = {scene.material['nu']:g} is nearly incompressible: P1 tetrahedra lock; "
                          f"use [solvers.solid] degree = 2")
