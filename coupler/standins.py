"""Stand-in participants: light processes that speak the protocol (docs/protocol.md) like
the real solvers, so that tests exercise the coupler, the messaging and solver swapping
without dolfinx or OpenFOAM.

``python -m coupler.standins KIND --run-id R --name NAME --connect ENDPOINT`` (or
``--kind KIND`` anywhere, as :class:`coupler.launch.Launcher` extra arguments) with KIND
below. Their settings (``pressure``, ``feedback``, ``unconverged``; ``stiffness``; ``reply``,
``delay``, ``fail``) are declared once, with their defaults, in :data:`REPLAY_FLUID`,
:data:`SPRING_SOLID` and :data:`ECHO`.

``replay_fluid``
    Serves prescribed fields on a structured grid. Config::

        {"grid": {"origin": [x, y, z], "spacing": [hx, hy, hz], "shape": [nx, ny, nz]},
         "location": "points",          # or "cells": Q1 (grid points) or Q0 (cells) fields
         "pressure": 1.0e6,             # uniform pressure (Pa)
         "velocity": [0, 0, 0],         # uniform velocity (m/s), default 0
         "npz": "path.npz"}             # optional: arrays "pressure" (W, n) and/or
                                        # "velocity" (W, n, 3), row w served in window w
                                        # (the last row once w >= W)

    With ``"unconverged": [w, ...]`` it reports (``report_solve``) an unconverged solve in
    those windows and a converged one in the others: the coupler's handling of inner
    solvers that fail is tested with it.

    Grid points and cells are numbered x fastest (as :class:`transfer.StructuredGrid`).
    Accepts ``solid_velocity`` and ``solid_fraction`` (checked for their size). With
    ``"feedback": c`` (Pa s/m) the served pressure reacts to the solid:
    ``p = pressure - c * <v_z>``, ``<v_z>`` the fraction-weighted mean of the solid
    velocity's z component: a linear fixed point whose gain the coupling tests set
    (above 1 the plain iteration diverges, IQN-ILS still converges).

``spring_solid``
    A linear spring at every point of a point set: ``displacement = traction / stiffness`` and
    ``velocity = (displacement - displacement at the start of the window) / dt``. Config::

        {"points": [[x, y, z], ...]}    # or
        {"box": {"lower": [...], "upper": [...], "shape": [nx, ny, nz]}}  # (nx+1)(ny+1)(nz+1) points
        "stiffness": 1.0e9              # Pa/m

    ``save_state``/``restore_state`` keep the displacement per window, so repeating a
    window after ``restore_state`` gives identical fields.

``echo``
    Returns its inputs unchanged (for benchmarks and tests). Config: ``{"reply": "same"}``
    or ``"empty"`` (reply without arrays: one-way timing), ``"delay": s`` (sleep in
    ``advance``, logging a line every ``"progress": s`` when given: a slow solver that reports
    progress), ``"fail": "message"`` (``advance`` raises it).

Participants that solve nothing, which the runner serves in its own process
(:mod:`coupler.run.local`):

``rigid_solid``
    A fixed solid: its tetrahedral mesh, and zero displacement and velocity in every
    ``advance`` (no inner solve). Config: ``{"mesh": "file"}`` (any format meshio reads),
    ``{"box": {...}}`` (as ``spring_solid``) or ``{"generator": {"name": ..., "parameters":
    {...}}}`` (:mod:`transfer.generators`). Bound to rank r of P > 1, it makes or reads the whole
    mesh, checks that every rank has the same, and serves its part as ``mesh_file`` does
    (:class:`MeshParts`), its outputs at the points it owns.

``mesh_file``
    A mesh file and, with ``"field"``, one of its fields, served as its output (P1/Q1 point
    data or P0/Q0 cell data). It accepts any input (a transferred field, which the runner
    writes with its own outputs) and gives ``covered``: 1 at the dofs where every input is
    finite (a transfer reached them), 0 elsewhere. Config: ``{"file": "path", "field": "name",
    "location": "points"}`` (``"cells"``: its fields' rows are its cells, for P0/Q0 data).
    ``report_figures``: ``reoriented_cells``, cells the file numbers with negative orientation
    (reordered on reading). Its ``geometry`` names the mesh after the file and describes it
    (``note``: cells, points, reordered cells, the field). Bound to rank r of P > 1 (a coupler
    on P ranks serves one on each), it reads the whole file and serves its part
    (docs/protocol.md, "Parts"): its cells as ``mpirun -n P varcouple transfer`` cuts the file
    and the points it owns (:func:`transfer.partition.part_rows`; :class:`MeshParts`), with point
    fields at those points, cell fields (location ``cells``) at those cells.
"""

from __future__ import annotations

import hashlib
import logging
import sys
import time

import numpy as np

from coupler.protocol.errors import InputError
from coupler.protocol.participant import Participant, main
from coupler.protocol.settings import ParticipantSpec, Setting, Settings
from coupler.protocol.wire import Field

log = logging.getLogger("varcouple.standins")

# The stand-ins' declarations (entry points of pyproject.toml, cases/README.md's reference)
_MODULE = "coupler.standins"
SPRING_SOLID = ParticipantSpec(
    kind="spring_solid", module=_MODULE, role="solid", arguments=("--kind", "spring_solid"),
    description="stand-in: a linear spring at every vertex, displacement = traction / stiffness",
    settings=Settings(Setting("stiffness", "number", "spring stiffness", positive=True, unit="Pa/m")))
REPLAY_FLUID = ParticipantSpec(
    kind="replay_fluid", module=_MODULE, role="fluid", arguments=("--kind", "replay_fluid"),
    description="stand-in: prescribed pressure and velocity on the grid (ignores [flow])",
    settings=Settings(
        Setting("pressure", "number", "uniform pressure served", default=0.0, unit="Pa"),
        Setting("feedback", "number", "the served pressure drops by this times the fraction-weighted mean solid "
                "velocity (z): a fixed point whose gain tests choose", default=0.0, unit="Pa s/m"),
        Setting("unconverged", "integers", "time steps in which it reports an unconverged solve (tests of the "
                "coupler's handling)", default=[], minimum=0)))
ECHO = ParticipantSpec(
    kind="echo", module=_MODULE, role=None, arguments=("--kind", "echo"),
    description="returns its inputs (benchmarks and tests of the messaging; no scene role)",
    settings=Settings(
        Setting("reply", "string", "same: the inputs; empty: a reply without arrays (one-way timing)",
                default="same", choices=("same", "empty")),
        Setting("delay", "number", "sleep in advance", default=0.0, minimum=0.0, unit="s"),
        Setting("progress", "number", "while it sleeps, log a line every this many seconds (its progress: "
                "docs/protocol.md); 0: silent", default=0.0, minimum=0.0, unit="s"),
        Setting("fail", "string", "advance raises this message", default=None)))


def _vec3(value, what) -> np.ndarray:
    v = np.asarray(value, dtype=np.float64).reshape(-1)
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise ValueError(f"{what} must be 3 finite numbers, got {value!r}")
    return v


class ReplayFluid(Participant):
    """Prescribed pressure and velocity on a structured grid (see module doc)."""

    kind = REPLAY_FLUID.kind

    def __init__(self):
        self.grid = None
        self.n = 0
        self.pressure = self.velocity = None
        self.replay: dict[str, np.ndarray] = {}

    def announce(self) -> dict:
        return {"kind": self.kind, "provides": ["pressure", "velocity"],
                "accepts": ["solid_velocity", "solid_fraction"]}

    def configure(self, config: dict) -> None:
        g = config.get("grid")
        if not isinstance(g, dict):
            raise ValueError("replay_fluid needs config 'grid' = {origin, spacing, shape}")
        origin, spacing = _vec3(g.get("origin"), "grid.origin"), _vec3(g.get("spacing"), "grid.spacing")
        shape = [int(s) for s in np.asarray(g.get("shape")).reshape(-1)]
        if len(shape) != 3 or min(shape) < 1 or np.any(spacing <= 0):
            raise ValueError(f"grid shape must be 3 positive cell counts and spacing positive, got {g!r}")
        self.grid = {"origin": origin.tolist(), "spacing": spacing.tolist(), "shape": shape}
        self.location = config.get("location", "points")
        if self.location not in ("points", "cells"):
            raise ValueError(f"location must be 'points' or 'cells', got {self.location!r}")
        self.n = int(np.prod([s + 1 for s in shape]) if self.location == "points" else np.prod(shape))
        settings = REPLAY_FLUID.configuration(config)
        self.pressure = np.full(self.n, settings["pressure"])
        self.feedback = settings["feedback"]
        self.velocity = np.tile(_vec3(config.get("velocity", [0, 0, 0]), "velocity"), (self.n, 1))
        self.unconverged = set(settings["unconverged"])
        self.replay = {}
        if config.get("npz"):
            with np.load(config["npz"]) as data:
                for name, tail in (("pressure", (self.n,)), ("velocity", (self.n, 3))):
                    if name in data:
                        arr = np.asarray(data[name], dtype=np.float64)
                        if arr.shape[1:] != tail:
                            raise ValueError(f"{config['npz']}: {name} has shape {arr.shape}, expected (W, {', '.join(map(str, tail))})")
                        self.replay[name] = arr
        log.info("replay_fluid: grid %s, %d %s values, replayed %s", shape, self.n, self.location, sorted(self.replay))

    def geometry(self):
        if self.grid is None:
            raise RuntimeError("geometry before configure")
        return {"grid": self.grid, "location": self.location}, None

    def advance(self, window, iteration, t, dt, inputs):
        if self.grid is None:
            raise RuntimeError("advance before configure")
        for name, f in inputs.items():
            if f.data.shape[:1] != (self.n,):
                raise ValueError(f"input {name!r} has shape {f.data.shape}, expected {self.n} values first")
        out = {}
        for name, default, units in (("pressure", self.pressure, "Pa"), ("velocity", self.velocity, "m/s")):
            rows = self.replay.get(name)
            data = default if rows is None else rows[min(max(int(window), 0), len(rows) - 1)]
            out[name] = Field(name, data, units)
        if self.feedback and "solid_velocity" in inputs and "solid_fraction" in inputs:
            w = inputs["solid_fraction"].data
            vz = inputs["solid_velocity"].data[:, 2]
            mean_vz = float(w @ vz / w.sum()) if w.sum() > 0 else 0.0
            out["pressure"] = Field("pressure", out["pressure"].data - self.feedback * mean_vz, "Pa")
        if int(window) in self.unconverged:
            self.report_solve("replay", False, 10, 1e-2, 1e-6, "told to (config 'unconverged')")
        else:
            self.report_solve("replay", True, 1, 0.0, 1e-6)
        return out

    def save_state(self, window):
        pass  # stateless

    def restore_state(self, window):
        pass


class SpringSolid(Participant):
    """Linear springs on a point set: displacement = traction / stiffness (see module doc)."""

    kind = SPRING_SOLID.kind

    def __init__(self):
        self.points = self.tets = None
        self.stiffness = None
        self.displacement = self.start = None
        self.checkpoints: dict[int, np.ndarray] = {}

    def announce(self) -> dict:
        return {"kind": self.kind, "provides": ["displacement", "velocity"], "accepts": ["traction", "pressure"]}

    def configure(self, config: dict) -> None:
        if "points" in config:
            pts = np.asarray(config["points"], dtype=np.float64)
        elif "box" in config:
            b = config["box"]
            lower, upper = _vec3(b["lower"], "box.lower"), _vec3(b["upper"], "box.upper")
            shape = np.asarray(b.get("shape", [1, 1, 1]), dtype=int).reshape(3)
            if np.any(shape < 1) or np.any(upper <= lower):
                raise ValueError(f"box needs upper > lower and shape >= 1, got {b!r}")
            from transfer.generate import box_tetrahedra

            box = box_tetrahedra(shape, lower, upper, jitter=float(b.get("jitter", 0.0)), seed=int(b.get("seed", 0)))
            pts, self.tets = box.points, box.cells
        else:
            raise ValueError("spring_solid needs config 'points' or 'box'")
        if pts.ndim != 2 or pts.shape[1] != 3 or not np.all(np.isfinite(pts)):
            raise ValueError(f"points must be finite, of shape (n, 3), got {pts.shape}")
        self.points, self.stiffness = pts, SPRING_SOLID.configuration(config)["stiffness"]
        self.ids = np.arange(self.rank, len(pts), self.size)  # this rank's points
        self.displacement = np.zeros((len(self.ids), 3))
        self.checkpoints = {}
        log.info("spring_solid: %d points, stiffness %g Pa/m", len(pts), self.stiffness)

    def geometry(self):
        """This rank's part (docs/protocol.md, "Parts"): on several ranks, rank r owns the points
        and cells r, r + size, ..."""
        if self.points is None:
            raise RuntimeError("geometry before configure")
        n = len(self.points)
        cells = self.tets if self.tets is not None else np.arange(n, dtype=np.int64).reshape(n, 1)
        own = np.arange(self.rank, len(cells), self.size)
        return ({"cell_type": "tetra" if self.tets is not None else "vertex", "boundaries": {}},
                {"point_ids": self.ids, "points": Field("points", self.points[self.ids], "m"),
                 "cell_ids": own, "cells": Field("cells", cells[own])})

    def advance(self, window, iteration, t, dt, inputs):
        if self.points is None:
            raise RuntimeError("advance before configure")
        n = len(self.ids)
        if "traction" in inputs:
            traction = inputs["traction"].data
        elif "pressure" in inputs:
            p = inputs["pressure"].data
            if p.shape != (n,):
                raise ValueError(f"pressure has shape {p.shape}, expected ({n},)")
            traction = np.outer(p, [0.0, 0.0, 1.0])
        else:
            raise ValueError(f"advance needs input 'traction' or 'pressure', got {sorted(inputs)}")
        if traction.shape != (n, 3):
            raise ValueError(f"traction has shape {traction.shape}, expected ({n}, 3)")
        if not dt > 0:
            raise ValueError(f"dt must be positive, got {dt!r}")
        if iteration == 0 or self.start is None:
            self.start = self.displacement.copy()  # the state the window starts from
        d = traction / self.stiffness
        v = (d - self.start) / dt
        self.displacement = d
        return {"displacement": Field("displacement", d, "m"), "velocity": Field("velocity", v, "m/s")}

    def save_state(self, window):
        self.checkpoints[int(window)] = self.displacement.copy()
        for w in [w for w in self.checkpoints if w < int(window) - 1]:
            del self.checkpoints[w]  # keep the last two windows only

    def restore_state(self, window):
        if int(window) not in self.checkpoints:
            raise KeyError(f"no state saved for window {window} (saved: {sorted(self.checkpoints)})")
        self.displacement = self.checkpoints[int(window)].copy()


class Echo(Participant):
    """Returns its inputs (see module doc)."""

    kind = ECHO.kind

    def __init__(self):
        self.config = ECHO.configuration({})  # the defaults: advance works unconfigured

    def announce(self) -> dict:
        return {"kind": self.kind, "provides": ["*"], "accepts": ["*"]}

    def configure(self, config: dict) -> None:
        self.config = ECHO.configuration(config)

    def geometry(self):
        return {}, None

    def advance(self, window, iteration, t, dt, inputs):
        end, every = time.monotonic() + self.config["delay"], self.config["progress"]
        while (left := end - time.monotonic()) > 0:
            time.sleep(min(left, every) if every else left)
            if every:
                log.info("echo: %.1f s of %.1f s slept", self.config["delay"] - max(left - every, 0.0),
                         self.config["delay"])
        if self.config["fail"]:
            raise RuntimeError(self.config["fail"])
        return {} if self.config["reply"] == "empty" else inputs

    def save_state(self, window):
        pass

    def restore_state(self, window):
        pass


# -- participants that solve nothing (served in the coupler's process) ------------------------------
class MeshParts:
    """A mesh every rank of the participant holds whole, served in parts when it is bound to
    rank r of P > 1 (a coupler on P ranks serves it on each): its cells as ``mpirun -n P
    varcouple transfer`` cuts a file and the points it owns (:func:`transfer.partition.part_rows`).
    ``part``: (cells, points) of this rank, None on one rank."""

    part = None

    def cut(self, mesh, what: str) -> None:
        """This rank's part of `mesh` (`what`: the mesh as the error names it), which must be the
        same mesh on every rank (ValueError naming the first rank that made another). Collective."""
        from transfer.partition import part_rows

        if self.size == 1:
            return
        digest = hashlib.sha256(np.ascontiguousarray(mesh.points).tobytes()
                                + np.ascontiguousarray(mesh.cells).tobytes()).hexdigest()
        other = next((r for r, d in enumerate(self.comm.allgather(digest)) if d != digest), None)
        if other is not None:
            raise ValueError(f"{what}: rank {other} made another mesh than rank {self.rank} (each rank "
                             f"makes it whole: its points and cells must not depend on the rank)")
        self.part = part_rows(mesh, self.rank, self.size)

    def mesh_fields(self, mesh) -> dict:
        """The geometry's fields of this rank's part of `mesh` (the whole mesh on one rank)."""
        if self.part is None:
            return {"points": Field("points", mesh.points, "m"), "cells": Field("cells", mesh.cells)}
        cells, points = self.part
        return {"point_ids": points, "points": Field("points", mesh.points[points], "m"), "cell_ids": cells,
                "cells": Field("cells", mesh.cells[cells])}


class RigidSolid(MeshParts, Participant):
    """A fixed solid: its mesh, zero displacement (see module doc)."""

    kind = "rigid_solid"

    def __init__(self):
        self.mesh = None

    def announce(self) -> dict:
        return {"kind": self.kind, "provides": ["displacement", "velocity"], "accepts": []}

    def configure(self, config: dict) -> None:
        """The mesh of the file, box or generator of `config`; a file or generator that gives none,
        or cells other than tetrahedra, is bad input (:class:`InputError`)."""
        from transfer import TransferError

        try:
            mesh, made = self._made(config)
        except (TransferError, ValueError) as exc:
            raise InputError(f"rigid_solid: {exc}") from None
        if mesh.cell_type != "tetra":
            raise InputError(f"rigid_solid needs a tetrahedral mesh, got {mesh.cell_type} cells from {made}")
        self.cut(mesh, f"rigid_solid ({made})")
        self.mesh = mesh
        log.info("rigid_solid: %d tetrahedra, %d points", mesh.num_cells, mesh.num_points)

    @staticmethod
    def _made(config: dict):
        """(mesh, what made it) of `config`."""
        if "mesh" in config:
            from transfer.meshfile import MeshFile

            return MeshFile.read(config["mesh"]).mesh, config["mesh"]
        if "box" in config:
            from transfer.generate import box_tetrahedra

            b = config["box"]
            return box_tetrahedra(b["shape"], b["lower"], b["upper"], jitter=float(b.get("jitter", 0.0)),
                                  seed=int(b.get("seed", 0))), "its box"
        if "generator" in config:
            from transfer.generators import generate

            g = config["generator"]
            try:
                return generate(g["name"], g.get("parameters")).mesh, f"the generator {g['name']!r}"
            except ValueError as exc:
                raise ValueError(f"generator {g['name']!r}: {exc}") from None
        raise ValueError("needs config 'mesh', 'box' or 'generator'")

    def geometry(self):
        if self.mesh is None:
            raise RuntimeError("geometry before configure")
        return {"cell_type": "tetra", "boundaries": {}}, self.mesh_fields(self.mesh)

    def advance(self, window, iteration, t, dt, inputs):
        if self.mesh is None:
            raise RuntimeError("advance before configure")
        zero = np.zeros((self.mesh.num_points if self.part is None else len(self.part[1]), 3))
        return {"displacement": Field("displacement", zero, "m"), "velocity": Field("velocity", zero, "m/s")}

    def save_state(self, window):
        pass  # nothing moves

    def restore_state(self, window):
        pass


class MeshFileParticipant(MeshParts, Participant):
    """A mesh file, and optionally one of its fields as output (see module doc)."""

    kind = "mesh_file"

    def __init__(self):
        self.file = self.field = None
        self.location = "points"

    def announce(self) -> dict:
        return {"kind": self.kind, "provides": [self.field.name] if self.field else ["covered"], "accepts": ["*"]}

    def configure(self, config: dict) -> None:
        from transfer.meshfile import MeshFile

        self.file = MeshFile.read(config["file"])
        self.field = self.file.field(config["field"]) if config.get("field") else None
        self.cut(self.file.mesh, self.file.path)
        self.location = config.get("location", "points")
        if self.location not in ("points", "cells"):
            raise ValueError(f"location must be 'points' or 'cells', got {self.location!r}")
        log.info("mesh_file %s: %s", self.file.path, self.file.describe())

    def geometry(self):
        if self.file is None:
            raise RuntimeError("geometry before configure")
        m = self.file.mesh
        note = f"{self.file.path}: {self.file.describe()}" + (f"; {self.field.describe()}" if self.field else "")
        header = {"cell_type": m.cell_type, "boundaries": {}, "name": self.file.path, "note": note,
                  "location": self.location}
        return header, self.mesh_fields(m)

    @property
    def rows(self) -> np.ndarray:
        """This part's rows of its fields: its cells' ids (location cells) or its points' ids."""
        cells, points = self.part
        return cells if self.location == "cells" else points

    def advance(self, window, iteration, t, dt, inputs):
        if self.file is None:
            raise RuntimeError("advance before configure")
        self.report_figures(reoriented_cells=self.file.mesh.reoriented)
        out = {}
        if self.field is not None:
            values = self.field.values if self.part is None else self.field.values[self.rows]
            out[self.field.name] = Field(self.field.name, values)
        if inputs:
            arrays = [np.asarray(f.data).reshape(len(f.data), -1) for f in inputs.values()]
            out["covered"] = Field("covered", np.all([np.isfinite(a).all(axis=1) for a in arrays], axis=0)
                                   .astype(np.uint8))
        return out

    def save_state(self, window):
        pass  # a file does not change

    def restore_state(self, window):
        pass


STANDINS = {"replay_fluid": ReplayFluid, "spring_solid": SpringSolid, "echo": Echo,
            "rigid_solid": RigidSolid, "mesh_file": MeshFileParticipant}


def cli(argv=None):
    """``python -m coupler.standins KIND ...`` or ``... --kind KIND`` (as the launcher's
    extra arguments)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    kind = None
    if argv and argv[0] in STANDINS:
        kind = argv.pop(0)
    elif "--kind" in argv[:-1]:
        i = argv.index("--kind")
        kind = argv[i + 1]
        del argv[i:i + 2]
    if kind not in STANDINS:
        print(f"usage: python -m coupler.standins {{{','.join(STANDINS)}}} --run-id R --name NAME --connect ENDPOINT\n"
              f"   or: python -m coupler.standins --kind KIND --run-id R ...  (unknown kind {kind!r})",
              file=sys.stderr)
        raise SystemExit(2)
    main(STANDINS[kind], argv, prog=f"python -m coupler.standins {kind}")


if __name__ == "__main__":
    cli()
