"""The participant protocol (docs/protocol.md): the only part of the coupler a participant
imports. Wire format (:mod:`.wire`), zenoh transport (:mod:`.transport`), the participant
server (:mod:`.server`), the :class:`~.participant.Participant` base class and its ``main``
(:mod:`.participant`), errors (:mod:`.errors`), expressions in x, y, z (:mod:`.expressions`),
settings declarations (:mod:`.settings`), the roles' contracts and conformance kit
(:mod:`.roles`), child processes (:mod:`.exits`, :mod:`.mpi`).

Nothing here imports scene parsing, planning, the runner or a participant.
"""
