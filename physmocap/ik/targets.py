"""IK targets that fit the character: positions and orientations per tracked joint.

The actor's canonical joints (from the name mapping) are turned into targets
for the character's tracked sites without distorting the motion when the two
have different proportions:

* **Root.** The pelvis target is the actor's pelvis with its height above the
  actor's floor and its horizontal travel (from the first frame) scaled by
  :math:`k = h_c / h_a`, the ratio of the character's and the actor's hip
  heights (measured as leg length, hip to knee to ankle, plus ankle height in
  the rest pose), so stride length matches the character.
* **Rigid torso segments.** A joint whose parent is a torso segment with an
  orientation target (pelvis, chest, head) is placed at the parent's target
  plus the character's own rest offset rotated by the parent's target
  orientation: :math:`T_c = T_p + R_p(t) R_{p,0}^{-1} (x_{c,0} - x_{p,0})`.
  The hips therefore sit where the character's pelvis puts them.
* **Limbs.** Any other joint walks the character's chain: parent target plus
  the character's segment length along the actor's segment direction,
  :math:`T_c = T_p + L^{char}_{pc}\\, \\widehat{(a_c - a_p)}`.
* **Orientations** (pelvis, chest, head, wrists, ankles by default).  For
  rotational sources (BVH) the actor's world rotation :math:`R_a(t)` of the
  segment is calibrated once against the character's rest pose:
  :math:`R_c^{target}(t) = R_a(t)\\, R_{a,0}^{-1}\\, M\\, Y\\, R_{c,0}`, where
  :math:`Y` is the yaw from the character's facing to the actor's rest
  facing and :math:`M` the smallest rotation taking the character's rest
  segment direction (after :math:`Y`) onto the actor's (T-pose arms versus
  arms-down, for example).  For positional sources the same formula uses
  frames built from positions (:mod:`physmocap.frames`) on both sides.
  A character whose foot has no toe joint follows the actor's ankle-to-toe-tip
  line rather than the foot segment (:mod:`physmocap.ik.rigidfoot`), and its
  ball target turns with it.

All quantities are metres and radians, Z-up, quaternions x-y-z-w.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from functools import partial
from typing import Callable

import numpy as np

from ..canonical import CANONICAL_NAMES, canonical_parent
from ..options import check_fields
from ..errors import MappingError, OptionError, warn
from ..motion import Motion
from ..rotations import Rotation, quat_apply, quat_between, quat_conj, quat_mul, quat_to_rotvec
from ..spill import blocks, is_spilled, release, spilled_copy, spilled_empty
from .calibration import POSE_JOINTS, CalibrationPose, calibration_pose
from .limbtwist import LIMB_CHAINS, MIN_BEND, FlexionAxis, TwistCalibration, flexion_axis, follow_bend
from .rigidfoot import tip_reference, toe_line_correction
from .trunkreach import SMOOTHING_TIME, TrunkReach, trunk_reach
from ..vectors import unit

__all__ = ["Calibration", "Targets", "TargetOptions", "build_targets", "character_rest_frames", "DEFAULT_WEIGHTS"]

#: Default task weights: (position cost per metre, orientation cost per radian).
DEFAULT_WEIGHTS: dict[str, tuple[float, float]] = {
    "pelvis": (10.0, 3.0),
    "spine": (1.0, 0.0),
    "chest": (2.0, 1.0),
    "neck": (1.0, 0.0),
    "head": (2.0, 0.5),
    "head_end": (0.5, 0.0),
    "clavicle": (0.5, 0.0),
    "shoulder": (3.0, 0.2),
    "elbow": (5.0, 0.0),
    "wrist": (5.0, 0.3),
    "hand_end": (1.0, 0.0),
    "hip": (5.0, 0.0),
    "knee": (5.0, 0.0),
    "ankle": (8.0, 1.0),
    "toe": (3.0, 0.0),
    "toe_end": (2.0, 0.0),
}

ORIENTED = (
    "pelvis", "chest", "head", "left_shoulder", "right_shoulder", "left_wrist", "right_wrist", "left_ankle", "right_ankle",
)
RIGID_PARENTS = ("pelvis", "chest", "head")
#: Joints placed rigidly with a torso segment (not along the actor's segment direction).
RIGID_SEGMENT = {
    "spine": "pelvis",
    "left_hip": "pelvis",
    "right_hip": "pelvis",
    # the neck follows the actor's chest-to-neck direction (a rotating neck joint may sit between)
    "left_clavicle": "chest",
    "right_clavicle": "chest",
    "left_shoulder": "chest",
    "right_shoulder": "chest",
    "head_end": "head",
}
#: A character without a chest carries the upper torso on its spine (or pelvis).
TORSO_BELOW = {"chest": ("spine", "pelvis")}
#: Source joints whose rotation turns the upper torso when there is no chest, highest first.
TORSO_CARRIERS = ("spine", "pelvis")
#: Frames of the actor's kinematics held at once while the targets' inputs are gathered.
BLOCK_FRAMES = 1024


def weight_of(name: str) -> tuple[float, float]:
    stem = name.split("_", 1)[1] if name.startswith(("left_", "right_")) else name
    return DEFAULT_WEIGHTS.get(stem, (1.0, 0.0))


@dataclass
class TargetOptions:
    """How targets are built.

    Attributes:
        scale_root: Scale the root's travel and height by the hip-height ratio.
        oriented: Canonical joints that get an orientation target where the
            source has one.
        source_floor: Height of the actor's floor in the source (metres); None
            estimates it from the clip.
    """

    scale_root: bool = True
    oriented: tuple[str, ...] = ORIENTED
    source_floor: float | None = None

    def __post_init__(self) -> None:
        check_fields(self, "target")
        if self.source_floor is not None and (
            isinstance(self.source_floor, bool)
            or not isinstance(self.source_floor, (int, float))
            or not math.isfinite(self.source_floor)
        ):
            raise OptionError(f"target option source_floor must be a finite number (metres), got {self.source_floor!r}")


@dataclass(eq=False)
class Calibration:
    """The one-time quantities of :func:`build_targets`, reusable frame by frame.

    A streaming retargeter calibrates on its first frame(s) and then builds
    each frame's targets with the same values, so offline and streaming
    targets follow the same maths; the upper arms' twist calibrations
    (``limb_twists``, :class:`~physmocap.ik.limbtwist.TwistCalibration`) go on
    learning from the frames of every call, and their ``orientation_offsets``
    with them.  All metres / quaternions x-y-z-w.
    """

    def restart_twists(self) -> None:
        """Forget what the twist calibrations learnt (their frames are to be given again):
        their sums to zero, their offsets back to the rest-pose calibration."""
        for c, twist in self.limb_twists.items():
            twist.sin = twist.cos = 0.0
            self.orientation_offsets[c] = twist.base

    rest: dict
    present: tuple[str, ...]
    scale: float
    floor: float
    yaw: np.ndarray
    movable: dict
    orientation_offsets: dict
    start_xy: np.ndarray
    ankle_actor: float
    ankle_character: float
    actor_points: dict = field(default_factory=dict)
    pose_rotations: dict = field(default_factory=dict)
    pose: CalibrationPose | None = None
    level: np.ndarray | None = None
    level_centre: np.ndarray | None = None
    info: dict = field(default_factory=dict)
    foot_tips: dict = field(default_factory=dict)  # side -> toe-tip direction in the foot's frame (rigidfoot)
    limb_axes: dict = field(default_factory=dict)  # limb's upper segment -> its FlexionAxis or None (limbtwist)
    limb_twists: dict = field(default_factory=dict)  # limb's upper segment -> its TwistCalibration (limbtwist)
    trunk_reach: TrunkReach | None = None  # the trunk directions the torso joints reach (trunkreach)
    trunk_turns: deque | None = None  # a stream's last pelvis turns, averaged (TrunkReach.give_way)
    bone_lengths: dict = field(default_factory=dict)  # joint -> the character's rest distance to its parent (m)


@dataclass(eq=False)
class Targets:
    """Per-frame targets for the character's tracked frames.

    Attributes:
        names: Canonical joints that are tracked (mapped in source and character).
        positions: ``(F, N, 3)`` target positions, metres, character world.
        orientations: ``(F, N, 4)`` target orientations x-y-z-w (identity where none).
        has_orientation: ``(N,)`` which joints have an orientation target.
        valid: ``(F, N)`` False where the source lost the joint (task off that frame).
        fps: Frames per second.
        scale: Root scale factor :math:`k` used.
        source_positions: ``(F, N, 3)`` the actor's joints in the source world
            (metres; 0 where lost); recomputed when read after
            :meth:`release_source_positions`.
        source_recipe: How :func:`build_targets` recomputes ``source_positions`` from
            the motion (None for targets built from given kinematics or by hand).
    """

    names: tuple[str, ...]
    positions: np.ndarray
    orientations: np.ndarray
    has_orientation: np.ndarray
    valid: np.ndarray
    fps: float
    scale: float = 1.0
    source_positions: np.ndarray | None = None
    info: dict = field(default_factory=dict)
    calibration: Calibration | None = None
    source_recipe: Callable[[], np.ndarray] | None = field(default=None, repr=False)

    @property
    def num_frames(self) -> int:
        return int(self.positions.shape[0])

    def index(self, name: str) -> int:
        return self.names.index(name)

    def release_source_positions(self) -> bool:
        """Stop holding ``source_positions`` (``24 N`` bytes per frame) when they can be
        recomputed: reading them again runs the actor's kinematics again (the same
        numbers, the same memory layout).  False, and kept, without a recipe."""
        if self.source_recipe is None:
            return False
        self.__dict__["_source_positions"] = None
        return True


def _get_source_positions(self: Targets) -> np.ndarray | None:
    held = self.__dict__.get("_source_positions")
    return self.source_recipe() if held is None and self.source_recipe is not None else held


def _set_source_positions(self: Targets, value: np.ndarray | None) -> None:
    self.__dict__["_source_positions"] = value


# a property over the dataclass field: held, or recomputed once released
Targets.source_positions = property(_get_source_positions, _set_source_positions)  # type: ignore[assignment]


def _masked_positions(positions: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """The actor's positions with 0 where the joint is lost (``valid`` False)."""
    return np.where(valid[..., None], positions, 0.0)


def _mask_lost(S: np.ndarray, motion: Motion, idx: np.ndarray) -> np.ndarray:
    """``(F, N)`` False where the actor lost a joint (not finite, or no confidence), laid out
    as numpy lays out ``np.all(np.isfinite(S), axis=-1)``; ``S`` is set to 0 there, in place.
    A block of frames at a time (a spilled ``S``: its pages let go after each block)."""
    valid = np.empty(S.shape[1::-1], dtype=bool).T  # joint-major, as S
    for s, rows in blocks(S, BLOCK_FRAMES):
        ok = valid[s : s + rows.shape[0]]
        np.all(np.isfinite(rows), axis=-1, out=ok)
        if motion.confidence is not None:
            ok &= motion.confidence[s : s + rows.shape[0], idx] > 0.0
        rows[~ok] = 0.0
    return valid


def _source_positions_again(motion: Motion, idx: np.ndarray, level: np.ndarray | None, centre: np.ndarray | None,
                            valid: np.ndarray) -> np.ndarray:
    """``Targets.source_positions`` recomputed from the motion, as :func:`build_targets` computed them."""
    return _masked_positions(_ActorKinematics(motion, idx, [], level, centre).positions, valid)


def character_rest_frames(character) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Canonical joint -> (rest world position, rest world quaternion xyzw) of the character."""
    model = character.model
    data = character.rest_data()
    out = {}
    for canon, tf in character.tracked.items():
        out[canon] = (tf.position(model, data).copy(), Rotation.from_matrix(tf.rotation(model, data)).as_quat())
    return out


def _yaw_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Quaternion (xyzw) of the rotation about Z taking horizontal direction a to b."""
    ang = np.arctan2(b[1], b[0]) - np.arctan2(a[1], a[0])
    return Rotation.from_rotvec([0.0, 0.0, ang]).as_quat()


def _min_rotation(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Smallest rotation (xyzw) taking unit vector a onto unit vector b."""
    a = a / np.linalg.norm(a)
    b = b / np.linalg.norm(b)
    axis = np.cross(a, b)
    s = np.linalg.norm(axis)
    c = float(np.dot(a, b))
    if s < 1e-9:
        if c > 0:
            return np.array([0.0, 0.0, 0.0, 1.0])
        perp = np.cross(a, [1.0, 0.0, 0.0])
        if np.linalg.norm(perp) < 1e-6:
            perp = np.cross(a, [0.0, 1.0, 0.0])
        return Rotation.from_rotvec(np.pi * perp / np.linalg.norm(perp)).as_quat()
    return Rotation.from_rotvec(axis / s * np.arctan2(s, c)).as_quat()


def _facing(left_hip: np.ndarray, right_hip: np.ndarray) -> np.ndarray:
    """Horizontal forward direction from the hip line: forward = left x up."""
    left = left_hip - right_hip
    fwd = np.cross(left, [0.0, 0.0, 1.0])
    fwd[2] = 0.0
    n = np.linalg.norm(fwd)
    if n < 1e-9:
        raise MappingError("cannot tell which way the skeleton faces: its hips coincide")
    return fwd / n


#: The segment direction that calibrates each torso segment's rest posture.
TORSO_UP = {"spine": ("chest", "neck"), "chest": ("neck", "head")}
#: The torso segments whose calibration the head takes, nearest first: the head is held
#: neutral on the trunk in the calibration pose.  Its own "top of the head" is no
#: direction to calibrate on: vendors put it anywhere (Mixamo's HeadTop_End sits 17-19
#: degrees forward of the head joint, CMU's end site 2-7 degrees back), and aligning the
#: character's head-to-top direction on it bowed the character's head by that much.
HEAD_CARRIERS = ("chest", "spine", "pelvis")


def _rest_alignment(c: str, present: set, actor_pts: dict, char_pts: dict, yaw: np.ndarray) -> np.ndarray:
    """Smallest rotation taking the character's rest segment direction (after the
    facing yaw) onto the actor's rest segment direction, x-y-z-w.

    The segment runs from ``c`` to its first canonical child (limbs) or up the
    torso (:data:`TORSO_UP`; the pelvis on the trunk line; the head as the torso segment
    carrying it, :data:`HEAD_CARRIERS`); a limb's end with no child
    on both sides, from its parent to ``c``.  It calibrates a
    rest posture that differs between actor and character: T-pose arms against
    arms down, a rest spine that leans.
    """
    ident = np.array([0.0, 0.0, 0.0, 1.0])
    if c == "head":
        carrier = next((x for x in HEAD_CARRIERS if x in present), None)
        return ident if carrier is None else _rest_alignment(carrier, present, actor_pts, char_pts, yaw)
    if c == "pelvis":
        # The pelvis is aligned on the whole trunk line, pelvis to neck (the spine's lean,
        # as the eye and the fidelity figures read it; the torso segments between have
        # other proportions on every skeleton).  Not the line from the hip centres:
        # skeletons place those differently relative to the pelvis joint (CMU's sit 6 cm in
        # front of it and 9 cm below, as in real anatomy; the humanoid's and the robot's
        # straight below), and a character aligned on the actor's hip-to-neck line leaned
        # back 7-9 degrees where the actor stood upright.
        # Without a neck or a head the top is a chest or spine joint a few centimetres above
        # the pelvis joint (the Unitree G1's waist 4 cm): too short a lever to set a tilt by,
        # so the line runs from the hip centres there, as it did everywhere before stop 37.
        top = next((x for x in ("neck", "head", "chest", "spine") if x in present), None)
        if top is None:
            return ident
        if top in ("neck", "head"):
            base_a, base_c = actor_pts["pelvis"], char_pts["pelvis"]
        elif "left_hip" in present and "right_hip" in present:
            base_a = 0.5 * (actor_pts["left_hip"] + actor_pts["right_hip"])
            base_c = 0.5 * (char_pts["left_hip"] + char_pts["right_hip"])
        else:
            return ident
        d_a = actor_pts[top] - base_a
        d_c = quat_apply(yaw, char_pts[top] - base_c)
        if np.linalg.norm(d_a) < 1e-6 or np.linalg.norm(d_c) < 1e-6:
            return ident
        return _min_rotation(d_c, d_a)
    if c in TORSO_UP:
        child = next((x for x in TORSO_UP[c] if x in present), None)
    else:
        child = _first_child(c, present)
    if child is not None:
        d_a = actor_pts[child] - actor_pts[c]
        d_c = quat_apply(yaw, char_pts[child] - char_pts[c])
    elif c not in TORSO_UP and canonical_parent(c, present) is not None:
        # a limb's end without a child on both sides (a hand without finger joints): it turns
        # with the limb ending at it (a wrist is near neutral in a calibration pose), not left
        # as the character's rest hand, which calibrated on an actor whose forearms point up
        # (a boxing guard) asked for a wrist bent by 180 degrees
        return _limb_alignment(c, present, actor_pts, char_pts, yaw)
    else:
        return ident
    if np.linalg.norm(d_a) < 1e-6 or np.linalg.norm(d_c) < 1e-6:
        return ident
    return _min_rotation(d_c, d_a)


def _limb_alignment(c: str, present: set, actor_pts: dict, char_pts: dict, yaw: np.ndarray) -> np.ndarray:
    r"""The rotation that takes the character's rest limb ending at ``c`` onto the actor's,
    x-y-z-w, following the chain: the upper segment (grandparent to parent, the upper arm)
    by its smallest rotation :math:`M_1`, then the lower one (parent to ``c``, the forearm)
    about the actor's hinge axis :math:`\hat n \propto a_1 \times a_2` by the angle that
    takes :math:`M_1 c_2` onto :math:`a_2`.

    The twist about the lower segment then comes from the actor's bent elbow, not from the
    smallest rotation between two nearly opposite directions (a character's forearm hanging
    at rest, an actor's raised), which is arbitrary about them.  A limb bent less than
    :data:`~physmocap.ik.limbtwist.MIN_BEND` (no hinge plane: the one threshold of the
    upper arm's twist calibration too) or without its upper segment falls back to the
    smallest rotation of the lower segment.
    """
    p = canonical_parent(c, present)
    a2, c2 = actor_pts[c] - actor_pts[p], quat_apply(yaw, char_pts[c] - char_pts[p])
    if np.linalg.norm(a2) < 1e-6 or np.linalg.norm(c2) < 1e-6:
        return np.array([0.0, 0.0, 0.0, 1.0])
    g = canonical_parent(p, present)
    if g is None:
        return _min_rotation(c2, a2)
    a1, c1 = actor_pts[p] - actor_pts[g], quat_apply(yaw, char_pts[p] - char_pts[g])
    if np.linalg.norm(a1) < 1e-6 or np.linalg.norm(c1) < 1e-6:
        return _min_rotation(c2, a2)
    M1 = _min_rotation(c1, a1)
    b2 = quat_apply(M1, c2)
    n = np.cross(a1, a2)
    if np.linalg.norm(n) < np.sin(MIN_BEND) * np.linalg.norm(a1) * np.linalg.norm(a2):
        return quat_mul(_min_rotation(b2, a2), M1)  # a nearly straight limb: no hinge plane
    n = n / np.linalg.norm(n)
    b, a = b2 - np.dot(b2, n) * n, a2 - np.dot(a2, n) * n
    angle = np.arctan2(np.dot(np.cross(b, a), n), np.dot(b, a))
    hinge = Rotation.from_rotvec(angle * n).as_quat()
    # what the hinge leaves of the lower segment off the plane, by its smallest rotation
    rest = _min_rotation(quat_apply(hinge, b2), a2)
    return quat_mul(rest, quat_mul(hinge, M1))


def _limb_chain(character, c: str, present: set, axes: dict) -> tuple[str, str, FlexionAxis] | None:
    """``(middle, end, axis)`` of a limb's upper segment ``c`` whose middle joint is a
    hinge on the character (:mod:`physmocap.ik.limbtwist`), else None; the axis is
    found once and kept in ``axes`` (the calibration's, its sign settled there)."""
    side, _, stem = c.partition("_")
    chain = LIMB_CHAINS.get(stem)
    if not side or chain is None:
        return None
    middle, end = (f"{side}_{x}" for x in chain)
    if middle not in present or end not in present:
        return None
    if c not in axes:
        axes[c] = flexion_axis(character, c, middle, end)
    return None if axes[c] is None else (middle, end, axes[c])


def _relative_to_pose(pose_rot: dict[str, np.ndarray], c: str, q: np.ndarray) -> np.ndarray:
    """:math:`R_a(t_c)^{-1} q`: an offset applied after the actor's world rotation, relative to
    the calibration pose (identity at the rest pose)."""
    r = pose_rot.get(c)
    return q if r is None else quat_mul(quat_conj(r), q)


def _median_leg(S: np.ndarray, valid: np.ndarray, col: dict, side: str) -> float | None:
    """Median over frames of hip-knee plus knee-ankle length (metres), or None."""
    chain = [f"{side}_hip", f"{side}_knee", f"{side}_ankle"]
    if not all(c in col for c in chain):
        return None
    i, j, k = (col[c] for c in chain)
    ok = valid[:, i] & valid[:, j] & valid[:, k]
    if not ok.any():
        return None
    length = np.linalg.norm(S[ok, i] - S[ok, j], axis=-1) + np.linalg.norm(S[ok, j] - S[ok, k], axis=-1)
    return float(np.median(length))


def _positional_orientations(S: np.ndarray, col: dict, present: set, char_pts: dict) -> dict[str, np.ndarray]:
    """Pelvis and chest orientations built from positions (:mod:`physmocap.frames`),
    with the same construction on the character's rest pose under ``"<name>@rest"``."""
    from ..frames import chest_frame, matrix_to_quat, pelvis_frame

    out: dict[str, np.ndarray] = {}
    spine = next((c for c in ("spine", "chest", "neck") if c in present), None)
    if spine and "left_hip" in present and "right_hip" in present:
        def pelvis(p):
            return matrix_to_quat(pelvis_frame(p("left_hip"), p("right_hip"), p(spine)))

        out["pelvis"] = pelvis(lambda c: S[:, col[c]])
        out["pelvis@rest"] = pelvis(lambda c: char_pts[c])
    top = next((c for c in ("neck", "head") if c in present), None)
    # the long pelvis-to-neck axis: robust to where a tracker puts its "torso" joint
    bottom = next((c for c in ("pelvis", "spine", "chest") if c in present), None)
    if top and bottom and "left_shoulder" in present and "right_shoulder" in present:
        def chest(p):
            return matrix_to_quat(chest_frame(p("left_shoulder"), p("right_shoulder"), p(top), p(bottom)))

        out["chest"] = chest(lambda c: S[:, col[c]])
        out["chest@rest"] = chest(lambda c: char_pts[c])
    return out


def _frame_body(character, name: str) -> int:
    return character.tracked[name].body_id(character.model)


def _has_dofs_between(character, child: str, parent: str | None) -> bool:
    """True if some joint moves ``child``'s frame relative to ``parent``'s frame."""
    if parent is None:
        return True
    m = character.model
    b, top = _frame_body(character, child), _frame_body(character, parent)
    ancestors = set()
    a = top
    while a > 0:
        ancestors.add(a)
        a = int(m.body_parentid[a])
    while b > 0 and b not in ancestors:
        if m.body_jntnum[b] > 0:
            return True
        b = int(m.body_parentid[b])
    return False


def _ankle_heights(S, valid, col, char_pts, floor, floor_s, present) -> tuple[float, float]:
    """Ankle joint height above the floor in stance: ``(actor, character)`` in metres.

    The actor's comes from contact detection's stance levels of the heel points
    (the ankle joints) where available, else from the 5th percentile of the
    ankles' heights over the clip; the character's from its rest pose (sole on
    z = 0).
    """
    sides = [s for s in ("left", "right") if f"{s}_ankle" in present]
    if not sides:
        return 0.0, 0.0
    ankle_c = float(np.mean([char_pts[f"{s}_ankle"][2] for s in sides]))
    levels = getattr(floor, "levels", None) or {}
    lv = [levels[f"{s}_heel"] for s in sides if f"{s}_heel" in levels]
    if lv:
        return float(np.mean(lv)), ankle_c
    z = [S[valid[:, col[f"{s}_ankle"]], col[f"{s}_ankle"], 2] for s in sides]
    z = np.concatenate(z)
    ankle_a = float(np.percentile(z, 5) - floor_s) if z.size else ankle_c
    return ankle_a, ankle_c


class _ActorKinematics:
    r"""The actor's world kinematics that the targets read, levelled onto the character's floor.

    Forward kinematics runs :data:`BLOCK_FRAMES` frames at a time and keeps only the
    positions of the tracked joints and the world rotations of the joints that turn
    targets, so the whole skeleton's kinematics is never held (each frame is computed
    on its own: the same numbers as one pass over the clip).  The floor levelling is
    :math:`x \mapsto L (x - c) + (c_x, c_y, 0)`, :math:`R \mapsto L R` (``level`` L,
    ``centre`` c; none without a level).

    Attributes:
        positions: ``(F, N, 3)`` world positions (metres) of the joints ``idx``.
        extra: Source joint -> ``(F, 3)`` world positions of the joints ``extra``
            (read by the targets, not tracked: the toe tips of a rigid foot).
        rotations: Source joint -> ``(F, 4)`` world rotation x-y-z-w of the joints
            ``turning``, or None for a positional source (or kinematics without rotations).
    """

    def __init__(self, motion: Motion, idx: np.ndarray, turning: list[int], level: np.ndarray | None,
                 centre: np.ndarray | None, kinematics: tuple[np.ndarray, np.ndarray | None] | None = None,
                 extra: list[int] | None = None) -> None:
        self.motion, self.level, self.centre, self.kinematics = motion, level, centre, kinematics
        F = motion.num_frames
        # laid out joint-major, as numpy lays out ``positions[:, idx]`` (the clip's joints picked
        # from the whole skeleton's kinematics): arrays derived from it (``valid``) keep that
        # layout, and the NPZ writer records it (``fortran_order``), so outputs keep their bytes
        # a long clip's in a temporary file (:func:`~physmocap.spill.spilled_empty`), each block's
        # pages let go once written
        self.positions = spilled_empty((F, len(idx), 3), by_column=True)
        rotational = motion.is_rotational and (kinematics is None or kinematics[1] is not None)
        # the rotations and the extra joints' positions likewise, column by column: a reader
        # maps in the columns it reads (and lets them go with release(self.store))
        self.store, self.rotations = _columns(F, turning, 4) if rotational else (None, None)
        self.extra_store, self.extra = _columns(F, extra or [], 3)
        for s in range(0, F, BLOCK_FRAMES):
            e = min(F, s + BLOCK_FRAMES)
            pos, rot = self._block(s, e)
            self.positions[s:e] = pos[:, idx]
            for j, out in self.extra.items():
                out[s:e] = pos[:, j]
            for j, out in (self.rotations or {}).items():
                out[s:e] = rot[:, j]
            for array in (self.positions, self.store, self.extra_store):
                release(array)

    def release(self) -> None:
        """Unmap the pages read so far of every spilled array held (their data stay)."""
        for array in (self.positions, self.store, self.extra_store):
            release(array)

    def _block(self, s: int, e: int) -> tuple[np.ndarray, np.ndarray | None]:
        """Levelled ``(positions (n, J, 3), rotations (n, J, 4) or None)`` of frames ``[s, e)``."""
        if self.kinematics is not None:
            pos, rot = self.kinematics[0][s:e], None if self.kinematics[1] is None else self.kinematics[1][s:e]
        else:
            pos, rot = self.motion.slice_frames(s, e).forward_kinematics()
        if self.level is None:
            return pos, rot
        assert self.centre is not None
        pos = quat_apply(self.level, pos - self.centre) + np.array([self.centre[0], self.centre[1], 0.0])
        return pos, None if rot is None else quat_mul(self.level, rot)

    def frame_rotations(self, frame: int, joints: list[int]) -> list[np.ndarray]:
        """The levelled world rotations ``(4,)`` of ``joints`` on one frame."""
        _, rot = self._block(frame, frame + 1)
        assert rot is not None
        return [rot[0, j] for j in joints]


def orientation_array(columns: dict[int, np.ndarray], frames: int, n: int) -> np.ndarray:
    """``(frames, n, 4)`` orientations x-y-z-w: ``columns`` (target column -> ``(frames, 4)``)
    where given, the identity elsewhere; written a block of frames at a time into an array
    kept in a temporary file for a long clip (:func:`~physmocap.spill.spilled_empty`; spilled
    ``columns``' pages are let go after each block too)."""
    out = spilled_empty((frames, n, 4))
    for s, rows in blocks(out):
        rows[..., 3] = 1.0
        for i, q in columns.items():
            rows[:, i] = q[s : s + rows.shape[0]]
            release(q)
    return out


def _columns(frames: int, keys: list[int], width: int) -> tuple[np.ndarray, dict[int, np.ndarray]]:
    """``(store, key -> store[:, k])``: one ``(frames, width)`` column per key (zeros, each
    C-contiguous), in one array laid out column by column, in a temporary file for a long
    clip (:func:`~physmocap.spill.spilled_empty`): a reader maps in only the columns it
    reads until :func:`~physmocap.spill.release`."""
    store = spilled_empty((frames, len(keys), width), by_column=True)
    return store, {key: store[:, k] for k, key in enumerate(keys)}


def _continuous_signs(q: np.ndarray) -> np.ndarray:
    """``q`` (``(F, 4)`` x-y-z-w), in place, each quaternion negated where needed so that
    consecutive frames' dot products are not negative (the same rotations)."""
    if len(q) < 2:
        return q  # one frame (a stream's): nothing to follow
    d = np.sum(q[1:] * q[:-1], axis=-1)
    flip = np.cumsum(d < 0) % 2 == 1
    q[1:][flip] *= -1.0
    return q


class _ColumnStore:
    """Whole-clip ``(F, 4)`` columns kept as they are finished in one array laid out column by
    column, in a temporary file for a long clip (:func:`~physmocap.spill.spilled_empty`): a
    reader maps in only the columns it reads until :meth:`release`.  Every :meth:`keep` takes
    a new column (an earlier one may still be read under another name), up to ``columns``."""

    def __init__(self, frames: int, columns: int) -> None:
        self.array = spilled_empty((frames, columns, 4), by_column=True)
        self.used = 0

    def keep(self, q: np.ndarray) -> np.ndarray:
        """A new column holding ``q`` (``(F, 4)``; the same values, C-contiguous), the pages
        written let go."""
        out = self.array[:, self.used]
        self.used += 1
        out[:] = q
        self.release()
        return out

    def release(self) -> None:
        """Unmap the pages read or written so far (:func:`~physmocap.spill.release`; the data stay)."""
        release(self.array)


def _rigid_foot_tips(motion: Motion, joint_indices: dict[str, int], character, pset: set[str],
                     opt: TargetOptions, cal: Calibration | None) -> dict[str, int]:
    """Side -> the actor's toe-tip joint, for each foot the character carries rigidly
    (:mod:`physmocap.ik.rigidfoot`): an oriented ankle with no joint between it and the
    character's foremost mapped foot point, on a rotational source that has toe tips."""
    if not motion.is_rotational:
        return {}
    out = {}
    for side in ("left", "right"):
        ankle, toe, tip = f"{side}_ankle", f"{side}_toe", f"{side}_toe_end"
        if ankle not in pset or ankle not in opt.oriented or tip not in joint_indices:
            continue
        if cal is not None and side not in cal.foot_tips:
            continue
        front = tip if tip in pset else (toe if toe in pset else None)
        if front is not None and _has_dofs_between(character, front, ankle):
            continue  # the character bends at its own toes
        out[side] = int(joint_indices[tip])
    return out


def _tip_reference(motion: Motion, pose, pose_rot: dict, S: np.ndarray, S_rest: np.ndarray, col: dict,
                   ankle: str, tip: int, actor: "_ActorKinematics") -> np.ndarray | None:
    """The actor's toe-tip direction in its foot's frame in the calibration pose: the rest
    pose (BVH rest world rotations are the identity) or the chosen frame."""
    if pose is None or pose.frame is None:
        rest_tip = motion.skeleton.rest_positions()[tip]
        return tip_reference(np.array([0.0, 0.0, 0.0, 1.0]), S_rest[col[ankle]], rest_tip)
    if ankle not in pose_rot:
        return None
    return tip_reference(pose_rot[ankle], S[pose.frame, col[ankle]], actor.extra[tip][pose.frame])


def _first_child(name: str, present: set[str]) -> str | None:
    for c in CANONICAL_NAMES:
        if c in present and canonical_parent(c, present) == name:
            return c
    return None


def build_targets(
    motion: Motion,
    joint_indices: dict[str, int],
    character,
    options: TargetOptions | None = None,
    source_orientations: dict[str, np.ndarray] | None = None,
    floor=None,
    calibration: Calibration | None = None,
    kinematics: tuple[np.ndarray, np.ndarray | None] | None = None,
) -> Targets:
    """Build the character's IK targets from a motion.

    Args:
        motion: The actor's motion (metres, Z-up).
        joint_indices: Canonical joint -> joint index in ``motion.skeleton``
            (``JointMap.indices``).
        character: A :class:`physmocap.models.Character`.
        options: :class:`TargetOptions`.
        source_orientations: For positional sources, canonical joint ->
            ``(F, 4)`` world orientations built from positions, with the same
            construction applied to the character's rest pose under the key
            ``"<name>@rest"`` (``(4,)``).  Rotational sources need none.
        floor: The actor's floor (:class:`physmocap.ik.contacts.FloorPlane`)
            as estimated by contact detection.  A tilted capture floor is
            levelled by the smallest rotation taking its normal to +Z about
            the plane's origin, so the character walks on z = 0 throughout.
            None estimates a level floor (``Motion.floor_height``).
        calibration: Reuse the calibration of an earlier call (streaming: the
            first frames calibrate, later frames reuse it); ``floor`` is then
            ignored.  Its twist calibrations learn from this call's frames (in place).
        kinematics: ``motion.forward_kinematics()`` if the caller has it already.

    Returns:
        :class:`Targets` for every canonical joint mapped on both sides, with
        their :class:`Calibration`.
    """
    opt = options or TargetOptions()
    cal = calibration
    rest_c = cal.rest if cal is not None else character_rest_frames(character)
    present = list(cal.present) if cal is not None else [c for c in CANONICAL_NAMES if c in joint_indices and c in rest_c]
    if "pelvis" not in present:
        raise MappingError("the pelvis must be mapped in both the source and the character")
    pset = set(present)
    idx = np.array([joint_indices[c] for c in present])
    level_info = {} if cal is None else dict(cal.info)
    level, centre = (None, None) if cal is None else (cal.level, cal.level_centre)
    if cal is None and floor is not None:
        sx, sy = (float(v) for v in floor.slope)
        ox, oy = (float(v) for v in floor.origin)
        centre = np.array([ox, oy, float(floor.height)])
        level = _min_rotation(np.array([-sx, -sy, 1.0]), np.array([0.0, 0.0, 1.0]))
        level_info = {"floor_slope": [sx, sy], "floor_height": float(floor.height)}
    turning = [joint_indices[c] for c in present if c in opt.oriented or c in RIGID_PARENTS or c in TORSO_CARRIERS]
    tips = _rigid_foot_tips(motion, joint_indices, character, pset, opt, cal)
    actor = _ActorKinematics(motion, idx, turning, level, centre, kinematics, extra=list(tips.values()))
    S, rot_all = actor.positions, actor.rotations  # (F, N, 3) actor canonical positions; rotations by joint
    F, N = S.shape[:2]
    valid = _mask_lost(S, motion, idx)  # as _masked_positions, in place: the actor's positions are held once
    col = {c: i for i, c in enumerate(present)}

    # --- actor rest pose: skeleton rest for rotational sources, the first valid frame otherwise
    # (read for the calibration only)
    S_rest: np.ndarray | None = None
    if cal is None and motion.is_rotational:
        S_rest = motion.skeleton.rest_positions()[idx]
    elif cal is None:
        S_rest = np.array([S[np.argmax(valid[:, i]), i] for i in range(N)])
    # --- calibration pose (rotational sources): the rest pose if it stands, else the most
    # upright frame of the motion (see physmocap.ik.calibration)
    pose = cal.pose if cal is not None else None
    pose_rot: dict[str, np.ndarray] = {} if cal is None else dict(cal.pose_rotations)
    if cal is not None:
        calib_pts = dict(cal.actor_points)
    elif motion.is_rotational and rot_all is not None:
        pose = calibration_pose(
            {c: S_rest[col[c]] for c in present},
            lambda: {c: np.where(valid[:, col[c], None], S[:, col[c]], np.nan) for c in present if c in POSE_JOINTS},
        )
        if pose.frame is None:
            calib_pts = {c: S_rest[col[c]] for c in present}
        else:
            calib_pts = {c: S[pose.frame, col[c]] for c in present}
            pose_rot = dict(zip(present, actor.frame_rotations(pose.frame, [joint_indices[c] for c in present])))
        if not pose.standing:
            seen = "any frame" if F > 1 else "the first frame (a stream calibrates on the frames it has)"
            warn(
                f"{motion.source}: no usable calibration pose: neither the rest pose nor {seen} shows "
                f"the actor standing upright; orientations calibrated on {pose.describe()}, the most upright"
            )
    else:
        calib_pts = {c: S_rest[col[c]] for c in present}

    # --- root scale from the leg chains
    def leg_len(points: dict[str, np.ndarray], side: str) -> float | None:
        chain = [f"{side}_hip", f"{side}_knee", f"{side}_ankle"]
        if not all(c in points for c in chain):
            return None
        return float(
            np.linalg.norm(points[chain[0]] - points[chain[1]])
            + np.linalg.norm(points[chain[1]] - points[chain[2]])
        )

    char_pts = {c: rest_c[c][0] for c in present}
    if cal is not None:
        scale = cal.scale
    else:
        assert S_rest is not None
        actor_pts = {c: S_rest[col[c]] for c in present}  # for bone lengths (any pose)
        if motion.is_rotational:
            la = [x for x in (leg_len(actor_pts, s) for s in ("left", "right")) if x]
        else:  # no rest pose: median leg length over the clip's valid frames
            la = [x for x in (_median_leg(S, valid, col, s) for s in ("left", "right")) if x]
        lc = [x for x in (leg_len(char_pts, s) for s in ("left", "right")) if x]
        scale = float(np.mean(lc) / np.mean(la)) if (la and lc and opt.scale_root) else 1.0

    if cal is not None:
        floor_s = cal.floor
    elif opt.source_floor is not None:
        floor_s = opt.source_floor
    elif floor is not None:
        floor_s = 0.0  # levelled above
    else:
        floor_s = motion.floor_height()

    # --- orientations: only the columns with a target are held (the identity elsewhere)
    Q: dict[int, np.ndarray] = {}
    has_q = np.zeros(N, dtype=bool)
    yaw = np.array([0.0, 0.0, 0.0, 1.0]) if cal is None else cal.yaw
    if cal is None and "left_hip" in pset and "right_hip" in pset:
        f_a = _facing(calib_pts["left_hip"], calib_pts["right_hip"])
        f_c = _facing(char_pts["left_hip"], char_pts["right_hip"])
        yaw = _yaw_between(f_c, f_a)
    # which character sites can turn relative to their canonical parent's site
    if cal is not None:
        movable = cal.movable
    else:
        movable = {c: _has_dofs_between(character, c, canonical_parent(c, pset)) for c in present}
    offsets = {} if cal is None else cal.orientation_offsets
    limb_axes = {} if cal is None else cal.limb_axes
    twists = {} if cal is None else cal.limb_twists
    foot_tips = {} if cal is None else cal.foot_tips
    toe_turn: dict[str, np.ndarray] = {}  # side -> (F, 4) a rigid foot's toe-line correction
    if not motion.is_rotational and source_orientations is None:
        source_orientations = _positional_orientations(S, col, pset, char_pts)
    # each finished column is kept in ``held`` (a long clip's in a temporary file: a column
    # mapped in while read), the actor's columns it read let go
    candidates = [c for c in opt.oriented if c in pset and movable.get(c, True)]
    held = _ColumnStore(F, len(candidates) + 2)  # and the pelvis given way, and the chest turned with the neck
    for c in candidates:
        actor.release()
        i = col[c]
        q_c0 = rest_c[c][1]
        if motion.is_rotational and rot_all is not None:
            R_a = rot_all[joint_indices[c]]  # rest world rotation is identity for BVH
            limb = _limb_chain(character, c, pset, limb_axes)
            if limb is not None and not limb[2].twists:
                # a limb's upper segment whose twist the character's frame cannot show
                if c not in ORIENTED and cal is None:
                    warn(f"{character.name}: no orientation target for {c}: its frame does not turn with the "
                         "segment's twist (a joint sits between it and the next hinge)")
                continue
            if limb is not None:  # the upper segment's twist from the actor's bent elbow or knee
                middle, end, axes = limb
                segs = (S[:, col[middle]] - S[:, i], S[:, col[end]] - S[:, col[middle]])
                ok = valid[:, i] & valid[:, col[middle]] & valid[:, col[end]]
            if c not in offsets:
                aligned = quat_mul(quat_mul(_rest_alignment(c, pset, calib_pts, char_pts, yaw), yaw), q_c0)
                offsets[c] = _relative_to_pose(pose_rot, c, aligned)
                if limb is not None:
                    twists[c] = TwistCalibration(offsets[c], axes)
            if limb is not None:  # learnt from these frames (a stream goes on learning it)
                twists[c].update(R_a, *segs, ok)
                offsets[c] = twists[c].offset()
            Q[i] = quat_mul(R_a, offsets[c])
            if limb is not None:
                Q[i] = quat_mul(Q[i], follow_bend(Q[i], twists[c].axes, *segs, ok))
            has_q[i] = True
            side = c.split("_", 1)[0]
            if c.endswith("_ankle") and side in tips:
                u = foot_tips.get(side)
                if u is None and cal is None:
                    u = foot_tips[side] = _tip_reference(motion, pose, pose_rot, S, S_rest, col, c, tips[side], actor)
                if u is not None:
                    ok_t = valid[:, i] & np.all(np.isfinite(actor.extra[tips[side]]), axis=-1)
                    toe_turn[side] = toe_line_correction(R_a, S[:, i], actor.extra[tips[side]], u, ok_t)
                    Q[i] = quat_mul(toe_turn[side], Q[i])
        elif source_orientations is not None and c in source_orientations:
            R_a = np.asarray(source_orientations[c], dtype=float)
            R_a0 = source_orientations.get(f"{c}@rest")
            if R_a0 is None:
                continue
            Q[i] = quat_mul(R_a, quat_mul(quat_conj(np.asarray(R_a0)), q_c0))
            has_q[i] = True
        if i in Q:  # signs kept continuous over frames (nicer for users; SE3 does not care)
            Q[i] = held.keep(_continuous_signs(Q[i]))
    actor.release()

    # --- the pelvis gives way where the actor's trunk leans further over it than the
    # character's torso joints reach (trunkreach), so that the trunk follows the actor's
    reach = trunk_reach(character) if cal is None else cal.trunk_reach
    if reach is not None and "neck" in pset and has_q[col["pelvis"]]:
        ipv = col["pelvis"]
        window = max(1, int(round(SMOOTHING_TIME * motion.fps)))
        history = None
        if cal is not None and F == 1:  # a stream: averaged over its last frames
            if cal.trunk_turns is None or cal.trunk_turns.maxlen != window:
                cal.trunk_turns = deque(maxlen=window)
            history = cal.trunk_turns
        Q[ipv] = held.keep(reach.give_way(Q[ipv], S[:, col["neck"]] - S[:, ipv], window, history))

    # --- world rotation of each torso segment from its rest pose, for rigid placement:
    # Delta(t) = R_a(t) R_a0^-1 Y for rotational sources (M = I on the torso), or
    # Q(t) R_c0^-1 where an orientation target exists.
    # (kept as they are made, a long clip's in a temporary file: a column mapped in while read)
    delta: dict[str, np.ndarray] = {}
    turned = _ColumnStore(F, len(RIGID_PARENTS) + 2)  # and the chest's carrier, and the neck's turn
    for seg in RIGID_PARENTS:
        if seg in pset and has_q[col[seg]]:
            delta[seg] = turned.keep(quat_mul(Q[col[seg]], quat_conj(rest_c[seg][1])))
        elif motion.is_rotational and rot_all is not None and seg in joint_indices and seg in pset:
            A = _rest_alignment(seg, pset, calib_pts, char_pts, yaw)
            delta[seg] = turned.keep(quat_mul(rot_all[joint_indices[seg]], _relative_to_pose(pose_rot, seg, quat_mul(A, yaw))))
        actor.release()
        held.release()
    if "chest" not in delta:  # the upper torso turns with the highest source torso joint
        for seg in TORSO_CARRIERS:
            if motion.is_rotational and rot_all is not None and seg in joint_indices and seg in pset:
                A = _rest_alignment(seg, pset, calib_pts, char_pts, yaw)
                delta["chest"] = turned.keep(
                    quat_mul(rot_all[joint_indices[seg]], _relative_to_pose(pose_rot, seg, quat_mul(A, yaw)))
                )
                break
            if seg in delta:
                delta["chest"] = delta[seg]
                break

    rot_all = actor.rotations = actor.store = None  # read no more: let go before the positions are built
    # --- positions: root, then rigid children and limb chains in canonical order
    # Root: anchored on the midpoint of the hip joint centres where both are known
    # (vendors put their "pelvis" joint anywhere between the hips and the waist;
    # the hip centres are anatomical), else on the pelvis joint.
    # built joint by joint (each column's pages let go once placed: a long clip's are kept in a
    # temporary file), then laid out frame by frame (spilled_copy)
    T = spilled_empty((F, N, 3), by_column=True)
    ip = col["pelvis"]
    hips = "left_hip" in pset and "right_hip" in pset
    if hips:
        anchor_a = 0.5 * (S[:, col["left_hip"]] + S[:, col["right_hip"]])
        anchor_c0 = 0.5 * (char_pts["left_hip"] + char_pts["right_hip"])
        ok = valid[:, col["left_hip"]] & valid[:, col["right_hip"]]
    else:
        anchor_a, anchor_c0, ok = S[:, ip], char_pts["pelvis"], valid[:, ip]
    start_xy = anchor_a[np.argmax(ok), :2] if cal is None else cal.start_xy
    anchor = np.empty((F, 3))
    anchor[:, :2] = start_xy + scale * (anchor_a[:, :2] - start_xy)
    # Height: scale the part above the ankles by the leg ratio and stand it on the
    # character's own ankle height (ankle heights above the sole do not scale with legs).
    if cal is not None:
        ankle_a, ankle_c = cal.ankle_actor, cal.ankle_character
    else:
        ankle_a, ankle_c = _ankle_heights(S, valid, col, char_pts, floor, floor_s, present)
    anchor[:, 2] = scale * (anchor_a[:, 2] - floor_s - ankle_a) + ankle_c
    pelvis_delta = delta.get("pelvis")
    off = char_pts["pelvis"] - anchor_c0
    T[:, ip] = anchor + (quat_apply(pelvis_delta, off) if pelvis_delta is not None else off)
    spilled = [a for a in (S, T, held.array, turned.array) if is_spilled(a)]
    lengths = {} if cal is None else cal.bone_lengths  # the character's: worked out once
    for c in present:
        for array in spilled:  # the columns read for the previous joint
            release(array)
        if c == "pelvis":
            continue
        p = canonical_parent(c, pset)
        if p is None:
            continue
        i, j = col[c], col[p]
        seg = RIGID_SEGMENT.get(c)
        if seg is not None and seg in delta and (p == seg or p in TORSO_BELOW.get(seg, ())):
            # c is carried rigidly by a torso segment that the character's parent p belongs to
            T[:, i] = T[:, j] + quat_apply(delta[seg], char_pts[c] - char_pts[p])
            continue
        if c == "neck":
            # the trunk line, pelvis to neck, follows the actor's (the chain of torso joints
            # between has other proportions on every skeleton; see _rest_alignment)
            length = float(np.linalg.norm(char_pts[c] - char_pts["pelvis"]))
            d, n = unit(S[:, i] - S[:, ip])
            ok_n = (n > 1e-6) & valid[:, i] & valid[:, ip]
            T[:, i] = np.where(ok_n[:, None], T[:, ip] + length * d, T[:, j] + (char_pts[c] - char_pts[p]))
            # The upper torso turns with its corrected neck.  The rigid carrier of the
            # shoulders turns by the smallest rotation taking the neck it carries (its rest
            # neck, turned by it) onto the corrected one, so shoulders and neck targets agree
            # whatever the carrier (on a character without a chest it is the actor's spine,
            # which need not carry the neck along the actor's chest-to-neck line: the
            # robot's neck and shoulder targets disagreed by up to 10 cm and its trunk
            # leaned 7-13 degrees off the actor's).  The parent's orientation target keeps
            # the actor's own chest-to-neck turn (turned like the carrier instead, the
            # humanoid's flexible spine leaned 2 degrees past the CMU walk's trunk line and
            # its pelvis rose and fell faster than the actor's).
            rest_neck, neck_now = char_pts[c] - char_pts[p], T[:, i] - T[:, j]
            if has_q[j]:
                walked = float(np.linalg.norm(rest_neck)) * unit(S[:, i] - S[:, j])[0]
                Q[j] = held.keep(quat_mul(quat_between(walked, neck_now), Q[j]))
            carrier = p if p in delta else ("chest" if "chest" not in pset else None)
            if carrier is not None and carrier in delta:
                carried = quat_apply(delta[carrier], rest_neck)
                delta[carrier] = turned.keep(quat_mul(quat_between(carried, neck_now), delta[carrier]))
            continue
        length = lengths.get(c)
        if length is None:
            length = lengths[c] = float(np.linalg.norm(char_pts[c] - char_pts[p]))
        d, n = unit(S[:, i] - S[:, j])
        if c.endswith("_toe") and p.endswith("_ankle") and c.split("_", 1)[0] in toe_turn:
            d = quat_apply(toe_turn[c.split("_", 1)[0]], d)  # the ball turns with its rigid foot
        bad = (n < 1e-6) | ~valid[:, i] | ~valid[:, j]
        if bad.any():
            # undefined direction: keep the character's rest direction, rotated like the parent
            rest_dir = unit(char_pts[c] - char_pts[p])[0]
            if has_q[j]:
                fallback = quat_apply(quat_mul(Q[j], quat_conj(rest_c[p][1])), rest_dir)
            else:
                fallback = np.broadcast_to(rest_dir, d.shape)
            d = np.where(bad[:, None], fallback, d)
        T[:, i] = T[:, j] + length * d

    if cal is None:
        cal = Calibration(
            rest=rest_c,
            present=tuple(present),
            scale=scale,
            floor=float(floor_s),
            yaw=yaw,
            movable=movable,
            orientation_offsets=offsets,
            start_xy=np.array(start_xy, dtype=float),
            ankle_actor=float(ankle_a),
            ankle_character=float(ankle_c),
            actor_points=calib_pts,
            pose_rotations=pose_rot,
            pose=pose,
            level=level,
            level_centre=centre,
            info=level_info,
            foot_tips=foot_tips,
            limb_axes=limb_axes,
            limb_twists=twists,
            trunk_reach=reach,
            bone_lengths=lengths,
        )
    release(S)
    del delta, turned  # let go before the orientations and positions are laid out frame by frame
    orientations = orientation_array(Q, F, N)
    del Q, held
    return Targets(
        names=tuple(present),
        positions=spilled_copy(T),
        orientations=orientations,
        has_orientation=has_q,
        valid=valid,
        fps=motion.fps,
        scale=scale,
        source_positions=S,
        info={
            "source_floor": float(floor_s),
            "yaw_deg": float(np.degrees(np.linalg.norm(quat_to_rotvec(yaw)))),
            **level_info,
        },
        calibration=cal,
        source_recipe=None if kinematics is not None else partial(_source_positions_again, motion, idx, level, centre, valid),
    )

