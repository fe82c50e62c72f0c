"""TRC marker files (OpenSim / Motion Analysis text format), tab- or comma-separated.

Line 1 ``PathFileType``; line 2 the header names, line 3 their values (``DataRate``,
``NumFrames``, ``NumMarkers``, ``Units``...); line 4 ``Frame# Time`` then each marker's
label above its three columns; line 5 the ``X1 Y1 Z1`` row; then one row per frame.
Empty cells are missing samples.  A file that declares more frames than it holds is read
as far as it goes, with a warning; a cell that is not a number is an error naming its
line and marker.  ``load_motion`` gives the solved actor
skeleton (:mod:`physmocap.markers`; its joint centres with ``solve=False``).
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from ..errors import InputError, warn
from ..markers.recording import UNITS, MarkerRecording, unique_labels, unit_scale

__all__ = ["read_trc_markers"]

#: Largest file read whole (bytes): a TRC of a long take stays well below.
MAX_BYTES = 2_000_000_000


def _split(line: str, sep: str) -> list[str]:
    return [c.strip() for c in line.rstrip("\r\n").split(sep)]


def _lines(numbers: list[int], shown: int = 5) -> str:
    """Line numbers for a message: the first ``shown``, then how many more."""
    text = ", ".join(str(n) for n in numbers[:shown])
    return text + (f" and {len(numbers) - shown} more" if len(numbers) > shown else "")


def read_trc_markers(path: str | os.PathLike, units: str | float | None = None) -> MarkerRecording:
    """The labelled markers of a TRC file (metres, the file's axes).

    ``units`` overrides the header's ``Units`` (a unit name of
    :data:`~physmocap.markers.recording.UNITS` or metres per file unit)."""
    p = Path(path)
    if not p.is_file():
        raise InputError("file not found", path=p)
    if p.stat().st_size > MAX_BYTES:
        raise InputError(f"file larger than {MAX_BYTES} bytes", path=p)
    try:
        lines = p.read_text(encoding="utf-8", errors="replace").splitlines()
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror}", path=p) from None
    if len(lines) < 5 or not lines[0].startswith("PathFileType"):
        raise InputError("not a TRC file (line 1 must start with PathFileType and 5 header lines follow)", path=p,
                         line=1)
    sep = "\t" if "\t" in lines[0] else ","
    keys, values = _split(lines[1], sep), _split(lines[2], sep)
    head = {k: v for k, v in zip(keys, values) if k}
    try:
        rate = float(head.get("DataRate") or head.get("CameraRate") or "nan")
    except ValueError:
        rate = math.nan
    if not (math.isfinite(rate) and 0 < rate < 1e6):
        raise InputError(f"DataRate must be a positive number, got {head.get('DataRate')!r}", path=p, line=3)
    unit = (head.get("Units") or "mm").strip().lower()
    if units is not None:
        scale = unit_scale(units, p)
    elif unit not in UNITS:
        raise InputError(f"unknown Units {unit!r}; expected one of {', '.join(UNITS)} "
                         "(or give the unit with --in-units)", path=p, line=3)
    else:
        scale = UNITS[unit]
    names = _split(lines[3], sep)[2:]
    while names and not names[-1]:
        names.pop()
    if not names:
        raise InputError("no marker labels", path=p, line=4)
    stray = next((k for k, n in enumerate(names) if n and k % 3), None)
    if stray is not None:
        raise InputError(f"label {names[stray][:40]!r} is in column {stray + 3}, not at the first of a "
                         "marker's three columns (a label is missing or a column is extra before it)", path=p, line=4)
    labels = unique_labels([names[k] or f"marker{k // 3}" for k in range(0, len(names), 3)], f"{p}:4")
    M = len(labels)
    rows: list[list[float]] = []
    short: list[int] = []
    long: list[int] = []
    for ln, line in enumerate(lines[5:], start=6):
        if not line.strip() or not line.replace(sep, "").strip():
            continue
        cells = _split(line, sep)
        vals = cells[2 : 2 + 3 * M]
        if len(vals) < 3 * M:
            short.append(ln)
            vals = vals + [""] * (3 * M - len(vals))
        if any(cells[2 + 3 * M :]):
            long.append(ln)
        row = []
        for k, cell in enumerate(vals):
            if cell == "" or cell.lower() == "nan":
                row.append(math.nan)
                continue
            try:
                v = float(cell)
            except ValueError:
                raise InputError(f"marker {labels[k // 3]} {'XYZ'[k % 3]} is not a number: {cell[:20]!r}", path=p,
                                 line=ln) from None
            if not math.isfinite(v) or abs(v) > 1e9:
                raise InputError(f"marker {labels[k // 3]} {'XYZ'[k % 3]} is out of range: {cell[:20]!r}", path=p, line=ln)
            row.append(v)
        rows.append(row)
    if not rows:
        raise InputError("no data rows after the header", path=p)
    declared = head.get("NumFrames")
    if declared and declared.isdigit() and int(declared) != len(rows):
        warn(f"{p}: the header declares {declared} frames but the file holds {len(rows)}; read what is there")
    if short:
        warn(f"{p}: {len(short)} row(s) end early (line {_lines(short)}); their missing markers are gaps")
    if long:
        warn(f"{p}: {len(long)} row(s) hold more values than the {M} markers of line 4 (line {_lines(long)}); "
             "the extra values are ignored")
    pos = np.array(rows, dtype=float).reshape(len(rows), M, 3) * scale
    pos[np.all(pos == 0.0, axis=2)] = np.nan
    if not np.isfinite(pos).any():
        raise InputError("every marker sample is missing", path=p)
    return MarkerRecording(labels=tuple(labels), positions=pos, fps=rate, source=p)
