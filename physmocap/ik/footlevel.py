r"""Feet levelled from the actor's stance: a foot flat on the floor becomes the character's flat foot.

The orientation targets are calibrated on one pose (:mod:`.targets`), and for the
feet that calibration inherits each skeleton's own idea of where the toe joint
sits: the actor's ankle-to-toe bone may point 9 degrees down on one vendor's
skeleton and 40 on another's, while the character's points 20 degrees down.
Aligning those bone directions, or trusting a rest pose, leaves the character's
foot tilted by 10-25 degrees whenever the actor's is flat, so during stance
its toe target floats centimetres above the floor (or sinks below it) and the
planted foot, the ankle and the pelvis fight over it.

The contact labels say when a foot *is* flat: heel and toe both on the floor.
On those frames the character's foot should have its rest orientation (its
sole on the floor) turned only about the vertical to the actor's heading.
With the ankle's orientation target :math:`Q(t)` (the actor's foot rotation
times a constant calibration offset), the correction is one constant rotation
:math:`C` in the foot's own frame,

.. math::

    C = \operatorname{mean}_{t \in \text{stance}} \; Q(t)^{-1}\, R_z(\psi(t))\, Q_{c,0},

with :math:`Q_{c,0}` the character's rest orientation of the foot and
:math:`\psi(t)` the heading of the actor's foot (ankle to toe on the floor,
or where there is no toe target the rest forward direction turned by
:math:`Q(t) Q_{c,0}^{-1}`), so toe-in and toe-out are kept.  Every frame's target
becomes :math:`Q(t)\,C` (stance or not, so the actor's heel raise, toe-off and
swing pitch are kept, relative to flat).  The toe joint is then placed
rigidly from the corrected orientation,
:math:`T_{toe} = T_{ankle} + Q(t) C Q_{c,0}^{-1} (x_{toe,0} - x_{ankle,0})`,
and the toe segment is levelled the same way (:func:`_level_toes`): flat where
the actor's toes are flat, with the actor's toe flexion relative to that.  Nothing is learnt from one file: a foot that is never flat on
both contact points is left as it was.  Units: metres.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import numpy as np

from ..rotations import Rotation, quat_apply, quat_between, quat_conj, quat_from_rotvec, quat_mul, quat_to_rotvec
from ..vectors import direction

__all__ = ["FootLevel", "FootLeveller", "level_feet", "MIN_STANCE_TIME"]

#: Least time (seconds) a foot must stand flat on both contact points to be levelled.
MIN_STANCE_TIME = 0.1


@dataclass(frozen=True)
class FootLevel:
    """The levelling applied to one foot.

    Attributes:
        side: ``left`` or ``right``.
        correction_deg: Angle of the constant correction :math:`C` (degrees).
        stance_frames: Frames on which the foot stood flat (both contact points down).
    """

    side: str
    correction_deg: float
    stance_frames: int


def _heading(rot: np.ndarray, forward: np.ndarray) -> np.ndarray:
    """Heading (radians about +Z) of ``forward`` turned by ``rot`` (x-y-z-w), projected on the floor."""
    f = quat_apply(rot, forward)
    return np.arctan2(f[..., 1], f[..., 0])


def _unit_quats(q: np.ndarray) -> np.ndarray:
    """``q`` ``(..., 4)`` normalised."""
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def _foot_rest(rest: Mapping[str, tuple[np.ndarray, np.ndarray]], side: str) -> tuple[np.ndarray, np.ndarray] | None:
    """The character's rest foot orientation :math:`Q_{c,0}` (``(4,)`` x-y-z-w) and its
    forward direction on the floor (towards the toe, else the ankle site's x axis); None
    where it has none."""
    ankle, toe = f"{side}_ankle", f"{side}_toe"
    q_c0 = _unit_quats(np.asarray(rest[ankle][1], dtype=float))
    fwd = rest[toe][0] - rest[ankle][0] if toe in rest else quat_apply(q_c0, [1.0, 0.0, 0.0])
    fwd = np.array([fwd[0], fwd[1], 0.0])
    if np.linalg.norm(fwd) < 1e-9:
        return None
    return q_c0, fwd / np.linalg.norm(fwd)


def _flat_corrections(Q: np.ndarray, toe_dir: np.ndarray | None, q_c0: np.ndarray, fwd: np.ndarray) -> np.ndarray:
    r"""Per stance frame ``(F, 4)`` x-y-z-w, the rotation :math:`Q^{-1} R_z(\psi) Q_{c,0}` that
    makes the foot flat with the actor's heading :math:`\psi` (from ``toe_dir``, ankle to
    toe, where given); ``Q`` ``(F, 4)`` unit quaternions."""
    heading = np.arctan2(toe_dir[:, 1], toe_dir[:, 0]) if toe_dir is not None else _heading(quat_mul(Q, quat_conj(q_c0)), fwd)
    psi = heading - np.arctan2(fwd[1], fwd[0])
    return quat_mul(quat_conj(Q), quat_mul(quat_from_rotvec(np.outer(psi, [0.0, 0.0, 1.0])), q_c0))


def _toe_offset(foot: np.ndarray, q_c0: np.ndarray, rest: Mapping, side: str) -> np.ndarray:
    """``(F, 3)`` the toe joint relative to the ankle for feet oriented ``foot`` (``(F, 4)``
    x-y-z-w): the character's rest offset turned rigidly with the foot."""
    return quat_apply(quat_mul(foot, quat_conj(q_c0)), rest[f"{side}_toe"][0] - rest[f"{side}_ankle"][0])


def level_feet(
    positions: np.ndarray,
    orientations: np.ndarray,
    has_orientation: np.ndarray,
    names: tuple[str, ...],
    labels: Mapping[str, np.ndarray],
    rest: Mapping[str, tuple[np.ndarray, np.ndarray]],
    fps: float,
    *,
    in_place: bool = False,
) -> tuple[np.ndarray, np.ndarray, list[FootLevel]]:
    """Targets with each foot levelled on its flat-stance frames (see the module docstring).

    Args:
        positions: ``(F, N, 3)`` target positions (metres; not modified unless ``in_place``).
        orientations: ``(F, N, 4)`` target orientations x-y-z-w (the same).
        has_orientation: ``(N,)`` which targets have an orientation.
        names: Canonical joint of each target column.
        labels: ``left_heel``, ``left_toe``, ``right_heel``, ``right_toe`` -> ``(F,)`` bool.
        rest: Canonical joint -> (rest position, rest orientation x-y-z-w) of the
            character (:func:`~physmocap.ik.targets.character_rest_frames`).
        fps: Frame rate.
        in_place: Level ``positions`` and ``orientations`` themselves (writeable float64
            arrays the caller gives up; every value is read before it is changed) and
            return them: no copy of either, the same numbers.

    Returns:
        ``(positions, orientations, levels)``: new arrays (or the given ones, ``in_place``),
        and one :class:`FootLevel` per foot that was levelled.
    """
    pos = positions if in_place else np.array(positions, dtype=float, copy=True)
    ori = orientations if in_place else np.array(orientations, dtype=float, copy=True)
    col = {n: i for i, n in enumerate(names)}
    F = pos.shape[0]
    need = max(2, int(round(MIN_STANCE_TIME * fps)))
    levels: list[FootLevel] = []
    for side in ("left", "right"):
        ankle, toe, tip = f"{side}_ankle", f"{side}_toe", f"{side}_toe_end"
        if ankle not in col or not has_orientation[col[ankle]] or ankle not in rest:
            continue
        heel_l, toe_l = labels.get(f"{side}_heel"), labels.get(f"{side}_toe")
        if heel_l is None or toe_l is None:
            continue
        ia = col[ankle]
        # frames with a usable target (a positional source may leave lost joints undefined)
        good = np.all(np.isfinite(ori[:, ia]), axis=1) & (np.linalg.norm(ori[:, ia], axis=1) > 0.5)
        good &= np.all(np.isfinite(pos[:, ia]), axis=1)
        if toe in col:
            good &= np.all(np.isfinite(pos[:, col[toe]]), axis=1)
        stance = np.asarray(heel_l, dtype=bool)[:F] & np.asarray(toe_l, dtype=bool)[:F] & good
        frame = _foot_rest(rest, side)
        if int(stance.sum()) < need or frame is None:
            continue
        q_c0, fwd = frame
        toe_dir = positions[stance, col[toe]] - positions[stance, ia] if toe in col else None
        C = Rotation.from_quat(_flat_corrections(_unit_quats(ori[stance, ia]), toe_dir, q_c0, fwd)).mean()
        old_ankle_q = ori[good, ia].copy()
        new = Rotation.from_quat(old_ankle_q) * C
        q_new = new.as_quat()
        # keep the quaternion sign continuous with the old track (nicer for users)
        q_new[np.sum(q_new * old_ankle_q, axis=-1) < 0] *= -1.0
        ori[good, ia] = q_new
        del old_ankle_q, q_new  # not held while the toes are levelled (a long clip's are large)
        levels.append(FootLevel(side, float(np.degrees(C.magnitude())), int(stance.sum())))
        if toe not in col or toe not in rest:
            continue
        it = col[toe]
        old_dir = positions[good, it] - positions[good, ia]
        tipped = tip in col and tip in rest
        old_toes = positions[good, col[tip]] - positions[good, it] if tipped else None  # read before the toe moves
        pos[good, it] = pos[good, ia] + _toe_offset(new.as_quat(), q_c0, rest, side)
        if tipped:
            ie = col[tip]
            turn = quat_between(old_dir, pos[good, it] - pos[good, ia])
            toe_dir = quat_apply(turn, old_toes)
            del turn, old_toes, old_dir
            pos[good, ie] = pos[good, it] + _level_toes(toe_dir, new, stance[good], q_c0, rest[tip][0] - rest[toe][0])
    return pos, ori, levels


def _level_toes(toe_dir: np.ndarray, foot: Rotation, stance: np.ndarray, q_c0: np.ndarray, rest_dir: np.ndarray) -> np.ndarray:
    r"""``(F, 3)`` toe segments (toe joint to tip, world) with the toes levelled like the foot.

    Skeletons also disagree on where the toe tip sits relative to the foot, so
    the actor's toe segment, seen in the (levelled) foot's frame, is turned by
    one constant rotation :math:`D` that makes its mean direction over the
    flat-stance frames the character's rest one
    (:math:`D` = the smallest rotation from
    :math:`\operatorname{mean}_{stance} \widehat{F(t)^{-1} d(t)}` to
    :math:`\widehat{Q_{c,0}^{-1} d_{c,0}}`, :math:`F(t)` the foot's target orientation):
    the toes lie flat when the actor's do, and their flexion relative to that
    (toes bending at toe-off, curling in the swing) is the actor's.

    Args:
        toe_dir: ``(F, 3)`` the actor's toe segments (toe joint to tip), world.
        foot: ``F`` levelled foot orientations (the ankle's targets).
        stance: ``(F,)`` flat-stance frames.
        q_c0: The character's rest orientation of the foot (``(4,)`` x-y-z-w).
        rest_dir: The character's rest toe segment (toe joint to tip), world.
    """
    local = foot.inv().apply(toe_dir)
    unit = direction(local, 1e-12)
    mean = unit[stance].mean(axis=0)
    want = quat_apply(quat_conj(q_c0), rest_dir)
    if np.linalg.norm(mean) < 1e-6 or np.linalg.norm(want) < 1e-9:
        return toe_dir
    D = quat_between(mean, want)
    return foot.apply(quat_apply(D, local))


class FootLeveller:
    r"""The causal counterpart of :func:`level_feet`, for streaming: one frame at a time.

    The correction :math:`C` of each foot is the mean of the per-frame corrections over
    the flat-stance frames seen so far (a normalised, sign-aligned quaternion sum), so it
    settles within the first stance and then barely moves (it is a property of the two
    skeletons, not of the motion).  Until :data:`MIN_STANCE_TIME` of flat stance has been
    seen a foot is left as it is; then the correction is eased in over ``ease_time``
    (slerp from the identity), so the foot does not snap.  The toe joint is placed
    rigidly from the corrected foot, blended the same way; toe tips are left to the
    actor's (the offline :func:`_level_toes` needs the whole clip's stance).

    Args:
        names: Canonical joint of each target column.
        has_orientation: ``(N,)`` which targets have an orientation.
        rest: The character's rest frames (:func:`~physmocap.ik.targets.character_rest_frames`).
        fps: Frame rate.
        ease_time: Seconds over which a foot's correction is eased in.
    """

    def __init__(self, names, has_orientation: np.ndarray, rest: Mapping, fps: float, ease_time: float) -> None:
        self.names = tuple(names)
        self.rest = rest
        self.need = max(2, int(round(MIN_STANCE_TIME * fps)))
        self.ease_frames = max(1, int(round(ease_time * fps)))
        col = {n: i for i, n in enumerate(self.names)}
        #: side -> (ankle column, toe column or None, rest orientation (4,) x-y-z-w, rest forward direction)
        self.feet: dict[str, tuple[int, int | None, np.ndarray, np.ndarray]] = {}
        for side in ("left", "right"):
            ankle, toe = f"{side}_ankle", f"{side}_toe"
            if ankle not in col or not has_orientation[col[ankle]] or ankle not in rest:
                continue
            frame = _foot_rest(rest, side)
            if frame is not None:
                self.feet[side] = (col[ankle], col[toe] if toe in col and toe in rest else None, *frame)
        self._sum = {side: np.zeros(4) for side in self.feet}
        self._count = {side: 0 for side in self.feet}
        self._eased = {side: 0 for side in self.feet}

    def correction(self, side: str) -> np.ndarray | None:
        """The foot's current correction :math:`C` (``(4,)`` x-y-z-w; None before enough flat stance)."""
        if self._count.get(side, 0) < self.need:
            return None
        return self._sum[side] / np.linalg.norm(self._sum[side])

    def step(self, positions: np.ndarray, orientations: np.ndarray, labels: Mapping[str, bool]) -> tuple[np.ndarray, np.ndarray]:
        """``(positions, orientations)`` of one frame ``(N, 3)``, ``(N, 4)`` with the feet
        levelled (new arrays; the inputs are not modified)."""
        pos = np.array(positions, dtype=float, copy=True)
        ori = np.array(orientations, dtype=float, copy=True)
        for side, (ia, it, q_c0, fwd) in self.feet.items():
            q = ori[ia]
            if not (np.all(np.isfinite(q)) and np.linalg.norm(q) > 0.5 and np.all(np.isfinite(pos[ia]))):
                continue
            Q = _unit_quats(q)
            if labels.get(f"{side}_heel", False) and labels.get(f"{side}_toe", False):
                toe_dir = None if it is None else (positions[it] - positions[ia])[None]
                sample = _flat_corrections(Q[None], toe_dir, q_c0, fwd)[0]
                if sample @ self._sum[side] < 0:
                    sample = -sample
                self._sum[side] += sample
                self._count[side] += 1
            C = self.correction(side)
            if C is None:
                continue
            self._eased[side] = min(self._eased[side] + 1, self.ease_frames)
            w = self._eased[side] / self.ease_frames
            q_new = quat_mul(Q, quat_from_rotvec(w * quat_to_rotvec(C)))  # slerp from the identity
            ori[ia] = -q_new if q_new @ q < 0 else q_new
            if it is not None and np.all(np.isfinite(pos[it])):
                rigid = pos[ia] + _toe_offset(q_new[None], q_c0, self.rest, side)[0]
                pos[it] = (1.0 - w) * positions[it] + w * rigid
        return pos, ori
