"""Validation shared by the option dataclasses (one rule, one message format)."""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Iterable

from .errors import OptionError

__all__ = ["check_fields", "check_frame_range"]


def check_fields(
    obj: Any,
    what: str,
    *,
    signed: Iterable[str] = (),
    counts: Iterable[str] = (),
    positive: Iterable[str] = (),
    skip: Iterable[str] = (),
) -> None:
    """Refuse bad numbers in a dataclass of options.

    Every ``bool`` field must be a bool; every other numeric field a finite
    number, >= 0 unless named in ``signed``; fields in ``positive`` > 0;
    fields in ``counts`` whole numbers >= 0 (>= 1 if also in ``positive``).
    Fields in ``skip`` and non-numeric fields are not checked here.

    Raises:
        OptionError: ``"<what> option <name> must be ..., got <value>"``.
    """
    signed, counts, positive, skip = set(signed), set(counts), set(positive), set(skip)
    for f in dataclasses.fields(obj):
        name, v = f.name, getattr(obj, f.name)
        if name in skip:
            continue
        if f.type in ("bool", bool):
            if not isinstance(v, bool):
                raise OptionError(f"{what} option {name} must be true or false, got {v!r}")
            continue
        if f.type not in ("float", "int", float, int):
            continue
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise OptionError(f"{what} option {name} must be a finite number, got {v!r}")
        if name in counts and (v != int(v)):
            raise OptionError(f"{what} option {name} must be a whole number, got {v!r}")
        if name in positive and v <= 0:
            raise OptionError(f"{what} option {name} must be > 0, got {v!r}")
        if name not in signed and v < 0:
            raise OptionError(f"{what} option {name} must be >= 0, got {v!r}")


def check_frame_range(start: int | None, end: int | None) -> None:
    """``--start`` / ``--end`` (source frames, end exclusive) before any file is read:
    no negative frame, and a range that holds at least one frame."""
    if start is not None and start < 0:
        raise OptionError(f"--start must be a frame number >= 0, got {start}")
    if end is not None and end < 1:
        raise OptionError(f"--end must be a frame number >= 1 (it is exclusive), got {end}")
    if start is not None and end is not None and end <= start:
        raise OptionError(
            f"--start {start} --end {end}: the range is empty (--end is exclusive, so it must be "
            "greater than --start)"
        )
