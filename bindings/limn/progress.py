"""A small terminal progress bar (stderr), shown only when stderr is a terminal."""
from __future__ import annotations

import sys
import time


class ProgressBar:
    def __init__(self, label: str, stream=None, width: int = 30):
        self.label, self.width = label, width
        self.stream = stream or sys.stderr
        self.enabled = hasattr(self.stream, "isatty") and self.stream.isatty()
        self.start = time.perf_counter()
        self._last = -1.0

    def __call__(self, fraction: float) -> bool:
        if self.enabled and (fraction >= 1.0 or fraction - self._last >= 0.01):
            self._last = fraction
            filled = int(round(self.width * fraction))
            elapsed = time.perf_counter() - self.start
            eta = elapsed * (1.0 - fraction) / fraction if fraction > 0 else 0.0
            self.stream.write(f"\r{self.label} [{'#' * filled}{'.' * (self.width - filled)}] {100 * fraction:5.1f}% "
                              f"{elapsed:6.1f}s elapsed, {eta:5.1f}s left ")
            self.stream.flush()
        return True

    def close(self) -> None:
        if self.enabled:
            self.stream.write("\n")
            self.stream.flush()
