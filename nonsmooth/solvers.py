"""The registry of nonsmooth solvers: name -> ``function(qp, x0=None, **options) -> Solution``.

``"active_set"`` (primal-dual active set, :mod:`.active_set`) and ``"snes_vi"``
(PETSc SNES VI, :mod:`.petsc`) are built in; other modules add theirs with
:func:`register` when imported (``"multilevel"``: :mod:`nonsmooth.multilevel`,
imported on first use).
"""

from __future__ import annotations

import importlib
from typing import Callable

from .active_set import solve_active_set
from .petsc import solve_snes_vi
from .problem import BoundConstrainedQP, Solution

SolverFunction = Callable[..., Solution]

SOLVERS: dict[str, SolverFunction] = {"active_set": solve_active_set, "snes_vi": solve_snes_vi}

#: solvers that live in modules of their own, imported when first asked for
_PROVIDERS = {"multilevel": "nonsmooth.multilevel"}


def register(name: str, function: SolverFunction) -> None:
    """Make a solver available under `name` (to :func:`solve` and scenes): ``function(qp, x0=...,
    monitor=..., **options)``, calling ``monitor(**values)`` (when not None) at each iteration."""
    SOLVERS[name] = function


def available() -> list[str]:
    """Names a scene may ask for."""
    return sorted(set(SOLVERS) | set(_PROVIDERS))


def get(method: str) -> SolverFunction:
    """The solver function of a name; ValueError naming the known ones."""
    if method not in SOLVERS and method in _PROVIDERS:
        try:
            importlib.import_module(_PROVIDERS[method])
        except ModuleNotFoundError as exc:
            raise ValueError(f"solver {method!r} is not available ({exc})") from exc
    if method not in SOLVERS:
        raise ValueError(f"unknown nonsmooth solver {method!r}; use one of {available()}")
    return SOLVERS[method]


def solve(qp: BoundConstrainedQP, method: str = "active_set", x0=None, monitor=None, **options) -> Solution:
    """Solve `qp` with the named solver; ``monitor(**values)``, when given, hears each of its
    iterations (every solver takes it: a caller's progress lines)."""
    return get(method)(qp, x0=x0, monitor=monitor, **options)
