"""``python -m solid_fenicsx --run-id R --name NAME --connect ENDPOINT``: the solid participant."""

from coupler.protocol.participant import main

from .participant import SolidParticipant

if __name__ == "__main__":
    main(SolidParticipant, prog="python -m solid_fenicsx")
