"""What a benchmark does last: print its lines and save its figures as JSON (bench/results/)."""

from __future__ import annotations

import json
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def finish(result: dict, lines: list[str], out: Path) -> dict:
    """Print `lines`, write `result` to `out` (numbers numpy gives as floats) and say where; `result`."""
    print("\n".join(lines))
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=2, default=float))
    print(f"written {out.relative_to(ROOT) if out.resolve().is_relative_to(ROOT) else out}")
    return result
