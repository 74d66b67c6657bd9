"""Effect ``fluid_pressure``: a fluid at rest in the fracture, its uniform pressure a load on
the faces (its ``[[loads]]`` of type ``fluid_pressure``); no fluid solver is started.

With ``contact`` the fluid fills the open part of the fracture (paper figure 12): a fluid
load on one contact face needs the same on the other, and the solid applies it to the
whole faces, which is exactly the fluid on the open parts with the contact stress carrying
the load where the faces touch (:mod:`solid_fenicsx.load_steps`)."""

from coupler.errors import SceneError

NAME = "fluid_pressure"
DESCRIPTION = "a static fluid pressure on fracture faces, applied as a load (no fluid solver)"
ORDER = 2
NEEDS = ("elasticity",)  # a load on the elastic solid


def parse(scene, data: dict) -> None:
    """With contact: the fluid loads on the contact faces come in pairs of equal values."""
    contact = scene.effect_settings.get("contact")
    if not contact or "master" not in contact:
        return
    faces = (contact["slave"], contact["master"])
    values = {}
    for i, load in enumerate(scene.loads, start=1):
        if load.type == "fluid_pressure" and load.boundary in faces:
            values.setdefault(load.boundary, []).append((i, load.value))
    for face, other in (faces, faces[::-1]):
        for i, value in values.get(face, []):
            if not any(v == value for _, v in values.get(other, [])):
                raise SceneError(f"{scene.path}: [loads.{i}] value: the fluid in the fracture presses on both contact "
                                 f"faces: give the same fluid_pressure on '{other}' too (one fluid, one pressure)")


def plan(scene, plan) -> None:
    """The elasticity rule sends the fluid_pressure loads to the solid; with contact, say how
    they act."""
    contact = scene.effect_settings.get("contact")
    if contact and "master" in contact:
        plan.tasks.append("solid: the fluid at rest in the fracture (the cheap variant: a uniform pressure per step, "
                          "no flow solver; effects elasticity, contact and flow run the flow solver instead)")
        plan.tasks.append(f"solid: the fluid pressure on '{contact['slave']}' and '{contact['master']}' acts on the "
                          f"open parts of the faces: applied to the whole faces, the contact multiplier is the "
                          f"contact stress beyond it (exact, no iteration on the contact set); reported as the "
                          f"total contact stress and the fluid's force on the open parts")
