"""The ``[solvers.X]`` key reference of cases/README.md, generated from the declarations: the
coupler's keys (:func:`coupler.scene.participants.common`) and each registered participant's
own (its ``settings`` module). tests/coupler/test_reference.py fails when the README is out
of sync::

    .venv/bin/python -m coupler.scene.reference                          # print it
    .venv/bin/python -m coupler.scene.reference --write cases/README.md  # replace it between the markers
    .venv/bin/python -m coupler.scene.reference --check cases/README.md  # exit 1 when out of sync
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from coupler.protocol.settings import Setting, Settings
from coupler.scene.participants import DEFAULTS, common, for_role

BEGIN = ("<!-- BEGIN [solvers.X] reference: generated from the participants' declarations by "
         "`python -m coupler.scene.reference --write cases/README.md`; edit the declarations, not this text -->")
END = "<!-- END [solvers.X] reference -->"
ROLES = tuple(DEFAULTS)
_HEAD = "| key | default | type | meaning |\n| --- | --- | --- | --- |"


def _row(s: Setting, default: str | None = None, type_: str | None = None) -> str:
    meaning = s.description + (f" (only with {s.only.text})" if s.only else "")
    return (f"| `{s.name}` | {default or s.describe_default()} | {type_ or s.describe_type()} | "
            f"{meaning.replace('|', '/')} |")


def _common_table() -> str:
    keys = {role: common(role) for role in ROLES}
    first = keys[ROLES[0]]
    rows = []
    for s in first:
        if s.name == "participant":
            default = ", ".join(f"{role}: {keys[role]['participant'].describe_default()}" for role in ROLES)
            rows.append(_row(s, default, "string"))
        else:
            rows.append(_row(s))
    return "\n".join([_HEAD, *rows])


def _participant_table(settings: Settings) -> str:
    return "\n".join([_HEAD, *(_row(s) for s in settings)])


def reference() -> str:
    """The generated text (markdown, without the markers)."""
    out = ["### `[solvers.solid]`, `[solvers.fluid]`: the participants", "",
           "Every `[solvers.X]` table has the coupler's keys below; the participant it names declares the "
           "others (in its package's `settings.py`), and the table is validated through that declaration. A key "
           "that only another participant of the role declares is ignored, with a note in the plan (`varcouple "
           "check` prints it), so swapping a participant stays its `participant` line; any other unknown key is "
           "refused.", "", _common_table()]
    for role in ROLES:
        for kind, spec in for_role(role).items():
            command = " ".join(["python -m", spec.module, *spec.arguments])
            out += ["", f"#### `participant = \"{kind}\"` in `[solvers.{role}]`",
                    f"{spec.description[0].upper()}{spec.description[1:]}; started as `{command}`"
                    + (", one process: `ranks` are its solver's" if spec.own_ranks else "") + "."]
            out += ["", _participant_table(spec.settings) if len(spec.settings) else "No keys of its own."]
    return "\n".join(out) + "\n"


def spliced(text: str, where: str = "cases/README.md") -> str:
    """`text` with the part between :data:`BEGIN` and :data:`END` replaced by :func:`reference`."""
    if text.count(BEGIN) != 1 or text.count(END) != 1 or text.index(BEGIN) > text.index(END):
        raise ValueError(f"{where}: needs one '{BEGIN[:40]}...' line and one '{END}' line after it")
    head, rest = text.split(BEGIN)
    _, tail = rest.split(END)
    return f"{head}{BEGIN}\n{reference()}{END}{tail}"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m coupler.scene.reference", description=__doc__.split("\n\n")[0])
    group = parser.add_mutually_exclusive_group()
    group.add_argument("--write", metavar="FILE", type=Path, help="replace the reference in FILE")
    group.add_argument("--check", metavar="FILE", type=Path, help="exit 1 when FILE's reference is out of sync")
    args = parser.parse_args(argv)
    if args.write is None and args.check is None:
        sys.stdout.write(reference())
        return 0
    file = args.write or args.check
    text = file.read_text()
    new = spliced(text, str(file))
    if args.write is not None:
        if new != text:
            file.write_text(new)
        return 0
    if new != text:
        print(f"{file}: the [solvers.X] reference is out of sync with the declarations; run "
              f"python -m coupler.scene.reference --write {file}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
