"""The [solvers.X] key reference of cases/README.md is generated from the declarations
(coupler/scene/reference.py): the README is in sync, and a changed declaration is seen."""

import dataclasses

import pytest

from coupler.protocol.settings import Setting, Settings
from coupler.scene import participants, reference
from vc_helpers import ROOT

README = ROOT / "cases" / "README.md"


def test_cases_readme_is_in_sync_with_the_declarations():
    text = README.read_text()
    assert reference.spliced(text) == text, ("cases/README.md: run .venv/bin/python -m coupler.scene.reference "
                                            "--write cases/README.md")
    assert reference.main(["--check", str(README)]) == 0


def test_every_declared_key_is_in_the_reference():
    block = README.read_text().split(reference.BEGIN)[1].split(reference.END)[0]
    for kind, spec in participants.registered().items():
        if spec.role is None:
            continue
        section = block.split(f'#### `participant = "{kind}"`')[1].split("####")[0]
        for s in spec.settings:
            assert f"| `{s.name}` | {s.describe_default()} | {s.describe_type()} | {s.description}" in section


def test_a_changed_declaration_puts_the_readme_out_of_sync(tmp_path, monkeypatch, capsys):
    copy = tmp_path / "README.md"
    copy.write_text(README.read_text())
    spring = participants.registered()["spring_solid"]
    changed = dataclasses.replace(spring, settings=spring.settings + Settings(
        Setting("damping", "number", "dashpot coefficient", default=0.0, minimum=0.0, unit="Pa s/m")))
    monkeypatch.setattr(participants, "_registered", {**participants.registered(), "spring_solid": changed})
    assert reference.main(["--check", str(copy)]) == 1
    assert "out of sync" in capsys.readouterr().err
    assert reference.main(["--write", str(copy)]) == 0
    assert reference.main(["--check", str(copy)]) == 0
    assert "| `damping` | `0.0` | number >= 0.0 [Pa s/m] | dashpot coefficient |" in copy.read_text()
    assert copy.read_text().split(reference.END)[1] == README.read_text().split(reference.END)[1]


def test_a_readme_without_the_markers_is_an_error():
    with pytest.raises(ValueError, match="notes.md: needs one '<!-- BEGIN"):
        reference.spliced("# notes\n", "notes.md")
