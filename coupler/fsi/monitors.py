"""Per-step figures a plan asks for (:attr:`coupler.plan.plan.Plan.monitors`): name -> class,
built as ``cls(context)`` once per run; ``figures(outputs, reported)`` on each converged step's
outputs and the participants' figures of the step (by name) goes to the step's record under the
name, ``table(steps)`` gives the lines printed at the end."""

from . import fracture

MONITORS = {"fracture": (fracture.FractureFigures, fracture.table)}
