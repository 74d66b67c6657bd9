"""The import graph of the project (docs/architecture.md): no cycles, and every import goes
to the importer's own layer or a lower one. Top-level and function-level imports count."""

from __future__ import annotations

import ast
import importlib.util

from vc_helpers import ROOT

PACKAGES = ("transfer", "nonsmooth", "coupler", "solid_fenicsx", "fluid_openfoam", "fluid_chorin", "fluid_reynolds")

#: module prefix -> layer (the longest matching prefix wins); docs/architecture.md
LAYERS = {
    "transfer": 0, "nonsmooth": 0,
    "coupler.errors": 1, "coupler.protocol": 1, "coupler.coupling": 1,
    "solid_fenicsx": 2, "fluid_openfoam": 2, "fluid_chorin": 2, "fluid_reynolds": 2, "coupler.standins": 2,
    "coupler.scene": 3, "coupler.plan": 3, "coupler.fsi": 3, "coupler.checks": 3,
    "coupler.run": 4, "coupler.output": 4,
    "coupler.cli": 5, "coupler": 5,
}
#: participants may import these parts of the coupler, and nothing else of it
PARTICIPANT_MAY_IMPORT = ("coupler.errors", "coupler.protocol")
#: the participants' packages (the stand-ins are a module of the coupler)
PARTICIPANT_PACKAGES = ("solid_fenicsx", "fluid_openfoam", "fluid_chorin", "fluid_reynolds")
#: a participant's settings module (its declaration, read by the coupler) imports only these
#: (the declarations, the penalization keys every grid fluid shares, the slab cut of a grid on MPI ranks)
SETTINGS_MAY_IMPORT = {"coupler.errors", "coupler.protocol.settings", "coupler.protocol.penalization",
                       "coupler.protocol.slabs"}


def modules() -> dict[str, ast.Module]:
    found = {}
    for package in PACKAGES:
        for path in (ROOT / package).rglob("*.py"):
            parts = list(path.relative_to(ROOT).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts.pop()
            found[".".join(parts)] = (path, ast.parse(path.read_text()))
    return found


def _compiled(name: str) -> bool:
    """A compiled extension module (the kernels: built outside the source tree, no imports)."""
    try:
        spec = importlib.util.find_spec(name)
    except (ImportError, ValueError):
        return False
    return spec is not None and str(spec.origin).endswith(".so")


def imports(name: str, path, tree, known) -> set[str]:
    """The project modules `name` imports (resolving relative imports and `from a import b`
    where b is a module)."""
    out = set()
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    for node in ast.walk(tree):
        targets = []
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                base = ".".join(anchor + ([base] if base else []))
            targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in known or _compiled(f"{base}.{a.name}") else base
                       for a in node.names]
        for t in targets:
            if _compiled(t):
                continue
            while t and t not in known:
                t = t.rpartition(".")[0]
            if t and t != name:
                out.add(t)
    return out


def graph() -> dict[str, set[str]]:
    known = modules()
    return {name: imports(name, path, tree, known) for name, (path, tree) in known.items()}


def layer(module: str) -> int:
    best = max((p for p in LAYERS if module == p or module.startswith(p + ".")), key=len)
    return LAYERS[best]


def test_the_import_graph_has_no_cycles():
    g = graph()
    state, cycles = {}, []

    def visit(node, stack):
        state[node] = "open"
        stack.append(node)
        for nxt in sorted(g.get(node, ())):
            if state.get(nxt) == "open":
                cycles.append(stack[stack.index(nxt):] + [nxt])
            elif nxt not in state:
                visit(nxt, stack)
        stack.pop()
        state[node] = "done"

    for node in sorted(g):
        if node not in state:
            visit(node, [])
    assert not cycles, "import cycles:\n" + "\n".join(" -> ".join(c) for c in cycles)


def test_every_import_goes_to_the_same_or_a_lower_layer():
    upward = [f"{a} ({layer(a)}) -> {b} ({layer(b)})" for a, targets in graph().items() for b in targets
              if layer(b) > layer(a)]
    assert not upward, "imports of a higher layer:\n" + "\n".join(sorted(upward))


def test_participants_import_only_the_protocol_of_the_coupler():
    participants = (*PARTICIPANT_PACKAGES, "coupler.standins")
    wrong = [f"{a} -> {b}" for a, targets in graph().items() if a.startswith(participants) for b in targets
             if b.startswith("coupler") and not b.startswith(PARTICIPANT_MAY_IMPORT + participants)]
    assert not wrong, "\n".join(sorted(wrong))


def settings_module(module: str) -> bool:
    """A participant package's light settings module (``solid_fenicsx.settings``)."""
    return module in {f"{p}.settings" for p in PARTICIPANT_PACKAGES}


def test_the_coupler_imports_no_participant_but_its_settings():
    wrong = {f"{a} -> {b}" for a, targets in graph().items() if a.startswith("coupler")
             and not a.startswith("coupler.standins") for b in targets
             if b.startswith(PARTICIPANT_PACKAGES) and not settings_module(b)}
    assert not wrong, "\n".join(sorted(wrong))


def test_a_settings_module_imports_only_the_protocol_settings():
    """What the coupler reads of a participant pulls in no solver: its settings module imports
    the declarations' module and nothing else of the project (tests/coupler/test_participants.py
    checks the third-party side in a fresh interpreter)."""
    g = graph()
    found = sorted(m for m in g if settings_module(m))
    assert found == ["fluid_chorin.settings", "fluid_openfoam.settings", "fluid_reynolds.settings",
                     "solid_fenicsx.settings"]
    wrong = {f"{m} -> {b}" for m in found for b in g[m] if b not in SETTINGS_MAY_IMPORT}
    assert not wrong, "\n".join(sorted(wrong))
    assert g["coupler.protocol.settings"] <= {"coupler.errors"}
    assert g["coupler.protocol.penalization"] <= {"coupler.protocol.settings", "transfer.penalization"}
    assert not g["coupler.protocol.slabs"]


def test_the_scanner_sees_a_participant_import_other_than_settings():
    """The rule above is not vacuous: an import of a participant's solver module from the
    coupler would be flagged, an import of its settings module would not."""
    tree = ast.parse("from fluid_openfoam.settings import PARTICIPANT\nfrom fluid_openfoam.case import CaseSpec\n")
    found = imports("coupler.scene.x", ROOT / "coupler" / "scene" / "x.py", tree, modules())
    assert {b for b in found if not settings_module(b)} == {"fluid_openfoam.case"}


def test_the_graph_sees_function_level_imports():
    """A sanity check of the scanner: a known function-level import is an edge."""
    assert "coupler.protocol.server" in graph()["coupler.protocol.participant"]
