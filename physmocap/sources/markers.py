"""The one way into a marker recording: a .c3d, .trc or marker .mcap file to a
:class:`~physmocap.markers.recording.MarkerRecording` (labels, metres, the file's axes).

Every command that takes markers (``inspect``, ``convert``, ``solve``, ``retarget``,
``replay``, ``clean``, ``preview``, ``batch``) asks :func:`is_marker_file` whether its input
is one and reads it with :func:`read_markers`; ``load_motion`` reaches the same per-format
readers (:func:`~physmocap.sources.c3d.read_c3d_markers`,
:func:`~physmocap.sources.trc.read_trc_markers`,
:func:`~physmocap.sources.mcap.read_mcap_markers`), so a format is parsed in one place.
"""

from __future__ import annotations

import importlib
import os
from pathlib import Path
from typing import TYPE_CHECKING, Any


if TYPE_CHECKING:
    from ..markers.recording import MarkerRecording
    from ..markers.solve import MarkerSolveOptions
    from ..motion import Motion

__all__ = ["MARKER_READERS", "MARKER_FILE_TYPES", "is_marker_file", "read_markers", "read_marker_motion"]

#: suffix -> (module, function) of the marker readers, each ``(path, units) -> MarkerRecording``.
MARKER_READERS: dict[str, tuple[str, str]] = {
    ".c3d": ("physmocap.sources.c3d", "read_c3d_markers"),
    ".trc": ("physmocap.sources.trc", "read_trc_markers"),
    ".mcap": ("physmocap.sources.mcap", "read_mcap_markers"),
}

#: How the marker inputs are named in messages.
MARKER_FILE_TYPES = ".c3d, .trc, or .mcap with labelled markers (physmocap.LabelledPoints or a foxglove.PointCloud)"


def is_marker_file(path: str | os.PathLike) -> bool:
    """Whether ``path`` is read as markers: a .c3d or .trc file, or an existing .mcap file that
    :func:`~physmocap.sources.mcap.read_mcap` reads as markers (a marker channel and no
    physmocap skeleton track; :func:`~physmocap.sources.mcap.has_markers`)."""
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix != ".mcap":
        return suffix in MARKER_READERS
    if not p.is_file():
        return False
    from .mcap import has_markers

    return has_markers(p)


def read_markers(path: str | os.PathLike, units: str | float | None = None) -> "MarkerRecording":
    """The marker recording of a .c3d, .trc or marker .mcap file.

    Args:
        path: The file.
        units: Overrides the file's length unit (a name of
            :data:`~physmocap.markers.recording.UNITS` or metres per file unit).

    Raises:
        InputError: Another file type, a missing file, or anything the format's reader
            refuses (naming the file, and the line, message or frame where it can).
    """
    from . import pick_reader

    p, (module, func) = pick_reader(path, MARKER_READERS, "a marker file")
    return getattr(importlib.import_module(module), func)(p, units)


def read_marker_motion(path: str | os.PathLike, marker_set: str | os.PathLike | None = None,
                       units: str | float | None = None, solve: bool = True,
                       solve_options: "MarkerSolveOptions | None" = None, **options: Any) -> "Motion":
    """``load_motion``'s reader of .c3d and .trc files: the solved actor skeleton (with
    ``solve_options``), or with ``solve=False`` the canonical joint centres
    (:func:`physmocap.markers.motion.marker_motion`, which takes ``options``); ``units``
    overrides the file's."""
    from ..markers.motion import marker_motion

    return marker_motion(read_markers(path, units), marker_set, solve, solve_options, **options)
