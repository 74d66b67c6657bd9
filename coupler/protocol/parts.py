"""The coupler's side of the parts of a participant (docs/protocol.md, "Parts"): the arrays each
rank of a participant publishes for its own vertices or cells, joined into the arrays of the
whole participant, and the inputs split into each rank's rows.

A part of ``geometry`` numbers its rows by global ids: ``point_ids`` (the input ids of the
part's vertices; ``points`` holds their coordinates in that order) and ``cell_ids`` (its cells;
``cells`` holds them with input vertex ids). Every field of ``advance`` has one row per id of
the participant's field location (``point_ids``, or ``cell_ids`` when the geometry header says
``"location": "cells"``), in that order. A part may add ``input_ids``: the rows of every input
it needs (default: its field ids), e.g. a ghost layer. Any other geometry array (the wetted
triangles) is concatenated in rank order and its rows sorted by their sorted entries, an order
that does not depend on the partition. Joining checks that the ids of all parts number each row
of the whole exactly once, and every part's rows: a part that does not is rejected naming the
participant, the rank and its key.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import ProtocolError
from .wire import Field

#: geometry arrays placed by ids: array -> its ids
PLACED = {"points": "point_ids", "cells": "cell_ids"}
IDS = ("point_ids", "cell_ids", "input_ids")


@dataclass
class Part:
    """One rank's reply: its rank, the key it came on, its header and arrays."""

    rank: int
    key: str
    header: dict
    fields: dict

    def fail(self, participant: str, text: str) -> ProtocolError:
        return ProtocolError(f"participant {participant!r}, rank {self.rank} ({self.key}): {text}")


def _numbering(participant: str, parts: list[Part], name: str) -> tuple[int, list[np.ndarray]] | None:
    """(count, ids of each part) for ids array `name`, checked to number 0..count-1 once each;
    None when no part has it."""
    have = [name in p.fields for p in parts]
    if not any(have):
        return None
    ids = []
    for p in parts:
        if name not in p.fields:
            raise p.fail(participant, f"its geometry part has no {name!r} (rank 0's has)")
        a = np.asarray(p.fields[name].data)
        if a.ndim != 1 or a.dtype.kind not in "iu":
            raise p.fail(participant, f"{name!r} must be a 1-d integer array, got {a.dtype} of shape {a.shape}")
        ids.append(a.astype(np.int64))
    count = sum(len(a) for a in ids)
    seen = np.zeros(count, np.int64)
    for p, a in zip(parts, ids):
        if len(a) and (a.min() < 0 or a.max() >= count):
            bad = a[(a < 0) | (a >= count)][0]
            raise p.fail(participant, f"{name!r} holds {bad}, outside 0..{count - 1} ({count} rows in all parts)")
        np.add.at(seen, a, 1)
    if np.any(seen != 1):
        twice = np.flatnonzero(seen > 1)
        owners = [p.rank for p, a in zip(parts, ids) if np.isin(twice[:1], a).any()]
        raise parts[owners[-1]].fail(participant, f"{name!r} of ranks {owners} both hold id {twice[0]} "
                                                  f"({len(twice)} ids given twice): each row must have one owner")
    return count, ids


def _place(participant: str, part: Part, name: str, ids: np.ndarray, out: np.ndarray | None, count: int):
    a = np.asarray(part.fields[name].data)
    if a.shape[:1] != ids.shape:
        raise part.fail(participant, f"{name!r} has {a.shape[0] if a.ndim else 0} rows, its ids {len(ids)}")
    if out is None:
        out = np.empty((count, *a.shape[1:]), a.dtype)
    elif a.shape[1:] != out.shape[1:] or a.dtype != out.dtype:
        raise part.fail(participant, f"{name!r} is {a.dtype} of shape {a.shape}, rank 0's rows "
                                     f"{out.dtype} of shape {out.shape[1:]}")
    out[ids] = a
    return out


def canonical_rows(a: np.ndarray) -> np.ndarray:
    """The rows of an integer array sorted by their sorted entries (a partition-independent order)."""
    if a.ndim != 2 or len(a) == 0:
        return a
    key = np.sort(a, axis=1)
    return a[np.lexsort(key.T[::-1])]


class Layout:
    """How the rows of a participant's fields are spread over its parts (from its geometry)."""

    def __init__(self, participant: str, count: int, ids: list[np.ndarray], inputs: list[np.ndarray], keys: list[str]):
        self.participant, self.count, self.ids, self.inputs, self.keys = participant, count, ids, inputs, keys

    @property
    def parts(self) -> int:
        return len(self.ids)

    @classmethod
    def join_geometry(cls, participant: str, parts: list[Part]) -> tuple["Layout | None", dict[str, Field]]:
        """The layout (None: the parts carry no ids) and the geometry arrays of the whole."""
        location = "cell_ids" if parts[0].header.get("location") == "cells" else "point_ids"
        numbered = {name: _numbering(participant, parts, name) for name in ("point_ids", "cell_ids")}
        if numbered[location] is None:
            if len(parts) > 1:
                raise parts[0].fail(participant, f"{len(parts)} parts, but its geometry gives no {location!r}: "
                                                 f"the rows of its fields have no owners")
            return None, dict(parts[0].fields)
        out: dict[str, Field] = {}
        for name, ids_name in PLACED.items():
            if numbered[ids_name] is None or name not in parts[0].fields:
                continue
            count, ids = numbered[ids_name]
            whole = None
            for p, a in zip(parts, ids):
                if name not in p.fields:
                    raise p.fail(participant, f"its geometry part has no {name!r} (rank 0's has)")
                whole = _place(participant, p, name, a, whole, count)
            out[name] = Field(name, whole, parts[0].fields[name].units)
        for name, f in parts[0].fields.items():
            if name in IDS or name in PLACED:
                continue
            rows = []
            for p in parts:
                if name not in p.fields:
                    raise p.fail(participant, f"its geometry part has no {name!r} (rank 0's has)")
                rows.append(np.asarray(p.fields[name].data))
            out[name] = Field(name, canonical_rows(np.concatenate(rows)), f.units)
        count, ids = numbered[location]
        inputs = []
        for p, a in zip(parts, ids):
            given = p.fields.get("input_ids")
            need = a if given is None else np.asarray(given.data, np.int64)
            if len(need) and (need.min() < 0 or need.max() >= count):
                raise p.fail(participant, f"'input_ids' reach outside 0..{count - 1}")
            inputs.append(need)
        return cls(participant, count, ids, inputs, [p.key for p in parts]), out

    def split(self, fields: dict[str, Field]) -> list[dict[str, Field]]:
        """Each part's inputs: the rows of its ``input_ids`` of every field of one row per id; a
        field of another length (a single value, e.g. an inlet pressure) goes whole to every part."""
        out = [{} for _ in self.ids]
        for name, f in fields.items():
            data = np.asarray(f.data)
            for rows, part in zip(self.inputs, out):
                part[name] = Field(name, data[rows] if data.shape[:1] == (self.count,) else data, f.units)
        return out

    def join(self, parts: list[Part]) -> dict[str, Field]:
        """The whole of each output field from the parts' rows (each in its ids' order)."""
        names = list(parts[0].fields)
        out = {}
        for p in parts[1:]:
            if list(p.fields) != names:
                raise p.fail(self.participant, f"its fields {sorted(p.fields)} are not rank 0's {sorted(names)}")
        for name in names:
            whole = None
            for p, ids in zip(parts, self.ids):
                whole = _place(self.participant, p, name, ids, whole, self.count)
            out[name] = Field(name, whole, parts[0].fields[name].units)
        return out
