"""Operators between the fluid grid and the solid mesh (paper 2.3, Steps 2, 3 and 6): volume
fractions, the wetted-interface trace of the pressure, the solid velocity on the grid and the
viscous traction."""
