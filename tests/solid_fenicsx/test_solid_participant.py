"""The solid participant (solid_fenicsx/participant.py) in process: every inner solve
reported to the coupler (converged or not, iterations, residual against tolerance), and
loads on boundaries that select no facet refused at configure."""

from __future__ import annotations


import numpy as np
import pytest

pytest.importorskip("dolfinx")

from coupler.plan.plan import make_plan  # noqa: E402
from coupler.scene import load  # noqa: E402
from vc_helpers import ROOT

BLOCK = ROOT / "cases" / "block_compression"


def participant(config):
    from solid_fenicsx.participant import SolidParticipant

    p = SolidParticipant()
    p.comm, p.rank = None, 0
    p.configure(config)
    return p


def block_config(**changes) -> dict:
    """The solid's config of cases/block_compression with `changes`."""
    return {**make_plan(load(BLOCK)).participant("solid").config, **changes}


def advance(p, window=0, dt=1.0):
    """One advance: (outputs, solve reports, figures)."""
    out = p.advance(window, 0, window * dt, dt, {})
    solves, figures = p.take_reports()
    return out, solves, figures


def test_a_capped_krylov_solve_is_reported_unconverged():
    p = participant(block_config(linear_solver="cg", rtol=1e-20, max_iterations=3))
    out, (report,), _ = advance(p)
    assert (report.solver, report.converged, report.iterations, report.detail) == (
        "CG+GAMG static", False, 3, "DIVERGED_MAX_IT")
    assert report.tolerance == 1e-20 and 1e-20 < report.residual < 1.0
    assert np.all(np.isfinite(out["displacement"].data))


@pytest.mark.parametrize("solver, name, iterations", [("cg", "CG+GAMG static", None), ("lu", "LU static", 1)])
def test_a_normal_solve_is_reported_converged(solver, name, iterations):
    _, (report,), _ = advance(participant(block_config(linear_solver=solver, rtol=1e-10)))
    assert report.solver == name and report.converged and report.residual <= report.tolerance == 1e-10
    assert report.iterations == iterations if iterations else report.iterations > 1


def test_a_time_step_reports_the_initial_acceleration_and_the_step():
    p = participant(block_config(linear_solver="cg", rtol=1e-10, dynamic=True))
    _, first, _ = advance(p, 0, dt=1e-4)
    assert [r.solver for r in first] == ["CG+JACOBI initial acceleration", "CG+GAMG time step"]
    _, second, _ = advance(p, 1, dt=1e-4)
    assert [r.solver for r in second] == ["CG+GAMG time step"]
    assert all(r.converged and r.residual <= r.tolerance for r in first + second)


# -- boundaries that select nothing -------------------------------------------------------

BOTTOM_EMPTY = ("[loads.1] boundary 'bottom': selects no facet of the mesh (expression 'z < -5' is false on "
                "every boundary facet midpoint; the mesh spans z in [0, 1])")


def test_a_dirichlet_boundary_selecting_nothing_is_refused():
    """Before: no facet fixed, a singular system and |u| ~ 3.5e11 m with exit 0."""
    from solid_fenicsx import SolidMeshError

    config = block_config(boundaries={**block_config()["boundaries"], "bottom": "z < -5"})
    config["loads"][0]["boundary"] = "bottom"
    with pytest.raises(SolidMeshError) as error:
        participant(config)
    assert str(error.value) == BOTTOM_EMPTY


def test_every_use_of_an_empty_boundary_is_named():
    """A pressure whose boundary is overridden by a later one, the wetted interface and a
    contact face: each refused with its scene key; a load without a key is named by its number."""
    from solid_fenicsx import SolidMeshError

    base = block_config()
    config = block_config(boundaries={"top": "z > 0.99", **base["boundaries"], "lid": "z > 0.99"})
    config["loads"][3] = {k: v for k, v in config["loads"][3].items() if k != "key"} | {"boundary": "top"}
    with pytest.raises(SolidMeshError, match=r"^load 4 boundary 'top': selects no facet of the mesh \(the 32 "
                                             r"facets expression 'z > 0.99' selects all carry boundary 'lid', "
                                             r"given after it \(a facet has one tag\)\)$"):
        participant(config)
    config = block_config(boundaries={**base["boundaries"], "side": "x > 2"}, wetted=["zmax", "side"])
    with pytest.raises(SolidMeshError, match=r"^\[coupling\] interface boundary 'side': selects no facet of the "
                                             r"mesh \(expression 'x > 2' is false on every boundary facet midpoint; "
                                             r"the mesh spans x in \[0, 1\]\)$"):
        participant(config)
    config = block_config(boundaries={**base["boundaries"], "corner": "(x > 2) | (y < -1)"},
                          contact={"slave": "zmax", "master": "corner", "solver": "active_set", "tolerance": 1e-10,
                                   "max_iterations": 10}, steps=1)
    with pytest.raises(SolidMeshError, match=r"^\[contact\] master boundary 'corner': .*the mesh spans x in "
                                             r"\[0, 1\], y in \[0, 1\]\)$"):
        participant(config)


@pytest.mark.parametrize("boundary, load, ranks", [("bottom = \"z < -5\"", 1, 1), ("top = \"z > 2\"", 4, 1),
                                                   ("top = \"z > 2\"", 4, 2)])
def test_varcouple_run_refuses_a_load_on_an_empty_boundary(tmp_path, boundary, load, ranks):
    """On 2 solid ranks the reason's extent of the mesh was a ValueError of the ranks' reduction."""
    import json
    import subprocess
    import sys

    from vc_helpers import copy_case

    name = boundary.split()[0]
    old = ['boundary = "zmin"', "", "", 'boundary = "zmax"'][load - 1]
    case = copy_case(BLOCK, tmp_path, {old: f'boundary = "{name}"',
                                       "[materials.solid]": f"[geometry.solid.boundaries]\n{boundary}\n\n"
                                                            "[materials.solid]",
                                       '[check]\nkind = "uniaxial"': "[check]\nz = \"0\"",  # not uniaxial now
                                       'participant = "solid_fenicsx"': f'participant = "solid_fenicsx"\nranks = {ranks}'})
    out = tmp_path / "out"
    run = subprocess.run([sys.executable, "-m", "coupler.cli", "run", str(case), "--output", str(out)],
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 2, run.stderr  # bad input, found by the participant (before: 4, a failed run)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "invalid"
    expression = boundary.split(" = ")[1].strip('"')
    message = (f"[loads.{load}] boundary '{name}': selects no facet of the mesh (expression '{expression}' is false "
               f"on every boundary facet midpoint; the mesh spans z in [0, 1])")
    assert message in summary["error"] and message in run.stderr, run.stderr
    assert f"varcouple: error: {case / 'scene.toml'}: participant 'solid' refused its input: " in run.stderr
