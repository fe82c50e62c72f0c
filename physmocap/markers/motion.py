"""A marker recording as a :class:`~physmocap.motion.Motion` the retargeter reads: the solved
actor skeleton (the default), or the canonical joint centres (``solve=False``)."""

from __future__ import annotations

import dataclasses
import os
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import InputError
from ..motion import Motion
from .functional import functional_joint_centres, warn_fallbacks
from .joints import up_axis, warn_unused
from .markerset import MarkerSet, recording_marker_set
from .recording import MarkerRecording

if TYPE_CHECKING:
    from .solve import MarkerSolveOptions

__all__ = ["marker_motion", "solved_motion", "check_legs", "LegsNotCapturedError", "LEG_SEGMENTS"]

#: Segments a solved actor needs markers on before it is handed to the retargeter: without
#: them its legs would hang in the rest pose under a moving pelvis, and the character's feet
#: (floor, contacts, planting) would be invented, not captured.
LEG_SEGMENTS = tuple(f"{side}_{seg}" for side in ("left", "right") for seg in ("thigh", "shank", "foot"))


def _to_z_up(up: np.ndarray) -> np.ndarray:
    """A proper rotation (3x3) taking the signed axis ``up`` to +Z."""
    k = int(np.argmax(np.abs(up)))
    z = np.zeros(3)
    z[k] = np.sign(up[k])
    x = np.zeros(3)
    x[(k + 1) % 3] = 1.0
    y = np.cross(z, x)
    return np.stack([x, y, z])  # rows: the new axes in the file's coordinates


def marker_motion(rec: MarkerRecording, marker_set: str | os.PathLike | None = None, solve: bool = True,
                  solve_options: "MarkerSolveOptions | None" = None, **options: Any) -> Motion:
    """What ``load_motion`` returns for a marker recording.

    By default the actor skeleton solved by marker-driven IK (:func:`solved_motion`:
    rotational, rigid calibrated lengths, joint ranges and floor held): markers -> actor ->
    character, as issue 11 asks.  With ``solve=False`` the older, faster route: the canonical
    joint centres (functional where the clip exercises the joint, else the regression:
    :func:`.functional.functional_joint_centres`) as a positional
    :class:`~physmocap.motion.Motion` (metres, Z-up, floor at 0), through the same
    conventions as tracker files (:func:`physmocap.sources.positions.positional_motion`: gaps
    up to ``max_gap`` filled, levelling, floor); no rigid skeleton and no joint ranges on the
    actor, and no leg markers needed.

    Args:
        rec: The :class:`MarkerRecording`.
        marker_set: A TOML file of ``[markers] ROLE = "label"`` overriding the aliases.
        solve: The solved actor skeleton (default) rather than the joint centres.
        solve_options: How the actor is solved (:class:`~.solve.MarkerSolveOptions`; default
            its defaults); with ``solve=True`` only.
        **options: Options of ``positional_motion`` (``max_gap``, ``smooth``, ``floor``...);
            with ``solve=False`` only.

    Raises:
        OptionError: Options of the other route (``solve_options`` with ``solve=False``,
            ``**options`` with ``solve=True``).
    """
    from ..errors import OptionError
    from ..sources.positions import positional_motion

    if solve:
        return solved_motion(rec, marker_set, solve_options, **options)
    if solve_options is not None:
        raise OptionError("marker solve options apply to the solved actor, not to the joint centres "
                          "(solve=False, --joint-centres)", path=rec.source)
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


class LegsNotCapturedError(InputError):
    """A marker recording with no marker on the leg ``segments``: the full-body actor is not
    solved from it.  The message says what follows for the command at hand: by default that
    the skeleton cannot be built; :meth:`for_character` (retargeting) that the take cannot
    drive a character's legs."""

    def __init__(self, segments, path=None, consequence: str = "a full-body skeleton cannot be built without "
                 "leg markers") -> None:
        self.segments = tuple(segments)
        super().__init__(f"no marker on {', '.join(self.segments)}: the legs were not captured (an upper-body "
                         f"take?), so {consequence}; `physmocap solve FILE -o actor.bvh` solves the captured "
                         "part alone", path=path)

    def for_character(self) -> "LegsNotCapturedError":
        """The same refusal as a retarget states it: the take cannot drive a character's legs."""
        return LegsNotCapturedError(self.segments, self.path, "they cannot drive a character's legs")


def check_legs(rec: MarkerRecording, ms: MarkerSet) -> None:
    """A :class:`LegsNotCapturedError` naming the leg segments (:data:`LEG_SEGMENTS`) that no
    marker of the recording is on (by role or label hint: :func:`.functional.segment_markers`)."""
    from .functional import segment_markers

    have = set(segment_markers(rec, ms).values())
    bare = [s for s in LEG_SEGMENTS if s not in have]
    if bare:
        raise LegsNotCapturedError(bare, rec.source)


def solved_motion(rec: MarkerRecording, marker_set: str | os.PathLike | MarkerSet | None = None,
                  solve_options: "MarkerSolveOptions | None" = None, **options: Any) -> Motion:
    """The actor skeleton solved from the markers (:func:`.solve.solve_markers` with
    ``solve_options``) as a rotational :class:`~physmocap.motion.Motion` (metres, Z-up,
    canonical joint names), with the joint-centre methods, ignored markers and the residual
    RMS in ``meta``.  A recording with no marker on a leg segment is refused before the solve
    (:func:`check_legs`); ``options`` (the joint-centre route's) are refused."""
    from ..errors import OptionError
    from .solve import MarkerSolveOptions, actor_motion, solve_markers

    if options:
        raise OptionError(f"option(s) {', '.join(sorted(options))} do not apply to a solved marker recording "
                          "(only to its joint centres: solve=False, --joint-centres)", path=rec.source)
    ms = recording_marker_set(rec, marker_set)
    if not ms.roles:
        from .joints import joint_centres

        joint_centres(rec, ms)  # raises: the labels match no known marker set
    check_legs(rec, ms)
    sol = solve_markers(rec, ms, solve_options)
    motion = actor_motion(sol)
    rep = sol.report()
    motion.meta["joint_centre_methods"] = dict(sol.calibration.method)
    motion.meta["ignored_markers"] = list(sol.ignored)
    motion.meta["marker_residual_rms_mm"] = rep["overall"]["rms_mm"]
    motion.meta["marker_solve_options"] = dataclasses.asdict(solve_options or MarkerSolveOptions())
    return motion
