"""Shared fixtures of the transfer tests: small non-matching meshes of the unit cube.

Meshes are session-scoped (they are immutable) and small, so that the whole
volume suite runs in seconds. Jittered boxes keep their boundary vertices on the
box faces, so two jittered meshes of the same box cover exactly the same domain.
"""

from __future__ import annotations

import os
import uuid
import warnings

from coupler.protocol.mpi import confine

confine()  # before any test imports mpi4py: this process and the mpiruns it starts listen on loopback only

import numpy as np  # noqa: E402
import pytest  # noqa: E402

from transfer import FunctionSpace, StructuredGrid  # noqa: E402
from transfer.generate import box_hexahedra, box_tetrahedra  # noqa: E402

from vc_helpers import SHIFT, deliver_stopping_signals, stopping_signals_not_delivered  # noqa: E402


@pytest.fixture(params=["l2", "pseudo_l2"])
def method(request):
    return request.param


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


@pytest.fixture(scope="session")
def src_tets():
    """Source: 5x5x5 lattice, 750 tets, jittered."""
    return box_tetrahedra((5, 5, 5), jitter=0.2, seed=1, name="src")


@pytest.fixture(scope="session")
def dst_tets():
    """Target: a different, anisotropic resolution and seed; 432 tets."""
    return box_tetrahedra((4, 6, 3), jitter=0.2, seed=2, name="dst")


@pytest.fixture(scope="session")
def shifted_tets():
    """Target box [0,1]^3 + SHIFT: overlaps the unit cube only partly."""
    return box_tetrahedra((4, 4, 4), lower=SHIFT, upper=1.0 + SHIFT, jitter=0.2, seed=3, name="shifted")


@pytest.fixture(scope="session")
def src_hexes():
    return box_hexahedra((3, 4, 3), jitter=0.2, seed=4, name="hexes")


@pytest.fixture(scope="session")
def grid():
    return StructuredGrid.from_bounds((0, 0, 0), (1, 1, 1), (3, 4, 5), name="grid")


@pytest.fixture(scope="session")
def spaces(src_tets, dst_tets):
    return FunctionSpace(src_tets, "P1"), FunctionSpace(dst_tets, "P1")


@pytest.fixture(autouse=True)
def no_pictures(monkeypatch):
    """Runs in tests render no pictures unless the test asks for them ([output] pictures = true
    or VARCOUPLE_PICTURES=1): rendering is tested on its own (tests/coupler/test_pictures.py)."""
    monkeypatch.setenv("VARCOUPLE_PICTURES", "0")


@pytest.fixture(scope="session")
def signals_at_start():
    return set(stopping_signals_not_delivered())


@pytest.fixture(autouse=True)
def signals_not_ignored(request, signals_at_start):
    """No test leaves SIGINT or SIGTERM ignored or blocked: both are inherited by every process a
    later test starts, whose Ctrl-C or SIGTERM would then do nothing. A test that does is named in
    a warning and the signals are given back, so that the tests after it are not affected (the
    tests that send signals start their runs with both delivered: vc_helpers.deliver_stopping_signals)."""
    yield
    found = set(stopping_signals_not_delivered()) - signals_at_start
    if found:
        deliver_stopping_signals()
        warnings.warn(f"{request.node.nodeid} left {', '.join(sorted(found))} in the test process "
                      "(given back)", RuntimeWarning)


@pytest.fixture
def launch_script(tmp_path):
    """``launch_script(name, module, text, extra_args=(), env=None, ranks=2, timeout=60)``: writes the
    participant script ``text`` as ``tmp_path/<module>.py``, starts it as participant ``name`` on
    ``ranks`` MPI ranks behind a new coupler session (``env`` added to the environment) and returns
    its client once alive; all it started is stopped after the test."""
    from coupler.run.client import CouplerSession
    from coupler.run.launch import Launcher

    opened = []

    def start(name: str, module: str, text: str, extra_args=(), env=None, ranks: int = 2, timeout: float = 60.0):
        (tmp_path / f"{module}.py").write_text(text)
        coupler = CouplerSession(f"test-{uuid.uuid4().hex[:12]}")
        environ = dict(os.environ, **(env or {}),
                       PYTHONPATH=os.pathsep.join([str(tmp_path), os.environ.get("PYTHONPATH", "")]))
        launcher = Launcher(coupler.run_id, tmp_path, coupler.endpoints, env=environ)
        opened.append((coupler, launcher))
        launcher.start(name, module, ranks=ranks, extra_args=list(extra_args))
        client = coupler.client(name, timeout, process_check=lambda: launcher.check(name))
        client.wait_alive(60)
        return client

    yield start
    for coupler, launcher in opened:
        launcher.stop_all(timeout=3.0)
        coupler.close()
