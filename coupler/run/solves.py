"""The inner solves of a time step, as the participants report them (docs/protocol.md,
``advance`` reply ``solves``), and what the run may claim from them.

A step is converged only when the coupling iteration converged *and* every inner solve
of its accepted iteration (the last one) converged, or was accepted unconverged on
purpose (``[solvers.X] allow_unconverged = true``, e.g. a deliberately capped steady
solve). Unconverged solves of earlier coupling iterations of the step are counted: they
only shaped an iterate that was not accepted.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

from coupler.errors import NotConverged
from coupler.protocol.wire import SolveReport


class InnerSolveNotConverged(NotConverged):
    """An inner solve of the accepted coupling iteration did not converge."""


@dataclass
class StepSolves:
    """The reports of one step: ``final[name]`` those of the accepted iteration,
    ``unconverged_before`` the unconverged ones of earlier iterations (count per participant)."""

    allow_unconverged: dict[str, bool]
    final: dict[str, list[SolveReport]] = field(default_factory=dict)
    final_iteration: int = 0
    unconverged_before: dict[str, int] = field(default_factory=dict)

    def add(self, name: str, iteration: int, reports: list[SolveReport]) -> None:
        """The reports of participant `name` in coupling iteration `iteration` (0, 1, ...)."""
        if iteration > self.final_iteration:  # the earlier iteration was not accepted
            for other, old in self.final.items():
                self.unconverged_before[other] = (self.unconverged_before.get(other, 0)
                                                  + sum(not r.converged for r in old))
            self.final, self.final_iteration = {}, iteration
        if self.allow_unconverged.get(name):
            reports = [replace(r, accepted=True) for r in reports]
        self.final[name] = list(reports)

    @property
    def failures(self) -> list[tuple[str, SolveReport]]:
        """(participant, report) of the accepted iteration's solves that did not converge and were not accepted."""
        return [(name, r) for name, reports in self.final.items() for r in reports if not r.ok]

    @property
    def accepted(self) -> list[tuple[str, SolveReport]]:
        """(participant, report) of the accepted iteration's solves accepted unconverged on purpose."""
        return [(name, r) for name, reports in self.final.items() for r in reports if r.accepted and not r.converged]

    @property
    def converged(self) -> bool:
        return not self.failures

    def as_dict(self) -> dict:
        """For the step's record in summary.json."""
        return {"inner_converged": self.converged,
                "solves": {name: [r.as_dict() for r in reports] for name, reports in self.final.items()},
                "unconverged_in_earlier_iterations": dict(self.unconverged_before),
                "accepted_unconverged": [f"{name}: {r.solver}" for name, r in self.accepted]}

    def error(self, step: int) -> InnerSolveNotConverged:
        """The error naming the participant, solver, step, iteration and residual of each failure,
        and where the first failure's limits are set (:func:`limits`)."""
        what = "; ".join(f"participant {name!r}: {r.describe()}" for name, r in self.failures)
        name, report = self.failures[0]
        return InnerSolveNotConverged(
            f"not converged in time step {step}, coupling iteration {self.final_iteration}: {what}. The step's "
            f"result is not trustworthy; raise the solver's iteration limit (max_iterations) or loosen its "
            f"tolerance in {limits(name, report.solver)}, or set [solvers.{name}] allow_unconverged = true to "
            f"accept it on purpose")


def limits(participant: str, solver: str) -> str:
    """The scene table holding a solver's iteration limit and tolerance: ``[contact]`` for the
    contact solvers, the platen's ``[[loads]]`` entry for its stress search, else ``[solvers.X]``."""
    if solver.startswith("contact"):
        return "[contact]"
    if solver == "platen":
        return "the platen's [[loads]] entry"
    return f"[solvers.{participant}]"
