"""The Chorin fluid participant (paper 2.3, Step 1): incompressible Navier-Stokes on the
structured grid by Chorin's projection (a predictor, a pressure Poisson equation, a
correction) on a staggered grid, the rock immersed by volume penalization from exact solid
fractions, driven towards the solid's velocity cell by cell. State in memory.

Modules: :mod:`.staggered` (the MAC grid, boundary conditions, operators), :mod:`.poisson`
(the pressure equation, PETSc CG + GAMG), :mod:`.slabs` (the grid cut over MPI ranks),
:mod:`.spec` (the configuration), :mod:`.solver` (time and pseudo-time stepping), :mod:`.steady`
(Newton on the steady equations, ``steady = "newton"``),
:mod:`.participant` (``python -m fluid_chorin``).
"""
