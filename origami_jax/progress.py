"""A one-line text progress bar for long solves (stderr, updated in place)."""

from __future__ import annotations

import sys
import time
from typing import TextIO


class ProgressBar:
    """Shows nothing for the first ``delay`` seconds, then ``[####....] it 1200/5000 ...``."""

    def __init__(
        self,
        total: int,
        delay: float = 1.0,
        stream: TextIO | None = None,
        width: int = 24,
        unit: str = "it",
    ):
        self.total = max(int(total), 1)
        self.delay = delay
        self.stream = stream or sys.stderr
        self.width = width
        self.start = time.perf_counter()
        self.shown = False
        self.unit = unit

    def update(self, done: int, note: str = "") -> None:
        elapsed = time.perf_counter() - self.start
        if elapsed < self.delay:
            return
        frac = min(done / self.total, 1.0)
        bar = "#" * int(round(frac * self.width))
        line = f"\r[{bar:<{self.width}}] {done}/{self.total} {self.unit}  {elapsed:6.1f} s  {note}"
        self.stream.write(line.ljust(80))
        self.stream.flush()
        self.shown = True

    def close(self) -> None:
        if self.shown:
            self.stream.write("\n")
            self.stream.flush()
