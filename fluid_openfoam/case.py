"""Write an OpenFOAM (v1912, ESI) case for an axis-aligned structured grid from Python.

Grid: ``origin``, ``spacing``, ``shape`` (cells); one blockMesh block, so the cells are
numbered x fastest, then y, then z, as :class:`transfer.StructuredGrid`. Every face of
the box is its own patch, named ``xmin xmax ymin ymax zmin zmax``.

Boundary conditions: ``inlet`` (xmin), ``outlet`` (xmax), ``walls`` and ``boundaries`` of the
fluid config, one condition per face (:mod:`coupler.protocol.fluid_faces`).

Units. The case is incompressible (simpleFoam): ``nu = mu / rho`` (m^2/s) in
constant/transportProperties, and OpenFOAM's ``p`` is the *kinematic* pressure p/rho
(m^2/s^2). Pressures given here in Pa are divided by ``rho`` when written; the participant
multiplies the solver's ``p`` by ``rho`` to return Pa.

Immersed solid (volume penalization): the volScalarField ``solid`` (solid volume fraction
per cell, 0..1) is loaded by a ``readFields`` function object and drives an
``explicitPorositySource`` fvOption with the ``solidification`` porosity model
(``T solid;``) over the cellZone ``allCells`` (all cells, made once by topoSet
``boxToCell`` + ``setToCellZone``). The model adds ``-D(solid) U`` to the kinematic
momentum equation (implicitly, on the diagonal); ``D`` is a table linear in the
field, from 0 at 0 to ``drag`` (1/s) at 1. The field written is not always the fraction
itself: ``penalization`` (default ``"wall"``, see :mod:`transfer.penalization`) maps
fractions to a per-cell drag with a sub-cell wall position; ``"linear"`` writes the fraction.

Inlet masking: a fixed-velocity inlet (xmin) gets per-face values ``u_in (1 - f)``, f the
solid fraction of the cell behind each face (rewritten by the solver before each run).

Drag. Default ``drag = 1e4 * max(nu / h_min^2, 1 / dt, U_ref / h_min)``: ``nu/h^2`` is the
viscous relaxation rate of one cell, ``1/dt`` the time-step rate (transient solvers),
``U_ref/h`` the advective rate (``U_ref`` the inlet speed, if given). A fully solid cell
then carries a velocity about 1e-4 of its fluid neighbours'. It is a diagonal term, so a
large value does not hurt the linear solvers.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from coupler.protocol.fluid_faces import face_conditions
from transfer.grid import BOX_FACES
from transfer.penalization import default_drag

from .settings import PARTICIPANT

# vertex numbering of the block: 0 (x0,y0,z0) 1 (x1,y0,z0) 2 (x1,y1,z0) 3 (x0,y1,z0), 4-7 at z1
_FACE_VERTS = {"xmin": (0, 4, 7, 3), "xmax": (2, 6, 5, 1), "ymin": (1, 5, 4, 0),
               "ymax": (3, 7, 6, 2), "zmin": (0, 3, 2, 1), "zmax": (4, 5, 6, 7)}

ZONE = "allCells"


def _header(cls: str, obj: str, location: str | None = None, fmt: str = "ascii") -> str:
    loc = f'    location    "{location}";\n' if location else ""
    return ("FoamFile\n{\n    version     2.0;\n    format      " + fmt + ";\n"
            f"    class       {cls};\n{loc}    object      {obj};\n}}\n\n")


def _vec(v) -> str:
    return "(" + " ".join(repr(float(x)) for x in v) + ")"


@dataclass
class Grid:
    origin: np.ndarray
    spacing: np.ndarray
    shape: tuple[int, int, int]

    @classmethod
    def from_config(cls, g: dict) -> "Grid":
        if not isinstance(g, dict):
            raise ValueError("fluid config needs 'grid' = {origin, spacing, shape}")
        origin = np.asarray(g.get("origin"), dtype=float).reshape(-1)
        spacing = np.asarray(g.get("spacing"), dtype=float).reshape(-1)
        shape = tuple(int(s) for s in np.asarray(g.get("shape")).reshape(-1))
        if origin.shape != (3,) or spacing.shape != (3,) or len(shape) != 3:
            raise ValueError(f"grid origin, spacing, shape must have 3 entries each, got {g!r}")
        if np.any(spacing <= 0) or min(shape) < 1 or not np.all(np.isfinite(origin)):
            raise ValueError(f"grid spacing must be positive and shape >= 1, got {g!r}")
        return cls(origin, spacing, shape)

    @property
    def n_cells(self) -> int:
        return int(np.prod(self.shape))

    @property
    def upper(self) -> np.ndarray:
        return self.origin + self.spacing * np.asarray(self.shape)

    def to_json(self) -> dict:
        return {"origin": self.origin.tolist(), "spacing": self.spacing.tolist(), "shape": list(self.shape)}

    def cell_centres(self) -> np.ndarray:
        """(n, 3), x fastest."""
        idx = [np.arange(n) for n in self.shape]
        k, j, i = np.meshgrid(idx[2], idx[1], idx[0], indexing="ij")
        ijk = np.stack([i.ravel(), j.ravel(), k.ravel()], axis=1)
        return self.origin + (ijk + 0.5) * self.spacing


@dataclass
class CaseSpec:
    """The case: grid, face conditions, fluid, time step and the participant's settings
    (:data:`fluid_openfoam.settings.PARTICIPANT`: their meaning and defaults)."""

    grid: Grid
    faces: dict[str, dict]
    drag: float | None                 # 1/s, see module doc (None: the default of drag_value)
    penalization: str                  # how fractions become drag, see transfer/penalization.py
    penalization_exponent: float       # for penalization "power"
    max_iterations: int                # simpleFoam iterations per advance
    tolerance: float                   # residualControl for p and U
    substeps: int                      # pimpleFoam time steps per coupling step
    outer_correctors: int              # PIMPLE outer iterations per time step at most
    solid_velocity: str                # "bodies": one velocity source per solid body (zones.py); "none"
    ranks: int                         # processors of the decomposed case (parallel.py): the participant's ranks
    decomposition: str                 # decomposePar method with ranks > 1
    rho: float = 1000.0
    mu: float = 1.0e-3
    drag_table: list | None = None     # [[fraction, D], ...] overriding the linear table
    dt: float = 1.0                    # coupling time step [s]
    transient: bool = False            # pimpleFoam over each coupling step (else simpleFoam)
    write_binary: bool = True

    @property
    def nu(self) -> float:
        return self.mu / self.rho

    @property
    def time_step(self) -> float:
        """pimpleFoam's deltaT (transient), else the coupling step."""
        return self.dt / self.substeps if self.transient else self.dt

    def drag_value(self) -> float:
        if self.drag is not None:
            return float(self.drag)
        u_ref = max((float(np.linalg.norm(c["value"])) for c in self.faces.values()
                     if c["kind"] == "velocity"), default=0.0)
        rate = 1.0 / self.time_step if self.transient else 0.0
        return default_drag(self.nu, float(self.grid.spacing.min()), u_ref, rate)

    def table(self) -> list:
        if self.drag_table is not None:
            return [[float(a), float(b)] for a, b in self.drag_table]
        return [[0.0, 0.0], [1.0, self.drag_value()]]

    @classmethod
    def from_config(cls, config: dict, ranks: int = 1) -> "CaseSpec":
        """The case of a fluid configuration, decomposed in ``ranks`` processors (the participant's)."""
        grid = Grid.from_config(config.get("grid"))
        faces = face_conditions(config)
        for d, (a, b) in enumerate((("xmin", "xmax"), ("ymin", "ymax"), ("zmin", "zmax"))):
            ea, eb = faces[a]["kind"] == "empty", faces[b]["kind"] == "empty"
            if ea != eb or (ea and grid.shape[d] != 1):
                raise ValueError(f"'empty' needs both {a} and {b} and one cell in that direction")
        settings = PARTICIPANT.configuration(config)
        del settings["keep_case"]  # the coupler's: it gives case_dir then
        spec = cls(grid, faces, **settings, ranks=int(ranks),
                   rho=float(config.get("rho", 1000.0)), mu=float(config.get("mu", 1.0e-3)),
                   drag_table=config.get("drag_table"), dt=float(config.get("dt", 1.0)),
                   transient=bool(config.get("transient", False)))
        if spec.drag_table is not None and spec.penalization != "linear":
            raise ValueError("drag_table applies to the fraction itself: it needs penalization 'linear'")
        if spec.dt <= 0:
            raise ValueError(f"dt must be positive, got {spec.dt}")
        if spec.rho <= 0 or spec.mu <= 0:
            raise ValueError(f"rho and mu must be positive, got {spec.rho}, {spec.mu}")
        return spec


# ------------------------------------------------------------------ dictionaries

def block_mesh_dict(grid: Grid, faces: dict) -> str:
    (x0, y0, z0), (x1, y1, z1) = grid.origin, grid.upper
    verts = [(x0, y0, z0), (x1, y0, z0), (x1, y1, z0), (x0, y1, z0),
             (x0, y0, z1), (x1, y0, z1), (x1, y1, z1), (x0, y1, z1)]
    nx, ny, nz = grid.shape
    mesh_type = {"wall": "wall", "slip": "patch", "symmetry": "symmetryPlane", "empty": "empty",
                 "velocity": "patch", "pressure": "patch"}
    bnd = []
    for f in BOX_FACES:
        bnd.append(f"    {f}\n    {{\n        type {mesh_type[faces[f]['kind']]};\n"
                   f"        faces ( ({' '.join(map(str, _FACE_VERTS[f]))}) );\n    }}")
    return (_header("dictionary", "blockMeshDict", "system")
            + "convertToMeters 1;\n\nvertices\n(\n"
            + "".join(f"    {_vec(v)}\n" for v in verts)
            + f");\n\nblocks\n(\n    hex (0 1 2 3 4 5 6 7) ({nx} {ny} {nz}) simpleGrading (1 1 1)\n);\n\n"
            + "edges\n(\n);\n\nboundary\n(\n" + "\n".join(bnd) + "\n);\n\nmergePatchPairs\n(\n);\n")


def boundary_u(faces: dict, face_values: dict | None = None, binary: bool = False):
    """boundaryField body of U. ``face_values`` {face: (n_faces, 3) array} gives a fixed-velocity
    face a nonuniform value (in the patch's face order); then the result is ``bytes``
    (binary lists when ``binary``), else ``str``."""
    from .fields import format_list

    out = []
    for f in BOX_FACES:
        c = faces[f]
        body = {"wall": "type noSlip;", "slip": "type slip;", "symmetry": "type symmetryPlane;",
                "empty": "type empty;", "pressure": "type zeroGradient;"}.get(c["kind"])
        if c["kind"] == "velocity":
            if face_values and f in face_values:
                out.append(f"    {f} {{ type fixedValue; value ".encode() + format_list(face_values[f], binary)
                           + b" }")
                continue
            body = f"type fixedValue; value uniform {_vec(c['value'])};"
        out.append(f"    {f} {{ {body} }}")
    if face_values:
        return b"\n".join(o if isinstance(o, bytes) else o.encode() for o in out)
    return "\n".join(out)


def boundary_p(faces: dict, rho: float) -> str:
    out = []
    for f in BOX_FACES:
        c = faces[f]
        body = {"symmetry": "type symmetryPlane;", "empty": "type empty;"}.get(c["kind"], "type zeroGradient;")
        if c["kind"] == "pressure":
            body = f"type fixedValue; value uniform {c['value'] / rho!r};"
        out.append(f"    {f} {{ {body} }}")
    return "\n".join(out)


def boundary_scalar_passive(faces: dict) -> str:
    """boundaryField of the ``solid`` field (zero gradient wherever a value is allowed)."""
    out = []
    for f in BOX_FACES:
        body = {"symmetry": "type symmetryPlane;", "empty": "type empty;"}.get(faces[f]["kind"], "type zeroGradient;")
        out.append(f"    {f} {{ {body} }}")
    return "\n".join(out)


def control_dict(start, end, write_binary: bool = True, application: str = "simpleFoam",
                 delta_t: float = 1.0, write_interval: int = 100000000, write_control: str = "timeStep") -> str:
    """``start`` and ``end`` as numbers (written ``%g``) or time names (written as given)."""
    start, end = (t if isinstance(t, str) else f"{t:g}" for t in (start, end))
    return (_header("dictionary", "controlDict", "system")
            + f"application     {application};\nstartFrom       startTime;\nstartTime       {start};\n"
            f"stopAt          endTime;\nendTime         {end};\ndeltaT          {delta_t!r};\n"
            f"writeControl    {write_control};\nwriteInterval   {write_interval};\npurgeWrite      0;\n"
            f"writeFormat     {'binary' if write_binary else 'ascii'};\nwritePrecision  17;\n"
            "writeCompression off;\ntimeFormat      general;\ntimePrecision   12;\n"
            "runTimeModifiable false;\n\n"
            "functions\n{\n    readSolid\n    {\n        type            readFields;\n"
            '        libs            ("libfieldFunctionObjects.so");\n        fields          (solid);\n'
            "    }\n}\n")


def fv_schemes(transient: bool = False) -> str:
    """Euler in time when transient: a restart from a saved time directory is then exact
    (backward would need the state before it)."""
    return (_header("dictionary", "fvSchemes", "system")
            + f"ddtSchemes {{ default {'Euler' if transient else 'steadyState'}; }}\n"
            "gradSchemes { default Gauss linear; }\n"
            "divSchemes\n{\n    default none;\n    div(phi,U) bounded Gauss linearUpwind grad(U);\n"
            "    div((nuEff*dev2(T(grad(U))))) Gauss linear;\n}\n"
            "laplacianSchemes { default Gauss linear corrected; }\n"
            "interpolationSchemes { default linear; }\n"
            "snGradSchemes { default corrected; }\n")


#: simpleFoam's pressure solve stops at this fraction of ``residualControl``'s tolerance (see fv_solution)
PRESSURE_TOLERANCE = 0.01


def fv_solution(tolerance: float, needs_ref: bool, transient: bool = False, outer_correctors: int = 50) -> str:
    """simpleFoam's (or, ``transient``, pimpleFoam's) solvers and loop. Steady: SIMPLEC, p by GAMG
    smoothed by DICGaussSeidel (incomplete Cholesky, then Gauss-Seidel: point Gauss-Seidel smooths
    the strong coupling across flat cells, as in a thin gap, slowly) to the absolute tolerance
    :data:`PRESSURE_TOLERANCE` times ``tolerance``, above the round-off floor of p's normalised
    residual, which grows with the cells' aspect ratio: once p's outer residual is below it p is no
    longer re-solved, and velocity components that are zero in the exact flow (whose normalised
    residuals measure noise) can settle. An absolute 1e-12 ran every late solve on such cells to
    GAMG's iteration cap, and the run never met residualControl (docs/benchmarks.md, "OpenFOAM on
    flat cells")."""
    ref = "    pRefCell 0;\n    pRefValue 0;\n" if needs_ref else ""
    if transient:  # PIMPLE: outer iterations per time step until the initial residuals fall below tolerance
        return (_header("dictionary", "fvSolution", "system")
                + "solvers\n{\n"
                "    \"p|pFinal\" { solver GAMG; smoother GaussSeidel; tolerance 1e-12; relTol 0.01; }\n"
                "    \"U|UFinal\" { solver smoothSolver; smoother symGaussSeidel; tolerance 1e-14; relTol 0.01; }\n"
                "}\n\nPIMPLE\n{\n    momentumPredictor yes;\n"
                f"    nOuterCorrectors {int(outer_correctors)};\n    nCorrectors 2;\n"
                "    nNonOrthogonalCorrectors 0;\n" + ref
                + f"    residualControl\n    {{\n        p {{ tolerance {tolerance:g}; relTol 0; }}\n"
                f"        U {{ tolerance {tolerance:g}; relTol 0; }}\n    }}\n}}\n\n"
                "relaxationFactors\n{\n    equations { \".*\" 1; }\n}\n")
    return (_header("dictionary", "fvSolution", "system")
            + "solvers\n{\n"
            f"    p {{ solver GAMG; smoother DICGaussSeidel; tolerance {PRESSURE_TOLERANCE * tolerance:g}; "
            "relTol 0.01; }\n"
            "    U { solver smoothSolver; smoother symGaussSeidel; tolerance 1e-14; relTol 0.01; }\n"
            "}\n\nSIMPLE\n{\n    nNonOrthogonalCorrectors 0;\n    consistent yes;\n" + ref
            + f"    residualControl {{ p {tolerance:g}; U {tolerance:g}; }}\n}}\n\n"
            "relaxationFactors\n{\n    equations { U 0.95; \".*\" 0.95; }\n}\n")


def fv_options(table: list, sources=()) -> str:
    """The penalization (``immersedSolid``) and, per :class:`zones.BodySource`, a
    ``vectorSemiImplicitSource`` on its cellSet with ``Su = D_max U_s`` (specific, i.e.
    per unit volume, kinematic) and ``Sp = 0``: with the penalization's implicit
    ``-D_max U`` in those cells the momentum balance there is ``D_max (U_s - U) ~ 0``."""
    rows = " ".join(f"({a!r} {b!r})" for a, b in table)
    extra = "".join(f"\n{src.name}\n{{\n    type            vectorSemiImplicitSource;\n    active          yes;\n"
                    f"    selectionMode   cellSet;\n    cellSet         {src.name};\n"
                    f"    volumeMode      specific;\n    injectionRateSuSp\n    {{\n"
                    f"        U ({_vec(src.su)} 0);\n    }}\n}}\n" for src in sources)
    return (_header("dictionary", "fvOptions", "constant")
            + "immersedSolid\n{\n    type            explicitPorositySource;\n    active          yes;\n\n"
            "    explicitPorositySourceCoeffs\n    {\n        selectionMode   cellZone;\n"
            f"        cellZone        {ZONE};\n        type            solidification;\n\n"
            "        solidificationCoeffs\n        {\n            T   solid;\n"
            f"            D   table ( {rows} );\n"
            "            coordinateSystem\n            {\n                origin  (0 0 0);\n"
            "                e1      (1 0 0);\n                e2      (0 1 0);\n            }\n"
            "        }\n    }\n}\n" + extra)


def topo_set_dict(grid: Grid) -> str:
    pad = grid.spacing * 0.5
    lo, hi = grid.origin - pad, grid.upper + pad
    return (_header("dictionary", "topoSetDict", "system")
            + "actions\n(\n"
            f"    {{ name {ZONE}Set; type cellSet; action new; source boxToCell; box {_vec(lo)} {_vec(hi)}; }}\n"
            f"    {{ name {ZONE}; type cellZoneSet; action new; source setToCellZone; set {ZONE}Set; }}\n);\n")


_PROCESSOR_SCALAR = b'\n    "procBoundary.*" { type processor; value uniform 0; }'
_PROCESSOR_VECTOR = b'\n    "procBoundary.*" { type processor; value uniform (0 0 0); }'


def write_inputs(time_dir, spec: CaseSpec, fraction, drag, inlet_cells, processor: bool = False) -> None:
    """The inputs of one solve in a time directory (the case's, or with ``processor`` a
    processor directory's, whose fields also get its processor patches): the ``solid`` drag
    field and, for a fixed-velocity inlet (xmin), ``U`` with each inlet face masked to
    ``u_in (1 - f)``, f the solid fraction of the cell behind it (``inlet_cells``, in the
    patch's face order); U's internal field is kept."""
    from .fields import read_internal_field, write_field

    time_dir, faces, binary = Path(time_dir), spec.faces, spec.write_binary
    inlet = faces["xmin"]
    if inlet["kind"] == "velocity":
        values = np.outer(1.0 - fraction[inlet_cells], inlet["value"])
        U = read_internal_field(time_dir / "U", len(drag))
        write_field(time_dir / "U", U,
                    boundary_u(faces, {"xmin": values}, binary) + (_PROCESSOR_VECTOR if processor else b""),
                    obj="U", location=time_dir.name, binary=binary, dimensions="[0 1 -1 0 0 0 0]")
    write_field(time_dir / "solid", drag,
                boundary_scalar_passive(faces).encode() + (_PROCESSOR_SCALAR if processor else b""),
                obj="solid", location=time_dir.name, binary=binary)


def write_case(case_dir, spec: CaseSpec) -> Path:
    """Write system/, constant/ and 0/ (U, p, solid = 0). Returns the case directory."""
    case = Path(case_dir)
    for d in ("system", "constant", "0"):
        (case / d).mkdir(parents=True, exist_ok=True)
    faces = spec.faces
    needs_ref = not any(c["kind"] == "pressure" for c in faces.values())
    files = {
        "system/blockMeshDict": block_mesh_dict(spec.grid, faces),
        "system/controlDict": control_dict(0, spec.max_iterations, spec.write_binary),
        "system/fvSchemes": fv_schemes(spec.transient),
        "system/fvSolution": fv_solution(spec.tolerance, needs_ref, spec.transient, spec.outer_correctors),
        "system/topoSetDict": topo_set_dict(spec.grid),
        "constant/transportProperties": _header("dictionary", "transportProperties", "constant")
        + f"transportModel  Newtonian;\n\nnu              {spec.nu!r};\n",
        "constant/turbulenceProperties": _header("dictionary", "turbulenceProperties", "constant")
        + "simulationType  laminar;\n",
        "constant/fvOptions": fv_options(spec.table()),
        "0/U": _header("volVectorField", "U", "0") + "dimensions      [0 1 -1 0 0 0 0];\n\n"
        "internalField   uniform (0 0 0);\n\nboundaryField\n{\n" + boundary_u(faces) + "\n}\n",
        "0/p": _header("volScalarField", "p", "0") + "dimensions      [0 2 -2 0 0 0 0];\n\n"
        "internalField   uniform 0;\n\nboundaryField\n{\n" + boundary_p(faces, spec.rho) + "\n}\n",
        "0/solid": _header("volScalarField", "solid", "0") + "dimensions      [0 0 0 0 0 0 0];\n\n"
        "internalField   uniform 0;\n\nboundaryField\n{\n" + boundary_scalar_passive(faces) + "\n}\n",
    }
    for rel, text in files.items():
        (case / rel).write_text(text)
    return case
