"""One field carried from a source mesh to a target mesh by :class:`transfer.Transfer`."""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass

import numpy as np

from transfer import FunctionSpace, OverlapWarning, Transfer
from transfer.meshfile import MeshFileField


@dataclass
class Projection:
    """A transferred field and what it cost."""

    method: str
    operator: Transfer
    values: np.ndarray  # target dof values, trailing shape of the source field, NaN where uncovered
    assembly_seconds: float  # wall time of Transfer.assemble (search, clipping, integration, solver set-up)
    apply_seconds: float
    conservation_error: float

    @property
    def covered(self) -> np.ndarray:
        return self.operator.covered

    @property
    def covered_fraction(self) -> float:
        return self.operator.covered_fraction

    @property
    def uncovered(self) -> int:
        return int(np.count_nonzero(~self.operator.covered))

    @property
    def kernel_seconds(self) -> float:
        return float(self.operator.stats.get("assembly_seconds", float("nan")))


def project(field: MeshFileField, source: FunctionSpace, target: FunctionSpace, method: str, *,
            quadrature_degree: int | None = None, threads: int = 1) -> Projection:
    """Assemble ``T`` from `source` to `target` with `method` and apply it to `field`.
    Overlap warnings are not issued but left in ``operator.warnings`` for the caller to report."""
    start = time.perf_counter()
    with warnings.catch_warnings(action="ignore", category=OverlapWarning):
        operator = Transfer.assemble(source, target, method, quadrature_degree=quadrature_degree,
                                     nthreads=threads)
    assembly = time.perf_counter() - start
    u = field.flat
    start = time.perf_counter()
    v = operator(u)
    apply = time.perf_counter() - start
    conservation = operator.conservation_error(u, v)
    values = v.reshape((target.num_dofs,) + field.values.shape[1:])
    return Projection(method, operator, values, assembly, apply, conservation)
