"""Fracture closure under normal stress (paper 4.1, figures 6-10), a script case.

A square specimen (0.1 m side; a box instead of the paper's 122 mm cylinder: the
fracture generator and the block mesher work on rectangles) cut by a synthetic
self-affine fracture (Hurst 0.8, RMS 0.2 mm per face, mean aperture 0.2 mm), E = 10 GPa,
nu = 0.33. The lower face is meshed twice as finely as the upper (non-matching); the
bottom rests on a fixed platen and a rigid platen on the top is moved until the mean
normal stress reaches 1 ... 20 MPa (solid_fenicsx/contact_fracture.py), each step from
the last. Outputs in results/: loading curve (closure_curve.png, closure_table.md),
aperture and contact pressure on the lower face at 2, 10, 20 MPa
(fracture_face_<s>MPa.vtu), von Mises stress at 4 MPa (von_mises_4MPa.vtu), contact
area fraction per step and the Bandis fit (summary.json).

    .venv/bin/python cases/fracture_closure/closure.py [--large]
"""

import json
import sys
import time
from pathlib import Path

from solid_fenicsx.contact_fracture import ClosureTest, Specimen, bandis_fit
from solid_fenicsx.vertex_io import write_vtu

OUT = Path(__file__).with_name("results")
STRESSES_MPA = (1, 2, 4, 6, 10, 15, 20)
FACES_AT = (2, 10, 20)
VON_MISES_AT = 4


def main(large=False):
    OUT.mkdir(exist_ok=True)
    spec = Specimen(shape=(32, 32, 8)) if large else Specimen()
    start = time.perf_counter()
    test = ClosureTest(spec)
    print(f"specimen: lattice {spec.shape}, upper face {spec.ratio}x coarser, {test.contact.num_dofs} dofs, "
          f"initial mean aperture {test.initial_aperture * 1e6:.1f} um", flush=True)
    rows = []
    for mpa in STRESSES_MPA:
        state, row = test.load_to(mpa * 1e6, rtol=5e-3)
        rows.append(row)
        print(f"{mpa:5.1f} MPa: closure {row['closure'] * 1e6:7.2f} um, contact area {row['area_fraction']:.3f}, "
              f"{row['solves']} solves, active-set iterations {row['iterations']}", flush=True)
        if mpa in FACES_AT:
            test.contact.write_face(OUT / f"fracture_face_{mpa}MPa.vtu", state)
        if mpa == VON_MISES_AT:
            el = test.contact.elasticity
            write_vtu(OUT / f"von_mises_{mpa}MPa.vtu", el.vertices,
                      point_data={"displacement": el.u}, cell_data={"von_mises": el.von_mises("DG0")})
    fit = bandis_fit([r["stress"] for r in rows], [r["closure"] for r in rows])
    summary = {"case": "fracture_closure", "specimen": spec.__dict__, "dofs": test.contact.num_dofs,
               "initial_mean_aperture": test.initial_aperture, "steps": rows, "bandis": fit,
               "wall_seconds": time.perf_counter() - start}
    (OUT / "summary.json").write_text(json.dumps(summary, indent=2, default=float))
    table = ["| stress [MPa] | closure [um] | mean aperture [um] | contact area fraction | active-set iterations |",
             "| --- | --- | --- | --- | --- |"]
    table += [f"| {r['stress'] / 1e6:.2f} | {r['closure'] * 1e6:.2f} | {r['mean_aperture'] * 1e6:.2f} | "
              f"{r['area_fraction']:.3f} | {r['iterations']} |" for r in rows]
    table.append(f"\nBandis fit sigma = k_ni d / (1 - d / d_max): k_ni = {fit['k_ni']:.3g} Pa/m, "
                 f"d_max = {fit['d_max'] * 1e6:.1f} um, RMS deviation {fit['rms_deviation']:.1%} of the largest closure")
    (OUT / "closure_table.md").write_text("\n".join(table) + "\n")
    print(f"Bandis: k_ni {fit['k_ni']:.3g} Pa/m, d_max {fit['d_max'] * 1e6:.1f} um, RMS deviation "
          f"{fit['rms_deviation']:.1%}; {summary['wall_seconds']:.0f} s")
    plot(rows, fit)


def plot(rows, fit):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.5, 4))
    closure = [r["closure"] * 1e6 for r in rows]
    stress = [r["stress"] / 1e6 for r in rows]
    ax.plot(closure, stress, "o-", label="mortar contact")
    ax.plot([c * 1e6 for c in fit["fitted_closure"]], stress, "k--", label="Bandis fit")
    ax.set_xlabel("closure [um]"), ax.set_ylabel("normal stress [MPa]"), ax.legend()
    ax2 = ax.twinx()
    ax2.plot(closure, [r["area_fraction"] for r in rows], "s:", color="tab:gray")
    ax2.set_ylabel("contact area fraction", color="tab:gray")
    fig.tight_layout(), fig.savefig(OUT / "closure_curve.png", dpi=120), plt.close(fig)


if __name__ == "__main__":
    main(large="--large" in sys.argv[1:])
