r"""The calibration pose: where the actor's posture is matched to the character's rest.

Orientation targets of a rotational source are the actor's segment rotations
*relative to a calibration pose* in which the actor stands like the
character's rest pose (upright, legs straight):
:math:`R_c^{target}(t) = R_a(t)\, R_a(t_c)^{-1}\, M\, Y\, R_{c,0}`
(:mod:`physmocap.ik.targets`).  Many skeletons rest in a standing T- or
A-pose (all rotations zero), but not all: Bandai Namco and LAFAN1 skeletons
rest lying down with every bone along one axis, and a calibration that
assumed the rest pose stands bent such characters 40-90 degrees at the
waist.  So the rest pose is used only when its *geometry* shows a standing
body; otherwise the frame of the motion where the actor stands most
upright is used, and a warning names the file when none is upright.

Standing score of a pose (all from joint centres, no naming or axis
conventions beyond Z-up metres):

* torso uprightness :math:`u = \hat z \cdot \widehat{(n - h)}` with ``h`` the
  mid-hip point and ``n`` the neck (or the highest torso joint);
* leg straightness :math:`s = |a - h_s| / (|k - h_s| + |a - k|)` per leg
  (hip, knee, ankle), the smaller of the two legs;
* level hips: :math:`l = 1 - |\hat z \cdot \widehat{(h_l - h_r)}|`;
* feet below the hips: both ankles lower than both hips.

``score = u + s + l`` when the feet are below the hips, else :math:`-\infty`.
A pose counts as standing when :math:`u \ge \cos 20^\circ`,
:math:`s \ge 0.95` and :math:`l \ge \cos 20^\circ`... expressed as
:data:`UPRIGHT_COS`, :data:`STRAIGHT_LEG` and :data:`LEVEL_HIPS` (fractions,
not tuned to any clip: a person standing at ease is well inside them).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..vectors import direction

__all__ = ["CalibrationPose", "standing_score", "is_standing", "calibration_pose"]

#: Cosine of the largest torso tilt from vertical that still counts as standing (20 degrees).
UPRIGHT_COS = float(np.cos(np.radians(20.0)))
#: Hip-to-ankle distance over the leg's length above which a leg counts as straight.
STRAIGHT_LEG = 0.95
#: 1 - |sin| of the largest hip-line tilt from horizontal that counts as level (20 degrees).
LEVEL_HIPS = float(np.cos(np.radians(70.0)))


@dataclass(frozen=True)
class CalibrationPose:
    """Where the actor's posture is calibrated.

    Attributes:
        frame: Index of the motion frame used, or None for the skeleton's rest pose.
        standing: Whether that pose passes :func:`is_standing`.
        score: Its :func:`standing_score`.
    """

    frame: int | None
    standing: bool
    score: float

    def describe(self) -> str:
        return "the rest pose" if self.frame is None else f"frame {self.frame}"


#: The joints :func:`standing_score` and :func:`is_standing` read (where present).
POSE_JOINTS = frozenset(("left_hip", "right_hip", "left_knee", "right_knee", "left_ankle", "right_ankle",
                         "neck", "head", "chest", "spine"))


def _parts(P: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """Torso uprightness, leg straightness, hip levelness, feet-below-hips for ``(F, 3)`` joints."""
    need = ("left_hip", "right_hip", "left_knee", "right_knee", "left_ankle", "right_ankle")
    top = next((c for c in ("neck", "head", "chest", "spine") if c in P), None)
    if top is None or not all(c in P for c in need):
        return None
    mid = 0.5 * (P["left_hip"] + P["right_hip"])
    up = direction(P[top] - mid)[..., 2]
    straight = []
    for s in ("left", "right"):
        h, k, a = P[f"{s}_hip"], P[f"{s}_knee"], P[f"{s}_ankle"]
        length = np.linalg.norm(k - h, axis=-1) + np.linalg.norm(a - k, axis=-1)
        straight.append(np.linalg.norm(a - h, axis=-1) / np.maximum(length, 1e-9))
    level = 1.0 - np.abs(direction(P["left_hip"] - P["right_hip"])[..., 2])
    below = np.maximum(P["left_ankle"][..., 2], P["right_ankle"][..., 2]) < np.minimum(
        P["left_hip"][..., 2], P["right_hip"][..., 2]
    )
    return up, np.minimum(*straight), level, below


def standing_score(P: dict[str, np.ndarray]) -> np.ndarray | None:
    """``(F,)`` standing score of canonical joints ``P[name] (F, 3)`` (higher stands better;
    -inf where the feet are not below the hips or a joint is lost), None without the joints."""
    parts = _parts(P)
    if parts is None:
        return None
    up, straight, level, below = parts
    score = up + straight + level
    return np.where(below & np.isfinite(score), score, -np.inf)


def is_standing(P: dict[str, np.ndarray]) -> np.ndarray | None:
    """``(F,)`` True where the pose stands upright with straight legs and level hips."""
    parts = _parts(P)
    if parts is None:
        return None
    up, straight, level, below = parts
    return below & (up >= UPRIGHT_COS) & (straight >= STRAIGHT_LEG) & (level >= LEVEL_HIPS)


def calibration_pose(rest: dict[str, np.ndarray], frames) -> CalibrationPose:
    """Choose the calibration pose: the rest pose if it stands, else the motion's most upright frame.

    Args:
        rest: Canonical joint -> ``(3,)`` rest-pose position, or an empty dict
            when the source has no rest pose (positional sources).
        frames: Canonical joint -> ``(F, 3)`` positions over the motion (NaN where lost),
            at least :data:`POSE_JOINTS`; or a function returning them, called only when
            the rest pose does not stand.

    Returns:
        The :class:`CalibrationPose`; ``standing`` False means no pose of the
        clip stands (the caller warns), and the most upright frame is used.
    """
    if rest:
        ok = is_standing({k: v[None] for k, v in rest.items()})
        if ok is None or bool(ok[0]):
            score = standing_score({k: v[None] for k, v in rest.items()})
            return CalibrationPose(None, True, float(score[0]) if score is not None else 0.0)
    if callable(frames):
        frames = frames()
    score = standing_score(frames)
    if score is None or not np.isfinite(score).any():
        return CalibrationPose(None if rest else 0, False, float("-inf"))
    standing = is_standing(frames)
    assert standing is not None
    if standing.any():
        # the most upright of the standing frames (ties: the earliest)
        masked = np.where(standing, score, -np.inf)
        t = int(np.argmax(masked))
        return CalibrationPose(t, True, float(score[t]))
    t = int(np.argmax(score))
    return CalibrationPose(t, False, float(score[t]))
