"""The distributed [check] kinds (coupler/checks: ``DISTRIBUTED``) on a coupler of several ranks
(docs/scaling.md, step 3): mpi_checks_cases.py under mpirun (2 ranks with uneven rows, 3 with
rank 0 holding none; the rows shuffled) gives the serial report of hertz, sneddon, uniaxial and
expression to 1e-12, the same on every rank, and the serial message of a check that cannot be
made; the hertz fit recovers the contact radius and peak pressure of the pressure it was given."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from vc_helpers import run_mpi

HERE = Path(__file__).resolve().parent
pytestmark = pytest.mark.skipif(shutil.which("mpirun") is None, reason="mpirun not installed")


@pytest.fixture(scope="module", params=["3,2", "0,3,2"])
def evaluated(request):
    shares = request.param
    result = run_mpi(HERE / "mpi_checks_cases.py", len(shares.split(",")), shares, timeout=300)
    assert result["ranks"] == len(shares.split(","))
    return result


def test_every_distributed_kind_gives_the_serial_report(evaluated):
    assert set(evaluated["checks"]) == {"hertz", "sneddon", "uniaxial", "expression"}
    for kind, found in evaluated["checks"].items():
        assert found["difference"] <= 1e-12, (kind, found["difference"])
        assert found["same_keys"] and found["same_text"] and found["ranks_agree"], kind


def test_the_hertz_fit_finds_the_pressure_it_was_given(evaluated):
    """p = 5e7 sqrt(1 - r^2 / 0.15^2) with 1 % noise on a cap of the unit sphere."""
    report = evaluated["checks"]["hertz"]["serial"]
    assert report["a"] == pytest.approx(0.15, rel=0.02) and report["p0"] == pytest.approx(5e7, rel=0.02)
    assert report["fitted_vertices"] > 50


def test_a_check_that_cannot_be_made_fails_alike_on_the_ranks(evaluated):
    for kind, (serial, ranks) in evaluated["failures"].items():
        assert serial == ranks, kind
    assert "0 slave vertices carry pressure" in evaluated["failures"]["hertz"][0]
    assert "the crack plane within 0.8 a selects no vertex" in evaluated["failures"]["sneddon"][0]
