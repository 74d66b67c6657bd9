"""A participant on several MPI ranks whose rank 1 misbehaves (docs/protocol.md, "Parts"): a part with
rows missing, a field missing, an id given twice, a rank that dies in the middle of advance. Each is a
one-line error naming the participant, the rank and its key, never data used (a spring_solid stand-in
on 2 ranks with a fault, started by the Launcher)."""

from __future__ import annotations

import os
import shutil
import textwrap
import uuid

import numpy as np
import pytest

from coupler.protocol.errors import ParticipantDied, ProtocolError
from coupler.run.client import CouplerSession
from coupler.run.launch import Launcher

pytestmark = pytest.mark.skipif(shutil.which("mpirun") is None, reason="mpirun not installed")

BOX = {"box": {"lower": [0, 0, 0], "upper": [1, 2, 3], "shape": [3, 4, 5]}, "stiffness": 4.0}
N_BOX = 4 * 5 * 6

FAULTY = '''
import os, signal
from coupler.protocol.participant import main
from coupler.standins import SpringSolid

class Faulty(SpringSolid):
    """spring_solid whose rank 1 breaks its part as its argument says."""
    def fault(self, what):
        return self.rank == 1 and self.extra_args == [what]

    def geometry(self):
        header, fields = super().geometry()
        if self.fault("twice"):
            fields["point_ids"] = fields["point_ids"].copy()
            fields["point_ids"][0] = 0  # rank 0's first point
        return header, fields

    def advance(self, window, iteration, t, dt, inputs):
        out = super().advance(window, iteration, t, dt, inputs)
        if self.fault("die"):
            os.kill(os.getpid(), signal.SIGKILL)
        if self.fault("rows"):
            out["displacement"].data = out["displacement"].data[1:]
        if self.fault("missing"):
            del out["velocity"]
        return out

main(Faulty)
'''


def start(tmp_path, fault: str):
    (tmp_path / "faulty_parts.py").write_text(FAULTY)
    coupler = CouplerSession(f"test-{uuid.uuid4().hex[:12]}")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(tmp_path), os.environ.get("PYTHONPATH", "")]))
    launcher = Launcher(coupler.run_id, tmp_path, coupler.endpoints, env=env)
    launcher.start("solid", "faulty_parts", ranks=2, extra_args=[fault])
    client = coupler.client("solid", 60, process_check=lambda: launcher.check("solid"))
    client.wait_alive(60)
    client.configure(BOX)
    return coupler, launcher, client


@pytest.fixture
def faulty(tmp_path):
    opened = []

    def make(fault):
        opened.append(start(tmp_path, fault))
        return opened[-1][2]

    yield make
    for coupler, launcher, _ in opened:
        launcher.stop_all(timeout=3.0)
        coupler.close()


def traction():
    return np.random.default_rng(0).random((N_BOX, 3))


@pytest.mark.parametrize("fault, error, text", [
    ("rows", ProtocolError, "'displacement' has 59 rows, its ids 60"),
    ("missing", ProtocolError, "its fields ['displacement'] are not rank 0's ['displacement', 'velocity']")])
def test_a_malformed_part_is_refused_naming_participant_rank_and_key(faulty, fault, error, text):
    solid = faulty(fault)
    solid.geometry()
    with pytest.raises(error) as info:
        solid.advance(0, 0, 0.0, 1.0, {"traction": traction()})
    assert str(info.value) == (f"participant 'solid', rank 1 (varcouple/{solid.run_id}/solid/advance/1): {text}")


def test_an_id_given_twice_is_refused(faulty):
    solid = faulty("twice")
    with pytest.raises(ProtocolError, match=r"participant 'solid', rank 1 \(varcouple/.*/solid/geometry/1\): "
                                            r"'point_ids' of ranks \[0, 1\] both hold id 0 \(1 ids given twice\)"):
        solid.geometry()


def test_a_rank_that_dies_is_named_with_its_key(faulty):
    solid = faulty("die")
    solid.geometry()
    with pytest.raises(ParticipantDied) as info:
        solid.advance(0, 0, 0.0, 1.0, {"traction": traction()})
    message = str(info.value)
    assert f"participant 'solid' died: rank 1 gave no reply on varcouple/{solid.run_id}/solid/advance/1" in message
