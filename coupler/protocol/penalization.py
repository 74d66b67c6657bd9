"""The penalization settings every grid fluid with an immersed solid declares (the OpenFOAM
and the Chorin fluids), once: how solid volume fractions become drag in the fluid cells
(:mod:`transfer.penalization`)."""

from transfer.penalization import PENALIZATIONS

from .settings import Setting, Settings, When

PENALIZATION = Settings(
    Setting("penalization", "string", "how solid fractions become drag in the fluid cells "
            "(transfer/penalization.py): wall (a sub-cell wall position from the fractions, second order for "
            "grid-aligned walls), linear (drag proportional to the fraction: the wall at the centre of the first cell "
            "the solid touches), power (drag proportional to fraction^k), lubrication (the wall drag, with the cells next to the walls of "
            "each column across a gap given the drag that passes the cubic law of the column's opening: exact for "
            "plates at any resolution, for pressure-driven flow along a fracture; the Chorin fluid also gives each "
            "face column in the gap's plane the cubic law of its two cells' overlap)", default="wall",
            choices=PENALIZATIONS),
    Setting("penalization_exponent", "number", "k of penalization power", default=2.0, positive=True,
            only=When.equals("penalization", "power")),
    Setting("drag", "number", "largest penalization drag (a fully solid cell); none: 1e4 x max(nu / h^2, "
            "1 / time step (dynamics), U_inlet / h), h the smallest grid spacing (transfer.penalization.default_drag)",
            default=None, positive=True, unit="1/s"))
