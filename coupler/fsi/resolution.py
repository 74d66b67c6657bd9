"""What a hydro-mechanical fracture's figures cost in accuracy, as warnings: a contact area above
one half, and a mean open aperture resolved by less than one fluid cell, with the number of
cells across it and the flow rate's error the immersed plates measured at that resolution
(cases/parallel_plates/README.md: +12.5 %, +3.1 %, +0.78 %, +0.20 % at 4, 8, 16, 32 cells across,
exact fractions and wall drag: 2 (h/w)^2)."""

from __future__ import annotations

#: contact area fraction above which the open space is a few channels near percolation
CONTACT_AREA_LIMIT = 0.5


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
