"""The Chorin fluid on 2 MPI ranks behind the coupler's client (docs/protocol.md, "Parts"): each
rank declares as ``input_ids`` its slab, the ghost layer and the wall drag's reach, and receives
exactly those rows of every input (recorded by the participant itself); the joined fields equal one
process's. A rank whose input rows are missing answers a one-line error naming the participant,
the rank, its key, the input and its input planes."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from coupler.protocol.errors import ParticipantError
from coupler.protocol.wire import Field
from fluid_chorin.participant import ChorinParticipant
from mpi_chorin_cases import plates

pytestmark = pytest.mark.skipif(shutil.which("mpirun") is None, reason="mpirun not installed")

RECORDING = '''
import os
import numpy as np
from coupler.protocol.participant import main
from fluid_chorin.participant import ChorinParticipant

class Recording(ChorinParticipant):
    """The Chorin fluid saving, per rank, the input ids it declared and the input rows it received;
    with the argument "drop", rank 1 declares one input id fewer than its input cells."""
    def geometry(self):
        header, fields = super().geometry()
        if self.rank == 1 and self.extra_args == ["drop"]:
            fields["input_ids"] = fields["input_ids"][:-1]
        self.declared = fields["input_ids"]
        return header, fields

    def advance(self, window, iteration, t, dt, inputs):
        np.savez(os.path.join(os.environ["RECORD_DIR"], f"rank{self.rank}.npz"), declared=self.declared,
                 **{name: f.data for name, f in inputs.items()})
        return super().advance(window, iteration, t, dt, inputs)

main(Recording)
'''


def config() -> tuple[dict, dict[str, np.ndarray]]:
    """The plates (4 x 13 cells, wall penalization) cut along y, and inputs whose rows name their cell."""
    cfg, (fraction,) = plates()
    velocity = np.zeros((fraction.size, 3))
    velocity[:, 0] = 1e-9 * np.arange(fraction.size)
    return {**cfg, "slab_axis": "y", "poisson": "direct"}, {"solid_fraction": fraction, "solid_velocity": velocity}


@pytest.fixture
def fluid(tmp_path, launch_script):
    def start(fault: str = ""):
        client = launch_script("fluid", "recording_chorin", RECORDING, [fault] if fault else [],
                               {"RECORD_DIR": str(tmp_path)})
        client.configure(config()[0])
        client.geometry()
        return client

    return start


def test_each_rank_receives_the_rows_it_declared_and_the_fields_are_one_process(fluid, tmp_path):
    cfg, inputs = config()
    out = fluid().advance(0, 0, 0.0, 1.0, inputs)
    # slabs of rows 0-5 and 6-12 along y (4 cells a row): each with its ghost row and one more
    rows = {0: np.arange(0, 8 * 4), 1: np.arange(4 * 4, 13 * 4)}
    for rank, ids in rows.items():
        got = np.load(tmp_path / f"rank{rank}.npz")
        assert np.array_equal(got["declared"], ids)
        assert np.array_equal(got["solid_fraction"], inputs["solid_fraction"][ids])
        assert np.array_equal(got["solid_velocity"], inputs["solid_velocity"][ids])
    serial = ChorinParticipant()
    serial.configure(cfg)
    whole = serial.advance(0, 0, 0.0, 1.0, {k: Field(k, v) for k, v in inputs.items()})
    for name in ("pressure", "velocity"):
        a, b = out[name].data, whole[name].data
        assert np.abs(a - b).max() <= 1e-10 * np.abs(b).max()


def test_a_rank_missing_input_rows_answers_an_error_naming_it(fluid):
    client = fluid("drop")
    with pytest.raises(ParticipantError) as info:
        client.advance(0, 0, 0.0, 1.0, config()[1])
    assert str(info.value) == (f"participant 'fluid' failed: ProtocolError: rank 1: varcouple/{client.run_id}/fluid/"
                               f"advance/1: input 'solid_fraction' has shape (35,), expected (36,) (rank 1's "
                               f"input_ids: planes 4 to 12 along y)")
