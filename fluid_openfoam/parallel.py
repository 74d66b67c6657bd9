"""Decomposed (MPI-parallel) fluid runs: ``decomposePar`` once, fields per processor.

With ``ranks = N > 1`` the case is split once, after ``blockMesh`` and ``topoSet``, by
``decomposePar`` with method ``simple``: N = nx ny nz blocks of the grid, the factors chosen
so that the blocks have the fewest cut faces (:func:`simple_split`); on a structured grid
that is also what a graph partitioner would aim for. ``scotch`` is not offered: Debian's
OpenFOAM v1912 ships only the dummy ``libscotchDecomp.so`` (decomposePar stops with "Please
install <scotch>"). Every solve then runs ``mpirun -np N <solver> -parallel``.

Nothing is reconstructed: the solver's inputs (the ``solid`` drag field and the masked inlet
velocity ``U``) are written straight into ``processorI/<time>/`` and ``U`` and ``p`` read from
there, through ``processorI/constant/polyMesh/cellProcAddressing`` (the global cell of each
local cell; blockMesh numbering, x fastest). The participant runs as one process per processor
(rank r handles ``processor<r>`` only: :class:`Decomposition` with ``mine = [r]``); one process
may also handle every processor (``mine`` None: arrays of the whole grid). Processor patches get
``"procBoundary.*" { type processor; value uniform 0; }``: the solver overwrites their values
with the neighbour's cells before it uses them. Time directories live in every ``processorI``;
the case root keeps only ``0`` and the dictionaries.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np

from . import case as _case
from .errors import OpenFOAMError
from .fields import read_internal_field, read_label_list, read_patches
from .settings import DECOMPOSITIONS



def simple_split(ranks: int, shape) -> tuple[int, int, int]:
    """Blocks per axis (nx, ny, nz), nx ny nz = ranks, with the fewest faces between blocks
    (sum over axes of (n_d - 1) times the grid's cross-section normal to d); on a tie the
    split along the later axis (z before y before x).
    Raises ValueError when an axis would get fewer cells than blocks."""
    shape = [int(s) for s in shape]
    best = None
    for nx in range(1, ranks + 1):
        if ranks % nx:
            continue
        for ny in range(1, ranks // nx + 1):
            if (ranks // nx) % ny:
                continue
            n = (nx, ny, ranks // nx // ny)
            if any(b > s for b, s in zip(n, shape)):
                continue
            cut = sum((n[d] - 1) * np.prod(shape) // shape[d] for d in range(3))
            if best is None or cut < best[0]:
                best = (cut, n)
    if best is None:
        raise ValueError(f"cannot split a grid of {shape} cells into {ranks} blocks")
    return best[1]


def decompose_par_dict(ranks: int, method: str, shape) -> str:
    if method not in DECOMPOSITIONS:
        raise ValueError(f"decomposition must be one of {', '.join(DECOMPOSITIONS)}, got {method!r}")
    n = simple_split(ranks, shape)
    return (_case._header("dictionary", "decomposeParDict", "system")
            + f"numberOfSubdomains {ranks};\n\nmethod          {method};\n\n"
            f"coeffs\n{{\n    n ({n[0]} {n[1]} {n[2]});\n}}\n")


def patch_cells(mesh_dir) -> dict[str, np.ndarray]:
    """Cell behind each face of every patch of a polyMesh, in the patch's face order."""
    mesh_dir = Path(mesh_dir)
    owner = read_label_list(mesh_dir / "owner")
    return {name: owner[start:start + n] for name, (start, n) in read_patches(mesh_dir / "boundary").items()}


class Decomposition:
    """The processor directories of a decomposed case this process handles (``mine``: their
    numbers; None: every processor) and the maps between them and the grid. Its arrays hold the
    rows of :attr:`cell_ids`: the grid's cells in grid order when it handles every processor,
    else its processors' cells in their local order (``cellProcAddressing``)."""

    def __init__(self, case_dir, spec: _case.CaseSpec, mine: list[int] | None = None):
        self.case = Path(case_dir)
        self.spec = spec
        self.ranks = int(spec.ranks)
        self.method = spec.decomposition
        self.whole = mine is None
        self.processors = [self.case / f"processor{r}" for r in (range(self.ranks) if mine is None else mine)]
        self.cells: list[np.ndarray] = []
        self.rows: list[np.ndarray] = []  # where each processor's cells go in this process's arrays
        self.patch_cells: list[dict[str, np.ndarray]] = []

    def decompose(self, run) -> None:
        """Write system/decomposeParDict and run decomposePar (``run`` is the solver's
        :meth:`OpenFOAMSolver.run`; once, by one process)."""
        (self.case / "system" / "decomposeParDict").write_text(
            decompose_par_dict(self.ranks, self.method, self.spec.grid.shape))
        run("decomposePar", "-force")

    def read_addressing(self) -> None:
        """Read the cell addressing and patches of this process's processors; OpenFOAMError naming
        the file when one is missing or malformed, or when they do not number the grid's cells
        (handling every processor: each cell once)."""
        self.cells, self.rows, self.patch_cells = [], [], []
        n = self.spec.grid.n_cells
        for proc in self.processors:
            mesh = proc / "constant" / "polyMesh"
            for name in ("cellProcAddressing", "boundary", "owner"):
                if not (mesh / name).is_file():
                    raise OpenFOAMError(f"{mesh / name}: missing (decomposePar did not write {proc.name})")
            cells = read_label_list(mesh / "cellProcAddressing")  # a FieldFormatError names the file
            patches = patch_cells(mesh)
            if len(cells) == 0 or cells.min() < 0 or cells.max() >= n or len(np.unique(cells)) != len(cells):
                raise OpenFOAMError(f"{mesh / 'cellProcAddressing'}: not distinct cells of the grid's 0..{n - 1}")
            if "xmin" not in patches:
                raise OpenFOAMError(f"{mesh / 'boundary'}: no patch xmin")
            self.cells.append(cells)
            self.patch_cells.append(patches)
        self.rows = list(self.cells) if self.whole else [np.arange(len(c)) for c in self.cells]
        if self.whole:
            covered = np.zeros(n, dtype=int)
            for cells in self.cells:
                np.add.at(covered, cells, 1)
            if not np.all(covered == 1):
                raise OpenFOAMError(f"{self.case}: cellProcAddressing does not cover every cell once")

    @property
    def cell_ids(self) -> np.ndarray:
        """The grid cell of each row of this process's arrays."""
        return np.arange(self.spec.grid.n_cells) if self.whole else np.concatenate(self.cells)

    def mpi_command(self, command: list[str]) -> list[str]:
        """``mpirun -np N <solver> -parallel ...`` for a solver command line, to run with the
        environment of :func:`fluid_openfoam.solver.openfoam_env` (Open MPI's settings,
        :mod:`coupler.mpi_env`: shared memory, loopback wire-up, messaging layer ob1). The
        solver is relaunched every coupling iteration, so start-up counts: fixing the messaging
        layer (ob1) halves the start-up against letting Open MPI choose it at every launch."""
        return ["mpirun", "-np", str(self.ranks), "--oversubscribe", command[0], "-parallel", *command[1:]]

    @property
    def time_root(self) -> Path:
        """Where this process's time directories appear (its first processor; every one has the same)."""
        return self.processors[0]

    def remove_time(self, name: str) -> None:
        for proc in self.processors:
            shutil.rmtree(proc / name, ignore_errors=True)

    def read(self, time: str, name: str) -> np.ndarray:
        """A cell field of this process's processors' ``time`` directory, in the rows of :attr:`cell_ids`."""
        parts = [read_internal_field(proc / time / name, len(cells)) for proc, cells in zip(self.processors, self.cells)]
        out = np.empty((sum(len(c) for c in self.cells), *parts[0].shape[1:]))
        for rows, part in zip(self.rows, parts):
            out[rows] = part
        return out

    def write_cell_sets(self, sets: dict[str, np.ndarray]) -> None:
        """cellSets given by global cells, as each processor's ``constant/polyMesh/sets/NAME``
        holding its local cells (the velocity sources' sets, :mod:`fluid_openfoam.zones`)."""
        from .zones import write_cell_set

        for proc, cells in zip(self.processors, self.cells):
            folder = proc / "constant" / "polyMesh" / "sets"
            folder.mkdir(exist_ok=True)
            for name, members in sets.items():
                write_cell_set(folder / name, name, np.flatnonzero(np.isin(cells, members)))

    def write_inputs(self, time: str, fraction: np.ndarray, drag: np.ndarray) -> None:
        """:func:`fluid_openfoam.case.write_inputs` in each processor's ``time`` directory
        (``fraction``, ``drag``: the rows of :attr:`cell_ids`)."""
        for proc, rows, patches in zip(self.processors, self.rows, self.patch_cells):
            _case.write_inputs(proc / time, self.spec, fraction[rows], drag[rows], patches["xmin"], processor=True)
