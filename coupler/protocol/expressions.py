"""Expressions in x, y, z that scenes write for boundaries, loads and known solutions, e.g.
``"(z > 0.99) & (x < 0.5)"``: checked when the scene is read (names, syntax) and evaluated
by participants and checks on points with numpy; no attribute access, no builtins."""

from __future__ import annotations

import ast

import numpy as np

from coupler.errors import SceneError

#: names an ``exact`` expression may use besides x, y, z
FUNCTIONS = {name: getattr(np, name) for name in (
    "sin", "cos", "tan", "arcsin", "arccos", "arctan", "arctan2", "sinh", "cosh", "tanh", "exp", "log",
    "log10", "log2", "sqrt", "abs", "minimum", "maximum", "where", "hypot", "floor", "ceil", "sign", "clip")}
CONSTANTS = {"pi": np.pi, "e": np.e}
VARIABLES = ("x", "y", "z")


def check_expression(text: str, where: str) -> None:
    """Reject an ``exact`` expression that does not parse or uses other names
    than x, y, z and :data:`FUNCTIONS` / :data:`CONSTANTS` (no attributes)."""
    try:
        tree = ast.parse(text.strip(), mode="eval")
    except SyntaxError as exc:
        raise SceneError(f"{where}: invalid expression {text!r}: {exc.msg}") from None
    allowed = set(VARIABLES) | set(FUNCTIONS) | set(CONSTANTS)
    for node in ast.walk(tree):
        if isinstance(node, ast.Name) and node.id not in allowed:
            raise SceneError(f"{where}: unknown name {node.id!r} in {text!r}; use x, y, z, "
                             f"{', '.join(CONSTANTS)} and {', '.join(FUNCTIONS)}")
        if isinstance(node, ast.Attribute):
            raise SceneError(f"{where}: attribute access ('.{node.attr}') is not allowed in {text!r}")


def evaluate_expression(text: str, points: np.ndarray) -> np.ndarray:
    """Values of an expression in x, y, z (checked by :func:`check_expression`) at (n, 3) points."""
    # copies: an expression like sin(x, y) writes into its second argument (numpy's out=)
    x, y, z = (np.array(np.asarray(points)[:, d], dtype=np.float64) for d in range(3))
    namespace = {"__builtins__": {}, **FUNCTIONS, **CONSTANTS}
    with np.errstate(all="ignore"):
        value = eval(compile(text.strip(), "<exact>", "eval"), namespace, {"x": x, "y": y, "z": z})
    return np.broadcast_to(np.asarray(value, dtype=np.float64), x.shape).copy()
