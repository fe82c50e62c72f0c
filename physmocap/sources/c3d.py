"""C3D marker files, read with ``ezc3d`` (the pure-Python ``c3d`` package rejects some real files).

Point labels (``POINT:LABELS`` and ``LABELS2``...), units (``POINT:UNITS``), rate
(``POINT:RATE``); a sample is invalid where its residual is negative, its coordinates
are not finite or all exactly zero.  Analog channels are ignored.  ``load_motion`` gives the
solved actor skeleton (:mod:`physmocap.markers`; its joint centres with ``solve=False``).
"""

from __future__ import annotations

import os
import struct
from pathlib import Path

import numpy as np

from ..errors import InputError, warn
from ..markers.recording import UNITS, MarkerRecording, unique_labels, unit_scale

__all__ = ["read_c3d_markers"]


def read_c3d_markers(path: str | os.PathLike, units: str | float | None = None) -> MarkerRecording:
    """The labelled markers of a C3D file (metres, the file's axes).

    ``units`` overrides the file's ``POINT:UNITS`` (a unit name of
    :data:`~physmocap.markers.recording.UNITS` or metres per file unit)."""
    p = Path(path)
    try:
        import ezc3d
    except ImportError:
        raise InputError("reading C3D needs ezc3d: pip install ezc3d", path=p) from None
    if not p.is_file():
        raise InputError("file not found", path=p)
    _check_parameter_section(p)
    try:
        c = ezc3d.c3d(str(p))
    except Exception as exc:  # noqa: BLE001 - ezc3d raises plain RuntimeError/ValueError on corrupt files
        raise InputError(f"not a readable C3D file: {str(exc).splitlines()[0][:160] if str(exc) else type(exc).__name__}", path=p) from None
    try:
        point = c["parameters"]["POINT"]
        labels = list(point["LABELS"]["value"])
        for extra in ("LABELS2", "LABELS3", "LABELS4"):
            if extra in point:
                labels += list(point[extra]["value"])
        unit = str((point.get("UNITS", {}).get("value") or ["mm"])[0]).strip().lower() or "mm"
        rate = float(np.asarray(point["RATE"]["value"]).reshape(-1)[0])
        data = np.asarray(c["data"]["points"], dtype=float)  # (4, M, F)
        residuals = np.asarray(c["data"]["meta_points"]["residuals"], dtype=float)  # (1, M, F)
        first = int(c["header"]["points"]["first_frame"])
    except (KeyError, IndexError, TypeError, ValueError) as exc:
        raise InputError(f"C3D file lacks point data or parameters ({exc})", path=p) from None
    if data.ndim != 3 or data.shape[1] == 0 or data.shape[2] == 0:
        raise InputError("C3D file holds no marker samples", path=p)
    M = data.shape[1]
    declared = _declared_frames(p, M)
    if declared is not None and declared > data.shape[2]:
        warn(f"{p}: the header declares {declared} frames but the file holds {data.shape[2]} (truncated?); "
             "read what is there")
    labels = [str(x).strip() for x in labels[:M]]
    if not any(labels):
        raise InputError("no point labels (POINT:LABELS is empty): the markers cannot be told apart", path=p)
    labels = [lab or f"marker{k}" for k, lab in enumerate(labels)] + [f"marker{k}" for k in range(len(labels), M)]
    labels = unique_labels(labels, f"{p}: POINT:LABELS")
    if units is not None:
        scale = unit_scale(units, p)
    elif unit not in UNITS:
        warn(f"{p}: unknown point unit {unit!r}; assuming millimetres (give the unit with --in-units)")
        scale = UNITS["mm"]
    else:
        scale = UNITS[unit]
    pos = np.transpose(data[:3], (2, 1, 0)) * scale  # (F, M, 3)
    bad = ~np.all(np.isfinite(pos), axis=2) | np.all(pos == 0.0, axis=2)
    if residuals.shape == (1, M, data.shape[2]):
        bad |= residuals[0].T < 0.0
    pos[bad] = np.nan
    if np.all(bad):
        raise InputError("every marker sample is invalid (NaN, zero or a negative residual)", path=p)
    return MarkerRecording(labels=tuple(labels), positions=pos, fps=rate, source=p, first_frame=first)


def _check_parameter_section(p: Path) -> None:
    """An :class:`InputError` when the file ends inside its parameter section: ezc3d loops
    forever on such a file.  The header's first byte is the section's first 512-byte block;
    the section's own third byte the number of blocks it spans."""
    try:
        with p.open("rb") as fh:
            head = fh.read(2)
            start = 512 * (head[0] - 1) if head and head[0] > 0 else 0
            fh.seek(start)
            section = fh.read(4)
        size = p.stat().st_size
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror}", path=p) from None
    if size == 0:
        raise InputError("empty file", path=p)
    if len(head) < 2 or head[1] != 0x50:
        raise InputError("not a C3D file (its second byte is not the C3D key 0x50)", path=p)
    if len(section) < 4:
        raise InputError(f"truncated C3D file: {size} bytes end before the parameter section (byte {start})", path=p)
    end = start + 512 * section[2]
    if size < end:
        raise InputError(f"truncated C3D file: {size} bytes end inside the parameter section (bytes {start} to {end})",
                         path=p)


def _declared_frames(p: Path, markers: int) -> int | None:
    """Frames the C3D header declares (``last - first + 1``, header words 4 and 5), or None
    when the header cannot be read or its byte order does not match ``markers`` (ezc3d
    silently rewrites its copy of the header to the frames it could read)."""
    try:
        with p.open("rb") as fh:
            head = fh.read(10)
    except OSError:
        return None
    if len(head) < 10:
        return None
    for order in ("<", ">"):
        count, _, first, last = struct.unpack(order + "4H", head[2:10])
        if count == markers and 0 < first <= last:
            return last - first + 1
    return None
