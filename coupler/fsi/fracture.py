"""The figures of a hydro-mechanical fracture per load step (effects elasticity, contact and
flow): the mechanical aperture e_m (contacts as zero), the contact area fraction, the flow rate
Q through the sections x = const, the hydraulic aperture e_h = (12 mu Q L / (W dp))^(1/3) and
the mean fluid pressure on the open parts of the faces, the fluid cells across the mean open
aperture and across the narrowest throat of the widest open path, the error estimate of e_h from
the fluid's flow rate on its grid coarsened 2x across the gap (its figure ``coarse_flow_rate``:
Richardson, :func:`coupler.fsi.resolution.aperture_error`; a fluid without it: the reason), and
the warnings on what these cost in accuracy (coupler/fsi/resolution.py); a table of them over
the steps."""

from __future__ import annotations

import numpy as np

from coupler.coupling.row_sums import RowSums
from coupler.protocol.roles import COARSE_FLOW_RATE, GAP, IN_CONTACT, MORTAR_WEIGHT, PRESSURE, SLAVE, VELOCITY
from transfer.grid import across_axis

from .apertures import contact_area_fraction, hydraulic_aperture, mean_open_aperture, mechanical_aperture
from .flow_rate import column_open_lengths, percolates, section_flow_rates, throat_aperture
from .context import OperatorContext, fluid_solid
from .operators import open_share
from .rate_control import FlowRateControl
from .resolution import (aperture_error, apertures_warning, cells_across_warning, coarse_aperture,
                         contact_area_warning, error_warning, throat_warning)


class FractureFigures:
    """Built once per run like an operator; :meth:`figures` on a converged step's outputs. Every
    figure is a sum (or a labelling) over the rows, cells and interface vertices given by
    :meth:`local`, taken over the coupler's ranks before dividing (``comm``; the serial run:
    None, the whole fields, ``block`` the whole grid): :class:`coupler.fsi.ranks.FractureFiguresRanks`
    gives each rank's own."""

    comm = None
    block = None  # the cells of the grid whose fraction and velocity :meth:`local` gives (None: all)
    rate_control = FlowRateControl  # the pressure difference of a flow rate, shared with its exchange

    def __init__(self, ctx: OperatorContext):
        scene, g = ctx.scene, ctx.scene.fluid
        self.ctx = ctx
        flow = scene.effect_settings["flow"]
        # a flow rate: dp is what the rate control found (coupler/fsi/rate_control.py)
        self.control = ctx.shared("flow_rate_control", self.rate_control) if "flow_rate" in flow["inlet"] else None
        self.fixed_drop = flow["inlet"].get("pressure", 0.0) - flow["outlet"]["pressure"]
        self.across = across_axis(g.shape, g.spacing)  # the fracture's normal: the fluids' rule
        extents = np.asarray(g.spacing) * np.asarray(g.shape)
        self.length, self.width = float(extents[0]), float(extents[3 - self.across])
        self.viscosity = scene.fluid_material["viscosity"]
        self.h = float(g.spacing[self.across])
        self.cell = tuple(float(g.spacing[d]) for d in range(3) if d != self.across)
        self.told: set[str] = set()
        self.hold(ctx)

    def hold(self, ctx) -> None:
        """What :meth:`local` reads: the whole solid and grid (serial)."""
        self.fs, self.grid = fluid_solid(ctx), ctx.meshes["fluid"]
        self.points = np.asarray(ctx.meshes["solid"].points)

    def local(self, outputs) -> dict:
        """The arrays the figures sum: the slave nodes' ``gap``, ``in_contact`` and mortar
        ``weights``, the grid cells' solid ``fraction`` and fluid ``velocity`` (at ``block``), the
        interface vertices' open area ``wet`` and fluid ``pressure``."""
        solid, fluid = outputs["solid"], outputs["fluid"]
        slave = solid[SLAVE] > 0.5
        on_grid = self.fs.update(outputs)
        interface = on_grid.interface
        return {"gap": solid[GAP][slave], "in_contact": solid[IN_CONTACT][slave] > 0.5,
                "weights": solid[MORTAR_WEIGHT][slave], "fraction": on_grid.fraction, "velocity": fluid[VELOCITY],
                "wet": interface.weights * open_share(interface, self.points, solid),  # the open area per vertex
                "pressure": interface.from_fluid(fluid[PRESSURE])}

    @property
    def pressure_drop(self) -> float:
        return self.control.pressure_drop if self.control is not None else self.fixed_drop

    def figures(self, outputs, reported: dict | None = None) -> dict:
        """This step's figures, the same on every rank (collective with ``comm``); ``reported``:
        the participants' figures of the step by name (the fluid's ``coarse_flow_rate``)."""
        f, comm = self.local(outputs), self.comm
        gap, touching, weights = f["gap"], f["in_contact"], f["weights"]
        connected = percolates(self.grid, f["fraction"], block=self.block, comm=comm)
        rate = float(section_flow_rates(self.grid, f["velocity"], self.block, comm).mean()) if connected else 0.0
        if not connected:
            self.ctx.warn(["fracture: no connected open path from the inlet (xmin) to the outlet (xmax): every path "
                           "crosses cells at least half solid; flow rate and hydraulic aperture reported as 0"])
        area, force = RowSums(comm).sum(np.array([np.sum(f["wet"]), np.sum(f["wet"] * f["pressure"])]))
        open_aperture = mean_open_aperture(gap, touching, weights, comm)
        fraction = contact_area_fraction(touching, weights, comm)
        throat = throat_aperture(column_open_lengths(self.grid, f["fraction"], self.across, self.block, comm))
        e_m = mechanical_aperture(gap, touching, weights, comm)
        e_h = hydraulic_aperture(rate, self.viscosity, self.length, self.width,
                                 self.pressure_drop) if self.pressure_drop else 0.0
        estimate = self.error_estimate(e_h, rate, (reported or {}).get("fluid", {}).get(COARSE_FLOW_RATE))
        warnings = self.warnings({"contact area": contact_area_warning(fraction, self.cell),
                                  "cells across": cells_across_warning(open_aperture, self.h),
                                  "throat": throat_warning(throat, self.h, "hydraulic_aperture_error" in estimate),
                                  "apertures": apertures_warning(e_h, e_m),
                                  "error": error_warning(e_h, estimate.get("hydraulic_aperture_error", 0.0),
                                                         open_aperture / self.h)})
        return {"mechanical_aperture": e_m, "hydraulic_aperture": e_h, **estimate, "pressure_drop": self.pressure_drop,
                "contact_area_fraction": fraction, "flow_rate": rate, "percolating": connected,
                "mean_face_pressure": float(force / area) if area else 0.0,
                "mean_open_aperture": open_aperture, "cells_across": open_aperture / self.h,
                "throat_aperture": throat, "throat_cells_across": throat / self.h,
                **({"warnings": warnings} if warnings else {})}

    def error_estimate(self, e_h: float, rate: float, coarse_rate: float | None) -> dict:
        """e_h on the coarse grid and the estimate of e_h's error, absolute [m] and relative, from
        the fluid's ``coarse_rate``; without it (or without flow) the reason instead."""
        if coarse_rate is None or e_h <= 0:
            return {"hydraulic_aperture_error_missing": self.no_estimate(e_h)}
        coarse = coarse_aperture(e_h, rate, coarse_rate)
        error = aperture_error(e_h, coarse)
        return {"coarse_hydraulic_aperture": coarse, "hydraulic_aperture_error": error,
                "hydraulic_aperture_relative_error": error / e_h}

    def no_estimate(self, e_h: float) -> str:
        """Why this step has no error estimate of e_h."""
        if e_h <= 0:
            return "no flow through the fracture (e_h = 0)"
        solver = self.ctx.scene.solvers["fluid"]
        if "error_estimate" not in solver.settings:
            return (f"the fluid participant {solver.kind!r} gives no {COARSE_FLOW_RATE} (the flow rate on its grid "
                    f"coarsened 2x across the gap): its model has no second grid across the fracture to compare with")
        if not solver.settings["error_estimate"]:
            return "[solvers.fluid] error_estimate = false (true: the flow solved again on the grid coarsened 2x across)"
        return (f"the fluid gave no {COARSE_FLOW_RATE} this step (it solves the coarsened grid for steady flow, "
                f"with more than one cell across the gap, and gives it when that solve converged: the fluid's log)")

    def warnings(self, found: dict[str, str | None]) -> list[str]:
        """This step's warnings on accuracy (by kind, None: none); each kind goes to the log (and
        summary.json's ``warnings``) the first time only."""
        for kind, text in found.items():
            if text and kind not in self.told:
                self.told.add(kind)
                self.ctx.warn([f"{text} (per step: summary.json steps[].fracture.warnings)"])
        return [text for text in found.values() if text]


def table(steps: list[dict]) -> list[str]:
    """The fracture's figures per step as text lines (the run's log)."""
    lines = ["fracture  step  stress [Pa]  coupling  inner  e_m [um]  e_h [um]  e_h error [um]  contact  Q [m^3/s]  "
             "p_faces [Pa]  cells across  throat cells"]
    for record in steps:
        f = record.get("fracture")
        if not f:
            continue
        solid = record.get("figures", {}).get("solid", {})
        inner = sum(r.get("iterations", 0) for reports in record.get("solves", {}).values() for r in reports)
        error = (f"{1e6 * f['hydraulic_aperture_error']:.3f} ({100 * f['hydraulic_aperture_relative_error']:.1f}%)"
                 if "hydraulic_aperture_error" in f else "-")
        lines.append(f"fracture  {record['step']:4d}  {solid.get('stress', float('nan')):11.4g}  "
                     f"{record['iterations']:8d}  {inner:5d}  {1e6 * f['mechanical_aperture']:8.3f}  "
                     f"{1e6 * f['hydraulic_aperture']:8.3f}  {error:>14s}  {f['contact_area_fraction']:7.3f}  "
                     f"{f['flow_rate']:9.3e}  {f['mean_face_pressure']:12.5g}  {f['cells_across']:12.2f}  "
                     f"{f['throat_cells_across']:12.2f}")
    notes = sorted({r["fracture"]["hydraulic_aperture_error_missing"] for r in steps
                    if "hydraulic_aperture_error_missing" in r.get("fracture", {})})
    return lines + [f"fracture  no e_h error estimate: {note}" for note in notes]
