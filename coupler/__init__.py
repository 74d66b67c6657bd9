"""varcouple.coupler: everything that reads a scene and runs it.

It reads and validates a case's ``scene.toml`` (:mod:`.scene`), plans which participants
and fields the scene's effects need (:mod:`.plan`), launches the participants as their own
processes and talks to them over zenoh (:mod:`.run`, the protocol in :mod:`.protocol`),
carries fields between their meshes (:mod:`transfer`, :mod:`.fsi`), iterates each time step
to convergence (:mod:`.coupling`) and owns all output (:mod:`.output`) and the ``varcouple``
command line (:mod:`.cli`). docs/architecture.md gives the layers and their order.
"""
