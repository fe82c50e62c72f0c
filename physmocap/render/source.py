"""What a preview shows, taken from the retargeter's result.

The only module of :mod:`physmocap.render` (and of the ``preview``/``view`` commands)
that knows the retargeter's API: the trajectory's ``stats`` (source motion as
retargeted, joint mapping, first source frame, contact labels) and the targets'
calibration.  When that API changes, this file changes, nothing else.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .skeleton import Placement, SourceSkeleton, source_skeleton

__all__ = ["PreviewInput", "preview_input", "preview_input_with_source"]


@dataclass(frozen=True, eq=False)
class PreviewInput:
    """A trajectory and what is drawn with it.

    Attributes:
        traj: The character's :class:`~physmocap.trajectory.Trajectory`.
        skeleton: The source skeleton over the same frames, or None when unknown.
        contacts: Contact label (``left_heel`` ...) -> ``(F,)`` bool, or None.
        first: Source frame number of the trajectory's frame 0 (images are labelled with it).
    """

    traj: object
    skeleton: SourceSkeleton | None
    contacts: dict[str, np.ndarray] | None
    first: int


def _placement(calibration) -> Placement:
    return Placement(
        scale=float(calibration.scale),
        start_xy=np.asarray(calibration.start_xy, dtype=float),
        floor=float(calibration.floor),
        ankle_actor=float(calibration.ankle_actor),
        ankle_character=float(calibration.ankle_character),
        level=calibration.level,
        level_centre=calibration.level_centre,
    )


def preview_input(traj) -> PreviewInput:
    """The preview of a trajectory from :func:`physmocap.retarget` (skeleton and contacts
    included) or read from an NPZ (no source: character only)."""
    motion, joints = traj.source_motion, traj.joint_indices
    cal = getattr(getattr(traj, "targets", None), "calibration", None)
    skeleton = None if motion is None or joints is None or cal is None else source_skeleton(motion, joints, _placement(cal))
    contacts = getattr(traj.contacts, "labels", None)
    return PreviewInput(traj, skeleton, contacts, int(traj.source_start))


def preview_input_with_source(traj, motion, start: int | None = None, profile=None, mapping=None) -> PreviewInput:
    """A saved trajectory with the source ``motion`` it was retargeted from: the source is
    cut like the retarget (``start``, default: the retargeter's own choice) and placed by
    the calibration the retargeter computes for it (default target options)."""
    from ..errors import OptionError
    from ..ik.retarget import default_start, map_motion
    from ..ik.targets import build_targets

    first = default_start(motion) if start is None else int(start)
    if not 0 <= first < motion.num_frames:
        raise OptionError(f"--start {first} is outside the source, which has {motion.num_frames} frames", path=motion.source)
    motion = motion.slice_frames(first, min(motion.num_frames, first + traj.num_frames))
    if motion.num_frames != traj.num_frames:
        raise OptionError(
            f"--source has {motion.num_frames} frames from frame {first} but the trajectory {traj.num_frames}; "
            "pass --start as used for the retarget",
            path=motion.source,
        )
    joints = map_motion(motion, profile=profile, mapping=mapping)
    cal = build_targets(motion, joints, traj.character).calibration
    return PreviewInput(traj, source_skeleton(motion, joints, _placement(cal)), None, first)
