"""What a marker file holds: labelled marker trajectories (metres, the file's axes).

A sample is *valid* only where the file says it is (finite coordinates, not all zero, a
non-negative residual where the format has residuals); invalid samples are NaN and never
used.  Subject prefixes (``Daphnee:LSHO``) are kept in :attr:`MarkerRecording.labels`
and stripped by :func:`plain_label`.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError

__all__ = ["MarkerRecording", "plain_label", "unique_labels", "UNITS", "unit_scale"]

#: Length unit name -> metres.
UNITS = {"mm": 1e-3, "cm": 1e-2, "dm": 0.1, "m": 1.0, "in": 0.0254, "inch": 0.0254, "inches": 0.0254, "ft": 0.3048}


def unit_scale(units: str | float, path: str | Path | None = None) -> float:
    """Metres per file unit for a unit given by the user: a name of :data:`UNITS` or a
    positive number (metres per unit)."""
    from ..errors import OptionError

    if isinstance(units, str) and units.strip().lower() in UNITS:
        return UNITS[units.strip().lower()]
    try:
        v = float(units)
    except (TypeError, ValueError):
        v = float("nan")
    if not (np.isfinite(v) and v > 0):
        raise OptionError(f"unknown marker unit {units!r}; use one of {', '.join(UNITS)} or metres per unit as a number",
                          path=path)
    return v


def plain_label(label: str) -> str:
    """A marker label without subject prefix, case or punctuation: ``"Daphnee:L_SHO"`` -> ``"LSHO"``."""
    base = label.rsplit(":", 1)[-1]
    return re.sub(r"[^A-Za-z0-9]", "", base).upper()


def unique_labels(labels: "list[str] | tuple[str, ...]", where: str) -> list[str]:
    """``labels`` with repeats told apart: the first of each keeps the label (and so its role),
    the later ones become ``LABEL#2``, ``LABEL#3``...; one warning, prefixed by ``where``
    (``"FILE:4"``), names every repeated label and its marker numbers (1-based), since which
    copy is the real marker cannot be known (``--marker-set`` can give the role to a copy)."""
    from ..errors import warn
    from .markerset import ALIASES

    out = list(labels)
    seen: dict[str, list[int]] = {}
    for i, lab in enumerate(out):
        seen.setdefault(lab, []).append(i)
    repeated = {lab: idx for lab, idx in seen.items() if len(idx) > 1}
    if not repeated:
        return out
    taken = set(out)
    for lab, idx in repeated.items():
        n = 1
        for i in idx[1:]:
            n += 1
            while f"{lab}#{n}" in taken:
                n += 1
            out[i] = f"{lab}#{n}"
            taken.add(out[i])
    names = "; ".join(f"{lab} (markers {', '.join(str(i + 1) for i in idx)})" for lab, idx in repeated.items())
    first = next(iter(repeated))
    warn(f"{where}: repeated marker label(s): {names}; the first of each keeps the label and its role, the others "
         f"are renamed {', '.join(out[i] for lab, idx in repeated.items() for i in idx[1:])} and play none "
         f'(to use another copy, a --marker-set file can name it, e.g. {ALIASES.get(plain_label(first), "ROLE")} = "{out[repeated[first][1]]}")')
    return out


@dataclass(frozen=True)
class MarkerRecording:
    """Labelled marker trajectories.

    Attributes:
        labels: ``(M,)`` marker labels as in the file.
        positions: ``(F, M, 3)`` metres in the file's axes, NaN where invalid.
        fps: Frame rate (Hz).
        source: The file.
        first_frame: The file's number of the first frame.
    """

    labels: tuple[str, ...]
    positions: np.ndarray
    fps: float
    source: Path
    first_frame: int = 0

    def __post_init__(self) -> None:
        P = self.positions
        if P.ndim != 3 or P.shape[2] != 3 or P.shape[1] != len(self.labels):
            raise InputError(f"marker array must be (frames, {len(self.labels)}, 3), got {P.shape}", path=self.source)
        if P.shape[0] == 0 or P.shape[1] == 0:
            raise InputError("no frames or no markers", path=self.source)
        if not (np.isfinite(self.fps) and self.fps > 0):
            raise InputError(f"frame rate must be positive, got {self.fps}", path=self.source)

    @property
    def num_frames(self) -> int:
        return int(self.positions.shape[0])

    @property
    def valid(self) -> np.ndarray:
        """``(F, M)`` True where a marker sample is usable."""
        return np.all(np.isfinite(self.positions), axis=2)

    def frames(self, start: int | None = None, end: int | None = None) -> "MarkerRecording":
        """Frames ``[start, end)`` (``--start`` / ``--end``: end exclusive, the file's first
        frame shifted); an :class:`~physmocap.errors.OptionError` naming the file when the
        range is not inside the recording."""
        from ..errors import OptionError

        F = self.num_frames
        s = 0 if start is None else int(start)
        e = F if end is None else int(end)
        if not 0 <= s < e <= F:
            raise OptionError(f"frame range [{s}, {e}) is not inside the recording, which has frames 0 to {F - 1} "
                              "(--start is inclusive, --end exclusive)", path=self.source)
        if (s, e) == (0, F):
            return self
        return MarkerRecording(self.labels, self.positions[s:e], self.fps, self.source, self.first_frame + s)

    def gaps(self) -> dict[str, int]:
        """Marker label -> number of invalid frames (markers with any)."""
        missing = (~self.valid).sum(axis=0)
        return {lab: int(n) for lab, n in zip(self.labels, missing) if n}
