r"""Anatomical angles of a capture, whatever its rig, and the frames where they leave the range of motion.

A file's Euler channels say nothing anatomical: their order, axes and the
rest pose they start from differ between vendors (a Bandai Namco skeleton
rests lying down).  The angles here come from the geometry of the joint
centres, the way a goniometer reads them off a body, in anatomical terms:

* **knee flexion** and **elbow flexion**, signed: the angle between the
  proximal and distal segments (0 straight), positive in the joint's flexion
  direction, negative for hyperextension.  The flexion direction is the hinge
  axis :math:`a` of the joint in the proximal segment's own frame, found from
  the clip itself: the bend-plane normal :math:`n = \widehat{u \times v}` of
  the segment directions :math:`u, v`, expressed in the proximal segment's
  frame, is the same vector :math:`a` whenever a hinge is bent, so
  :math:`a` is the normalised median of it over the frames bent more than
  ``axis_min_deg`` (10 degrees: a joint spends most of a clip flexed, so a
  glitch bending it backwards is a minority there and cannot turn the axis).  Then :math:`\theta = \operatorname{atan2}((u \times v)
  \cdot R a,\; u \cdot v)`.  The proximal segment's frame is its world
  rotation (rotational sources) or, for position-only sources, the pelvis
  frame (knees; elbows are not signed there, only over-flexion is checked);
  when the clip never bends the joint, the axis of the neutral standing pose
  is used (knee: the pelvis's left axis; elbow: the chest's right axis).
* **hip flexion** and **hip adduction** from the thigh's direction
  :math:`d` in the pelvis frame (x forward, y left, z up: from the hip joint
  centres and the trunk line in the calibration pose, carried by the pelvis
  segment's own rotation where the source has one, since the trunk line also
  bends at the lumbar spine; from the hip line and trunk line on every frame
  for position-only sources): flexion :math:`\operatorname{atan2}(d_x, -d_z)`
  (evaluated where the thigh is not abducted beyond 60 degrees, so that the
  sagittal angle is defined), adduction :math:`\arcsin(\mp d_y)` (left,
  right); the pelvis frame's z is the trunk line, so an upright trunk over
  vertical thighs reads 0.
* **trunk flexion, lateral flexion and rotation**: the chest frame (shoulder
  line and trunk line) relative to the pelvis frame, relative to the same
  rotation in the calibration pose, as intrinsic Y-X-Z angles (the default
  humanoid's spine chain order); the ranges are the lumbar plus thoracic ones.

Ranges come from :mod:`physmocap.models.rom` (the ``"default"`` policy:
largest clinical value plus a performer margin, none on the knee and elbow
hyperextension stops).  All angles are in degrees.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..frames import chest_frame, pelvis_frame
from ..models.rom import dof_entry, joint_range_deg
from ..vectors import direction as _direction

__all__ = ["Movement", "MOVEMENTS", "anatomical_angles", "movement_range", "beyond_range", "motion_angles", "bend_past_range"]


@dataclass(frozen=True)
class Movement:
    """One anatomical movement checked against its range of motion.

    Attributes:
        key: Identifier, e.g. ``"left_knee_flexion"``.
        joint: The canonical joint it belongs to (``"left_knee"``; ``"spine"`` for the trunk).
        positive, negative: Clinical names of the two directions
            (``"flexion"`` / ``"hyperextension"``).
        plane: Anatomical plane (``"sagittal"``, ``"frontal"``, ``"transverse"``).
        rom: The :mod:`~physmocap.models.rom` degrees of freedom whose ranges add up to it.
    """

    key: str
    joint: str
    positive: str
    negative: str
    plane: str
    rom: tuple[str, ...]

    @property
    def where(self) -> str:
        """The body part a glitch's movement name starts with (``"left knee"``, ``"trunk"``)."""
        return self.joint.replace("_", " ") if self.joint != "spine" else "trunk"


def _sided(side: str) -> list[Movement]:
    return [
        Movement(f"{side}_knee_flexion", f"{side}_knee", "flexion", "hyperextension", "sagittal", (f"{side}_knee_flexion",)),
        Movement(f"{side}_elbow_flexion", f"{side}_elbow", "flexion", "hyperextension", "sagittal", (f"{side}_elbow_flexion",)),
        Movement(f"{side}_hip_flexion", f"{side}_hip", "flexion", "hyperextension", "sagittal", (f"{side}_hip_flexion",)),
        Movement(f"{side}_hip_adduction", f"{side}_hip", "adduction", "abduction", "frontal", (f"{side}_hip_adduction",)),
    ]


MOVEMENTS: tuple[Movement, ...] = (
    *_sided("left"),
    *_sided("right"),
    Movement("trunk_flexion", "spine", "flexion", "extension", "sagittal", ("lumbar_flexion", "thoracic_flexion")),
    Movement(
        "trunk_lateral_flexion", "spine", "lateral flexion", "lateral flexion", "frontal",
        ("lumbar_lateral_flexion", "thoracic_lateral_flexion"),
    ),
    Movement("trunk_rotation", "spine", "rotation", "rotation", "transverse", ("lumbar_rotation", "thoracic_rotation")),
)  # fmt: skip


def movement_range(m: Movement, soft_margin: float = 0.0) -> tuple[float, float]:
    """``(lo, hi)`` degrees: the sum of the ranges of ``m.rom`` (``"default"`` policy),
    widened by ``soft_margin`` in each direction whose range performers exceed (every
    direction but the anatomical stops: knee and elbow hyperextension)."""
    lo = hi = 0.0
    for name in m.rom:
        a, b = joint_range_deg(name, "default")
        lo, hi = lo + a, hi + b
    entry = dof_entry(m.rom[0])
    return lo - (soft_margin if entry.negative.margin else 0.0), hi + (soft_margin if entry.positive.margin else 0.0)


def _bend_axis(
    u: np.ndarray, v: np.ndarray, frame: np.ndarray, fallback: np.ndarray, axis_min_deg: float
) -> np.ndarray:
    """Hinge axis in the proximal frame (see the module docstring): ``(3,)``."""
    n = np.cross(u, v)
    s = np.linalg.norm(n, axis=-1)
    bent = np.isfinite(s) & (s > np.sin(np.radians(axis_min_deg))) & (np.sum(u * v, axis=-1) < np.cos(np.radians(axis_min_deg)))
    if bent.sum() < 3:
        return fallback
    local = np.einsum("fji,fj->fi", frame[bent], _direction(n[bent], 1e-12))  # R^T n
    a = np.median(local, axis=0)
    norm = np.linalg.norm(a)
    return fallback if norm < 0.3 else a / norm


def _signed_bend(u: np.ndarray, v: np.ndarray, frame: np.ndarray, axis: np.ndarray) -> np.ndarray:
    world_axis = np.einsum("fij,j->fi", frame, axis)
    return np.degrees(np.arctan2(np.sum(np.cross(u, v) * world_axis, axis=-1), np.sum(u * v, axis=-1)))


def anatomical_angles(
    P: dict[str, np.ndarray],
    segment_rotations: dict[str, np.ndarray] | None = None,
    calibration_frame: int | None = None,
    axis_min_deg: float = 10.0,
) -> dict[str, np.ndarray]:
    """Movement key -> ``(F,)`` degrees (NaN where undefined), for the movements whose
    joints are present.

    Args:
        P: Canonical joint -> ``(F, 3)`` world positions (metres, Z-up).
        segment_rotations: Canonical joint -> ``(F, 3, 3)`` world rotation of the
            segment that joint drives (``pelvis``: the pelvis, ``left_hip``: the
            thigh, ``left_shoulder``: the upper arm); None for position-only sources.
        calibration_frame: A frame where the actor stands upright
            (:func:`~physmocap.ik.calibration.calibration_pose`): the trunk angles
            are measured from it, and a hinge the clip never bends takes its
            neutral axis there; None: frame 0.
        axis_min_deg: Bend above which a frame informs a hinge's axis.
    """
    out: dict[str, np.ndarray] = {}
    if not all(k in P for k in ("left_hip", "right_hip")):
        return out
    top = next((c for c in ("neck", "chest", "spine") if c in P), None)
    if top is None:
        return out
    pelvis = pelvis_frame(P["left_hip"], P["right_hip"], P[top])
    rot = segment_rotations or {}
    if "pelvis" in rot:  # the pelvis's own tilt (the trunk line also bends at the lumbar spine)
        t0 = calibration_frame or 0
        pelvis = np.einsum("fij,jk->fik", rot["pelvis"], rot["pelvis"][t0].T @ pelvis[t0])
    chest = None
    if all(k in P for k in ("left_shoulder", "right_shoulder")):
        mid = 0.5 * (P["left_hip"] + P["right_hip"])
        chest = chest_frame(P["left_shoulder"], P["right_shoulder"], P[top], mid)
    for side in ("left", "right"):
        hip, knee, ankle = (f"{side}_{j}" for j in ("hip", "knee", "ankle"))
        if all(j in P for j in (hip, knee, ankle)):
            u, v = _direction(P[knee] - P[hip], 1e-12), _direction(P[ankle] - P[knee], 1e-12)
            frame = rot.get(hip, pelvis)
            fallback = np.array([0.0, 1.0, 0.0]) if hip not in rot else None
            if fallback is None:  # the pelvis's left axis in the thigh's frame, at the calibration pose
                t0 = calibration_frame or 0
                fallback = _direction(frame[t0].T @ pelvis[t0][:, 1], 1e-12)
            axis = _bend_axis(u, v, frame, fallback, axis_min_deg)
            out[f"{side}_knee_flexion"] = _signed_bend(u, v, frame, axis)
            # hip: the thigh in the pelvis frame, from the calibration pose
            d = np.einsum("fji,fj->fi", pelvis, u)
            sign = 1.0 if side == "left" else -1.0
            flex = np.degrees(np.arctan2(d[:, 0], -d[:, 2]))
            add = np.degrees(np.arcsin(np.clip(-sign * d[:, 1], -1.0, 1.0)))
            flex = np.where(np.abs(add) <= 60.0, flex, np.nan)
            out[f"{side}_hip_flexion"] = flex
            out[f"{side}_hip_adduction"] = add
        shoulder, elbow, wrist = (f"{side}_{j}" for j in ("shoulder", "elbow", "wrist"))
        if all(j in P for j in (shoulder, elbow, wrist)):
            u, v = _direction(P[elbow] - P[shoulder], 1e-12), _direction(P[wrist] - P[elbow], 1e-12)
            if shoulder in rot:
                frame = rot[shoulder]
                t0 = calibration_frame or 0
                ref = chest if chest is not None else pelvis
                fallback = _direction(frame[t0].T @ -ref[t0][:, 1], 1e-12)
                axis = _bend_axis(u, v, frame, fallback, axis_min_deg)
                out[f"{side}_elbow_flexion"] = _signed_bend(u, v, frame, axis)
            else:  # position-only: unsigned (over-flexion only)
                out[f"{side}_elbow_flexion"] = np.degrees(np.arccos(np.clip(np.sum(u * v, axis=-1), -1.0, 1.0)))
    if chest is not None:
        from scipy.spatial.transform import Rotation

        rel = np.einsum("fji,fjk->fik", pelvis, chest)  # pelvis^T chest
        if calibration_frame is not None:
            rel = np.einsum("ji,fjk->fik", rel[calibration_frame], rel)
        ok = np.all(np.isfinite(rel), axis=(1, 2))
        # a frame whose shoulder line or trunk line has collapsed (a tracker putting both
        # shoulders, or a shoulder and the neck, on one point) has no orientation: no angle
        ok[ok] = np.abs(np.linalg.det(rel[ok]) - 1.0) < 1e-6
        angles = np.full((rel.shape[0], 3), np.nan)
        if ok.any():
            angles[ok] = Rotation.from_matrix(rel[ok]).as_euler("YXZ", degrees=True)
        out["trunk_flexion"], out["trunk_lateral_flexion"], out["trunk_rotation"] = angles.T
    return out


def beyond_range(angle: np.ndarray, lo: float, hi: float) -> list[tuple[int, int, str, float]]:
    """Runs of frames outside ``[lo, hi]``: ``(start, end inclusive, "positive" | "negative",
    largest excess in degrees)``; NaN frames are never outside."""
    a = np.asarray(angle, dtype=float)
    out = []
    for direction, bad in (("positive", a > hi), ("negative", a < lo)):
        bad = np.where(np.isfinite(a), bad, False)
        d = np.diff(np.concatenate([[0], bad.astype(np.int8), [0]]))
        for start, end in zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1) - 1):
            seg = a[start : end + 1]
            excess = float(np.max(seg - hi) if direction == "positive" else np.max(lo - seg))
            out.append((int(start), int(end), direction, excess))
    return sorted(out)


#: Canonical joint centres each movement is read from (``{side}`` is the movement's side;
#: the trunk's carry the pelvis and chest frames).
ANCHORS: dict[str, tuple[str, ...]] = {
    "knee_flexion": ("{side}_hip", "{side}_knee", "{side}_ankle"),
    "elbow_flexion": ("{side}_shoulder", "{side}_elbow", "{side}_wrist"),
    "hip_flexion": ("left_hip", "right_hip", "{side}_knee"),
    "hip_adduction": ("left_hip", "right_hip", "{side}_knee"),
    "trunk_flexion": ("left_hip", "right_hip", "left_shoulder", "right_shoulder", "neck"),
    "trunk_lateral_flexion": ("left_hip", "right_hip", "left_shoulder", "right_shoulder", "neck"),
    "trunk_rotation": ("left_hip", "right_hip", "left_shoulder", "right_shoulder", "neck"),
}

#: Canonical joints whose segment's world rotation the angles use (rotational sources).
ROTATED_SEGMENTS = ("pelvis", "left_hip", "right_hip", "left_shoulder", "right_shoulder")


def motion_angles(
    motion, joint_indices: dict[str, int], unreliable: np.ndarray | None = None
) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """``(angles, positions)`` of a :class:`~physmocap.motion.Motion`: movement key ->
    ``(F,)`` degrees (:func:`anatomical_angles`, calibrated on the clip's most upright
    frame), and canonical joint -> ``(F, 3)`` world positions.

    ``unreliable (F,)``: frames not to calibrate on (another glitch moves the joints there:
    the trunk angles of the whole clip are measured from the calibration frame, so one
    taken inside a left/right swap of the shoulders reads every frame as twisted 105
    degrees); every frame is a candidate again where all are unreliable."""
    from scipy.spatial.transform import Rotation

    from ..ik.calibration import calibration_pose

    world = motion.world_positions()
    P = {k: world[:, j] for k, j in joint_indices.items()}
    rot = None
    if motion.is_rotational:
        Q = motion.world_rotations()
        rot = {k: Rotation.from_quat(Q[:, joint_indices[k]]).as_matrix() for k in ROTATED_SEGMENTS if k in joint_indices}
    if not P:
        return {}, P
    usable = P
    if unreliable is not None and unreliable.any() and not unreliable.all():
        usable = {k: np.where(unreliable[:, None], np.nan, v) for k, v in P.items()}
    return anatomical_angles(P, rot, calibration_pose({}, usable).frame), P


def bend_past_range(motion, joint: str, frames, excess: float) -> tuple[int, np.ndarray] | None:
    """An anatomical glitch for evaluation: knee or elbow ``joint`` (``"left_knee"``...) of a
    rotational ``motion`` bent backwards ``excess`` degrees past its range of motion on
    ``frames``, turned about its own bend axis so that :func:`anatomical_angles` reads
    exactly that.

    Returns ``(source joint index, its new local rotations (n, 4) x-y-z-w)`` (the motion
    is not modified), or None when the joints are not mapped or the limb is never bent
    (no bend axis; on a frame where it is straight, the nearest bent frame's axis is used)."""
    from scipy.spatial.transform import Rotation

    from ..ik.retarget import map_motion

    side, limb = joint.split("_", 1)
    chain = ("hip", "knee", "ankle") if limb == "knee" else ("shoulder", "elbow", "wrist")
    names = [f"{side}_{x}" for x in chain]
    ji = map_motion(motion)
    if not all(x in ji for x in names):
        return None
    angles, P = motion_angles(motion, ji)
    key = f"{side}_{limb}_flexion"
    movement = next(m for m in MOVEMENTS if m.key == key)
    lo, _ = movement_range(movement)
    j = ji[names[1]]
    parent = int(motion.skeleton.parents[j])
    Q = motion.world_rotations()
    frames = list(frames)
    u = P[names[1]] - P[names[0]]
    v = P[names[2]] - P[names[1]]
    k = np.cross(u, v)
    theta = angles[key]
    ok = (np.linalg.norm(k, axis=-1) > 1e-3 * np.linalg.norm(u, axis=-1) * np.linalg.norm(v, axis=-1)) & np.isfinite(theta)
    if not ok.any():
        return None
    # the signed angle's axis on every frame; where the limb is straight, the nearest bent frame's
    axes = k / np.maximum(np.linalg.norm(k, axis=-1, keepdims=True), 1e-12) * np.where(theta >= 0, 1.0, -1.0)[:, None]
    good = np.flatnonzero(ok)
    nearest = good[np.clip(np.searchsorted(good, np.arange(len(ok))), 0, len(good) - 1)]
    axes = np.where(ok[:, None], axes, axes[nearest])
    out = np.empty((len(frames), 4))
    for i, t in enumerate(frames):
        if not np.isfinite(theta[t]):
            return None
        axis = axes[t]
        turn = Rotation.from_rotvec(np.radians((lo - excess) - theta[t]) * axis).as_matrix()
        Wp = Rotation.from_quat(Q[t, parent]).as_matrix()
        local = Rotation.from_quat(motion.rotations[t, j]).as_matrix()
        out[i] = Rotation.from_matrix(Wp.T @ turn @ Wp @ local).as_quat()
    return j, out
