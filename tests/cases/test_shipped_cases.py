"""Every shipped case runs, says honestly how it ended, and gives the numbers it gave when
recorded (tests/data/case_figures.json: the statistics of every field of every VTU file, the
coupling iterations and the summary's numbers). A loose characterisation that catches an
unintended change of any figure; that the figures are right is shown by the tests against
analytical and independent references. Record again with ``tests/case_figures.py`` after a
change meant to move results (say why in the commit).

Run the long ones with ``bash scripts/test.sh -m slow``."""

from __future__ import annotations

import json

import numpy as np
import pytest

from case_figures import RECORD, figures, run_case


RECORDED = json.loads(RECORD.read_text())
SLOW = {"cube_obstacle_large", "fracture_closure", "measured_fracture", "rock_obstacle", "fracture_flow", "hertz",
        "fracture_open_by_pressure", "hm_fracture"}
#: fields and figures equal to their record within this (relative to the largest of a field)
RTOL = 1e-6
#: residuals, step sizes, conservation errors, a closed contact's smallest gap and a multigrid's
#: asymptotic rate (from residuals near round-off) measure round-off once a solve has converged: a
#: reordered sum (the transfer kernels' polyhedral clip; contact unknowns numbered like the mesh's
#: input vertices) moved them by up to 1e-5 relative, figures below 1e-10 by up to 0.4 % and those
#: near 1e-15 by any factor, while every field stayed within RTOL: equal to NOISE_RTOL, or both below
#: NOISE_ATOL
#: figures that are round-off by construction (source_max_difference: the source field against the
#: expression it was made from, both evaluated in floats: 0 or an ulp)
NOISY = ("residual", "kkt_residual", "final_step", "conservation_error", "min_gap", "asymptotic_rate",
         "source_max_difference")
NOISE_RTOL, NOISE_ATOL = 1e-3, 1e-10


def cases() -> list:
    return [pytest.param(name, marks=pytest.mark.slow) if name in SLOW else name for name in sorted(RECORDED)]


def honest(summary: dict) -> None:
    """summary.json's status and converged flags agree with every inner solve it reports."""
    assert summary["status"] == "completed", summary.get("error")
    for step in summary.get("steps", []):
        final = [r for reports in step["solves"].values() for r in reports]
        inner = all(r["converged"] or r["accepted"] for r in final)
        assert step["inner_converged"] == inner and step["converged"] == (inner and step["coupling_converged"])
        assert step["converged"], step
        solvers = [p for p in summary["participants"] if not p.get("in_process")]  # stand-ins solve nothing
        assert final or not solvers, f"step {step['step']}: no inner solve reported"


def close(a, b) -> bool:
    return np.allclose(np.asarray(a, float), np.asarray(b, float), rtol=RTOL, atol=RTOL * max(
        np.max(np.abs(np.asarray(b, float)), initial=0.0), 1e-300))


def close_figure(path: str, a, b) -> bool:
    """A summary figure equals its record; one of the NOISY kinds to round-off."""
    parts = path.split("/")
    if parts[-1] in NOISY or parts[-2] == "residuals":
        return max(abs(a), abs(b)) <= NOISE_ATOL or bool(np.isclose(a, b, rtol=NOISE_RTOL, atol=0.0))
    return close(a, b)


@pytest.mark.parametrize("name", cases())
def test_a_shipped_case_is_honest_and_unchanged(tmp_path, name):
    out = run_case(name, tmp_path)
    summary = json.loads((out / "summary.json").read_text())
    honest(summary)
    found, recorded = figures(out), RECORDED[name]
    changed = []
    for file, fields in recorded.items():
        if file in ("iterations", "summary"):
            continue
        assert file in found, f"{name}: {file} no longer written"
        for field, stats in fields.items():
            assert field in found[file], f"{name}: {file} lost {field}"
            if not close(found[file][field], stats):
                changed.append(f"{file} {field}: {found[file][field]} (was {stats})")
    if "iterations" in recorded:  # a round-off change can move a convergence test across its tolerance once
        assert len(found["iterations"]) == len(recorded["iterations"])
        assert np.all(np.abs(np.subtract(found["iterations"], recorded["iterations"])) <= 1), found["iterations"]
    for path, value in recorded["summary"].items():
        if path not in found["summary"]:
            changed.append(f"summary {path}: missing (was {value})")
        elif not close_figure(path, found["summary"][path], value):
            changed.append(f"summary {path}: {found['summary'][path]} (was {value})")
    assert not changed, f"{name}:\n" + "\n".join(changed)
