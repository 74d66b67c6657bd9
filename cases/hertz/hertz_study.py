"""Hertz refinement study: the case at several contact cell sizes h, compared with
Hertz theory (contact radius a and peak pressure p0 from the elliptic fit of the
nodal pressures, largest nodal pressure, profile error), the fitted convergence rates,
results/hertz_study.json, results/hertz_profile.png and results/hertz_convergence.png.

    .venv/bin/python cases/hertz/hertz_study.py [h1 h2 ...]     (default 0.06 0.04 0.025)
"""

import json
import sys
import tempfile
from pathlib import Path

import numpy as np

from solid_fenicsx.contact_hertz import run

OUT = Path(__file__).with_name("results")


def fitted_rate(h, e):
    """Slope of log(error) against log(h)."""
    return float(np.polyfit(np.log(h), np.log(e), 1)[0])


def main(sizes):
    OUT.mkdir(exist_ok=True)
    rows, last = [], None
    with tempfile.TemporaryDirectory() as tmp:
        for h in sizes:
            row, contact, state = run(tmp, h)
            rows.append(row)
            last = (contact, state, row)
            print(f"h = {h:<6g} dofs {row['dofs']:>7d}  a/h {row['a_hertz'] / h:5.2f}  error a {row['error_a']:.4f}  "
                  f"p0 {row['error_p0']:.4f}  p_max {row['error_p_max']:.4f}  profile {row['error_profile']:.4f}  "
                  f"iterations {row['steps'][0]['iterations']}", flush=True)
    hs = np.array([r["h"] for r in rows])
    rates = {k: fitted_rate(hs, [max(r[k], 1e-16) for r in rows])
             for k in ("error_a", "error_p0", "error_p_max", "error_profile")} if len(rows) > 1 else {}
    within = [r["h"] for r in rows if r["error_a"] < 0.05 and r["error_p0"] < 0.05]
    summary = {"case": "hertz", "levels": rows, "rates": rates,
               "within_5_percent": {"h": max(within) if within else None, "criterion": "fitted a and p0 within 5 %"}}
    (OUT / "hertz_study.json").write_text(json.dumps(summary, indent=2))
    print("fitted rates (error ~ h^rate):", {k: round(v, 2) for k, v in rates.items()})
    plot(rows, last)


def plot(rows, last):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    contact, state, row = last
    pts = contact.mortar.slave.points
    r = np.hypot(pts[:, 0], pts[:, 1])
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.plot(r[contact.mortar.covered] / row["a_hertz"], state.pressure[contact.mortar.covered] / row["p0_hertz"], ".",
            ms=3, label=f"mortar contact, nodal pressure (h = {row['h']:g})")
    s = np.linspace(0, 1.5, 300)
    ax.plot(s, np.sqrt(np.clip(1 - s ** 2, 0, None)), "k-", label="Hertz")
    ax.set_xlabel("r / a (Hertz)"), ax.set_ylabel("p / p0 (Hertz)"), ax.set_xlim(0, 1.5), ax.legend()
    fig.tight_layout(), fig.savefig(OUT / "hertz_profile.png", dpi=120), plt.close(fig)
    fig, ax = plt.subplots(figsize=(5, 4))
    hs = [x["h"] for x in rows]
    for key, label in (("error_a", "a (fit)"), ("error_p0", "p0 (fit)"), ("error_p_max", "largest nodal p"),
                       ("error_profile", "profile, weighted L2")):
        ax.loglog(hs, [x[key] for x in rows], "o-", label=label)
    ax.axhline(0.05, color="gray", ls=":")
    ax.set_xlabel("contact cell size h [m]"), ax.set_ylabel("relative error vs Hertz"), ax.legend()
    fig.tight_layout(), fig.savefig(OUT / "hertz_convergence.png", dpi=120), plt.close(fig)


if __name__ == "__main__":
    main([float(a) for a in sys.argv[1:]] or [0.06, 0.04, 0.025])
