"""Drive Debian's stock OpenFOAM v1912 binaries for one structured-grid case.

``blockMesh`` and ``topoSet`` run once (:meth:`OpenFOAMSolver.setup`); each
:meth:`OpenFOAMSolver.solve` writes the ``solid`` field into the start-time directory,
relaunches ``simpleFoam`` (quasi-static) or ``pimpleFoam`` (transient: from the coupling
step's start ``t`` over ``dt``, Euler in time) from that time (``startFrom startTime``; a
running solver cannot pick up a new ``solid`` field) and reads ``U`` and ``p`` of the time
directory it wrote. With a solid velocity it also writes one velocity source per solid body
(:mod:`fluid_openfoam.zones`) into constant/fvOptions. Logs go to ``<case>/log.<application>``; a failing binary raises
:class:`OpenFOAMError` with the tail of its log, and non-finite output fields raise it
too (with the first bad cell).

simpleFoam's time directories are pseudo-time iteration counts (``deltaT 1``); it writes only
at its end (``writeControl runTime`` with the interval equal to the iteration budget, or
earlier when ``residualControl`` is met). Each launch pays OpenFOAM's start-up, which
matters on small grids.

On several processes (``comm``, one per processor of the decomposed case: the participant on
M ranks) rank 0 writes the case, runs blockMesh, topoSet, decomposePar and every solve
(``mpirun -np M <solver> -parallel``, from an environment without the participant's own MPI
job: :func:`openfoam_env`) while the other ranks wait, sleeping, on ``comm``; each rank writes the
inputs of its own processor and reads its results (:mod:`fluid_openfoam.parallel`). Its arrays
hold its processor's cells (:attr:`OpenFOAMSolver.cell_ids`), its inputs the cells the drag of
those reads (:attr:`OpenFOAMSolver.input_ids`). With rigid bodies in a transient run its inputs
also hold its cells' face neighbours and the bodies are labelled across the processors
(:func:`transfer.bodies.rigid_bodies`), each an index box of the grid: decomposePar's ``simple``
blocks are boxes when each axis's cells divide evenly among its blocks; where a processor is
not one, every rank receives the whole grid's inputs (logged). A failure on any rank is every
rank's :class:`~coupler.protocol.errors.RanksError` naming it.
"""

from __future__ import annotations

import logging
import re
import shutil
import subprocess
import time
from pathlib import Path

import numpy as np

from coupler.protocol.exits import describe_exit, oom_kills
from coupler.protocol.fluid_faces import closed_faces, dropped_velocity
from coupler.protocol.mpi import mpi_environment
from coupler.protocol.participant import on_each, on_root

from . import case as _case
from .errors import OpenFOAMError
from .fields import read_internal_field
from .parallel import Decomposition, patch_cells
from transfer.grid import across_axis
from transfer.labels import cell_box
from transfer.penalization import drag_fraction, drag_fraction_of, reach
from .zones import body_sources, write_cell_set

log = logging.getLogger("varcouple.fluid_openfoam")

OPENFOAM_DIR = "/usr/share/openfoam"


_RESIDUAL = re.compile(r"Solving for (\w+), Initial residual = ([^,]+),")

#: while a binary runs, the last line of its log is logged this often (seconds) when the log grew:
#: the participant's progress, which keeps the coupler's [messaging] timeout from cutting a long
#: solve off (docs/protocol.md); a binary whose log stands still is silent
PROGRESS_SECONDS = 10.0


def _wait_logging(proc: subprocess.Popen, logf: Path, app: str) -> int:
    """``proc.wait()``, logging the last line of its log `logf` every :data:`PROGRESS_SECONDS` in
    which the log grew."""
    size = 0
    while True:
        try:
            return proc.wait(PROGRESS_SECONDS)
        except subprocess.TimeoutExpired:
            try:
                with open(logf, "rb") as f:
                    grown = f.seek(0, 2)
                    f.seek(max(size, grown - 4096))
                    lines = f.read().decode("utf-8", "replace").split("\n")
            except OSError:
                continue
            last = next((line.strip() for line in reversed(lines) if line.strip()), "")
            if grown > size and last:
                log.info("%s running: %s", app, last)
            size = grown


def final_residual(log_text: str, transient: bool) -> float:
    """The quantity ``residualControl`` compares with the tolerance: the largest initial
    residual of p and U (any component; the first solve of each field in an iteration) in
    the last iteration of a simpleFoam log (pseudo-time: its last step), or of every time
    step of a pimpleFoam log (its last PIMPLE iteration), maximised over the time steps.
    NaN when the log has no residual."""
    worst = float("nan")
    blocks = re.split(r"^Time = ", log_text, flags=re.M)[1:]
    for block in blocks if transient else blocks[-1:]:
        last = re.split(r"^PIMPLE: iteration \d+", block, flags=re.M)[-1]
        first: dict[str, float] = {}
        for name, value in _RESIDUAL.findall(last):
            first.setdefault(name, float(value))
        if first:
            worst = max(first.values()) if not worst >= 0 else max(worst, *first.values())
    return worst


def openfoam_env() -> dict:
    """This environment with OpenFOAM's data directory and the Open MPI settings of
    :func:`coupler.protocol.mpi.mpi_environment` (the solver's ranks; without the variables of
    the MPI job this process may be a rank of: mpirun refuses to start from within a job)."""
    env = mpi_environment()
    env.setdefault("WM_PROJECT_DIR", OPENFOAM_DIR)
    return env


def _tail(path: Path, n: int = 25) -> str:
    try:
        return "\n".join(path.read_text(errors="replace").splitlines()[-n:])
    except OSError:
        return "(no log)"


def time_dirs(case_dir: Path) -> dict[float, str]:
    out = {}
    for p in Path(case_dir).iterdir():
        if p.is_dir():
            try:
                out[float(p.name)] = p.name
            except ValueError:
                pass
    return out


class OpenFOAMSolver:
    """One OpenFOAM case on disk, written from a :class:`case.CaseSpec`; with ``comm`` (of
    ``spec.ranks`` processes) this process's rank handles its own processor (module doc)."""

    def __init__(self, case_dir, spec: _case.CaseSpec, application: str | None = None, comm=None):
        self.case = Path(case_dir)
        self.spec = spec
        self.application = application or ("pimpleFoam" if spec.transient else "simpleFoam")
        self.comm = comm if comm is not None and comm.Get_size() > 1 else None
        self.rank = self.comm.Get_rank() if self.comm is not None else 0
        if self.comm is not None and self.comm.Get_size() != spec.ranks:
            raise ValueError(f"{self.comm.Get_size()} processes for a case decomposed in {spec.ranks}")
        self.n = spec.grid.n_cells
        self.start = "0"
        self.last_run: dict = {}
        self.parallel: Decomposition | None = None  # ranks > 1: the processor directories
        #: the grid cell of each row of the arrays this process returns, and of its inputs (whole grid: arange)
        self.cell_ids = self.input_ids = np.arange(self.n)
        #: this process's index box of the grid when the rigid bodies are labelled across the processors
        self.box = None
        self.sources: list = []
        self.warned_faces: set[str] = set()

    # -------------------------------------------------------------- running binaries
    def run(self, app: str, *args: str, log_name: str | None = None) -> float:
        """Run an OpenFOAM binary in the case; returns wall seconds. Interrupted (the
        participant's SIGTERM or SIGINT), it stops the binary with SIGTERM, so that mpirun ends
        its ranks and removes its session directory, and with SIGKILL after 5 s."""
        env = openfoam_env()
        exe = shutil.which(app, path=env.get("PATH"))
        if exe is None:
            raise OpenFOAMError(f"{app} not found on PATH (Debian package openfoam)")
        logf = self.case / f"log.{log_name or app}"
        oom_before = oom_kills()
        t0 = time.perf_counter()
        with open(logf, "wb") as out:
            cmd = [exe, "-case", str(self.case), *args]
            if self.parallel is not None and app == self.application:
                cmd = self.parallel.mpi_command(cmd)
            proc = subprocess.Popen(cmd, stdout=out, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                    env=env)
            try:
                rc = _wait_logging(proc, logf, app)
            except BaseException:
                proc.terminate()
                try:
                    proc.wait(5.0)
                except subprocess.TimeoutExpired:
                    proc.kill()
                    proc.wait()
                raise
        dt = time.perf_counter() - t0
        if rc != 0:
            raise OpenFOAMError(f"{app} failed in {self.case}: {describe_exit(rc, oom_before, pid=proc.pid)} (log {logf}):\n"
                                f"{_tail(logf)}")
        return dt

    # ------------------------------------------------------------------ the case
    def setup(self) -> None:
        """Write the case, run blockMesh and topoSet (once), and decomposePar with ranks > 1."""
        self.start = "0"
        self.parallel = None
        if self.spec.ranks > 1:  # decomposePar once; fields per processor from now on (parallel.py)
            self.parallel = Decomposition(self.case, self.spec, None if self.comm is None else [self.rank])
        on_root(self.comm, self._write_case)
        if self.parallel is None:
            self.patch_cells = self.read_patch_cells()
            return
        on_each(self.comm, self.parallel.read_addressing)
        self.cell_ids = self.parallel.cell_ids
        if self.comm is not None:
            self.input_ids = self.input_cells()

    @property
    def rigid_bodies(self) -> bool:
        """The solid's velocity reaches this fluid as rigid bodies (a transient run: zones.py)."""
        return self.spec.transient and self.spec.solid_velocity == "bodies"

    def input_cells(self) -> np.ndarray:
        """This process's input cells: its processor's cells and those their drag reads; with rigid
        bodies also their face neighbours (the bodies' interface layer), the bodies labelled across
        the processors (:attr:`box`) when every processor is an index box of the grid, else the
        whole grid (logged once). Collective."""
        shape, mode = self.spec.grid.shape, self.spec.penalization
        across = across_axis(shape, self.spec.grid.spacing)
        if not self.rigid_bodies:
            return reach(self.cell_ids, shape, mode, across=across)
        box = cell_box(self.cell_ids, shape)
        others = [r for r, boxed in enumerate(self.comm.allgather(box is not None)) if not boxed]
        if not others:
            self.box = box
            return reach(self.cell_ids, shape, mode, at_least=1, across=across)
        if self.rank == 0:
            log.info("fluid_openfoam: %s of the %s decomposition not an index box of the grid %s: every rank "
                     "receives the whole grid's inputs for the rigid bodies", ", ".join(f"processor{r}" for r in others),
                     self.spec.decomposition, self.spec.grid.shape)
        return np.arange(self.n)

    def _write_case(self) -> None:
        if self.case.exists():
            shutil.rmtree(self.case)
        _case.write_case(self.case, self.spec)
        self.run("blockMesh")
        self.run("topoSet")
        if self.parallel is not None:
            self.parallel.decompose(self.run)

    def read_patch_cells(self) -> dict[str, np.ndarray]:
        """Cell behind each face of every patch, in the patch's face order (from
        constant/polyMesh/boundary and owner). For blockMesh's single block the xmin patch
        lists the i = 0 column, j fastest then k (checked in tests/test_fluid_inlet.py)."""
        return patch_cells(self.case / "constant" / "polyMesh")

    @property
    def whole_inputs(self) -> bool:
        """This process receives the inputs of every cell of the grid."""
        return len(self.input_ids) == self.n

    @property
    def bodies_refused(self) -> str | None:
        """Why this process cannot take a solid velocity as rigid bodies (None: it can)."""
        if self.spec.solid_velocity != "bodies" or self.whole_inputs or self.box is not None:
            return None
        return ("solid_velocity 'bodies' on several ranks needs a transient fluid, whose ranks label the bodies "
                "across the processors: a steady fluid's ranks receive their processor's cells and those their "
                "drag reads only")

    # ------------------------------------------------------------------ one solve
    def write_solid(self, fraction, velocity=None) -> None:
        """The drag field (and masked inlet) of this process's cells from the solid fraction of
        its input cells (:attr:`input_ids`), once it and the solid velocity there are checked."""
        frac = np.asarray(fraction, dtype=np.float64).reshape(-1)
        if frac.shape != self.input_ids.shape:
            raise ValueError(f"solid_fraction has {frac.size} values, expected {len(self.input_ids)} (one per "
                             f"{'cell' if self.whole_inputs else 'input cell'})")
        if not np.all(np.isfinite(frac)):
            raise ValueError(f"solid_fraction holds NaN/inf at cell "
                             f"{int(self.input_ids[np.argmin(np.isfinite(frac))])}")
        if velocity is not None and self.spec.solid_velocity == "bodies":
            vel = np.asarray(velocity, dtype=np.float64).reshape(len(self.input_ids), 3)
            if not np.all(np.isfinite(vel)):
                raise ValueError(f"solid_velocity holds NaN/inf at cell "
                                 f"{int(self.input_ids[np.argmin(np.isfinite(vel).all(1))])}")
            if self.bodies_refused:
                raise ValueError(self.bodies_refused)
        frac = np.clip(frac, 0.0, 1.0)
        args = (self.spec.grid.shape, self.spec.grid.spacing, self.spec.nu, self.spec.drag_value(),
                self.spec.penalization, self.spec.penalization_exponent)
        if not self.whole_inputs:
            own, T = frac[np.searchsorted(self.input_ids, self.cell_ids)], drag_fraction_of(
                self.cell_ids, self.input_ids, frac, *args)
        else:
            T = drag_fraction(frac, *args)
            if self.parallel is None:
                _case.write_inputs(self.case / self.start, self.spec, frac, T, self.patch_cells["xmin"])
                return
            own, T = frac[self.cell_ids], T[self.cell_ids]
        self.parallel.write_inputs(self.start, own, T)

    def write_sources(self, fraction, velocity) -> None:
        """constant/fvOptions with one velocity source per solid body (:mod:`zones`) when the
        spec asks for it and the velocity is nonzero (rank 0), and their cellSets: the case's when
        it is not decomposed, else each rank its processor's (a decomposed run reads those only).
        The bodies are labelled across the processors when this process has a :attr:`box`
        (collective: every rank, inputs checked by :meth:`write_solid`)."""
        self.sources = []
        if velocity is not None and self.spec.solid_velocity == "bodies":
            vel = np.asarray(velocity, dtype=np.float64).reshape(len(self.input_ids), 3)
            ranks = {} if self.box is None else {"box": self.box, "ids": self.input_ids, "comm": self.comm}
            self.sources = body_sources(np.clip(fraction, 0.0, 1.0), vel, self.spec.grid.shape,
                                        self.spec.drag_value(), closed_faces(self.spec.faces), **ranks)
            for src in self.sources:
                for face, value in src.dropped.items():
                    if face not in self.warned_faces and self.rank == 0:
                        log.warning("%s", dropped_velocity(face, value))
                    self.warned_faces.add(face)
        if self.parallel is not None:
            self.parallel.write_cell_sets({src.name: src.cells for src in self.sources})
        if self.rank == 0:
            if self.parallel is None:
                for src in self.sources:
                    write_cell_set(self.case / "constant" / "polyMesh" / "sets" / src.name, src.name, src.cells)
            (self.case / "constant" / "fvOptions").write_text(_case.fv_options(self.spec.table(), self.sources))

    def control(self, t: float | None, dt: float | None) -> str:
        """controlDict of one run from the start time: simpleFoam for at most
        ``max_iterations`` pseudo-time steps (written once at the end), or pimpleFoam from
        ``t`` over ``dt`` in ``substeps`` steps (written at ``t + dt``)."""
        if not self.spec.transient:
            t0, budget = float(self.start), self.spec.max_iterations
            return _case.control_dict(t0, t0 + budget, self.spec.write_binary, self.application,
                                      write_interval=budget, write_control="runTime")
        if t is None or dt is None:
            raise ValueError("a transient fluid advances from t over dt: both are needed")
        if abs(float(self.start) - t) > 1e-9 * max(dt, abs(t)):
            raise OpenFOAMError(f"the fluid's state is at time {self.start}, the coupling step starts at {t!r} "
                                f"(restore_state to the step's start first)")
        n = self.spec.substeps
        return _case.control_dict(self.start, repr(t + dt), self.spec.write_binary, self.application,
                                  delta_t=dt / n, write_interval=n)

    def solve(self, solid_fraction, solid_velocity=None, t: float | None = None,
              dt: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Solve from the current start time with this solid fraction (and velocity) of the
        input cells; returns ``(U (n,3) m/s, p (n,) kinematic m^2/s^2)`` of :attr:`cell_ids` and
        makes the result the new start. Transient specs advance from ``t`` over ``dt``
        (:meth:`control`)."""
        t0 = float(self.start)
        fraction = np.asarray(solid_fraction, dtype=np.float64).reshape(-1)
        on_each(self.comm, self.write_solid, fraction, solid_velocity)  # checked on every rank before
        on_each(self.comm, self.write_sources, fraction, solid_velocity)  # the bodies' collectives
        on_each(self.comm, self._prepare, t, dt)
        wall = on_root(self.comm, self.run, self.application)
        end, self.last_run = on_root(self.comm, self._ended, t0, wall)
        U, p = on_each(self.comm, self._results, end)
        self.start = end
        log.info("%s: %s -> %s, %d iterations, converged %s, %.3f s", self.application, self.last_run["start"],
                 end, self.last_run["iterations"], self.last_run["converged"], wall)
        return U, p

    def _prepare(self, t, dt) -> None:
        """The controlDict of a run from the start time, no results after the start."""
        if self.rank == 0:
            (self.case / "system" / "controlDict").write_text(self.control(t, dt))
        for t, name in time_dirs(self.time_root).items():
            if t > float(self.start):  # stale results of a window being repeated (restore_state)
                self.remove_time(name)

    def _ended(self, t0: float, wall: float) -> tuple[str, dict]:
        """The time directory the run wrote and how it ended (from its log)."""
        logf = self.case / f"log.{self.application}"
        text = logf.read_text(errors="replace")
        new = {t: name for t, name in time_dirs(self.time_root).items() if t > t0}
        if not new:
            raise OpenFOAMError(f"{self.application} wrote no time directory after {self.start}:\n{_tail(logf)}")
        end = new[max(new)]
        if self.spec.transient:  # PIMPLE outer iterations per time step, all converged
            outer = [int(k) for k in re.findall(r"PIMPLE: converged in (\d+) iterations", text)]
            steps = len(re.findall(r"^Time = ", text, re.M))
            m = len(outer) == steps and steps > 0
            iters = sum(outer) + (steps - len(outer)) * self.spec.outer_correctors
        else:
            m = re.search(r"SIMPLE solution converged in (\S+) iterations", text)
            iters = int(round(float(end) - t0))  # the log names the converged *time*, not a count
        run = {"wall": wall, "iterations": iters, "converged": bool(m),
               "residual": final_residual(text, self.spec.transient), "start": self.start, "end": end,
               "velocity_sources": [src.velocity.tolist() for src in self.sources],
               "dropped": [src.dropped for src in self.sources if src.dropped]}
        if not m:
            log.warning("%s: not converged to %g within %d %s (%s -> %s)", self.application, self.spec.tolerance,
                        self.spec.outer_correctors if self.spec.transient else self.spec.max_iterations,
                        "PIMPLE iterations per time step" if self.spec.transient else "iterations", self.start, end)
        return end, run

    def _results(self, end: str) -> tuple[np.ndarray, np.ndarray]:
        U, p = self.read_cells(end, "U"), self.read_cells(end, "p")
        for name, arr in (("U", U), ("p", p)):
            bad = ~np.isfinite(arr)
            if bad.any():
                cell = int(self.cell_ids[np.argmax(bad.reshape(len(arr), -1).any(axis=1))])
                logf = self.case / f"log.{self.application}"  # one log for every rank: rank 0 quotes it
                raise OpenFOAMError(f"{self.application} produced non-finite {name} (first at cell {cell}) in "
                                    f"{self.time_root / end}; " + (f"log tail:\n{_tail(logf)}" if self.rank == 0
                                                                   else f"log {logf}"))
        return U, p

    def report(self) -> dict:
        """How the last :meth:`solve` ended, as the keywords of
        :meth:`coupler.participant.Participant.report_solve`."""
        run = self.last_run
        limit = (f"{self.spec.outer_correctors} PIMPLE iterations per time step" if self.spec.transient
                 else f"{self.spec.max_iterations} iterations")
        return {"solver": self.application, "converged": run["converged"], "iterations": run["iterations"],
                "residual": run["residual"], "tolerance": self.spec.tolerance,
                "detail": "" if run["converged"] else f"limit of {limit} reached"}

    def prune(self, keep: set[str]) -> None:
        """Delete time directories other than 0, the current start and ``keep``."""
        for t, name in time_dirs(self.time_root).items():
            if name not in keep and name != self.start and t != 0.0:
                self.remove_time(name)

    # ------------------------------------------- serial case or processor directories
    @property
    def time_root(self) -> Path:
        """The directory holding the time directories (this process's first processor when decomposed)."""
        return self.case if self.parallel is None else self.parallel.time_root

    def remove_time(self, name: str) -> None:
        if self.parallel is not None:
            self.parallel.remove_time(name)
        if self.rank == 0:
            shutil.rmtree(self.case / name, ignore_errors=True)

    def read_cells(self, time: str, name: str) -> np.ndarray:
        """A cell field of time directory ``time`` at :attr:`cell_ids` (from the processors when decomposed)."""
        if self.parallel is not None:
            return self.parallel.read(time, name)
        return read_internal_field(self.case / time / name, self.n)
