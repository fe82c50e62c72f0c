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

* **calibration** (:func:`twist_offset`): the circular mean of :math:`\varphi` over the
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

import mujoco
import numpy as np

from ..rotations import Rotation, quat_apply

__all__ = ["LIMB_CHAINS", "flexion_axis", "follow_bend", "twist_error", "twist_offset"]

#: A limb's upper segment (its root's tracked frame) -> the middle joint and the end.
LIMB_CHAINS = {"shoulder": ("elbow", "wrist"), "hip": ("knee", "ankle")}

#: Least bend (radians) of the actor's middle joint for its plane to count.
MIN_BEND = math.radians(20.0)
#: Bends (radians) over which the target's twist comes to follow the actor's plane in full.
FOLLOW_FROM, FOLLOW_BEND = math.radians(10.0), math.radians(25.0)


def _frame(character, name: str, data: mujoco.MjData) -> tuple[np.ndarray, np.ndarray, int]:
    """World position, rotation matrix and body id of a tracked frame at rest."""
    model = character.model
    tf = character.tracked[name]
    if tf.kind == "site":
        sid = model.site(tf.name).id
        return data.site_xpos[sid].copy(), data.site_xmat[sid].reshape(3, 3).copy(), int(model.site_bodyid[sid])
    bid = model.body(tf.name).id
    return data.xpos[bid].copy(), data.xmat[bid].reshape(3, 3).copy(), bid


def flexion_axis(character, root: str, middle: str, end: str) -> tuple[np.ndarray, np.ndarray] | None:
    """The character's flexion axis at ``middle`` and its upper segment direction, both
    in ``root``'s tracked frame at rest: ``(h, u)`` unit vectors, or None.

    The flexion joint is the hinge between ``root``'s body and ``end``'s that swings
    ``end`` the most (a pronation or a wrist joint barely moves it), signed so that its
    larger range side is positive (a flexion).  None where no hinge swings ``end`` by more
    than half its lever, where a joint sits between ``root``'s body and the hinge's (the
    tracked frame does not turn with the segment's twist: a robot whose shoulder frame is
    its roll link, the upper arm's yaw below it), or the upper segment has no length.
    """
    model = character.model
    data = character.rest_data()
    p_root, r_root, b_root = _frame(character, root, data)
    p_mid = _frame(character, middle, data)[0]
    p_end, _, b = _frame(character, end, data)
    upper = p_mid - p_root
    if np.linalg.norm(upper) < 1e-6:
        return None
    best, best_lever, best_body = None, 0.0, -1
    while b > 0 and b != b_root:
        for j in range(int(model.body_jntadr[b]), int(model.body_jntadr[b] + model.body_jntnum[b])):
            if model.jnt_type[j] != mujoco.mjtJoint.mjJNT_HINGE:
                continue
            axis = data.xmat[b].reshape(3, 3) @ model.jnt_axis[j]
            arm = p_end - data.xanchor[j]
            lever = float(np.linalg.norm(np.cross(axis, arm)))
            if lever > best_lever and lever > 0.5 * float(np.linalg.norm(arm)):
                sign = 1.0
                if model.jnt_limited[j]:
                    lo, hi = model.jnt_range[j]
                    sign = -1.0 if lo + hi < 0 else 1.0
                best, best_lever, best_body = sign * axis, lever, b
        b = int(model.body_parentid[b])
    if best is None:
        return None
    b = int(model.body_parentid[best_body])
    while b > 0 and b != b_root:
        if model.body_jntnum[b] > 0:
            return None  # a joint between (a robot's upper-arm yaw below its roll link): the frame has no twist
        b = int(model.body_parentid[b])
    return r_root.T @ (best / np.linalg.norm(best)), r_root.T @ (upper / np.linalg.norm(upper))


def twist_error(
    target: np.ndarray, axes: tuple[np.ndarray, np.ndarray], upper: np.ndarray, lower: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    r"""``(phi, bend)``, both ``(F,)`` radians: the twist error :math:`\varphi(t)` of the
    targets ``target`` (``(F, 4)``) against the actor's hinge normal (module docstring),
    and the actor's bend between ``upper`` and ``lower`` (``(F, 3)``, metres)."""
    h, u = axes
    n = np.cross(upper, lower)
    bend = np.arctan2(np.linalg.norm(n, axis=-1), np.einsum("ij,ij->i", upper, lower))
    d = quat_apply(target, u)
    predicted = quat_apply(target, h)
    predicted -= np.einsum("ij,ij->i", predicted, d)[:, None] * d
    n -= np.einsum("ij,ij->i", n, d)[:, None] * d
    phi = np.arctan2(np.einsum("ij,ij->i", np.cross(predicted, n), d), np.einsum("ij,ij->i", predicted, n))
    return phi, bend


def twist_offset(
    target: np.ndarray,
    axes: tuple[np.ndarray, np.ndarray],
    upper: np.ndarray,
    lower: np.ndarray,
    ok: np.ndarray,
    min_bend: float = MIN_BEND,
) -> np.ndarray | None:
    r"""The calibration :math:`R(u, \bar\varphi)` (x-y-z-w) that turns the flexion axis
    of ``target`` onto the actor's hinge normal on average (module docstring), or None
    where no frame is bent by ``min_bend``.

    Args:
        target: ``(F, 4)`` the upper segment's calibrated orientation targets.
        axes: ``(h, u)`` from :func:`flexion_axis`.
        upper, lower: ``(F, 3)`` the actor's upper and lower segments (metres).
        ok: ``(F,)`` frames where both are known.
    """
    phi, bend = twist_error(target, axes, upper, lower)
    use = ok & (bend > min_bend)
    if not use.any():
        return None
    w = np.sin(bend[use]) ** 2
    mean = math.atan2(float(np.sum(w * np.sin(phi[use]))), float(np.sum(w * np.cos(phi[use]))))
    return Rotation.from_rotvec(mean * axes[1]).as_quat()


def follow_bend(
    target: np.ndarray,
    axes: tuple[np.ndarray, np.ndarray],
    upper: np.ndarray,
    lower: np.ndarray,
    ok: np.ndarray,
) -> np.ndarray:
    r""":math:`R(u, b(t)\, \varphi(t))` per frame (``(F, 4)`` x-y-z-w) to apply after
    ``target``: its twist turned onto the actor's elbow plane where the limb is bent,
    :math:`b` rising linearly from 0 at :data:`FOLLOW_FROM` to 1 at :data:`FOLLOW_BEND`
    (identity where ``ok`` is False)."""
    phi, bend = twist_error(target, axes, upper, lower)
    b = np.clip((bend - FOLLOW_FROM) / (FOLLOW_BEND - FOLLOW_FROM), 0.0, 1.0) * ok
    return Rotation.from_rotvec((b * phi)[:, None] * axes[1]).as_quat()
