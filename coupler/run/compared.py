"""What ``varcouple study`` measures each run's error with: the scene's ``[check]``, a field's
relative L2 difference from the reference run (``--field participant.field``: the run's field
carried onto the reference's mesh by L2 projection, paper eq. 1-3, measured with the reference
mesh's mass matrix), or a per-step number of ``summary.json`` (``--figure``, a dotted path
such as ``fracture.hydraulic_aperture``): |f - f_ref| / |f_ref| at each time step of the
reference. The reference is the most accurate run: the largest cost, among equal costs the
longest.

What is compared is checked before any run against each run's plan (the participants, the
fields that cross between them, the plan's per-step figures), and what the plan cannot name
in advance (a participant's own output field or figure) on the first run that wrote it,
before the next run starts."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from coupler.errors import SceneError
from coupler.fsi.monitors import MONITORS
from coupler.output.results import read_summary
from coupler.run.projection import project
from transfer import TransferError
from transfer.meshfile import MeshFile

#: the study's default without a [check], --field or --figure
DEFAULT_FIELD = "solid.displacement"
REFERENCE = "the reference run (the largest cost; among equal costs the longest)"


def last_file(directory: Path, participant: str) -> Path | None:
    """The last VTU file of `participant`'s series in a run's directory."""
    files = sorted(directory.glob(f"{participant}_[0-9][0-9][0-9][0-9].vtu"))
    return files[-1] if files else None


def difference(file: Path, reference: Path, name: str) -> float | None:
    """||u - u_ref|| / ||u_ref|| in L2 on the reference's mesh: the field `name` of `file`
    carried there by L2 projection (taken as is when both files have the same mesh), the norm
    that of the reference's mass matrix over the dofs the projection covers. None when the
    reference field is zero."""
    run, ref = MeshFile.read(file), MeshFile.read(reference)
    u, u_ref = run.field(name), ref.field(name)
    space = ref.space(u_ref.kind)
    same = (run.mesh.cells.shape == ref.mesh.cells.shape and np.array_equal(run.mesh.cells, ref.mesh.cells)
            and np.array_equal(run.mesh.points, ref.mesh.points))
    if same:
        values, covered = u.values, np.ones(space.num_dofs, bool)
    else:
        p = project(u, run.space(u.kind), space, "l2")
        values, covered = p.values, p.covered
    mass = space.mass_matrix()[covered][:, covered]
    d = (values - u_ref.values)[covered].reshape(int(covered.sum()), -1)
    r = u_ref.values[covered].reshape(int(covered.sum()), -1)
    norm = float(np.sum(r * (mass @ r)))
    return float(np.sqrt(max(float(np.sum(d * (mass @ d))), 0.0) / norm)) if norm > 0 else None


def figure(step: dict, path: str):
    """The value at the dotted `path` of a step's record; KeyError naming the part not found
    and what its table has instead."""
    node, seen = step, []
    for part in path.split("."):
        if not isinstance(node, dict) or part not in node:
            where = ".".join(seen) or "the step's record"
            has = sorted(node) if isinstance(node, dict) else f"a value ({node!r}), not a table"
            raise KeyError(f"{where} has no {part!r} (it has {has})")
        node, seen = node[part], seen + [part]
    return node


def _number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def figure_errors(steps: list[dict], reference: list[dict], path: str) -> list[float | None]:
    """Per step of the `reference` run: |f - f_ref| / |f_ref| of the figure at `path` of the run's
    step at the same time t (None where the run has no such step or figure, or f_ref is 0)."""
    out = []
    for ref in reference:
        f_ref = _value(ref, path)
        f = next((_value(s, path) for s in steps if math.isclose(s["t"], ref["t"], rel_tol=1e-9, abs_tol=1e-15)),
                 None)
        out.append(None if f is None or not f_ref else abs(f - f_ref) / abs(f_ref))
    return out


def reference(runs: list[dict]) -> dict | None:
    """The most accurate of the completed runs: the largest cost, among equal costs the longest."""
    done = [run for run in runs if run["status"] == "completed" and run.get("cost")]
    return max(done, key=lambda run: (run["cost"]["cells"], run["seconds"]["total"])) if done else None


@dataclass
class Compared:
    """What the study compares: ``kind`` "check" (the scene's [check]), "field" or "figure",
    ``name`` the field (``participant.field``) or the figure's dotted path; ``pending`` while
    what the plan could not name in advance is still to be found in a run's outputs."""

    kind: str
    name: str = ""
    pending: bool = True

    @classmethod
    def of(cls, field: str | None, figure_path: str | None, check: str | None) -> "Compared":
        """From the options (--figure, else --field, else the scene's [check], else the default
        field); SceneError for both options given or a name that is no path."""
        if field is not None and figure_path is not None:
            raise SceneError(f"--field {field} and --figure {figure_path}: give one of them (the error of a "
                             f"run is measured on one quantity)")
        if figure_path is not None:
            if any(not part for part in figure_path.split(".")):
                raise SceneError(f"--figure {figure_path!r}: give the dotted path of a number in each step of "
                                 f"summary.json, e.g. fracture.hydraulic_aperture or max_displacement")
            return cls("figure", figure_path)
        if field is None and check:
            return cls("check", check, pending=False)
        name = field or DEFAULT_FIELD
        if name.count(".") < 1 or any(not part for part in name.split(".", 1)):
            raise SceneError(f"--field {name!r}: give participant.field, e.g. {DEFAULT_FIELD}")
        return cls("field", name)

    @property
    def option(self) -> str:
        return f"--{self.kind} {self.name}"

    def check_plan(self, plan, where: str) -> None:
        """SceneError unless the plan of a run (`where` names it) can produce what is compared;
        ``pending`` cleared when the plan alone shows it will."""
        if self.kind == "field":
            participant, name = self.name.split(".", 1)
            self._participant(plan, participant, where)
            crossing = {f for e in plan.exchanges for f in (*e.sources, e.target)}
            self.pending = self.pending and self.name not in crossing
        elif self.kind == "figure":
            parts = self.name.split(".")
            if parts[0] in MONITORS and parts[0] not in plan.monitors:
                raise SceneError(f"{self.option}: {where}: the plan has no per-step {parts[0]!r} figures (its "
                                 f"per-step figures: {', '.join(plan.monitors) or 'none'}; varcouple check prints "
                                 f"the plan)")
            if parts[0] in plan.monitors and len(parts) == 1:
                raise SceneError(f"{self.option}: a table of figures, not a number: name one of them "
                                 f"({parts[0]}.NAME)")
            if parts[0] == "figures":
                if len(parts) < 3:
                    raise SceneError(f"{self.option}: give figures.PARTICIPANT.NAME, e.g. figures.solid.stress")
                self._participant(plan, parts[1], where)

    def _participant(self, plan, participant: str, where: str) -> None:
        names = [p.name for p in plan.participants]
        if participant not in names:
            raise SceneError(f"{self.option}: {where}: the plan has no participant {participant!r} (it has "
                             f"{', '.join(names) or 'none'})")

    def check_run(self, directory: Path, summary: dict, name: str) -> None:
        """SceneError unless run `name` (its directory and summary) has what is compared, found
        on its first step (a figure) or its last output file (a field); ``pending`` cleared once
        found. A run that wrote no step or file leaves it pending."""
        if not self.pending:
            return
        if self.kind == "figure":
            steps = summary.get("steps") or []
            if not steps:
                return
            try:
                value = figure(steps[0], self.name)
            except KeyError as exc:
                raise SceneError(f"{self.option}: not in {name}'s summary.json, step 0: {exc.args[0]}") from None
            if not _number(value):
                kind = f"a table ({', '.join(sorted(value))})" if isinstance(value, dict) else repr(value)
                raise SceneError(f"{self.option}: {name}'s summary.json, step 0: {kind} is not a number")
        else:
            participant, field = self.name.split(".", 1)
            file = last_file(directory, participant)
            if file is None:
                return
            try:
                MeshFile.read(file).field(field)
            except TransferError as exc:
                raise SceneError(f"{self.option}: {exc}") from None
        self.pending = False

    def errors(self, study: dict, directory: Path) -> None:
        """Each run's ``error`` and the study's ``error`` (what it is against)."""
        runs = study["runs"]
        if self.kind == "check":
            study["error"] = {"against": f"the scene's [check] (kind {self.name})"}
            for run in runs:
                run["error"] = run["check"]["error"] if run.get("check") else None
            return
        ref = reference(runs)
        if ref is None:
            study["error"] = {"against": "no completed run to compare with", self.kind: self.name}
            return
        study["error"] = {"against": REFERENCE, "reference": ref["name"], self.kind: self.name}
        if self.kind == "field":
            study["error"]["norm"] = "relative L2 on the reference's mesh, the field carried there by L2 projection"
            participant, name = self.name.split(".", 1)
            ref_file = last_file(directory / ref["directory"], participant)
            for run in runs:
                file = last_file(directory / run["directory"], participant)
                run["error"] = None if run["status"] != "completed" or file is None or ref_file is None else \
                    difference(file, ref_file, name)
            return
        study["error"]["norm"] = "|f - f_ref| / |f_ref| at each step of the reference; error: the largest"
        ref_steps = _steps(directory / ref["directory"])
        study["error"]["t"] = [s["t"] for s in ref_steps]
        for run in runs:
            steps = _steps(directory / run["directory"])
            run["figure"] = [_value(s, self.name) for s in steps]
            run["errors"] = figure_errors(steps, ref_steps, self.name) if run["status"] == "completed" else \
                [None] * len(ref_steps)
            found = [e for e in run["errors"] if e is not None]
            run["error"] = max(found) if found else None


def _value(step: dict, path: str):
    try:
        value = figure(step, path)
    except KeyError:
        return None
    return value if _number(value) else None


def _steps(directory: Path) -> list[dict]:
    return read_summary(directory).get("steps", [])
