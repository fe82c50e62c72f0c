"""A minimal progress bar on stderr for long jobs (no dependency).

:func:`observe` lets a caller follow every bar of its process without drawing one: ``batch``
counts the frames a file has retargeted (and knows the frame a failure happened at) this way.
"""

from __future__ import annotations

import sys
import time
from contextlib import contextmanager
from typing import Callable, Iterator

from .errors import progress_enabled

#: Callbacks given every bar's state (:func:`observe`), in the order they were added.
_observers: list[Callable[["Progress"], None]] = []


@contextmanager
def observe(callback: Callable[["Progress"], None]) -> Iterator[None]:
    """Inside the block, call ``callback(bar)`` when any :class:`Progress` of this process
    starts and after each of its updates, drawn or not (``bar.label``, ``bar.done``,
    ``bar.total`` say where it is)."""
    _observers.append(callback)
    try:
        yield
    finally:
        _observers.remove(callback)


class Progress:
    """``with Progress(total, "retarget") as bar: bar.update(1)``; draws on stderr.

    Draws only when stderr is a terminal (or ``PHYSMOCAP_PROGRESS=1``), at most
    ten times a second, and always finishes with a summary line.  With ``tally`` (a unit,
    e.g. ``"frames"``) the bar also counts a second quantity with no known total
    (``update(tally=n)``) and shows its rate instead of the first one's.
    """

    def __init__(
        self, total: int, label: str, enabled: bool | None = None, unit: str = "frames", tally: str | None = None
    ) -> None:
        self.total = max(int(total), 1)
        self.label = label
        self.unit = unit
        self.tally_unit = tally
        self.enabled = progress_enabled() if enabled is None else enabled
        self.done = 0
        self.tally = 0
        self._t0 = time.perf_counter()
        self._last = 0.0

    def __enter__(self) -> "Progress":
        self._notify()
        return self

    def _notify(self) -> None:
        for callback in list(_observers):
            callback(self)

    def update(self, n: int = 1, tally: int = 0) -> None:
        """Count ``n`` more of the total (and ``tally`` more of the second quantity)."""
        self.done += n
        self.tally += tally
        self._notify()
        if not self.enabled:
            return
        now = time.perf_counter()
        if now - self._last < 0.1 and self.done < self.total:
            return
        self._last = now
        frac = min(self.done / self.total, 1.0)
        width = 30
        bar = "#" * int(frac * width) + "-" * (width - int(frac * width))
        sys.stderr.write(f"\r{self.label} [{bar}] {self.done}/{self.total} {self.unit}{self._counts(now - self._t0)}")
        sys.stderr.flush()

    def _counts(self, elapsed: float) -> str:
        """The rate (of the tally when there is one), with the tally before it."""
        if self.tally_unit is None:
            return f" ({self.done / max(elapsed, 1e-9):.0f}/s)"
        return f", {self.tally} {self.tally_unit} ({self.tally / max(elapsed, 1e-9):.0f} {self.tally_unit}/s)"

    def __exit__(self, *exc) -> None:
        if self.enabled:
            elapsed = time.perf_counter() - self._t0
            if self.tally_unit is None:
                counts = f" in {elapsed:.1f} s ({self.done / max(elapsed, 1e-9):.0f}/s)"
            else:
                counts = (f", {self.tally} {self.tally_unit} in {elapsed:.1f} s "
                          f"({self.tally / max(elapsed, 1e-9):.0f} {self.tally_unit}/s)")
            sys.stderr.write(f"\r{self.label}: {self.done}/{self.total} {self.unit}{counts}{' ' * 20}\n")
            sys.stderr.flush()
