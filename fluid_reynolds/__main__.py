"""``python -m fluid_reynolds --run-id R --name NAME --connect ENDPOINT``."""

from coupler.protocol.participant import main

from .participant import ReynoldsParticipant

if __name__ == "__main__":
    main(ReynoldsParticipant, prog="python -m fluid_reynolds")
