"""Effect ``contact``: frictionless two-body contact between the faces ``[contact] slave`` and
``master`` by mortar coupling (paper 2.2, eq. 9-11), solved by the solid participant on the
transformed system of eq. 10 in load steps."""

NAME = "contact"
DESCRIPTION = "contact between fracture faces (mortar coupling, paper 2.2)"
ORDER = 2


def plan(scene, plan) -> None:
    c = scene.contact
    solid = plan.participant("solid")
    solid.config.update(contact=c, steps=scene.time["steps"])  # loads ramped over the steps
    plan.tasks.append(f"solid: contact of '{c['slave']}' (slave) on '{c['master']}' (master), eq. 9-11: mortar "
                      f"projection T = D^-1 B with the dual basis on the slave, {c['solver']} on the transformed "
                      f"system of eq. 10")
    steps = scene.time["steps"]
    plan.iteration = (f"contact: {steps} load step{'s' * (steps > 1)} (loads ramped linearly, each step starts "
                      f"from the last), {c['solver']} on the transformed system of eq. 10 per step")
