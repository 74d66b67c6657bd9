"""The Reynolds fluid participant's settings, declared once (``[solvers.fluid]`` with
``participant = "reynolds"``; cases/README.md's reference is generated from it), and what it
cannot run (:func:`refuses`). Imports no solver: the coupler reads it to validate scenes
(entry point ``varcouple.participants``)."""

from coupler.protocol.settings import ParticipantSpec, Setting, Settings


def refuses(scene) -> str | None:
    """Why the Reynolds fluid cannot run `scene` (None: it can): it has no 3D velocity field and
    no time, so no solid moving in the flow, no viscous traction; it drives the flow by pressure,
    a flow rate or an inlet velocity (its part on the open inlet)."""
    if "dynamics" in scene.effects:
        return ("the Reynolds fluid is steady and has no 3D velocity field, so a solid moving in the flow "
                "(effect 'dynamics') needs a 3D fluid (chorin, openfoam)")
    if scene.coupling.get("traction") == "full":
        return ("[coupling] traction = \"full\" needs the viscous stress of a 3D velocity field; the Reynolds "
                "fluid gives the pressure only (traction = \"pressure\")")
    solver = scene.solvers["fluid"]
    if solver.ranks > 1:
        return "the Reynolds fluid solves the fracture's plane in one process: ranks = 1"
    resolution = solver.settings.get("resolution")
    if resolution is not None and len(resolution) != 2:
        return f"resolution: two numbers of cells [n_x, n_y] in the fracture's plane, got {resolution}"
    return None


PARTICIPANT = ParticipantSpec(
    kind="reynolds", module="fluid_reynolds", role="fluid", needs=("flow",), accepts=("inlet_pressure",),
    memory=(60 * 2**20, 300), refuses=refuses,
    description="steady flow in the fracture's mean plane by the Reynolds equation (the local cubic law) on the "
                "local aperture of the fluid grid's columns, one sparse direct solve; the pressure given to "
                "every cell of its column",
    settings=Settings(
        Setting("resolution", "integers", "[n_x, n_y] cells of the plane grid the Reynolds equation is solved on "
                "(x and the other in-plane axis; the apertures and the pressure go between it and the fluid "
                "grid's columns by the L2 projection); none: one cell per column of the fluid grid",
                default=None, positive=True),
        Setting("closed", "number", "a plane cell whose aperture is below this share of the fluid grid's "
                "height is closed (excluded from the solve)", default=1e-6, minimum=0.0, maximum=1.0)))
