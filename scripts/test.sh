#!/usr/bin/env bash
# Run the test suite (installing first if needed): bash scripts/test.sh [pytest args]
#   bash scripts/test.sh             fast tests (pyproject: -m 'not slow')
#   bash scripts/test.sh -m slow     slow-marked tests (long benchmarks, large cases)
#   VARCOUPLE_INSTALL=1 bash scripts/test.sh   force a reinstall first
#   VARCOUPLE_TEST_WORKERS=1 bash scripts/test.sh   in one process (default: 2 pytest-xdist
#                                   workers, the tests of a file on one worker: its module
#                                   fixtures are shared runs)
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$ROOT/scripts/ensure_installed.sh"
# shellcheck source=scripts/env.sh
. "$ROOT/scripts/env.sh"
cd "$ROOT"

workers=()
if ((${VARCOUPLE_TEST_WORKERS:-2} > 1)); then
  workers=(-n "${VARCOUPLE_TEST_WORKERS:-2}" --dist loadfile)
fi
rc=0
"$ROOT/.venv/bin/python" -m pytest -q "${workers[@]}" "$@" || rc=$?
if ((rc == 5)); then
  echo "[varcouple] FAILED: pytest collected no tests (exit 5) for: pytest -q $*" >&2
fi
exit "$rc"
