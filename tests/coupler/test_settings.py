"""Settings declarations (coupler/protocol/settings.py): a declared table is validated with
its defaults filled in, and every refusal is one line ``<where> <key>: <reason>``; scene
tables (coupler.scene.tables.Table) use the same checks."""

import math

import pytest

from coupler.errors import SceneError
from coupler.protocol.settings import REQUIRED, Invalid, ParticipantSpec, Setting, Settings, When
from coupler.scene.tables import Table

WHERE = "scene.toml: [solvers.x]"
SETTINGS = Settings(
    Setting("mode", "string", "how", default="a", choices=("a", "b")),
    Setting("k", "number", "exponent of mode b", default=2.0, positive=True, only=When.equals("mode", "b")),
    Setting("n", "integer", "iterations", default=10, minimum=1),
    Setting("ranks", "integer", "ranks", default=1, minimum=1),
    Setting("split", "string", "how to split", default="simple", choices=("simple",), only=When.above("ranks", 1)),
    Setting("stiffness", "number", "spring stiffness", unit="Pa/m", positive=True),
    Setting("steps", "integers", "some steps", default=[], minimum=0),
    Setting("keep", "boolean", "keep it", default=False),
    Setting("drag", "number", "drag", default=None, positive=True),
    Setting("x", "number", "a fraction", default=0.5, minimum=0.0, maximum=1.0))


def test_defaults_are_filled_in_and_given_values_kept():
    out = SETTINGS.validate({"stiffness": 3, "mode": "b", "k": 3.0, "steps": [2, 0]}, WHERE)
    assert out == {"mode": "b", "k": 3.0, "n": 10, "ranks": 1, "split": "simple", "stiffness": 3.0,
                   "steps": [2, 0], "keep": False, "drag": None, "x": 0.5}
    assert isinstance(out["stiffness"], float)
    again = SETTINGS.validate({"stiffness": 1.0}, WHERE)
    again["steps"].append(1)  # a list default is a copy
    assert SETTINGS.validate({"stiffness": 1.0}, WHERE)["steps"] == []


BAD = [
    ({"stiffness": 1.0, "tolerence": 1.0}, "tolerence: unknown key (participant 'x'); known keys: mode, k, n, "
                                           "ranks, split, stiffness, steps, keep, drag, x"),
    ({}, "stiffness: missing (spring stiffness)"),
    ({"stiffness": "stiff"}, "stiffness: must be a number, got 'stiff'"),
    ({"stiffness": True}, "stiffness: must be a number, got True"),
    ({"stiffness": math.nan}, "stiffness: must be a finite number, got nan"),
    ({"stiffness": math.inf}, "stiffness: must be a finite number, got inf"),
    ({"stiffness": -1.0}, "stiffness: must be positive, got -1.0"),
    ({"stiffness": 1.0, "x": 1.5}, "x: must lie in [0.0, 1.0], got 1.5"),
    ({"stiffness": 1.0, "n": 0}, "n: must be an integer >= 1, got 0"),
    ({"stiffness": 1.0, "n": 2.0}, "n: must be an integer >= 1, got 2.0"),
    ({"stiffness": 1.0, "mode": "c"}, "mode: unknown value 'c'; use one of 'a', 'b'"),
    ({"stiffness": 1.0, "keep": 1}, "keep: must be true or false, got 1"),
    ({"stiffness": 1.0, "steps": [1, -1]}, "steps: values must lie in [0, inf), got [1, -1]"),
    ({"stiffness": 1.0, "k": 3.0}, 'k: applies to mode = "b" only'),
    ({"stiffness": 1.0, "split": "simple"}, "split: applies to ranks > 1 only"),
]


@pytest.mark.parametrize("values, message", BAD)
def test_every_refusal_is_one_line_naming_where_key_and_reason(values, message):
    with pytest.raises(SceneError) as info:
        SETTINGS.validate(values, WHERE, owner="participant 'x'" if "tolerence" in values else "")
    assert str(info.value) == f"{WHERE} {message}"


def test_a_table_and_a_setting_give_the_same_reason_for_the_same_value():
    """One implementation of the typed checks: Table (scene tables) and Setting (declarations)."""
    for value in (-2.0, math.nan, "x", [1.0]):
        t = Table("scene.toml", "solvers.x", {"stiffness": value}, {"stiffness": "spring stiffness"})
        with pytest.raises(SceneError) as from_table:
            t.number("stiffness", positive=True)
        with pytest.raises(SceneError) as from_setting:
            SETTINGS.validate({"stiffness": value}, WHERE)
        assert str(from_table.value) == str(from_setting.value)


def test_pick_reads_the_declared_keys_of_a_configuration_and_ignores_the_rest():
    """A participant's configuration also holds its mesh, loads, ...: pick takes its settings out."""
    out = SETTINGS.pick({"grid": {"shape": [1, 1, 1]}, "stiffness": 2.0, "drag": None}, "spring configuration:")
    assert out["stiffness"] == 2.0 and out["drag"] is None and "grid" not in out
    with pytest.raises(SceneError, match=r"^spring configuration: n: must be an integer >= 1, got 0$"):
        SETTINGS.pick({"stiffness": 2.0, "n": 0}, "spring configuration:")


def test_a_declaration_whose_default_it_refuses_is_an_error():
    with pytest.raises(Invalid, match="unknown value 'c'"):
        Setting("mode", "string", "how", default="c", choices=("a", "b"))
    with pytest.raises(ValueError, match="declared twice"):
        Settings(Setting("a", "boolean", "a", default=True), Setting("a", "boolean", "b", default=False))
    assert Setting("a", "number", "required a").default is REQUIRED


def test_adding_settings_replaces_a_key_in_its_place():
    """How a participant that declares ranks itself overrides the coupler's ranks."""
    common = Settings(Setting("participant", "string", "who", default="p"), Setting("ranks", "integer", "mpirun -n",
                                                                                  default=1, minimum=1))
    own = Settings(Setting("ranks", "integer", "its solver's ranks", default=1, minimum=1),
                   Setting("tol", "number", "tolerance", default=1e-7, positive=True))
    merged = common + own
    assert merged.names == ["participant", "ranks", "tol"] and merged["ranks"].description == "its solver's ranks"
    spec = ParticipantSpec("p", "p", "fluid", "a participant", own)
    assert spec.own_ranks and not ParticipantSpec("q", "q", "solid", "another", Settings()).own_ranks


def test_the_reference_shows_types_and_defaults_as_a_scene_writes_them():
    s = SETTINGS
    assert (s["mode"].describe_type(), s["mode"].describe_default()) == ('`"a"` or `"b"`', '`"a"`')
    assert (s["stiffness"].describe_type(), s["stiffness"].describe_default()) == ("number > 0 [Pa/m]", "required")
    assert (s["k"].describe_default(), s["drag"].describe_default()) == ("`2.0`", "none")
    assert (s["x"].describe_type(), s["n"].describe_type()) == ("number in [0.0, 1.0]", "integer >= 1")
    assert Setting("t", "number", "tol", default=1e-7).describe_default() == "`1e-7`"


def test_a_positive_bounded_number_and_a_single_allowed_integer_read_as_intervals():
    cfl = Setting("cfl", "number", "Courant number", default=0.5, positive=True, maximum=1.0)
    ranks = Setting("ranks", "integer", "one process", default=1, minimum=1, maximum=1)
    assert (cfl.describe_type(), ranks.describe_type()) == ("number in (0, 1.0]", "integer = 1")
    with pytest.raises(SceneError, match=r"^s.toml: \[solvers.fluid\] ranks: must be 1, got 2$"):
        Settings(ranks).validate({"ranks": 2}, "s.toml: [solvers.fluid]")
    with pytest.raises(SceneError, match=r"^s.toml: \[solvers.fluid\] cfl: must lie in \(0, 1.0\], got 2.0$"):
        Settings(cfl).validate({"cfl": 2.0}, "s.toml: [solvers.fluid]")
