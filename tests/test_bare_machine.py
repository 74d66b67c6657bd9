"""Everything the project and its tests import is installed: scripts/install.sh brings it to a
bare Debian 12 machine (apt with --no-install-recommends, then pip), so a module that only a
developer's machine happens to have fails here and not first on CI.

The modules are found by reading every Python file of the project (top-level and
function-level imports); the libraries' own lazy imports that the project relies on are listed
in :data:`THROUGH_LIBRARIES`."""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

from vc_helpers import ROOT

SOURCES = ("transfer", "coupler", "solid_fenicsx", "fluid_openfoam", "nonsmooth", "bench", "tests", "cases")

#: imported only when present, and why that is fine
OPTIONAL = {"libsupermesh": "bench/transfer.py adds it to the comparison after `.venv/bin/pip install libsupermesh`"}

#: imported lazily by a library, for a feature the project uses (Debian package: apt-cache show)
THROUGH_LIBRARIES = {"h5py": "meshio's XDMF reader and writer (solid meshes; python3-h5py, a meshio Recommends)"}


def python_files() -> list[Path]:
    return sorted(p for d in SOURCES for p in (ROOT / d).rglob("*.py"))


def imports() -> dict[str, set[str]]:
    """Every module an absolute import statement names (``import a.b`` -> a.b; ``from a.b
    import c`` -> a.b, and a.b.c when c may be a submodule), with the files naming it."""
    found: dict[str, set[str]] = {}
    for path in python_files():
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0:
                names = [node.module] + [f"{node.module}.{a.name}" for a in node.names if a.name != "*"]
            else:
                continue
            for name in names:
                found.setdefault(name, set()).add(str(path.relative_to(ROOT)))
    return found


def local_modules() -> set[str]:
    """Top-level names the project itself provides: its packages and its scripts' modules."""
    return {p.name for p in ROOT.iterdir() if (p / "__init__.py").exists()} | {p.stem for p in python_files()}


def third_party() -> dict[str, set[str]]:
    skip = set(sys.stdlib_module_names) | local_modules()
    return {name: files for name, files in imports().items() if name.split(".")[0] not in skip}


def not_importable(names) -> dict[str, str]:
    """{module: error} for the names that cannot be imported, tried in a fresh interpreter (so
    that MPI, matplotlib's backend and the like start as in a run). ``a.b.c`` names that are
    attributes rather than submodules are fine when ``a.b`` imports."""
    code = """
import importlib, importlib.util, json, sys
bad = {}
for name in json.loads(sys.argv[1]):
    try:
        importlib.import_module(name)
    except ImportError as exc:
        parent, _, attr = name.rpartition(".")
        try:
            if not parent or not hasattr(importlib.import_module(parent), attr):
                bad[name] = repr(exc)
        except ImportError as exc2:
            bad[name] = repr(exc2)
print(json.dumps(bad))
"""
    out = subprocess.run([sys.executable, "-c", code, json.dumps(sorted(names))], capture_output=True, text=True,
                         timeout=300, cwd=ROOT)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout.splitlines()[-1])


def test_the_scan_finds_the_projects_dependencies():
    """Not vacuous: the scan sees the libraries the project is built on, and every optional
    module is still imported somewhere."""
    tops = {name.split(".")[0] for name in third_party()}
    assert {"numpy", "scipy", "meshio", "matplotlib", "gmsh", "dolfinx", "ufl", "petsc4py", "mpi4py",
            "zenoh", "pytest"} <= tops
    assert set(OPTIONAL) <= tops


def test_every_imported_module_is_installed():
    wanted = {name: files for name, files in third_party().items() if name.split(".")[0] not in OPTIONAL}
    bad = not_importable(wanted)
    assert not bad, "not installed (add its Debian package to APT_PACKAGES in scripts/install.sh):\n" + "\n".join(
        f"  {name}: {err} (imported by {', '.join(sorted(wanted[name])[:3])})" for name, err in sorted(bad.items()))


def test_the_libraries_lazy_imports_are_installed():
    bad = not_importable(THROUGH_LIBRARIES)
    assert not bad, "\n".join(f"  {name}: {err}; needed for {THROUGH_LIBRARIES[name]}" for name, err in bad.items())
