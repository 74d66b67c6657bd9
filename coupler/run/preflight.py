"""Before anything runs: how big a coupled scene is, whether it fits in memory, and whether
each participant accepts its part (``varcouple check``, and ``varcouple run`` before the
first step).

Sizes come from the scene (box and grid shapes) or from reading the mesh files; memory is
estimated per participant from the per-rank and per-cell costs it declares
(:attr:`coupler.protocol.settings.ParticipantSpec.memory`, measured peak resident memory, times
its ranks), and for the coupler (operators, fields) a fixed part per coupler rank and about 2 kB
per solid tet + 0.3 kB per fluid cell over all of them.

The first load step of a solid with contact (platen solves, each an active-set solve) is
estimated from the solid's cells by the rule its participant declares
(:attr:`~coupler.protocol.settings.ParticipantSpec.contact_step`, seconds on a core of its own,
measured by bench/first_step.py), times the machine's load per core; :func:`first_step` warns, naming ``[messaging] timeout`` and a value,
when :data:`MARGIN` times the estimate exceeds the timeout (the coupler waits that long for
each answer).

A scene whose estimate exceeds the memory available (the smallest of the machine's
MemAvailable, the cgroup's memory.max, the address-space limit and ``[resources]
memory_limit``) is refused naming the key that makes it large (``[coupling] ranks`` when the
scene would fit on one coupler rank); ``[resources] check_memory = false`` runs it anyway. The
coupler's ranks are also held to :data:`RANKS_PER_CORE` per core this process may run on
(``VARCOUPLE_RANKS_PER_CORE`` raises it, :func:`check_cores`); ``varcouple run`` checks both
before it starts the ranks. :func:`coupler.run.runner.rehearse` then starts the participants
and builds the operators without advancing anything: the participants' own validation
(mesh readable, every loaded boundary selects facets, tags present) and the overlap of their
meshes reach the user before a run is launched.
"""

from __future__ import annotations

import functools
import math
import os
import resource
from dataclasses import dataclass
from pathlib import Path

from coupler.errors import SceneError

MB = 2**20
#: (fixed bytes per coupler rank, bytes per cell) of the coupler's part for the solid and for the
#: fluid (bench/ranks.py: 159-207 MB per rank on the small scene, of it 130 MB before any mesh)
COSTS = {"coupler_solid": (150 * MB, 2000), "coupler_fluid": (0, 300)}
#: coupler ranks allowed per core (each rank polls while it waits: many more than the cores only
#: share them, and an MPI job of hundreds of ranks takes minutes to start); the variable raises it
RANKS_PER_CORE, RANKS_PER_CORE_VAR = 4, "VARCOUPLE_RANKS_PER_CORE"


#: a first step may take this many times the estimate (the spread of bench/first_step.py's runs
#: about the fit and the machine's load): the timeout it warns below and the value it suggests
MARGIN = 3.0

@dataclass
class Estimate:
    """Cells and estimated peak memory of one part of a run; `key` is the scene key that sets its size."""

    name: str
    cells: int
    bytes: int
    key: str


def available_memory(limit: float | None = None) -> tuple[int, str]:
    """The memory a run may use and where that figure comes from."""
    candidates = []
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                candidates.append((int(line.split()[1]) * 1024, "MemAvailable"))
    except OSError:
        pass
    try:
        cgroup = Path("/proc/self/cgroup").read_text().strip().split("::")[-1]
        text = Path(f"/sys/fs/cgroup{cgroup}/memory.max").read_text().strip()
        if text.isdigit():
            candidates.append((int(text), "the cgroup's memory.max"))
    except (OSError, IndexError):
        pass
    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    if soft != resource.RLIM_INFINITY:
        candidates.append((soft, "the address-space limit (ulimit -v)"))
    if limit is not None:
        candidates.append((int(limit), "[resources] memory_limit"))
    return min(candidates) if candidates else (2**62, "unknown")


def _mesh_cells(path: Path, where: str) -> int:
    """The cells of a mesh file: an XDMF file in dolfinx's layout from its XML and its HDF5
    file's header (the solid reads it in parallel: nothing here reads its data), any other file
    read with meshio once while it is unchanged (a study estimates every run before the first)."""
    from transfer.xdmf import layout

    try:
        path = Path(path).resolve()
        found = layout(path) if path.suffix.lower() == ".xdmf" else None
        if found is not None:
            return found.num_cells
        return _meshio_cells(path, path.stat().st_mtime_ns if path.exists() else None)
    except Exception as exc:  # noqa: BLE001 - any reader error is a bad input file
        raise SceneError(f"{where}: {exc}") from None


@functools.lru_cache(maxsize=64)
def _meshio_cells(path: Path, mtime_ns: int | None) -> int:  # (a reader's error is not cached)
    from transfer.meshfile import MeshFile

    return MeshFile.read(path).mesh.num_cells


def _solid_cells(scene) -> tuple[int, str]:
    """Tetrahedra of the scene's solid and the key that sets their number."""
    solid = scene.solid
    if solid.box is not None:
        shape = solid.box["shape"]
        return 6 * shape[0] * shape[1] * shape[2], f"{scene.path}: [geometry.solid] shape"
    if solid.generator is not None:
        from transfer.generators import cells

        g, key = solid.generator, f"{scene.path}: [geometry.solid.parameters]"
        try:
            return cells(g["name"], g["parameters"]), key
        except Exception as exc:  # noqa: BLE001 - a generator refusing its parameters is bad input
            raise SceneError(f"{key} (generator {g['name']!r}): {exc}") from None
    key = f"{scene.path}: [geometry.solid] mesh"
    return _mesh_cells(solid.mesh, key), key


def estimate(scene, coupler_ranks: int | None = None) -> list[Estimate]:
    """Cells and memory of every part of the coupled `scene` (participants and coupler; parts
    served in the coupler's process count as the coupler's), the coupler on `coupler_ranks`
    ranks (default: ``[coupling] ranks``)."""
    from coupler.plan.effects import RULES

    ranks = coupler_ranks or scene.coupling["ranks"]
    out, coupler = [], COSTS["coupler_solid"][0] * ranks
    if scene.solid is not None:
        tets, key = _solid_cells(scene)
        solid_cfg = scene.solvers.get("solid")
        if solid_cfg is None:  # a fixed solid, served in the coupler
            out.append(Estimate("solid", tets, 0, key))
        else:
            fixed, per = solid_cfg.spec.memory
            degree_factor = 5 if solid_cfg.settings.get("degree") == 2 else 1
            out.append(Estimate("solid", tets, fixed * solid_cfg.ranks + per * degree_factor * tets, key))
        coupler += COSTS["coupler_solid"][1] * tets
    for name in scene.effects:  # meshes an effect serves in the coupler (mesh files of a transfer)
        for part, cells, key in getattr(RULES[name], "in_process_cells", lambda scene: [])(scene):
            out.append(Estimate(part, cells, 0, key))
            coupler += COSTS["coupler_solid"][1] * cells
    if "fluid" in scene.solvers:
        fluid_cfg = scene.solvers["fluid"]
        g = scene.fluid.shape
        cells, key = g[0] * g[1] * g[2], f"{scene.path}: [geometry.fluid] shape"
        fixed, per = fluid_cfg.spec.memory
        out.append(Estimate("fluid", cells, fixed * fluid_cfg.ranks + per * cells, key))
        coupler += COSTS["coupler_fluid"][1] * cells
    out.append(Estimate("coupler", 0, coupler, f"{scene.path}: [geometry]"))
    return out


def _size(n: float) -> str:
    for unit, scale in (("TB", 2**40), ("GB", 2**30), ("MB", MB)):
        if n >= scale:
            return f"{n / scale:.3g} {unit}"
    return f"{n / 1024:.3g} kB"


def check_memory(scene, estimates: list[Estimate], ranks: int | None = None) -> str:
    """SceneError unless the estimates (of the coupler on `ranks`, default ``[coupling] ranks``)
    fit in the available memory (or the scene says not to check); the line describing the
    estimate otherwise."""
    total = sum(e.bytes for e in estimates)
    available, source = available_memory(scene.resources["memory_limit"])
    parts = ", ".join(f"{e.name} {_size(e.bytes)}" for e in estimates)
    line = f"about {_size(total)} ({parts}); {_size(available)} available ({source})"
    if total > available and scene.resources["check_memory"]:
        ranks = ranks or scene.coupling["ranks"]
        if ranks > 1 and total - COSTS["coupler_solid"][0] * (ranks - 1) <= available:  # it fits on one rank
            raise SceneError(f"{scene.path}: [coupling] ranks = {ranks}: about {_size(COSTS['coupler_solid'][0])} "
                             f"per coupler rank, the run would need {line}; give fewer ranks, or set "
                             f"[resources] check_memory = false to run it anyway")
        big = max((e for e in estimates if e.cells), key=lambda e: e.bytes)
        raise SceneError(f"{big.key}: {big.cells:,} {big.name} cells: the run would need {line}; make it "
                         f"smaller, or set [resources] check_memory = false to run it anyway")
    return line


def first_step(scene, estimates: list[Estimate]) -> tuple[str | None, str | None]:
    """The estimate of the solid's first load step with contact, as a line for ``varcouple
    check`` (None: nothing estimated): the rule's seconds on a core of its own, times the
    machine's load per core when above one; and a warning naming ``[messaging] timeout`` and a
    value to set when :data:`MARGIN` times the estimate exceeds it (else None)."""
    solid = scene.solvers.get("solid")
    rule = solid.spec.contact_step if solid is not None and "contact" in scene.effects else None
    if rule is None:
        return None, None
    cells = next(e.cells for e in estimates if e.name == "solid")
    core = rule[0] * (cells / 1e4) ** rule[1]
    load, n = os.getloadavg()[0], cores()
    seconds = core * max(1.0, load / n)
    timeout = scene.messaging["timeout"]
    line = (f"the solid's first load step with contact about {seconds:,.1f} s ({cells:,} cells: {core:,.1f} s on a "
            f"core of its own by the rule of {solid.spec.kind}, load {load:.1f} on {n} cores); [messaging] "
            f"timeout {timeout:g} s")
    if MARGIN * seconds <= timeout:
        return line, None
    value = 100 * math.ceil(MARGIN * seconds / 100)
    return line, (f"{scene.path}: the solid's first load step may take about {seconds:,.1f} s ({cells:,} cells) and "
                  f"up to {MARGIN:g} times that, more than [messaging] timeout = {timeout:g} s, after which the run "
                  f"stops (exit 4); set [messaging] timeout = {value} in the scene")


def cores() -> int:
    """The cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


def check_cores(scene, ranks: int) -> None:
    """SceneError naming ``[coupling] ranks`` when the coupler's `ranks` are more than
    :data:`RANKS_PER_CORE` (or ``VARCOUPLE_RANKS_PER_CORE``) per core."""
    text = os.environ.get(RANKS_PER_CORE_VAR, "")
    try:
        per_core = int(text) if text else RANKS_PER_CORE
    except ValueError:
        raise SceneError(f"{RANKS_PER_CORE_VAR}={text!r}: not an integer") from None
    if ranks > per_core * cores():
        raise SceneError(f"{scene.path}: [coupling] ranks = {ranks}: more than {per_core} coupler ranks per core "
                         f"({cores()} cores here, at most {per_core * cores()}); give fewer ranks, or set "
                         f"{RANKS_PER_CORE_VAR} to allow more per core")
