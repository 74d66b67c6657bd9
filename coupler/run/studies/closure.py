"""``varcouple check|run`` on a ``[closure]`` scene: the fracture closure test of paper 4.1
(figures 6-10; cases/fracture_closure), the solid alone with mortar contact.

A cylindrical (or box) specimen of two rock blocks around a synthetic self-affine fracture,
the lower face meshed ``ratio`` times finer than the upper one (non-matching), is loaded by a
rigid platen to each mean normal stress in turn (:class:`solid_fenicsx.contact_fracture.ClosureTest`,
each step from the last). Written to the output directory: ``closure_curve.png`` and
``closure_table.md`` (closure, mean aperture, contact area fraction, active-set iterations
per stress), ``fracture_face_<s>MPa.vtu`` (lower face: aperture ``gap``, ``contact_pressure``,
``in_contact``) at the stresses ``faces_at``, ``von_mises_<s>MPa.vtu`` (displacement, cellwise
von Mises stress) at ``von_mises_at``, ``summary.json`` (every step with its contact area
fraction, the Bandis fit sigma = k_ni d / (1 - d / d_max)).
"""

from __future__ import annotations

import platform
import time
from dataclasses import asdict, dataclass, fields
from pathlib import Path

from coupler.errors import NotConverged
from coupler.output.results import write_summary
from nonsmooth import NonsmoothSolveError
from coupler.scene.tables import Table, check_tables, output_directory

#: [closure] key -> one-line description (also the list of allowed keys); cases/README.md
CLOSURE_KEYS = {
    "shape": "specimen shape: 'cylinder' (paper 4.1) or 'box'",
    "size": "diameter of the cylinder, or side of the box [m]",
    "height": "thickness of each block [m]",
    "lattice": "[nx, ny, layers per block] of the lower (fine) block",
    "ratio": "the upper face's lattice is `ratio` times coarser (divides nx and ny)",
    "aperture": "mean initial aperture [m]",
    "rms": "RMS roughness of each face [m]",
    "hurst": "Hurst exponent of the faces, in (0, 1)",
    "mismatch_length": "the faces are identical at wavelengths longer than this [m]",
    "min_aperture": "smallest initial aperture (where the faces nearly touch) [m]",
    "seed": "random seed of the fracture",
    "E": "Young's modulus of the rock [Pa]",
    "nu": "Poisson's ratio of the rock",
    "stresses": "list of increasing mean normal stresses on the top [MPa]",
    "faces_at": "stresses (of `stresses`) at which the lower face is written",
    "von_mises_at": "stresses (of `stresses`) at which the von Mises stress is written",
    "solver": "contact QP solver (nonsmooth.solvers), default 'active_set'",
    "tolerance": "relative tolerance on each target stress (default 5e-3)",
}
TABLES = {"case": {"description": "one line on what the case shows"}, "closure": CLOSURE_KEYS,
          "output": {"directory": "output directory, relative to the case (default 'results')"}}


@dataclass
class ClosureScene:
    path: Path
    case_dir: Path
    description: str
    specimen: object  # solid_fenicsx.contact_fracture.Specimen
    stresses: list[float]  # [MPa]
    faces_at: list[float]
    von_mises_at: list[float]
    solver: str
    tolerance: float
    output_dir: Path



def parse(path: Path, case_dir: Path, data: dict, output=None) -> ClosureScene:
    """Validate a ``[closure]`` scene (already read from TOML)."""
    from nonsmooth.solvers import available
    from solid_fenicsx.contact_fracture import SHAPES, Specimen

    check_tables(path, data, TABLES, "a [closure] scene")
    case = Table(path, "case", data.get("case", {}), TABLES["case"])
    t = Table(path, "closure", data["closure"], CLOSURE_KEYS)
    d = {f.name: f.default for f in fields(Specimen)}
    lattice = t.shape("lattice", list(d["lattice"]))
    ratio = t.integer("ratio", d["ratio"])
    if lattice[0] % ratio or lattice[1] % ratio:
        raise t.error("ratio", f"{ratio} does not divide the lattice's nx, ny {lattice[:2]}")
    spec = Specimen(shape=t.string("shape", "cylinder", SHAPES), lattice=tuple(lattice), ratio=ratio,
                    **{k: t.number(k, d[k], positive=True) for k in
                       ("size", "height", "aperture", "rms", "mismatch_length", "min_aperture", "E")},
                    hurst=t.number("hurst", d["hurst"], positive=True, maximum=1.0),
                    seed=t.integer("seed", d["seed"], minimum=0),
                    nu=t.number("nu", d["nu"], minimum=0.0, maximum=0.499))
    if spec.min_aperture >= spec.aperture:
        raise t.error("min_aperture", f"{spec.min_aperture:g} m must be below the mean aperture {spec.aperture:g} m")
    stresses = t.numbers("stresses", positive=True, increasing=True)
    out = Table(path, "output", data.get("output", {}), TABLES["output"])
    return ClosureScene(path=path, case_dir=case_dir, description=case.string("description", None) or "",
                        specimen=spec, stresses=stresses, faces_at=t.numbers("faces_at", [], within=stresses),
                        von_mises_at=t.numbers("von_mises_at", [], within=stresses),
                        solver=t.string("solver", "active_set", tuple(available())),
                        tolerance=t.number("tolerance", 5e-3, positive=True, maximum=0.1),
                        output_dir=output_directory(case_dir, out, output))


def plan_lines(scene: ClosureScene) -> list[str]:
    """What ``varcouple check`` prints for a closure scene."""
    s = scene.specimen
    nx, ny, nz = s.lattice
    outline = f"cylinder, diameter {s.size:g} m" if s.shape == "cylinder" else f"box, side {s.size:g} m"
    return ["study         fracture closure under normal stress (paper 4.1), solid alone, mortar contact",
            f"specimen      {outline}, two blocks {s.height:g} m thick; E {s.E:g} Pa, nu {s.nu:g}",
            f"fracture      self-affine, Hurst {s.hurst:g}, RMS {s.rms:g} m per face, mean aperture {s.aperture:g} m, "
            f"seed {s.seed}",
            f"meshes        lower block {nx} x {ny} x {nz}, upper {nx // s.ratio} x {ny // s.ratio} x {nz} "
            f"(faces non-matching, {s.ratio}:1)",
            f"loading       {', '.join(f'{v:g}' for v in scene.stresses)} MPa (platen displacement to within "
            f"{scene.tolerance:g}), solver {scene.solver}",
            f"fields        lower face at {', '.join(f'{v:g}' for v in scene.faces_at) or 'none'} MPa; "
            f"von Mises at {', '.join(f'{v:g}' for v in scene.von_mises_at) or 'none'} MPa"]


def run(scene: ClosureScene, log=print) -> dict:
    """Load the specimen of `scene` to each stress, write its outputs, return the summary."""
    from solid_fenicsx.contact_fracture import ClosureTest, bandis_fit
    from solid_fenicsx.vertex_io import write_vtu

    out = Path(scene.output_dir)
    out.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    spec = scene.specimen
    test = ClosureTest(spec, solver=scene.solver)
    log(f"specimen: {spec.shape}, lattice {spec.lattice}, upper face {spec.ratio}x coarser, "
        f"{test.contact.num_dofs} dofs, initial mean aperture {test.initial_aperture * 1e6:.1f} um")
    rows, written = [], []
    for mpa in scene.stresses:
        try:
            state, row = test.load_to(mpa * 1e6, rtol=scene.tolerance)
        except NonsmoothSolveError as exc:
            raise NotConverged(f"{scene.path}: closure at {mpa:g} MPa: {exc}") from None
        rows.append(row)
        log(f"{mpa:5.1f} MPa: closure {row['closure'] * 1e6:7.2f} um, contact area {row['area_fraction']:.3f}, "
            f"{row['solves']} solves, active-set iterations {row['iterations']}")
        if mpa in scene.faces_at:
            written.append(out / f"fracture_face_{mpa:g}MPa.vtu")
            test.contact.write_face(written[-1], state)
        if mpa in scene.von_mises_at:
            el = test.contact.elasticity
            written.append(out / f"von_mises_{mpa:g}MPa.vtu")
            write_vtu(written[-1], el.vertices, point_data={"displacement": el.u},
                      cell_data={"von_mises": el.von_mises("DG0")})
    fit = bandis_fit([r["stress"] for r in rows], [r["closure"] for r in rows]) if len(rows) >= 2 else None
    written += [_table(rows, fit, out / "closure_table.md"), _plot(rows, fit, out / "closure_curve.png")]
    summary = {"scene": str(scene.path), "case": "fracture_closure", "specimen": {**asdict(spec), "area": spec.area},
               "solver": scene.solver, "dofs": test.contact.num_dofs, "initial_mean_aperture": test.initial_aperture,
               "steps": rows, "area_fraction": [r["area_fraction"] for r in rows], "bandis": fit,
               "setup_seconds": test.setup_seconds, "wall_seconds": time.perf_counter() - start,
               "platform": {"python": platform.python_version(), "machine": platform.machine()},
               "outputs": [f.name for f in written] + ["summary.json"], "status": "completed"}
    write_summary(out, summary)
    if fit:
        log(f"Bandis: k_ni {fit['k_ni']:.3g} Pa/m, d_max {fit['d_max'] * 1e6:.1f} um, RMS deviation "
            f"{fit['rms_deviation']:.1%}")
    for f in written:
        log(f"wrote {f}")
    log(f"wrote {out / 'summary.json'}")
    return summary


def _table(rows: list, fit: dict | None, path: Path) -> Path:
    lines = ["| stress [MPa] | closure [um] | mean aperture [um] | contact area fraction | active-set iterations |",
             "| --- | --- | --- | --- | --- |"]
    lines += [f"| {r['stress'] / 1e6:.2f} | {r['closure'] * 1e6:.2f} | {r['mean_aperture'] * 1e6:.2f} | "
              f"{r['area_fraction']:.3f} | {r['iterations']} |" for r in rows]
    if fit:
        lines.append(f"\nBandis fit sigma = k_ni d / (1 - d / d_max): k_ni = {fit['k_ni']:.3g} Pa/m, d_max = "
                     f"{fit['d_max'] * 1e6:.1f} um, RMS deviation {fit['rms_deviation']:.1%} of the largest closure")
    path.write_text("\n".join(lines) + "\n")
    return path


def _plot(rows: list, fit: dict | None, path: Path) -> Path:
    """Stress against closure with the Bandis fit; the contact area fraction on the right axis."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.5, 4))
    closure = [r["closure"] * 1e6 for r in rows]
    stress = [r["stress"] / 1e6 for r in rows]
    ax.plot(closure, stress, "o-", label="mortar contact")
    if fit:
        ax.plot([c * 1e6 for c in fit["fitted_closure"]], stress, "k--", label="Bandis fit")
    ax.set_xlabel("closure [um]"), ax.set_ylabel("mean normal stress [MPa]"), ax.legend(loc="upper left")
    ax2 = ax.twinx()
    ax2.plot(closure, [r["area_fraction"] for r in rows], "s:", color="tab:gray")
    ax2.set_ylabel("contact area fraction", color="tab:gray")
    fig.tight_layout(), fig.savefig(path, dpi=120), plt.close(fig)
    return path
