"""What a hydro-mechanical fracture's figures cost in accuracy, as warnings: a contact area above
one half, a mean open aperture resolved by less than one fluid cell, the narrowest throat of the
flow's widest path by less than :data:`THROAT_CELLS`, and e_h above e_m; with the number of
cells across and the flow rate's error the immersed plates measured at that resolution
(cases/parallel_plates/README.md: +12.5 %, +3.1 %, +0.78 %, +0.20 % at 4, 8, 16, 32 cells across,
exact fractions and wall drag: 2 (h/w)^2). And the error estimate of e_h from the flow rate on
the grid coarsened 2x across the gap (:func:`aperture_error`), with its warning above
:data:`ERROR_LIMIT`."""

from __future__ import annotations

#: cells across the narrowest throat of the widest open path below which its flow errs by more
#: than the plates' 2 / n^2 = 12.5 %
THROAT_CELLS = 4
#: contact area fraction above which the open space is a few channels near percolation
CONTACT_AREA_LIMIT = 0.5
#: the order of convergence of e_h across the gap the error estimate assumes (Richardson: the
#: error of the fine e_h is |e_h - e_h,c| / (2^p - 1)). Measured on hm_fracture with penalization
#: "wall" (cases/hm_fracture/README.md, "Converged e_h"): the observed order is about 1 from 8 cells
#: across on (1.10 / 0.98 / 0.82 at 1 / 2 / 4 MPa) but 0.3 between 4, 8 and 16, where p = 1 gives
#: 0.55 to 0.67 of the true error at 8 across and 0.76 at 16 across, 4 MPa: p = 1/2 (the factor
#: 2.41) is the largest order that brackets the true error on that study's grids; on plates, whose
#: flow converges at second order, it overestimates by 3 / (2^p - 1) = 7.2
ASSUMED_ORDER = 0.5
#: the relative error estimate of e_h above which a step warns
ERROR_LIMIT = 0.05


def plates_error(cells_across: float) -> float:
    """The relative error of the flow rate between immersed plates w apart on cells h across,
    2 (h/w)^2 (measured from 4 to 32 cells across; below 4 an extrapolation)."""
    return 2.0 / cells_across ** 2


def contact_area_warning(fraction: float, cell: tuple[float, float]) -> str | None:
    """The warning for a contact area fraction above :data:`CONTACT_AREA_LIMIT` (None below)."""
    if fraction <= CONTACT_AREA_LIMIT:
        return None
    return (f"fracture: the contact area is {100 * fraction:.0f} % of the fracture plane (above "
            f"{100 * CONTACT_AREA_LIMIT:.0f} %): the flow runs through a few channels between the contacts, each a few "
            f"fluid cells wide ({1e3 * cell[0]:.3g} x {1e3 * cell[1]:.3g} mm in the plane), near the loss of an open "
            f"path: the flow rate and e_h depend on the in-plane resolution of [geometry.fluid] shape as much as on the "
            f"aperture; refine it in the plane to trust them")


def cells_across_warning(mean_open_aperture: float, h: float) -> str | None:
    """The warning for a mean open aperture under one fluid cell `h` across (None from one cell up)."""
    n = mean_open_aperture / h
    if n >= 1.0:
        return None
    error = f"{100 * plates_error(n):.0f} %" if n > 0 else "unbounded"
    return (f"fracture: the mean open aperture {1e6 * mean_open_aperture:.3g} um is {n:.2f} fluid cells across "
            f"([geometry.fluid] cells {1e6 * h:.3g} um across the fracture): the gap is not resolved; the immersed "
            f"plates' flow rate errs by +12.5 % at 4 cells across, +3.1 % at 8 and +0.78 % at 16 (2 / n^2, "
            f"cases/parallel_plates), {error} extrapolated to {n:.2f}; a rough fracture converges more slowly "
            f"(cases/hm_fracture/README.md): Q and e_h are not to be trusted; refine [geometry.fluid] shape across "
            f"the fracture to at least 8 cells across the mean aperture")


def throat_warning(throat: float, h: float, estimated: bool = False) -> str | None:
    """The warning for a narrowest throat (:func:`coupler.fsi.flow_rate.throat_aperture`) under
    :data:`THROAT_CELLS` fluid cells `h` across (None when wider, or closed: no path is its own warning).
    With an error estimate of e_h (`estimated`) the plates' 2 / n^2 is no guide (the fluid's drag may
    be exact on plates; the estimate measures the error): then only a throat under one cell warns."""
    n = throat / h
    if throat <= 0 or n >= (1.0 if estimated else THROAT_CELLS):
        return None
    error = (f"{100 * plates_error(n):.0f} % at {n:.2f} (2 / n^2)" if n >= 1 else
             f"under one cell it is open or closed by the rounding of the solid fractions")
    return (f"fracture: the narrowest throat on the widest open path from inlet to outlet is {1e6 * throat:.3g} um, "
            f"{n:.2f} fluid cells across: the flow through it errs by more than the immersed plates' "
            f"{100 * plates_error(THROAT_CELLS):.1f} % at {THROAT_CELLS} cells ({error}), and the throat sets the "
            f"flow rate: refine [geometry.fluid] shape across the fracture to at least {THROAT_CELLS} cells across it")


def apertures_warning(hydraulic: float, mechanical: float) -> str | None:
    """The warning for e_h above e_m (None at or below)."""
    if hydraulic <= mechanical:
        return None
    return (f"fracture: e_h {1e6 * hydraulic:.4g} um exceeds e_m {1e6 * mechanical:.4g} um: the 3D flow between "
            f"rough faces passes less than plates at their mean gap (the flow avoids the narrow parts and turns "
            f"around the contacts); e_h above e_m says the gap is under-resolved across ([geometry.fluid] shape) "
            f"or the fluid model overestimates the flow (the local cubic law does, cases/hm_fracture/README.md)")


def coarse_aperture(hydraulic: float, rate: float, coarse_rate: float) -> float:
    """e_h on the coarsened grid at the same pressure drop: the cubic law's e_h is proportional
    to Q^(1/3), so e_h,c = e_h (Q_c / Q)^(1/3) (0 when no flow passes the coarse grid)."""
    ratio = coarse_rate / rate if rate else 0.0
    return hydraulic * ratio ** (1.0 / 3.0) if ratio > 0 else 0.0


def aperture_error(hydraulic: float, coarse: float, order: float = ASSUMED_ORDER) -> float:
    """Richardson's estimate of the error of e_h on the fine grid from e_h,c on the grid 2x
    coarser: |e_h - e_h,c| / (2^p - 1) at the order ``p`` (:data:`ASSUMED_ORDER`)."""
    return abs(hydraulic - coarse) / (2.0 ** order - 1.0)


def error_warning(hydraulic: float, error: float, cells_across: float) -> str | None:
    """The warning for an estimated error of e_h above :data:`ERROR_LIMIT` of it (None below)."""
    if hydraulic <= 0 or error <= ERROR_LIMIT * hydraulic:
        return None
    return (f"fracture: e_h {1e6 * hydraulic:.4g} um is uncertain by about +-{1e6 * error:.3g} um "
            f"({100 * error / hydraulic:.0f} %, above {100 * ERROR_LIMIT:.0f} %): estimated from the flow rate on the "
            f"fluid grid coarsened 2x across the fracture (Richardson at order {ASSUMED_ORDER:g}, "
            f"cases/hm_fracture/README.md); the gap is {cells_across:.1f} cells across: refine [geometry.fluid] shape "
            f"across the fracture")

