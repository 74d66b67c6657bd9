#!/usr/bin/env bash
# Run scripts/install.sh when the install is missing or stale; used by test.sh and demo.sh.
# Installs when:
#   - VARCOUPLE_INSTALL=1, or
#   - .venv/bin/varcouple is missing, or the last install did not finish, or
#   - scripts/install.sh (its package list), pyproject.toml, CMakeLists.txt or anything under
#     transfer/_kernels/ or nonsmooth/_kernels/ changed since, or
#   - a Python module of the packages was added, moved or removed (the editable install maps
#     every module to its file: a moved one is not found until it is reinstalled).
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
STAMP="$ROOT/.venv/.varcouple-installed"
MODULES="$ROOT/.venv/.varcouple-modules"   # written by install.sh

reason=""
if [[ "${VARCOUPLE_INSTALL:-0}" == 1 ]]; then
  reason="VARCOUPLE_INSTALL=1"
elif [[ ! -x "$ROOT/.venv/bin/varcouple" ]]; then
  reason=".venv/bin/varcouple is missing"
elif [[ ! -e "$STAMP" ]]; then
  reason="the last install did not finish"
else
  watched=()
  for p in scripts/install.sh pyproject.toml CMakeLists.txt transfer/_kernels nonsmooth/_kernels; do
    [[ -e "$ROOT/$p" ]] && watched+=("$ROOT/$p")
  done
  if ((${#watched[@]})); then
    newer="$(find "${watched[@]}" -newer "$STAMP" -print -quit)"
    [[ -z "$newer" ]] || reason="${newer#"$ROOT"/} changed since the last install"
  fi
  if [[ -z "$reason" ]] && ! (cd "$ROOT" && bash scripts/install.sh --list-modules | cmp -s - "$MODULES"); then
    reason="Python modules were added, moved or removed since the last install"
  fi
fi

if [[ -n "$reason" ]]; then
  echo "[varcouple] installing: $reason"
  bash "$ROOT/scripts/install.sh"
fi
