"""The OpenFOAM fluid participant: a structured-grid incompressible flow solved
by Debian's stock OpenFOAM v1912 binaries (no headers, no wmake), with the rock immersed
by volume penalization driven by a ``solid`` volume-fraction field.

Modules: :mod:`.case` (case dictionaries from Python), :mod:`.fields` (field file I/O),
:mod:`.solver` (runs blockMesh/topoSet/simpleFoam), :mod:`.participant` (the protocol
participant, ``python -m fluid_openfoam``).
"""
