"""A minimal progress bar on stderr for long jobs (no dependency)."""

from __future__ import annotations

import sys
import time

from .errors import progress_enabled


class Progress:
    """``with Progress(total, "retarget") as bar: bar.update(1)``; draws on stderr.

    Draws only when stderr is a terminal (or ``PHYSMOCAP_PROGRESS=1``), at most
    ten times a second, and always finishes with a summary line.
    """

    def __init__(self, total: int, label: str, enabled: bool | None = None, unit: str = "frames") -> None:
        self.total = max(int(total), 1)
        self.label = label
        self.unit = unit
        self.enabled = progress_enabled() if enabled is None else enabled
        self.done = 0
        self._t0 = time.perf_counter()
        self._last = 0.0

    def __enter__(self) -> "Progress":
        return self

    def update(self, n: int = 1) -> None:
        self.done += n
        if not self.enabled:
            return
        now = time.perf_counter()
        if now - self._last < 0.1 and self.done < self.total:
            return
        self._last = now
        frac = min(self.done / self.total, 1.0)
        width = 30
        bar = "#" * int(frac * width) + "-" * (width - int(frac * width))
        rate = self.done / max(now - self._t0, 1e-9)
        sys.stderr.write(f"\r{self.label} [{bar}] {self.done}/{self.total} {self.unit} ({rate:.0f}/s)")
        sys.stderr.flush()

    def __exit__(self, *exc) -> None:
        if self.enabled:
            elapsed = time.perf_counter() - self._t0
            sys.stderr.write(
                f"\r{self.label}: {self.done}/{self.total} {self.unit} in {elapsed:.1f} s"
                f" ({self.done / max(elapsed, 1e-9):.0f}/s){' ' * 20}\n"
            )
            sys.stderr.flush()
