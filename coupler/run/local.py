"""Participants served inside the coupler process: the same :class:`~coupler.protocol.participant.Participant`
interface and the same client verbs as a participant process (:class:`coupler.run.client.ParticipantClient`),
called directly instead of over zenoh.

The runner serves a planned participant this way when the plan says ``in_process`` (light
participants that solve nothing: a fixed solid, mesh files; :mod:`coupler.standins`). Its
configuration goes through JSON as it would over the wire; its replies are checked like the
wire's (outputs finite, names matching); an exception of the participant is its error reply
(:class:`~coupler.protocol.errors.ParticipantError`). Inputs are handed over as they are: a
mesh file receives NaN where a transfer did not reach it (documented by the operators that
deliver NaN), which the wire would refuse to carry.

A coupler on P ranks (:mod:`coupler.run.ranks`) serves such a participant on every rank, its
handler bound to that coupler rank (rank r of P): the participant has P parts, coupler rank r
holds part r, and :meth:`LocalClient.exchange` answers the part verbs (``geometry``,
``advance``) as :meth:`coupler.run.client.ParticipantClient.exchange` does for a participant
process's ranks (docs/protocol.md, "Parts"), with nothing sent between the ranks.
"""

from __future__ import annotations

import json
import os
import time

from coupler.protocol.errors import InputError, ParticipantError, ParticipantInputError
from coupler.protocol.parts import Layout, Part
from coupler.protocol.wire import Field, SolveReport, as_fields, check_finite
from transfer.errors import FieldError


class LocalClient:
    """The coupler's handle on a participant object in this process (see module doc)."""

    def __init__(self, name: str, handler):
        self.name, self.handler = name, handler
        self.finished = False
        self.layout = None
        self.last_solves: list[SolveReport] = []
        self.last_figures: dict[str, float] = {}
        self.stats = {"calls": 0, "seconds": 0.0, "remote_seconds": 0.0, "bytes_out": 0, "bytes_in": 0,
                      "shm_out": 0, "shm_in": 0}

    def _call(self, verb: str, *args):
        start = time.perf_counter()
        try:
            return getattr(self.handler, verb)(*args)
        except Exception as exc:  # noqa: BLE001 - a participant's failure is its error reply, as over the wire
            error = ParticipantInputError if isinstance(exc, InputError) else ParticipantError
            raise error(self.name, f"{type(exc).__name__}: {exc}") from exc
        finally:
            elapsed = time.perf_counter() - start
            self.stats["calls"] += 1
            self.stats["seconds"] += elapsed
            self.stats["remote_seconds"] += elapsed

    def wait_alive(self, timeout: float | None = None) -> None:
        """Nothing to wait for: the participant lives in this process."""

    def announce(self, timeout: float | None = None) -> dict:
        size = self.handler.size
        return {"name": self.name, "pid": os.getpid(), "ranks": size, "parts": size, "in_process": True,
                **(self._call("announce") or {})}

    def configure(self, config, timeout: float | None = None) -> None:
        self._call("configure", json.loads(json.dumps(dict(config))))

    def geometry(self, timeout: float | None = None) -> tuple[dict, dict[str, Field]]:
        header, fields = self._call("geometry")
        part = Part(0, "in process", dict(header or {}), {f.name: f for f in as_fields(fields)})
        self.layout, joined = Layout.join_geometry(self.name, [part])
        return part.header, joined

    def advance(self, window: int, iteration: int, t: float, dt: float, inputs=None,
                timeout: float | None = None) -> dict[str, Field]:
        inputs = {f.name: f for f in as_fields(inputs)}
        if self.layout is not None:  # the participant's rows in its order (ids from its geometry)
            inputs = self.layout.split(inputs)[0]
        fields = self._advanced(window, iteration, t, dt, inputs)
        if self.layout is not None:
            fields = self.layout.join([Part(0, "in process", {}, fields)])
        return self._checked(fields)

    def _advanced(self, window: int, iteration: int, t: float, dt: float, inputs: dict) -> dict[str, Field]:
        """The handler's outputs of one advance; its reports kept in ``last_solves``, ``last_figures``."""
        out = self._call("advance", int(window), int(iteration), float(t), float(dt), inputs)
        solves, figures = self.handler.take_reports()
        self.last_solves, self.last_figures = list(solves), {str(k): float(v) for k, v in figures.items()}
        return {f.name: f for f in as_fields(out)}

    def _checked(self, fields: dict[str, Field]) -> dict[str, Field]:
        for f in fields.values():
            try:
                check_finite(f.name, f.data)
            except FieldError as exc:  # what the participant's own encoding refuses over the wire
                raise ParticipantError(self.name, f"{type(exc).__name__}: {exc}") from None
        return fields

    def exchange(self, verb: str, header, parts: list, timeout: float | None = None,
                 before_root=None) -> list[Part]:
        """This coupler rank's part of `verb` (``geometry`` or ``advance`` with ``parts[rank]``, the
        inputs at its part's rows), as a one-part reply list like a participant process's
        (:meth:`coupler.run.client.ParticipantClient.exchange`; `before_root`, the coupler ranks'
        vote, runs first). The advance reply's header carries the solves and figures as the wire's."""
        if before_root is not None:
            before_root()
        rank = self.handler.rank
        if verb == "geometry":
            reply, fields = self._call("geometry")
            reply, fields = dict(reply or {}), {f.name: f for f in as_fields(fields)}
        else:  # advance
            h = header
            fields = self._checked(self._advanced(h["window"], h["iteration"], h["t"], h["dt"], parts[rank] or {}))
            reply = {"solves": [s.as_dict() for s in self.last_solves], "figures": dict(self.last_figures)}
        return [Part(rank, "in process", reply, fields)]

    def save_state(self, window: int, timeout: float | None = None) -> None:
        self._call("save_state", int(window))

    def restore_state(self, window: int, timeout: float | None = None) -> None:
        self._call("restore_state", int(window))

    def finish(self, timeout: float | None = None) -> None:
        self._call("finish")
        self.finished = True
