"""``python -m fluid_chorin --run-id R --name NAME --connect ENDPOINT``."""

from coupler.protocol.participant import main

from .participant import ChorinParticipant

if __name__ == "__main__":
    main(ChorinParticipant, prog="python -m fluid_chorin")
