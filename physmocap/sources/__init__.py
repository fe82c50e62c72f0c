"""Sources: read capture files into a :class:`~physmocap.motion.Motion`.

:func:`load_motion` picks the reader from the file's suffix.  Each reader lives
in its own module and is registered in :data:`READERS` by module and function
name, so importing this package stays cheap.
"""

from __future__ import annotations

import importlib
import os
from pathlib import Path

from ..errors import InputError
from ..motion import Motion
from ..resources import resolve_input

#: suffix -> (module, function).  Readers take ``(path, **options)``.
READERS: dict[str, tuple[str, str]] = {
    ".bvh": ("physmocap.sources.bvh", "read_bvh"),
    ".csv": ("physmocap.sources.positions", "read_positions"),
    ".npz": ("physmocap.sources.positions", "read_positions"),
    ".jsonl": ("physmocap.sources.positions", "read_positions"),
    ".mcap": ("physmocap.sources.mcap", "read_mcap"),
    ".c3d": ("physmocap.sources.c3d", "read_c3d"),
    ".trc": ("physmocap.sources.trc", "read_trc"),
}


def load_motion(path: str | os.PathLike, **options) -> Motion:
    """Read any supported capture file (``"example"`` is the bundled walk)."""
    p = resolve_input(path)
    suffix = p.suffix.lower()
    if suffix not in READERS:
        known = ", ".join(sorted(READERS))
        raise InputError(f"unknown file type {suffix or '(none)'!r}; physmocap reads {known}", path=p)
    if not p.exists():
        raise InputError("file not found", path=p)
    if p.is_dir():
        raise InputError("is a directory, expected a file", path=p)
    module_name, func_name = READERS[suffix]
    reader = getattr(importlib.import_module(module_name), func_name)
    return reader(Path(p), **options)
