"""Sources: read capture files into a :class:`~physmocap.motion.Motion`.

:func:`load_motion` picks the reader from the file's suffix.  Each reader lives
in its own module and is registered in :data:`READERS` by module and function
name, so importing this package stays cheap.
"""

from __future__ import annotations

import importlib
import os
from pathlib import Path

from typing import TYPE_CHECKING

from ..errors import InputError
from ..resources import resolve_input

if TYPE_CHECKING:  # the reader modules import numpy/scipy; listing them stays cheap
    from ..motion import Motion

#: suffix -> (module, function).  Readers take ``(path, **options)``.
READERS: dict[str, tuple[str, str]] = {
    ".bvh": ("physmocap.sources.bvh", "read_bvh"),
    ".csv": ("physmocap.sources.positions", "read_positions"),
    ".npz": ("physmocap.sources.positions", "read_positions"),
    ".jsonl": ("physmocap.sources.positions", "read_positions"),
    ".mcap": ("physmocap.sources.mcap", "read_mcap"),
    ".c3d": ("physmocap.sources.markers", "read_marker_motion"),
    ".trc": ("physmocap.sources.markers", "read_marker_motion"),
}


def load_motion(path: str | os.PathLike, *, min_frames: int = 0, **options) -> Motion:
    """Read any supported capture file (``"example"`` is the bundled walk).

    ``min_frames``: refuse a clip with fewer frames (commands that process motion need one;
    ``inspect`` and ``convert`` take an empty clip as it is)."""
    p = resolve_input(path)
    suffix = p.suffix.lower()
    if p.is_dir():
        raise InputError("is a directory, expected a motion file (" + ", ".join(sorted(READERS)) + ")", path=p)
    if suffix not in READERS:
        known = ", ".join(sorted(READERS))
        raise InputError(f"unknown file type {suffix or '(none)'!r}; physmocap reads {known}", path=p)
    if not p.exists():
        raise InputError("file not found", path=p)
    module_name, func_name = READERS[suffix]
    reader = getattr(importlib.import_module(module_name), func_name)
    motion = reader(Path(p), **options)
    check_plausible(motion, p)
    if motion.num_frames < min_frames:
        raise InputError(f"the clip has {motion.num_frames} frames; this command needs at least {min_frames}", path=p)
    return motion


def pick_reader(path: str | os.PathLike, readers: dict, what: str):
    """``(Path, readers[suffix])`` for a file that exists and whose suffix ``readers`` holds.

    Raises:
        InputError: Naming the file: not one of ``what`` (the suffixes known are listed), or
            not found.
    """
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix not in readers:
        raise InputError(f"not {what} (expected {', '.join(readers)}): {suffix or 'no suffix'!r}", path=p)
    if not p.is_file():
        raise InputError("file not found", path=p)
    return p, readers[suffix]


#: Plausible ranges of what a capture holds: frame rate (Hz), distances (metres).
FPS_RANGE = (0.1, 10000.0)
MAX_DISTANCE = 1000.0


def check_grid(path: str | os.PathLike, frames: float, joints: int, samples: int) -> None:
    """Refuse to lay ``samples`` values read from a file out as a ``frames x joints`` grid
    much larger than the file holds (sparse frame numbers, times or joint names would
    otherwise allocate gigabytes from a small file), or with more joints than any skeleton."""
    from ..motion import MAX_JOINTS

    if joints > MAX_JOINTS:
        raise InputError(f"{joints} joints; physmocap reads at most {MAX_JOINTS}", path=path)
    if frames * joints > 16 * samples + 100_000:
        raise InputError(
            f"{samples} samples would be spread over {frames:.6g} frames x {joints} joints; the recording "
            "is too sparse to hold as a clip (a wrong frame rate, or corrupt frame numbers or times)",
            path=path,
        )


def check_plausible(motion: "Motion", path: str | os.PathLike) -> None:
    """Refuse numbers no capture holds, naming the file, frame and joint: a frame rate outside
    0.1-10,000 Hz, offsets or positions farther than a kilometre, non-finite or zero-norm
    rotations (lost tracker samples are NaN positions, which are allowed)."""
    import numpy as np

    lo, hi = FPS_RANGE
    if not (lo <= motion.fps <= hi):
        raise InputError(f"frame rate {motion.fps:.6g} Hz is outside {lo:g}-{hi:g} Hz", path=path)
    names = motion.skeleton.names
    off = np.asarray(motion.skeleton.offsets)
    bad = ~np.all(np.isfinite(off) & (np.abs(off) < MAX_DISTANCE), axis=1)
    if bad.any():
        j = int(np.argmax(bad))
        raise InputError(f"joint {names[j]}: offset {off[j].tolist()} is not a finite distance within 1 km", path=path)

    def first_bad(arr: np.ndarray, what: str, allow_nan: bool) -> None:
        check_distances(arr, path, what, names if what == "joint" else None, allow_nan)

    if motion.rotations is not None:
        from ..spill import blocks

        for s, rows in blocks(motion.rotations):  # a block at a time: no temporaries the clip's size
            norms = np.linalg.norm(rows, axis=-1)
            ok = np.isfinite(norms) & (norms > 1e-9)
            if not ok.all():
                f, j = (int(x) for x in np.argwhere(~ok)[0])
                raise InputError(f"joint {names[j]} has no valid rotation (zero or non-finite)", path=path, frame=s + f)
        if motion.translations is not None and motion.translations.size:
            first_bad(motion.translations, "translated joint", allow_nan=False)
    if motion.positions is not None:
        first_bad(motion.positions, "joint", allow_nan=True)


def check_distances(arr, path: str | os.PathLike, what: str = "joint", names=None, allow_nan: bool = True) -> None:
    """Refuse ``(F, J, 3)`` positions in metres that are not finite (NaN, a lost sample, is
    allowed with ``allow_nan``) or farther than :data:`MAX_DISTANCE`, naming the frame and
    joint (by name when ``names`` are given)."""
    import numpy as np

    with np.errstate(invalid="ignore"):
        ok = np.abs(arr) < MAX_DISTANCE
    if allow_nan:
        ok |= np.isnan(arr)
    ok = np.all(ok, axis=-1)
    if not ok.all():
        f, j = (int(x) for x in np.argwhere(~ok)[0])
        label = names[j] if names is not None else j
        raise InputError(f"{what} {label} is not a finite distance within 1 km", path=path, frame=f)
