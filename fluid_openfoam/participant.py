"""``FluidParticipant``: the OpenFOAM fluid as a protocol participant (docs/protocol.md).

Config (the fluid's part of the scene; same grid conventions as
``coupler.standins.ReplayFluid`` with ``"location": "cells"``)::

    {"grid": {"origin": [x, y, z], "spacing": [hx, hy, hz], "shape": [nx, ny, nz]},
     "location": "cells",                 # only cells (Q0) is supported
     "rho": 1000.0, "mu": 1.0e-3,         # kg/m^3, Pa s (nu = mu/rho)
     "inlet": {"velocity": [1, 0, 0]},    # xmin, or {"pressure": Pa}
     "outlet": {"pressure": 0.0},         # xmax, Pa
     "walls": "wall",                     # other faces; "boundaries": {face: cond} overrides
     "case_dir": null,                    # kept; default: a temporary directory, removed on
                                          # every exit (the launcher removes it after SIGKILL)
     ...}                                 # the settings of fluid_openfoam/settings.py

From a scene, the flow rule (:func:`coupler.plan.effects.flow.fluid_config`) fills these keys: ``rho``, ``mu``
from ``[materials.fluid]``; ``inlet``, ``outlet``, ``walls``, ``boundaries`` from ``[flow]``
(inlet_velocity / inlet_pressure, outlet_pressure, walls, faces); ``dt``, ``transient`` from
``[time]`` and ``dynamics``; and every key of ``[solvers.fluid]`` as the participant declares it
(:data:`fluid_openfoam.settings.PARTICIPANT`: penalization, drag, max_iterations, tolerance, ...,
with their defaults; cases/README.md).

Transient (``"transient": true``, from a scene with ``dynamics``): each ``advance(t, dt)``
runs pimpleFoam from the state at ``t`` (the window's start, restored by the coupler for
every coupling iteration) to ``t + dt`` in ``substeps`` Euler steps of at most
``outer_correctors`` PIMPLE iterations each (initial residuals of p and U below
``tolerance``). Keys ``"dt"`` (the coupling step), ``"substeps"``, ``"outer_correctors"``.

Inputs of ``advance``: ``solid_fraction`` (n_cells,) in [0, 1] (clipped), and
``solid_velocity`` (n_cells, 3). Stock v1912 has no per-cell target velocity; with
``"solid_velocity": "bodies"`` (default) every solid body (connected solid-centred cells)
moves rigidly with the fraction-weighted mean velocity of its wetted cell layer, through a
``vectorSemiImplicitSource`` on top of the penalization (:mod:`fluid_openfoam.zones`:
what this represents and what not), except across a closed grid face the body touches (the
component normal to it is dropped, with a warning: open the face with a fixed pressure to let
the body move through it); ``"none"`` penalizes the solid towards rest. A zero velocity
(quasi-static solids) adds nothing. A fixed-velocity inlet (xmin) is masked: each face gets
``u_in (1 - f)`` with f the solid fraction of the cell behind it. Outputs: ``pressure`` (n_cells,) in Pa
(OpenFOAM's kinematic p times rho) and ``velocity`` (n_cells, 3) in m/s, at cell
centres, x fastest.

MPI: with ``[solvers.fluid] ranks = M > 1`` the participant runs as M processes (``mpirun -n
M``), the case decomposed in M processors: rank r handles ``processor<r>`` only
(:mod:`fluid_openfoam.solver`, :mod:`fluid_openfoam.parallel`). Rank 0 writes the case and runs
every OpenFOAM binary (``mpirun -np M simpleFoam -parallel``) while the others wait on the
participant's communicator; each rank writes the drag and inlet of its own cells and answers
with their pressure and velocity (``cell_ids``: ``cellProcAddressing``; docs/protocol.md,
"Parts"). Its inputs (``input_ids``) are its cells and those the drag of its cells reads (one
cell further along each axis with the "wall" penalization: :data:`transfer.penalization.REACH`);
with rigid bodies (``solid_velocity = "bodies"`` and ``transient``) also its cells' face
neighbours (the interface layer): the bodies are labelled across the processors
(:func:`transfer.bodies.rigid_bodies`), each a box of the grid (``simple`` blocks whose axes'
cells divide evenly; otherwise every rank receives the whole grid's inputs, logged). The
processes share the case directory: one host, or a shared file system.

State: the time directory the solver starts from. Each ``advance`` starts from the current
one (a warm start) and makes its result current; ``save_state(w)`` remembers it,
``restore_state(w)`` goes back to it, so a repeated window gives identical outputs.
"""

from __future__ import annotations

import atexit
import logging
import shutil
from pathlib import Path

import numpy as np

from coupler.protocol.participant import Participant, on_root, scratch_dir
from coupler.protocol.roles import PRESSURE, SOLID_FRACTION, SOLID_VELOCITY, VELOCITY
from coupler.protocol.wire import Field

from .case import CaseSpec
from .solver import OpenFOAMSolver

log = logging.getLogger("varcouple.fluid_openfoam")


class FluidParticipant(Participant):
    kind = "openfoam_fluid"

    def __init__(self):
        self.solver: OpenFOAMSolver | None = None
        self.spec: CaseSpec | None = None
        self.saved: dict[int, str] = {}
        self.fraction: np.ndarray | None = None
        self._tmp: Path | None = None
        self._warned_velocity = False
        atexit.register(self._cleanup)  # SIGTERM, SIGINT and a lost coupler end through SystemExit

    def announce(self) -> dict:
        return {"kind": self.kind, "provides": [PRESSURE, VELOCITY],
                "accepts": [SOLID_FRACTION, SOLID_VELOCITY], "location": "cells"}

    def configure(self, config: dict) -> None:
        spec = on_root(self.comm, self._spec, config)
        self._cleanup()
        self.solver = self.spec = None
        case_dir = config.get("case_dir")
        if case_dir is None and self.rank == 0:
            self._tmp = scratch_dir(self.run_id, self.name)
            case_dir = self._tmp / "case"
        if self.comm is not None:
            case_dir = self.comm.bcast(case_dir, root=0)  # rank 0's scratch directory: the case of all
        solver = OpenFOAMSolver(case_dir, spec, comm=self.comm)
        try:
            solver.setup()
        except Exception:
            self._cleanup()
            raise
        self.spec, self.solver = spec, solver
        self.saved = {}
        self.fraction = np.zeros(len(solver.input_ids))
        log.info("fluid_openfoam: grid %s (%d cells), nu %g, drag %g 1/s, case %s%s", spec.grid.shape,
                 spec.grid.n_cells, spec.nu, spec.drag_value(), case_dir,
                 f"; rank {self.rank} of {self.size}: processor{self.rank}, {len(solver.cell_ids)} cells, "
                 f"{len(solver.input_ids)} input cells" if self.size > 1 else "")

    def _spec(self, config: dict) -> CaseSpec:
        if config.get("location", "cells") != "cells":
            raise ValueError(f"fluid_openfoam serves cell values only (location 'cells'), got {config.get('location')!r}")
        return CaseSpec.from_config(config, ranks=self.size)

    def geometry(self):
        if self.spec is None:
            raise RuntimeError("geometry before configure")
        header = {"grid": self.spec.grid.to_json(), "location": "cells"}
        if self.size == 1:
            return header, None
        return header, {"cell_ids": self.solver.cell_ids, "input_ids": self.solver.input_ids}

    def input_problem(self, inputs) -> str | None:
        """An input that is not one row per input cell of this process (:attr:`OpenFOAMSolver.input_ids`)."""
        if self.solver is None:
            return "advance before configure"
        n = len(self.solver.input_ids)
        if SOLID_VELOCITY in inputs and self.solver.bodies_refused:
            return f"input 'solid_velocity': {self.solver.bodies_refused}"
        for name, f in inputs.items():
            want = (n,) if name == SOLID_FRACTION else (n, 3)
            if name in (SOLID_FRACTION, SOLID_VELOCITY) and f.data.shape != want:
                mine = "" if self.size == 1 else (f" (rank {self.rank}'s input_ids: " + (
                    "the whole grid)" if self.solver.whole_inputs else
                    f"processor{self.rank}'s cells and those their drag and bodies read)"))
                return f"input {name!r} has shape {f.data.shape}, expected {want}{mine}"
        return None

    def advance(self, window, iteration, t, dt, inputs):
        if self.solver is None:
            raise RuntimeError("advance before configure")
        problem = self.input_problem(inputs)
        if problem:
            raise ValueError(problem)
        if SOLID_FRACTION in inputs:
            self.fraction = np.array(inputs[SOLID_FRACTION].data, dtype=np.float64)
        velocity = inputs[SOLID_VELOCITY].data if SOLID_VELOCITY in inputs else None
        if velocity is not None and self.spec.solid_velocity == "none" and not self._warned_velocity \
                and np.any(velocity != 0):
            log.warning("fluid_openfoam: solid_velocity is not applied (solid_velocity 'none': the solid is "
                        "penalized towards rest)")
            self._warned_velocity = True
        U, p = self.solver.solve(self.fraction, velocity, t, dt)
        self.solver.prune(set(self.saved.values()))
        log.info("window %d iteration %d: %s", window, iteration, self.solver.last_run)
        self.report_solve(**self.solver.report())
        return {PRESSURE: Field(PRESSURE, p * self.spec.rho, "Pa"),
                VELOCITY: Field(VELOCITY, U, "m/s")}

    def save_state(self, window):
        if self.solver is None:
            raise RuntimeError("save_state before configure")
        self.saved[int(window)] = self.solver.start
        for w in [w for w in self.saved if w < int(window) - 1]:
            del self.saved[w]  # keep the last two windows
        self.solver.prune(set(self.saved.values()))

    def restore_state(self, window):
        if int(window) not in self.saved:
            raise KeyError(f"no state saved for window {window} (saved: {sorted(self.saved)})")
        self.solver.start = self.saved[int(window)]

    def _cleanup(self):
        if self._tmp is not None:
            shutil.rmtree(self._tmp, ignore_errors=True)
            self._tmp = None

    def finish(self):
        self._cleanup()
