"""The figures of a hydro-mechanical fracture per load step (effects elasticity, contact and
flow): the mechanical aperture e_m (contacts as zero), the contact area fraction, the flow rate
Q through the sections x = const, the hydraulic aperture e_h = (12 mu Q L / (W dp))^(1/3) and
the mean fluid pressure on the open parts of the faces, the fluid cells across the mean open
aperture and the warnings on what these cost in accuracy (coupler/fsi/resolution.py); a table of
them over the steps."""

from __future__ import annotations

import numpy as np

from .apertures import contact_area_fraction, hydraulic_aperture, mean_open_aperture, mechanical_aperture
from .flow_rate import percolates, section_flow_rates
from .context import OperatorContext, fluid_solid
from .operators import open_share
from .rate_control import FlowRateControl
from .resolution import cells_across_warning, contact_area_warning


class FractureFigures:
    """Built once per run like an operator; :meth:`figures` on a converged step's outputs."""

    def __init__(self, ctx: OperatorContext):
        scene, g = ctx.scene, ctx.scene.fluid
        self.ctx, self.fs = ctx, fluid_solid(ctx)
        flow = scene.effect_settings["flow"]
        # a flow rate: dp is what the rate control found (coupler/fsi/rate_control.py)
        self.control = ctx.shared("flow_rate_control", FlowRateControl) if "flow_rate" in flow["inlet"] else None
        self.fixed_drop = flow["inlet"].get("pressure", 0.0) - flow["outlet"]["pressure"]
        self.length, self.width = g.spacing[0] * g.shape[0], g.spacing[1] * g.shape[1]
        self.viscosity = scene.fluid_material["viscosity"]
        self.points = np.asarray(ctx.meshes["solid"].points)
        extents = np.asarray(g.spacing) * np.asarray(g.shape)
        across = int(np.argmin(extents))  # the fracture lies across the grid's thinnest extent
        self.h = float(g.spacing[across])
        self.cell = tuple(float(g.spacing[d]) for d in range(3) if d != across)
        self.told: set[str] = set()

    @property
    def pressure_drop(self) -> float:
        return self.control.pressure_drop if self.control is not None else self.fixed_drop

    def figures(self, outputs) -> dict:
        solid, fluid = outputs["solid"], outputs["fluid"]
        slave = solid["slave"] > 0.5
        weights, touching = solid["mortar_weight"][slave], solid["in_contact"][slave] > 0.5
        on_grid = self.fs.update(outputs)
        grid = self.ctx.meshes["fluid"]
        connected = percolates(grid, on_grid.fraction)
        rate = float(section_flow_rates(grid, fluid["velocity"]).mean()) if connected else 0.0
        if not connected:
            self.ctx.warn(["fracture: no connected open path from the inlet (xmin) to the outlet (xmax): every path "
                           "crosses cells at least half solid; flow rate and hydraulic aperture reported as 0"])
        interface = on_grid.interface
        wet = interface.weights * open_share(interface, self.points, solid)  # the open area per vertex
        pressure = interface.from_fluid(fluid["pressure"])
        area = float(wet.sum())
        open_aperture = mean_open_aperture(solid["gap"][slave], touching, weights)
        fraction = contact_area_fraction(touching, weights)
        warnings = self.warnings(fraction, open_aperture)
        return {"mechanical_aperture": mechanical_aperture(solid["gap"][slave], touching, weights),
                "hydraulic_aperture": (hydraulic_aperture(rate, self.viscosity, self.length, self.width,
                                                          self.pressure_drop) if self.pressure_drop else 0.0),
                "pressure_drop": self.pressure_drop,
                "contact_area_fraction": fraction, "flow_rate": rate, "percolating": connected,
                "mean_face_pressure": float(np.sum(wet * pressure) / area) if area else 0.0,
                "mean_open_aperture": open_aperture, "cells_across": open_aperture / self.h,
                **({"warnings": warnings} if warnings else {})}

    def warnings(self, contact_area: float, open_aperture: float) -> list[str]:
        """This step's warnings on accuracy; each kind goes to the log (and summary.json's
        ``warnings``) the first time only."""
        found = {"contact area": contact_area_warning(contact_area, self.cell),
                 "cells across": cells_across_warning(open_aperture, self.h)}
        for kind, text in found.items():
            if text and kind not in self.told:
                self.told.add(kind)
                self.ctx.warn([f"{text} (per step: summary.json steps[].fracture.warnings)"])
        return [text for text in found.values() if text]


def table(steps: list[dict]) -> list[str]:
    """The fracture's figures per step as text lines (the run's log)."""
    lines = ["fracture  step  stress [Pa]  coupling  inner  e_m [um]  e_h [um]  contact  Q [m^3/s]  p_faces [Pa]  cells across"]
    for record in steps:
        f = record.get("fracture")
        if not f:
            continue
        solid = record.get("figures", {}).get("solid", {})
        inner = sum(r.get("iterations", 0) for reports in record.get("solves", {}).values() for r in reports)
        lines.append(f"fracture  {record['step']:4d}  {solid.get('stress', float('nan')):11.4g}  "
                     f"{record['iterations']:8d}  {inner:5d}  {1e6 * f['mechanical_aperture']:8.3f}  "
                     f"{1e6 * f['hydraulic_aperture']:8.3f}  {f['contact_area_fraction']:7.3f}  "
                     f"{f['flow_rate']:9.3e}  {f['mean_face_pressure']:12.5g}  {f['cells_across']:12.2f}")
    return lines
