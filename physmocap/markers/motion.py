"""A marker recording as a positional motion of canonical joints (what the retargeter reads)."""

from __future__ import annotations

import os
from typing import Any

import numpy as np

from ..motion import Motion
from .functional import functional_joint_centres, warn_fallbacks
from .joints import up_axis, warn_unused
from .markerset import recording_marker_set
from .recording import MarkerRecording

__all__ = ["marker_motion"]


def _to_z_up(up: np.ndarray) -> np.ndarray:
    """A proper rotation (3x3) taking the signed axis ``up`` to +Z."""
    k = int(np.argmax(np.abs(up)))
    z = np.zeros(3)
    z[k] = np.sign(up[k])
    x = np.zeros(3)
    x[(k + 1) % 3] = 1.0
    y = np.cross(z, x)
    return np.stack([x, y, z])  # rows: the new axes in the file's coordinates


def marker_motion(rec: MarkerRecording, marker_set: str | os.PathLike | None = None, solve: bool = False,
                  **options: Any) -> Motion:
    """The recording's canonical joint centres (functional where the clip exercises the
    joint, else the regression: :func:`.functional.functional_joint_centres`) as a
    positional :class:`~physmocap.motion.Motion` (metres, Z-up, floor at 0), through the
    same conventions as tracker files (:func:`physmocap.sources.positions.positional_motion`:
    gaps up to ``max_gap`` filled, levelling, floor).  With ``solve``, the actor skeleton
    solved by marker-driven IK instead (:func:`.solve.solve_markers`, rotational, rigid
    calibrated lengths, joint ranges and floor held; :func:`.solve.actor_motion`).

    Args:
        rec: The :class:`MarkerRecording`.
        marker_set: A TOML file of ``[markers] ROLE = "label"`` overriding the aliases.
        solve: Return the solved actor skeleton rather than the joint centres.
        **options: Options of ``positional_motion`` (``max_gap``, ``smooth``, ``floor``...);
            none with ``solve``.
    """
    from ..sources.positions import positional_motion

    if solve:
        return solved_motion(rec, marker_set, **options)
    ms = recording_marker_set(rec, marker_set)
    warn_unused(rec, ms)
    centres = functional_joint_centres(rec, ms)
    warn_fallbacks(centres, rec.source)
    R = _to_z_up(up_axis(rec, ms))
    names = list(centres.positions)
    P = np.stack([centres.positions[n] for n in names], axis=1) @ R.T
    # a lab frame is level: no tilt estimate from the feet (that is for camera-frame trackers)
    opts = {"units": 1.0, "frame": "world", "up": "Z", "mirrored": False, "profile": "generic", "level": False}
    opts.update(options)
    motion = positional_motion(names, P, None, rec.fps, rec.source, **opts)
    motion.meta["joint_centre_methods"] = dict(centres.method)
    motion.meta["unused_markers"] = list(ms.unused)
    motion.meta["segment_lengths"] = {f"{a}-{b}": v for (a, b), v in centres.lengths.items()}
    return motion


def solved_motion(rec: MarkerRecording, marker_set: str | os.PathLike | None = None, **options: Any) -> Motion:
    """The actor skeleton solved from the markers (:func:`.solve.solve_markers`) as a
    rotational :class:`~physmocap.motion.Motion` (metres, Z-up, canonical joint names), with
    the joint-centre methods, ignored markers and the residual RMS in ``meta``."""
    from ..errors import OptionError
    from .solve import actor_motion, solve_markers

    if options:
        raise OptionError(f"option(s) {', '.join(sorted(options))} do not apply to a solved marker recording",
                          path=rec.source)
    sol = solve_markers(rec, marker_set)
    motion = actor_motion(sol)
    rep = sol.report()
    motion.meta["joint_centre_methods"] = dict(sol.calibration.method)
    motion.meta["ignored_markers"] = list(sol.ignored)
    motion.meta["marker_residual_rms_mm"] = rep["overall"]["rms_mm"]
    return motion
