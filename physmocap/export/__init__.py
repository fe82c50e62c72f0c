"""Exporters: write motions and character trajectories to files.

:func:`write_motion` picks the writer for a source :class:`~physmocap.motion.Motion`
from the output suffix (``physmocap convert`` uses it).  Writers are atomic:
they write a temporary file and rename it, so a failure leaves no partial file.
"""

from __future__ import annotations

import importlib
import os
from pathlib import Path

from ..errors import OutputError
from ..motion import Motion

#: suffix -> (module, function).  Writers take ``(motion, path, **options)``.
MOTION_WRITERS: dict[str, tuple[str, str]] = {
    ".bvh": ("physmocap.export.bvh", "write_bvh"),
    ".mcap": ("physmocap.export.mcap", "write_motion_mcap"),
}


def write_motion(motion: Motion, path: str | os.PathLike, **options) -> Path:
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix not in MOTION_WRITERS:
        known = ", ".join(sorted(MOTION_WRITERS))
        raise OutputError(f"unknown output type {suffix or '(none)'!r}; physmocap writes {known}", path=p)
    module_name, func_name = MOTION_WRITERS[suffix]
    writer = getattr(importlib.import_module(module_name), func_name)
    writer(motion, p, **options)
    return p
