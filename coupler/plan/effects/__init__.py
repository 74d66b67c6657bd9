"""The effect rules: one module per effect a scene may ask for (``[physics] effects``).

A rule module defines ``NAME``, ``DESCRIPTION``, ``ORDER`` (rules apply in increasing order:
the one that creates a participant before those that configure it) and ``plan(scene,
plan)``, which adds to the :class:`~coupler.plan.plan.Plan` what the effect needs:
participants, exchanges, loads, notes; optionally ``TABLES``, ``TIME_STEPS``, ``ROLES``,
``DOMAINS``, ``NEEDS``, ``in_process_cells`` and ``parse`` (docs/architecture.md). Adding an effect is adding a module here (and what
its participant must do); :data:`RULES` finds every module of this package.
"""

from __future__ import annotations

import importlib
import pkgutil


def _discover() -> dict:
    modules = [importlib.import_module(f"{__name__}.{m.name}") for m in pkgutil.iter_modules(__path__)]
    return {m.NAME: m for m in sorted(modules, key=lambda m: (m.ORDER, m.NAME))}


#: effect name -> rule module, in the order the rules apply
RULES = _discover()
