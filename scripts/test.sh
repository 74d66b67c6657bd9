#!/usr/bin/env bash
# Run the test suite (installing first if needed): bash scripts/test.sh [pytest args]
#   bash scripts/test.sh             fast tests (pyproject: -m 'not slow')
#   bash scripts/test.sh -m slow     slow-marked tests (long benchmarks, large cases)
#   VARCOUPLE_INSTALL=1 bash scripts/test.sh   force a reinstall first
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$ROOT/scripts/ensure_installed.sh"
# shellcheck source=scripts/env.sh
. "$ROOT/scripts/env.sh"
cd "$ROOT"

rc=0
"$ROOT/.venv/bin/python" -m pytest -q "$@" || rc=$?
if ((rc == 5)); then
  echo "[varcouple] FAILED: pytest collected no tests (exit 5) for: pytest -q $*" >&2
fi
exit "$rc"
