"""A text progress bar for long runs, written to stderr (no dependency).

On a terminal the bar redraws one line (``\\r``)::

    coupling [###########-------------------]  37/100  37%  00:12 < 00:20  it=4 res=3.1e-07

On a terminal the status also follows the coupling iterations of the current step
(:meth:`ProgressBar.iteration`). When the stream is not a terminal (a log file, CI) and the
bar was asked for, it writes a plain line at every tenth of the run instead; when it was not
asked for (``enabled=None``) it stays silent there.
"""

from __future__ import annotations

import sys
import time


def format_seconds(seconds: float) -> str:
    """``mm:ss`` or ``h:mm:ss``; ``--:--`` when unknown."""
    if not seconds >= 0 or seconds == float("inf"):
        return "--:--"
    s = int(round(seconds))
    h, rem = divmod(s, 3600)
    m, s = divmod(rem, 60)
    return f"{h}:{m:02d}:{s:02d}" if h else f"{m:02d}:{s:02d}"


class ProgressBar:
    """Progress of `total` units of work (time steps).

    Parameters
    ----------
    total: number of units.
    label: text in front of the bar.
    stream: where to write (default ``sys.stderr``).
    enabled: ``True`` always writes, ``False`` never, ``None`` only on a terminal.
    width: characters of the bar.
    min_interval: seconds between two redraws on a terminal.
    """

    def __init__(self, total: int, label: str = "", stream=None, enabled: bool | None = None,
                 width: int = 30, min_interval: float = 0.1):
        self.total = max(int(total), 0)
        self.label = label
        self.stream = stream if stream is not None else sys.stderr
        isatty = getattr(self.stream, "isatty", None)
        self.dynamic = bool(isatty and isatty())
        self.enabled = self.dynamic if enabled is None else bool(enabled)
        self.width = int(width)
        self.min_interval = float(min_interval)
        self.count = 0
        self.status = ""
        self.start = time.perf_counter()
        self._last_draw = -float("inf")
        self._last_decile = -1
        self._line_length = 0
        self._closed = False

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False

    def line(self) -> str:
        """The text of the bar as it stands."""
        elapsed = time.perf_counter() - self.start
        fraction = self.count / self.total if self.total else 1.0
        fraction = min(max(fraction, 0.0), 1.0)
        filled = int(round(fraction * self.width))
        bar = "#" * filled + "-" * (self.width - filled)
        remaining = elapsed / self.count * (self.total - self.count) if self.count else float("inf")
        digits = len(str(self.total))
        text = (f"[{bar}] {self.count:>{digits}}/{self.total} {fraction * 100:3.0f}%  "
                f"{format_seconds(elapsed)} < {format_seconds(remaining)}")
        if self.label:
            text = f"{self.label} {text}"
        if self.status:
            text = f"{text}  {self.status}"
        return text

    def update(self, n: int = 1, status: str | None = None) -> None:
        """Advance by `n` units; `status` is a short text shown after the bar (e.g. iterations, residual)."""
        self.count += n
        if status is not None:
            self.status = status
        if not self.enabled or self._closed:
            return
        now = time.perf_counter()
        done = self.count >= self.total
        if self.dynamic:
            if done or now - self._last_draw >= self.min_interval:
                self._draw_dynamic()
                self._last_draw = now
        else:
            decile = int(10 * self.count / self.total) if self.total else 10
            if decile > self._last_decile:
                self._last_decile = decile
                self.stream.write(self.line() + "\n")
                self.stream.flush()

    def iteration(self, window: int, iteration: int, residual: float) -> None:
        """A coupling iteration of step `window` ended with this relative residual: shown live
        on a terminal (a plain line per step elsewhere, from :meth:`update`)."""
        self.status = f"step {window + 1}: iteration {iteration + 1}, residual {residual:.2e}"
        if self.enabled and self.dynamic and not self._closed:
            now = time.perf_counter()
            if now - self._last_draw >= self.min_interval:
                self._draw_dynamic()
                self._last_draw = now

    def _draw_dynamic(self) -> None:
        text = self.line()
        pad = max(self._line_length - len(text), 0)
        self.stream.write("\r" + text + " " * pad)
        self.stream.flush()
        self._line_length = len(text)

    def close(self) -> None:
        """Draw the final state and end the line (idempotent)."""
        if self._closed:
            return
        self._closed = True
        if not self.enabled:
            return
        if self.dynamic:
            self._draw_dynamic()
            self.stream.write("\n")
            self.stream.flush()
        elif self._last_decile < 10 and self.count > 0 and self.count < self.total:
            self.stream.write(self.line() + "  (stopped)\n")
            self.stream.flush()
