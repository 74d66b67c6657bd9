#!/usr/bin/env bash
# Take a fresh Debian 12 machine to a working varcouple install:
#   1. Debian packages (OpenFOAM, dolfinx, MPI, numpy/scipy/..., compilers) via apt;
#   2. a venv at <repo>/.venv that sees Debian's Python packages (--system-site-packages);
#   3. the build tools (scikit-build-core, nanobind, pytest) and the project itself,
#      editable, with the C++ kernels (re)built on every run; tamaas, the half-space
#      contact reference of a test and a bench (without its declared numpy>=2).
#
# Safe to run again: apt is skipped when every package is already installed, the venv
# is reused, and only the project (C++ extension included) is rebuilt.
#
# numpy, scipy, meshio, matplotlib, mpi4py, petsc4py must stay Debian's: dolfinx 0.5.2
# is built against Debian's numpy 1.24. pip is held to the installed versions by a
# constraints file computed here from the system interpreter, and the result is checked.
#
# Usage: bash scripts/install.sh [--system-only | --list-modules]
#   --system-only   only the apt step (used by docker/Dockerfile to cache that layer)
#   --list-modules  print the packages' Python modules (the editable install maps each one;
#                   ensure_installed.sh reinstalls when the list changes)
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="$ROOT/.venv"
SYSTEM_PYTHON=/usr/bin/python3
STAMP="$VENV/.varcouple-installed"       # touched after a successful install
CONSTRAINTS="$VENV/debian-constraints.txt"

APT_PACKAGES=(
  openfoam
  python3-dolfinx python3-mpi4py python3-petsc4py
  python3-scipy python3-numpy python3-meshio python3-vtk9 python3-matplotlib python3-gmsh
  python3-h5py    # meshio's XDMF needs it; only a Recommends of python3-meshio
  libegl1 libosmesa6   # offscreen pictures: PyPI's vtk wheel renders through EGL, no X server
  chromium         # the report page is tested in a real headless browser
  python3-venv python3-dev python3-pip
  build-essential cmake ninja-build git
)
# Python distributions that must come from Debian (pinned for pip to what is installed).
DEBIAN_PY_DISTS=(numpy scipy meshio matplotlib h5py mpi4py petsc4py slepc4py
                 fenics-dolfinx fenics-basix fenics-ffcx fenics-ufl)

log() { printf '[install] %s\n' "$*"; }
die() { printf '[install] ERROR: %s\n' "$*" >&2; exit 1; }

list_modules() {
  (cd "$ROOT" && find transfer coupler solid_fenicsx fluid_openfoam fluid_reynolds nonsmooth -name '*.py' \
     -not -path '*/__pycache__/*' | LC_ALL=C sort)
}

system_only=0
for arg in "$@"; do
  case "$arg" in
    --list-modules) list_modules; exit 0 ;;
    --system-only) system_only=1 ;;
    -h|--help) sed -n '2,/^set -euo/p' "${BASH_SOURCE[0]}" | sed '$d; s/^# \{0,1\}//'; exit 0 ;;
    *) die "unknown argument: $arg (see --help)" ;;
  esac
done

t_start=$SECONDS

# ---------------------------------------------------------------- 1. apt
if [[ -r /etc/debian_version ]]; then
  case "$(cat /etc/debian_version)" in
    12*|bookworm*) ;;
    *) log "warning: written for Debian 12, this is Debian $(cat /etc/debian_version)" ;;
  esac
else
  log "warning: not a Debian system; the apt step will probably fail"
fi

missing=()
for pkg in "${APT_PACKAGES[@]}"; do
  status="$(dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null || true)"
  [[ "$status" == "install ok installed" ]] || missing+=("$pkg")
done

if ((${#missing[@]} == 0)); then
  log "apt: all ${#APT_PACKAGES[@]} Debian packages already installed, skipping apt"
else
  log "apt: installing ${#missing[@]} missing package(s): ${missing[*]}"
  command -v apt-get >/dev/null || die "apt-get not found: this script needs Debian 12"
  as_root=()
  if ((EUID != 0)); then
    command -v sudo >/dev/null || die "not root and no sudo: run as root or install sudo"
    as_root=(sudo)
  fi
  "${as_root[@]}" apt-get update
  "${as_root[@]}" env DEBIAN_FRONTEND=noninteractive \
    apt-get install -y --no-install-recommends "${missing[@]}"
  for pkg in "${missing[@]}"; do
    status="$(dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null || true)"
    [[ "$status" == "install ok installed" ]] || die "apt did not install $pkg"
  done
fi

if ((system_only)); then
  log "system packages done (--system-only) in $((SECONDS - t_start))s"
  exit 0
fi

[[ -x "$SYSTEM_PYTHON" ]] || die "$SYSTEM_PYTHON not found (python3-venv should have installed it)"

# ---------------------------------------------------------------- 2. venv
venv_ok() {
  [[ -x "$VENV/bin/python" && -r "$VENV/pyvenv.cfg" ]] || return 1
  grep -qiE '^include-system-site-packages *= *true' "$VENV/pyvenv.cfg" || return 1
  # It must be a venv of Debian's interpreter (not e.g. a pyenv one), and still work.
  local want got
  want="$("$SYSTEM_PYTHON" -c 'import sys; print(sys.base_prefix, sys.version_info[:2])')"
  got="$("$VENV/bin/python" -c 'import sys; print(sys.base_prefix, sys.version_info[:2])' 2>/dev/null)" || return 1
  [[ "$want" == "$got" ]]
}

new_venv=0
if [[ -e "$VENV" ]] && ! venv_ok; then
  log "venv: $VENV is not a --system-site-packages venv of $SYSTEM_PYTHON, recreating it"
  rm -rf "$VENV"
fi
if [[ ! -e "$VENV" ]]; then
  log "venv: creating .venv (--system-site-packages, $SYSTEM_PYTHON)"
  "$SYSTEM_PYTHON" -m venv --system-site-packages "$VENV"
  new_venv=1
else
  log "venv: reusing .venv"
fi

export PIP_DISABLE_PIP_VERSION_CHECK=1 PIP_NO_INPUT=1 PIP_PROGRESS_BAR=off
pip() { "$VENV/bin/python" -m pip "$@"; }

if ((new_venv)) || [[ ! -e "$STAMP" ]]; then   # first install into this venv
  pip install --upgrade pip
fi

# Pin Debian's Python packages to their installed versions, so that pip can never
# upgrade or shadow them (a conflicting requirement then fails loudly instead).
"$SYSTEM_PYTHON" - "${DEBIAN_PY_DISTS[@]}" >"$CONSTRAINTS" <<'EOF'
import importlib.metadata as md
import sys
for name in sys.argv[1:]:
    try:
        print(f"{name}=={md.version(name)}")
    except md.PackageNotFoundError:
        pass
EOF
grep -q '^numpy==' "$CONSTRAINTS" || die "Debian's numpy is not visible to $SYSTEM_PYTHON"
log "pip: holding Debian packages at $(tr '\n' ' ' <"$CONSTRAINTS")"

# ---------------------------------------------------------------- 3. build deps + project
# pytest>=8: the venv gets its own pytest rather than Debian's 7.2 (python3-pytest is on
# some machines and not others), so every machine runs the tests with the same one.
log "pip: build and test dependencies"
pip install -c "$CONSTRAINTS" 'scikit-build-core>=0.10' 'nanobind>=2.0' 'pytest>=8'

log "pip: building and installing varcouple (editable, C++ kernels rebuilt)"
t_build=$SECONDS
(cd "$ROOT" && pip install -c "$CONSTRAINTS" --no-build-isolation -e '.[test]')
log "pip: project built in $((SECONDS - t_build))s"

# tamaas: the periodic elastic half-space contact solver, the reference of bench/halfspace.py
# and tests/solid_fenicsx/test_contact_halfspace.py (bench and test only). Its 2.9 wheel
# declares numpy>=2 but runs on Debian's numpy 1.24 (pybind11, no numpy C API), so it is
# installed without its declared dependencies (and under the constraints holding Debian's numpy,
# so that pip refuses rather than fetches numpy 2 should --no-deps ever go) and checked by
# importing it beside dolfinx; the numpy check below proves numpy is still Debian's.
log "pip: tamaas (half-space reference for the rough-contact test, --no-deps)"
pip install -c "$CONSTRAINTS" --no-deps 'tamaas==2.9.*'
"$VENV/bin/python" -c 'import dolfinx, tamaas' 2>/dev/null \
  || die "tamaas does not import beside dolfinx on Debian's numpy: $("$VENV/bin/python" -c 'import dolfinx, tamaas' 2>&1 | tail -1)"

# ---------------------------------------------------------------- checks + summary
# numpy must be Debian's, imported from the system site packages, never from the venv.
np_check="$("$VENV/bin/python" - "$CONSTRAINTS" <<'EOF'
import sys, sysconfig, numpy
want = next(l.split("==")[1].strip() for l in open(sys.argv[1]) if l.startswith("numpy=="))
venv_site = sysconfig.get_paths()["purelib"]
if numpy.__file__.startswith(venv_site) or numpy.__version__ != want:
    print(f"numpy {numpy.__version__} from {numpy.__file__}, expected Debian's {want}")
EOF
)"
[[ -z "$np_check" ]] || die "pip changed numpy: $np_check"

py_ver="$("$VENV/bin/python" -c 'import platform; print(platform.python_version())')"
np_ver="$("$VENV/bin/python" -c 'import numpy; print(numpy.__version__)')"
dolfinx_ver="$("$VENV/bin/python" -c 'import dolfinx; print(dolfinx.__version__)' 2>/dev/null)" \
  || dolfinx_ver="NOT IMPORTABLE"
if cli_out="$("$VENV/bin/varcouple" --help 2>/dev/null)" && [[ -n "$cli_out" ]]; then
  cli="${cli_out%%$'\n'*}"
else
  cli="not ready"
fi

list_modules >"$VENV/.varcouple-modules"
touch "$STAMP"
log "done in $((SECONDS - t_start))s: python $py_ver, numpy $np_ver, dolfinx $dolfinx_ver; varcouple --help: $cli"
