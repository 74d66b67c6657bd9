"""Effect ``contact``: frictionless two-body contact between the faces ``[contact] slave`` and
``master`` by mortar coupling (paper 2.2, eq. 9-11), solved by the solid participant on the
transformed system of eq. 10 in load steps."""

from coupler.errors import SceneError
from coupler.scene.tables import Table

NAME = "contact"
DESCRIPTION = "contact between fracture faces (mortar coupling, paper 2.2)"
ORDER = 2
NEEDS = ("elasticity",)  # the bodies in contact deform
#: nonsmooth solvers of [contact] solver (nonsmooth.solvers)
CONTACT_SOLVERS = ("active_set", "snes_vi", "multilevel")
TABLES = {"contact": {
    "slave": "the boundary carrying the contact pressure (dual basis; the finer or curved side)",
    "master": "the opposite boundary (another body of the same mesh)",
    "solver": f"nonsmooth solver, one of {', '.join(CONTACT_SOLVERS)} (default active_set)",
    "tolerance": "active_set: scaled KKT residual (default 1e-10); snes_vi: relative residual; multilevel: step "
                 "length [m]",
    "max_iterations": "nonsmooth iterations per load step (default 100)",
    "search_distance": "how far along the slave normal the master is looked for [m] (default: half the slave's "
                       "mean edge); at least the largest gap that may close",
    "max_normal_angle": "largest angle between paired slave and master faces [deg] (default 45)"}}


def parse(scene, data: dict) -> None:
    """[contact]: the two contact boundaries and the nonsmooth solver."""
    path, effects, solid = scene.path, scene.effects, scene.solid
    if "contact" not in data:
        raise SceneError(f"{path}: [contact] slave: missing: the effect 'contact' needs a [contact] table "
                         f"with slave and master boundaries")
    t = Table(path, "contact", data["contact"], TABLES["contact"])
    for other in ("flow", "dynamics"):
        if other in effects:
            raise SceneError(f"{path}: [physics] effects: 'contact' with '{other}' is not supported "
                             f"(contact is static: load steps over [time] steps)")
    s = scene.solvers["solid"]
    if s["participant"] != "solid_fenicsx" or s["ranks"] != 1 or s["degree"] != 1:
        raise SceneError(f"{path}: [solvers.solid]: contact needs participant solid_fenicsx, ranks = 1, degree = 1")
    cfg = {"slave": t.string("slave"), "master": t.string("master"),
           "solver": t.string("solver", "active_set", CONTACT_SOLVERS),
           "tolerance": t.number("tolerance", 1e-10, positive=True),
           "max_iterations": t.integer("max_iterations", 100),
           "search_distance": t.number("search_distance", None, positive=True),
           "max_normal_angle": t.number("max_normal_angle", 45.0, positive=True, maximum=90.0)}
    for key in ("slave", "master"):
        if cfg[key] not in solid.boundaries:
            raise t.error(key, f"unknown boundary {cfg[key]!r}; named boundaries: {', '.join(solid.boundaries)}")
    if cfg["slave"] == cfg["master"]:
        raise t.error("master", f"the same boundary as slave ({cfg['slave']!r}): contact is between two bodies")
    scene.effect_settings[NAME] = cfg


def plan(scene, plan) -> None:
    c = scene.effect_settings[NAME]
    solid = plan.participant("solid")
    solid.config.update(contact=c, steps=scene.time["steps"])  # loads ramped over the steps
    plan.tasks.append(f"solid: contact of '{c['slave']}' (slave) on '{c['master']}' (master), eq. 9-11: mortar "
                      f"projection T = D^-1 B with the dual basis on the slave, {c['solver']} on the transformed "
                      f"system of eq. 10")
    steps = scene.time["steps"]
    plan.iteration = (f"contact: {steps} load step{'s' * (steps > 1)} (loads ramped linearly, each step starts "
                      f"from the last), {c['solver']} on the transformed system of eq. 10 per step")
