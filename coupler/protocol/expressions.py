"""Expressions in x, y, z that scenes write for boundaries, loads and known solutions, e.g.
``"(z > 0.99) & (x < 0.5)"``: checked when the scene is read (names, syntax, size, constants)
and evaluated by participants and checks on points with numpy; no attribute access, no builtins.

Numbers are floats: an integer constant is evaluated as a float, so no expression does integer
arithmetic of unbounded size (``10**10**10``). The check bounds what an expression may cost:
at most :data:`MAX_LENGTH` characters, :data:`MAX_NODES` syntax nodes nested at most
:data:`MAX_DEPTH` deep, only arithmetic, comparisons and calls of :data:`FUNCTIONS`, and every
part without x, y, z (its constants folded) a finite number."""

from __future__ import annotations

import ast
import math
import operator

import numpy as np

from coupler.errors import SceneError

#: names an ``exact`` expression may use besides x, y, z
FUNCTIONS = {name: getattr(np, name) for name in (
    "sin", "cos", "tan", "arcsin", "arccos", "arctan", "arctan2", "sinh", "cosh", "tanh", "exp", "log",
    "log10", "log2", "sqrt", "abs", "minimum", "maximum", "where", "hypot", "floor", "ceil", "sign", "clip")}
CONSTANTS = {"pi": np.pi, "e": np.e}
VARIABLES = ("x", "y", "z")

#: the largest expression accepted: characters, syntax nodes, nesting depth
MAX_LENGTH = 2000
MAX_NODES = 500
MAX_DEPTH = 50
#: operators on numbers and boolean masks (no shifts: not float operations)
BINARY = {ast.Add: operator.add, ast.Sub: operator.sub, ast.Mult: operator.mul, ast.Div: operator.truediv,
          ast.FloorDiv: operator.floordiv, ast.Mod: operator.mod, ast.Pow: operator.pow,
          ast.BitAnd: None, ast.BitOr: None, ast.BitXor: None}
UNARY = {ast.USub: operator.neg, ast.UAdd: operator.pos, ast.Invert: None}
#: the syntax an expression may use
ALLOWED = (ast.Expression, ast.BinOp, ast.UnaryOp, ast.Compare, ast.Call, ast.Name, ast.Constant, ast.keyword,
           ast.Load, ast.cmpop, *BINARY, *UNARY)


def _shown(text: str, limit: int = 60) -> str:
    """`text` quoted for a message, cut to its first `limit` characters."""
    text = " ".join(text.split())
    return repr(text) if len(text) <= limit else f"{text[:limit]!r}... ({len(text)} characters)"


def _depth(tree: ast.AST) -> int:
    """The nesting depth of `tree` (iterative: a deep tree costs no recursion)."""
    deepest, stack = 0, [(tree, 1)]
    while stack:
        node, depth = stack.pop()
        deepest = max(deepest, depth)
        stack.extend((child, depth + 1) for child in ast.iter_child_nodes(node))
    return deepest


def _fold(node: ast.AST, text: str, where: str):
    """The value of `node` as a float when it holds no name (its constants folded), else None;
    SceneError naming the part whose value is not a finite number. Recursive: called only on
    trees at most :data:`MAX_DEPTH` deep."""
    children = [_fold(child.value if isinstance(child, ast.keyword) else child, text, where)
                for child in ast.iter_child_nodes(node) if isinstance(child, (ast.expr, ast.keyword))]
    if isinstance(node, (ast.BinOp, ast.UnaryOp)) and type(node.op) in (ast.BitAnd, ast.BitOr, ast.BitXor, ast.Invert) \
            and any(child is not None for child in children):
        raise SceneError(f"{where}: & | ^ ~ combine conditions (comparisons), not numbers, in {_shown(text)}")
    if isinstance(node, ast.Constant):
        value = node.value
    elif isinstance(node, ast.BinOp) and BINARY[type(node.op)] and None not in children:
        try:
            value = BINARY[type(node.op)](*children)
        except OverflowError:
            value = math.inf
        except ZeroDivisionError:
            raise SceneError(f"{where}: {_shown(ast.get_source_segment(text, node) or text)} divides by zero "
                             f"in {_shown(text)}") from None
    elif isinstance(node, ast.UnaryOp) and UNARY[type(node.op)] and None not in children:
        value = UNARY[type(node.op)](*children)
    else:
        return None
    if isinstance(value, complex):  # a negative number to a fractional power: NaN, as numpy gives it
        return None
    value = float(value)
    if not math.isfinite(value):
        part = ast.get_source_segment(text, node) or text
        raise SceneError(f"{where}: {_shown(part)} is not a finite number (beyond {np.finfo(float).max:.3g}) "
                         f"in {_shown(text)}")
    return value


def check_expression(text: str, where: str) -> None:
    """Reject an ``exact`` expression that does not parse, uses other names than x, y, z and
    :data:`FUNCTIONS` / :data:`CONSTANTS` or other syntax than arithmetic, comparisons and
    calls, is larger than the bounds of the module, or has a constant part that is not a
    finite number."""
    text = text.strip()
    if len(text) > MAX_LENGTH:
        raise SceneError(f"{where}: expression of {len(text)} characters {_shown(text)}; at most {MAX_LENGTH}")
    try:
        tree = ast.parse(text, mode="eval")
    except SyntaxError as exc:
        raise SceneError(f"{where}: invalid expression {_shown(text)}: {exc.msg}") from None
    except (RecursionError, MemoryError):
        raise SceneError(f"{where}: expression {_shown(text)} is nested too deeply to parse") from None
    allowed = set(VARIABLES) | set(FUNCTIONS) | set(CONSTANTS)
    nodes = 0
    for node in ast.walk(tree):
        nodes += 1
        if isinstance(node, ast.Name) and node.id not in allowed:
            raise SceneError(f"{where}: unknown name {node.id!r} in {_shown(text)}; use x, y, z, "
                             f"{', '.join(CONSTANTS)} and {', '.join(FUNCTIONS)}")
        if isinstance(node, ast.Attribute):
            raise SceneError(f"{where}: attribute access ('.{node.attr}') is not allowed in {_shown(text)}")
        if isinstance(node, ast.Call) and not (isinstance(node.func, ast.Name)  # (an unknown name: said below)
                                               and (node.func.id in FUNCTIONS or node.func.id not in allowed)):
            raise SceneError(f"{where}: only the functions {', '.join(FUNCTIONS)} may be called, in {_shown(text)}")
        if isinstance(node, ast.Constant) and (isinstance(node.value, bool)
                                               or not isinstance(node.value, (int, float))):
            raise SceneError(f"{where}: {node.value!r} is not a number, in {_shown(text)}")
        if not isinstance(node, ALLOWED):
            raise SceneError(f"{where}: {type(node).__name__} is not allowed in an expression ({_shown(text)}): "
                             f"use numbers, x, y, z, arithmetic, comparisons, the functions and & | ~ (not and, "
                             f"or, not)")
    if nodes > MAX_NODES:
        raise SceneError(f"{where}: expression of {nodes} terms and operators {_shown(text)}; at most {MAX_NODES}")
    depth = _depth(tree)
    if depth > MAX_DEPTH:
        raise SceneError(f"{where}: expression nested {depth} deep {_shown(text)}; at most {MAX_DEPTH}")
    _fold(tree.body, text, where)


class _Floats(ast.NodeTransformer):
    """Integer constants as floats: arithmetic on them stays bounded."""

    def visit_Constant(self, node: ast.Constant) -> ast.Constant:
        return ast.copy_location(ast.Constant(float(node.value)), node) if type(node.value) is int else node


def evaluate_expression(text: str, points: np.ndarray) -> np.ndarray:
    """Values of an expression in x, y, z (checked by :func:`check_expression`) at (n, 3) points."""
    # copies: an expression like sin(x, y) writes into its second argument (numpy's out=)
    x, y, z = (np.array(np.asarray(points)[:, d], dtype=np.float64) for d in range(3))
    namespace = {"__builtins__": {}, **FUNCTIONS, **CONSTANTS}
    tree = ast.fix_missing_locations(_Floats().visit(ast.parse(text.strip(), mode="eval")))
    with np.errstate(all="ignore"):
        value = eval(compile(tree, "<exact>", "eval"), namespace, {"x": x, "y": y, "z": z})
    return np.broadcast_to(np.asarray(value, dtype=np.float64), x.shape).copy()
