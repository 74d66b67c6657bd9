"""``python -m fluid_openfoam --run-id R --name NAME --connect ENDPOINT``."""

from coupler.protocol.participant import main

from .participant import FluidParticipant

if __name__ == "__main__":
    main(FluidParticipant, prog="python -m fluid_openfoam")
