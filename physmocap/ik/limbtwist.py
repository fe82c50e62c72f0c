r"""The twist of a limb's upper segment, calibrated on the actor's bent middle joint.

A limb's upper segment (upper arm, thigh) gets an orientation target from the actor's
world rotation and a rest-pose calibration (:mod:`physmocap.ik.targets`).  The
calibration's smallest rotation between the two rest limbs fixes the segment's
direction, but its twist about the segment is only as good as the two skeletons'
rest conventions agree (CMU's T-pose upper arm against the humanoid's hanging one:
30 degrees off).  A twist error turns the plane the elbow bends in, and an IK that
follows it bends the forearm out of the actor's plane, or keeps a hyperextended elbow
and turns its small backward bend towards the hand (a local minimum with the arm
locked straight).

The bend itself says what the twist is.  Where the actor's middle joint is bent, its
hinge normal is :math:`\hat n_a(t) \propto a_1 \times a_2` (:math:`a_1` the upper
segment, :math:`a_2` the lower one, so that a positive rotation about :math:`\hat n_a`
bends :math:`a_1` towards :math:`a_2`); the calibrated target predicts the
character's flexion axis at :math:`Q(t)\, h` (:math:`h` the axis in the upper
segment's tracked frame, signed so a positive angle flexes).  Their angle
:math:`\varphi(t)` about the target's segment direction :math:`Q(t)\, u` is the twist
error of frame :math:`t`.  Two corrections follow from it:

* **calibration** (:class:`TwistCalibration`): the circular mean of :math:`\varphi` over the
  bent frames, weighted by :math:`\sin^2` of the bend (a nearly straight limb has no
  plane), applied once: :math:`Q'(t) = Q(t)\, R(u, \bar\varphi)`.  On a source whose
  elbow is a hinge (CMU) this is the whole error, a constant;
* **per frame** (:func:`follow_bend`): what is left, :math:`\varphi(t) - \bar\varphi`,
  applied in full where the limb is bent by :data:`FOLLOW_BEND` or more and faded out
  linearly down to :data:`FOLLOW_FROM`, so that a source whose upper segment twists
  against its elbow plane (OptiTrack: +-20 degrees) does not make the twist target
  fight the position targets, and a straight limb keeps the calibrated twist.

Radians, unit vectors, quaternions x-y-z-w.
"""

from __future__ import annotations

import math

from dataclasses import dataclass

import mujoco
import numpy as np

from ..rotations import cross, quat_apply, quat_mul

__all__ = ["LIMB_CHAINS", "FlexionAxis", "TwistCalibration", "flexion_axis", "follow_bend", "twist_error"]

#: A limb's upper segment (its root's tracked frame) -> the middle joint and the end.
LIMB_CHAINS = {"shoulder": ("elbow", "wrist"), "hip": ("knee", "ankle")}

#: Least bend (radians) of the actor's middle joint for its plane to count (here, and for a
#: hand without finger joints: ``targets._limb_alignment``); straighter, the plane is noise.
MIN_BEND = math.radians(20.0)
#: Bends (radians) over which the target's twist comes to follow the actor's plane in full.
FOLLOW_FROM, FOLLOW_BEND = math.radians(10.0), math.radians(25.0)


def _frame(character, name: str, data: mujoco.MjData) -> tuple[np.ndarray, np.ndarray, int]:
    """World position, rotation matrix and body id of a tracked frame (copies)."""
    tf, model = character.tracked[name], character.model
    return tf.position(model, data).copy(), tf.rotation(model, data).copy(), tf.body_id(model)


@dataclass(frozen=True)
class FlexionAxis:
    """A limb's flexion axis, in its upper segment's tracked frame at rest.

    Attributes:
        h: ``(3,)`` the flexion axis (unit), signed so a positive turn flexes where
            ``signed`` (else either way: see :class:`TwistCalibration`).
        u: ``(3,)`` the upper segment's direction (unit).
        signed: The sign of ``h`` is known from the joint's range (one side at least
            twice the other); False for an unlimited or nearly symmetric hinge.
        twists: The tracked frame turns with the segment's twist: no joint sits between
            its body and the hinge's (a robot whose shoulder frame is its roll link, the
            upper arm's yaw below it, has none; such a frame gets no twist target).
    """

    h: np.ndarray
    u: np.ndarray
    signed: bool
    twists: bool

    def flipped(self) -> "FlexionAxis":
        """The same axis the other way round, its sign then known."""
        return FlexionAxis(-self.h, self.u, True, self.twists)


#: A hinge's range is one-sided (its flexion side known) when one side is this many times the other.
ONE_SIDED = 2.0


def flexion_axis(character, root: str, middle: str, end: str) -> FlexionAxis | None:
    """The character's flexion axis at ``middle`` (:class:`FlexionAxis`), or None.

    The flexion joint is the hinge between ``root``'s body and ``end``'s that swings
    ``end`` the most (a pronation or a wrist joint barely moves it): its lever arm about
    the hinge is more than half the distance from the hinge to ``end``.  None where no
    hinge does, or the upper segment has no length.
    """
    model = character.model
    data = character.rest_data()
    p_root, r_root, b_root = _frame(character, root, data)
    p_mid = _frame(character, middle, data)[0]
    p_end, _, b = _frame(character, end, data)
    upper = p_mid - p_root
    if np.linalg.norm(upper) < 1e-6:
        return None
    best, best_lever, best_body, signed = None, 0.0, -1, False
    while b > 0 and b != b_root:
        for j in range(int(model.body_jntadr[b]), int(model.body_jntadr[b] + model.body_jntnum[b])):
            if model.jnt_type[j] != mujoco.mjtJoint.mjJNT_HINGE:
                continue
            axis = data.xmat[b].reshape(3, 3) @ model.jnt_axis[j]
            arm = p_end - data.xanchor[j]
            lever = float(np.linalg.norm(np.cross(axis, arm)))
            if lever > best_lever and lever > 0.5 * float(np.linalg.norm(arm)):
                sign, signed = 1.0, False
                if model.jnt_limited[j]:
                    lo, hi = (float(v) for v in model.jnt_range[j])
                    up, down = max(hi, 0.0), max(-lo, 0.0)
                    signed = max(up, down) >= ONE_SIDED * min(up, down) and max(up, down) > 0.0
                    sign = -1.0 if down > up else 1.0
                best, best_lever, best_body = sign * axis, lever, b
        b = int(model.body_parentid[b])
    if best is None:
        return None
    twists = True
    b = int(model.body_parentid[best_body])
    while b > 0 and b != b_root:
        twists = twists and model.body_jntnum[b] == 0
        b = int(model.body_parentid[b])
    return FlexionAxis(r_root.T @ (best / np.linalg.norm(best)), r_root.T @ (upper / np.linalg.norm(upper)), signed, twists)


def twist_error(
    target: np.ndarray, axes: FlexionAxis, upper: np.ndarray, lower: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    r"""``(phi, bend)``, both ``(F,)`` radians: the twist error :math:`\varphi(t)` of the
    targets ``target`` (``(F, 4)``) against the actor's hinge normal (module docstring),
    and the actor's bend between ``upper`` and ``lower`` (``(F, 3)``, metres)."""
    h, u = axes.h, axes.u
    n = cross(upper, lower)
    bend = np.arctan2(np.sqrt(np.add.reduce(n * n, axis=-1)), np.einsum("ij,ij->i", upper, lower))  # |n|
    d = quat_apply(target, u)
    predicted = quat_apply(target, h)
    predicted -= np.einsum("ij,ij->i", predicted, d)[:, None] * d
    n -= np.einsum("ij,ij->i", n, d)[:, None] * d
    phi = np.arctan2(np.einsum("ij,ij->i", cross(predicted, n), d), np.einsum("ij,ij->i", predicted, n))
    return phi, bend


@dataclass
class TwistCalibration:
    r"""The calibration of one upper segment's twist, kept as running sums so that a stream
    can go on learning it (:meth:`update`) as offline retargeting learns it from the whole
    clip at once.

    The segment's offset is :math:`O = B\, R(u, \bar\varphi)`: ``base`` (the rest-pose
    calibration) turned by the weighted circular mean :math:`\bar\varphi =
    \operatorname{atan2}(\sum w \sin\varphi, \sum w \cos\varphi)` of the twist errors
    :math:`\varphi` of :math:`R_a B` on the frames bent by :data:`MIN_BEND` or more, weights
    :math:`w = \sin^2` of the bend.

    Attributes:
        base: ``(4,)`` x-y-z-w, the offset before the twist.
        axes: The :class:`FlexionAxis`; an unsigned one is turned round, once, where that
            brings :math:`\bar\varphi` within 90 degrees of the rest-pose calibration's
            (which a skeleton's conventions put that far off only by accident).
        sin, cos: The running sums.
    """

    base: np.ndarray
    axes: FlexionAxis
    sin: float = 0.0
    cos: float = 0.0

    def update(self, rotations: np.ndarray, upper: np.ndarray, lower: np.ndarray, ok: np.ndarray) -> None:
        """Add frames: ``rotations`` ``(F, 4)`` the actor's world rotations of the segment,
        ``upper`` and ``lower`` ``(F, 3)`` its segments (metres), ``ok`` ``(F,)`` known."""
        phi, bend = twist_error(quat_mul(rotations, self.base), self.axes, upper, lower)
        use = ok & (bend > MIN_BEND)
        if not use.any():
            return
        w = np.sin(bend[use]) ** 2
        self.sin += float(np.sum(w * np.sin(phi[use])))
        self.cos += float(np.sum(w * np.cos(phi[use])))
        if not self.axes.signed:
            if abs(math.atan2(self.sin, self.cos)) > math.pi / 2:
                self.axes, self.sin, self.cos = self.axes.flipped(), -self.sin, -self.cos
            else:
                self.axes = FlexionAxis(self.axes.h, self.axes.u, True, self.axes.twists)

    def offset(self) -> np.ndarray:
        """``(4,)`` x-y-z-w: :math:`O`, the base alone before any bent frame."""
        if self.sin == 0.0 and self.cos == 0.0:
            return self.base
        return quat_mul(self.base, _turn(self.axes.u, np.array([math.atan2(self.sin, self.cos)]))[0])


def follow_bend(
    target: np.ndarray,
    axes: FlexionAxis,
    upper: np.ndarray,
    lower: np.ndarray,
    ok: np.ndarray,
) -> np.ndarray:
    r""":math:`R(u, b(t)\, \varphi(t))` per frame (``(F, 4)`` x-y-z-w) to apply after
    ``target``: its twist turned onto the actor's elbow plane where the limb is bent,
    :math:`b` rising linearly from 0 at :data:`FOLLOW_FROM` to 1 at :data:`FOLLOW_BEND`
    (identity where ``ok`` is False).  The plane is a line through the segment: an angle
    beyond 90 degrees either way is folded back (an actor's elbow bent backwards turns its
    hinge normal round)."""
    phi, bend = twist_error(target, axes, upper, lower)
    phi = (phi + math.pi / 2) % math.pi - math.pi / 2
    b = np.clip((bend - FOLLOW_FROM) / (FOLLOW_BEND - FOLLOW_FROM), 0.0, 1.0) * ok
    return _turn(axes.u, b * phi)


def _turn(u: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """``(F, 4)`` x-y-z-w rotations by ``angle`` (``(F,)`` radians) about the unit axis ``u``."""
    half = 0.5 * np.asarray(angle, dtype=float)
    out = np.empty((half.shape[0], 4))
    out[:, :3] = np.sin(half)[:, None] * u
    out[:, 3] = np.cos(half)
    return out
