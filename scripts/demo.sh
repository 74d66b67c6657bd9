#!/usr/bin/env bash
# Run the default case (installing first if needed): bash scripts/demo.sh [varcouple run args]
# Results are written under results/.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$ROOT/scripts/ensure_installed.sh"
# shellcheck source=scripts/env.sh
. "$ROOT/scripts/env.sh"
cd "$ROOT"

exec "$ROOT/.venv/bin/varcouple" run cases/small_fracture "$@"
