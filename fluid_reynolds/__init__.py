"""The Reynolds fluid participant (paper 1: the local cubic law): steady flow through a
fracture by the Reynolds equation in its mean plane, on the local aperture of the fluid grid's
columns, the pressure given back to the grid (and so to both faces) as a 3D fluid's.

Modules: :mod:`.reynolds` (the equation on a plane grid, one sparse direct solve),
:mod:`.columns` (the fluid grid's columns, their apertures, the plane grid and back),
:mod:`.spec` (the configuration), :mod:`.settings` (its keys, what it cannot run),
:mod:`.participant` (``python -m fluid_reynolds``).
"""
