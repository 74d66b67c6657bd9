# shellcheck shell=bash
# Runtime environment for varcouple, sourced by scripts/test.sh and scripts/demo.sh
# (docker/Dockerfile sets the same variables with ENV).
#   . scripts/env.sh

# Debian's OpenFOAM v1912 (package openfoam): solvers are on PATH, data lives here.
export WM_PROJECT_DIR="${WM_PROJECT_DIR:-/usr/share/openfoam}"
# Open MPI refuses to start as root without these (containers, CI).
export OMPI_ALLOW_RUN_AS_ROOT=1
export OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1

# The project's venv first on PATH, so processes started by the coupler (mpirun python ...)
# use the same interpreter and see the same packages.
_varcouple_venv_bin="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)/.venv/bin"
case ":$PATH:" in
  *":$_varcouple_venv_bin:"*) ;;
  *) export PATH="$_varcouple_venv_bin:$PATH" ;;
esac
unset _varcouple_venv_bin
