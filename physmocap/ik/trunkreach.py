r"""How far a character's torso joints can lean its trunk relative to its pelvis.

The trunk line runs from the pelvis to the neck (the torso segment of the fidelity figures).
Its direction in the pelvis body's frame depends only on the joints between the two: a robot's
waist (yaw and pitch), the humanoid's spine (three bodies of three hinges).  An actor can ask
for more than those joints reach: the CMU dance's actor tilts its pelvis some 24 degrees
forward under an upright spine, and the bundled robot's waist extends by 20 at most.  Followed
as it is, the pelvis's orientation target then holds the waist at its limit, and the trunk,
shoulders and arms share what is missing (the dance robot's arm 8 degrees off).

:func:`trunk_reach` samples the torso joints within their ranges once per character and keeps
the trunk directions reached, unit vectors in the pelvis body's frame.  :meth:`TrunkReach.give_way`
tips a pelvis orientation target about its hip line by the part of the demanded trunk direction
that lies beyond them:

.. math::

    R'_p = R_p \, \mathrm{Rot}\big(\hat h\,(\hat h \cdot \hat a)\,\max(0, \angle(\hat n, \hat d) - \tau)\big),
    \qquad \hat d = R_p^{-1} \hat t, \quad \hat n = \arg\max_{k} \hat r_k \cdot \hat d,
    \quad \hat a = \frac{\hat n \times \hat d}{\lVert \hat n \times \hat d \rVert}

(``t`` the trunk target's world direction, ``r_k`` the directions reached, ``h`` the hip line in
the pelvis body's frame, ``tau`` the sampling's tolerance), averaged over
:data:`SMOOTHING_TIME`, so that the torso can put the trunk where the actor's is and the pelvis
tips to take the rest, as a pelvis does under a spine (its hip line, heading and legs' roots
stay).  A demanded direction within reach leaves the target as it is.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import mujoco
import numpy as np

from ..rotations import Rotation, cross, quat_apply, quat_conj, quat_from_rotvec, quat_mul

__all__ = ["TrunkReach", "trunk_reach", "SAMPLES", "TOLERANCE_DEG", "SMOOTHING_TIME"]

#: Torso poses sampled per character (a third of the joint values at each end of the range:
#: the edges of the reach are what matters).
SAMPLES = 4096
#: A demanded direction this close to one reached counts as reached (degrees): about the
#: spacing of the samples over a robot waist's range.
TOLERANCE_DEG = 1.5
#: The turns are averaged over this long (s): the nearest direction reached steps from sample
#: to sample where the trunk runs along the edge of the reach.
SMOOTHING_TIME = 0.1
#: Frames compared against the samples at a time (a (frames, samples) array of dot products).
BLOCK = 1024


@dataclass(frozen=True)
class TrunkReach:
    """The trunk directions a character reaches, ``(K, 3)`` unit vectors in its pelvis body's
    frame, and the axis ``(3,)`` there the pelvis gives way about: its hip line (right to left
    hip at rest), so that it tips forward or back, as a pelvis does under a spine, and its hip
    line, its heading and its legs' roots stay where they were (a pelvis given way about a
    slanted axis turned the dance robot's heading 20 degrees off the actor's in a kick)."""

    directions: np.ndarray
    axis: np.ndarray
    #: The pelvis body's rotation in the tracked pelvis frame (x-y-z-w): the targets are the
    #: tracked frame's, the directions reached the body's.
    body_in_frame: np.ndarray

    def give_way(self, pelvis: np.ndarray, trunk: np.ndarray, window: int = 1,
                 history: deque | None = None) -> np.ndarray:
        """The pelvis targets ``(F, 4)`` x-y-z-w turned by what lies beyond reach.

        Args:
            pelvis: ``(F, 4)`` pelvis orientation targets (the tracked frame's world rotation).
            trunk: ``(F, 3)`` world directions of the trunk target (pelvis to neck); rows
                not finite are left alone.
            window: frames over which the turns (rotation vectors in the body's frame) are
                averaged: the nearest direction reached steps from sample to sample, and the
                pelvis should not (1: none), centred on each frame.
            history: A stream's: the turns of the frames before (a ``deque`` of at most
                ``window`` of them, ours to append to); the one frame given is turned by the
                mean of its turn and theirs, a causal average over ``window`` frames (its
                lag half of it) where offline's is centred.
        """
        from scipy.ndimage import uniform_filter1d

        out = np.array(pelvis, dtype=float, copy=True)
        ok = (np.all(np.isfinite(trunk), axis=1) & (np.linalg.norm(trunk, axis=1) > 1e-9)
              & np.all(np.isfinite(out), axis=1) & (np.linalg.norm(out, axis=1) > 1e-9))
        tol = np.radians(TOLERANCE_DEG)
        turns = np.zeros((len(out), 3))
        for s in range(0, len(out), BLOCK):
            e = min(s + BLOCK, len(out))
            rows = np.flatnonzero(ok[s:e]) + s
            if rows.size == 0:
                continue
            unit = out[rows] / np.linalg.norm(out[rows], axis=1, keepdims=True)
            d = quat_apply(quat_conj(quat_mul(unit, self.body_in_frame)), trunk[rows])  # in the body's frame
            d /= np.linalg.norm(d, axis=1, keepdims=True)
            dots = d @ self.directions.T
            best = np.argmax(dots, axis=1)
            n = self.directions[best]
            angle = np.arccos(np.clip(dots[np.arange(len(rows)), best], -1.0, 1.0))
            beyond = angle > tol
            axis = cross(n[beyond], d[beyond])
            axis /= np.maximum(np.linalg.norm(axis, axis=1, keepdims=True), 1e-12)
            turns[rows[beyond]] = axis * (angle[beyond] - tol)[:, None]
        turns = np.outer(turns @ self.axis, self.axis)  # about the hip line only
        if history is not None and len(out) == 1:
            history.append(turns[0])
            turns = np.add.reduce(np.array(history), axis=0, keepdims=True) / len(history) * ok[:, None]  # np.mean's
        elif window > 1:
            turns = uniform_filter1d(turns, size=int(window), axis=0, mode="nearest")
        if not np.any(turns):
            return out
        moved = np.flatnonzero(np.linalg.norm(turns, axis=1) > 1e-12)
        turn = quat_from_rotvec(turns[moved])
        out[moved] = quat_mul(out[moved], turn_in_tracked_frame(turn, self.body_in_frame))
        return out


def turn_in_tracked_frame(turn: np.ndarray, rest_offset: np.ndarray) -> np.ndarray:
    """A rotation given in the pelvis body's frame, expressed in the tracked frame's:
    :math:`O\\,E\\,O^{-1}` with ``O`` the body's rotation in the tracked frame."""
    o = np.broadcast_to(rest_offset, turn.shape)
    return quat_mul(quat_mul(o, turn), quat_conj(o))


def trunk_reach(character, samples: int = SAMPLES) -> TrunkReach | None:
    """The trunk directions the character's torso joints reach (see the module docstring), or
    None when it tracks no pelvis or no neck, when no hinge lies between them (a rigid trunk),
    or when a ball joint does (its cone of ranges is not sampled here: no give-way rather than
    one measured on part of the trunk's joints).  Slide joints stay at rest.  Deterministic:
    the samples come from a generator seeded with 0.  Measured once per character
    (:meth:`~physmocap.models.Character.derived`; tens of milliseconds) and kept."""
    derived = getattr(character, "derived", None)
    if derived is None:  # a stand-in for a character
        return _measure_reach(character, samples)
    return derived(("trunk_reach", int(samples)), lambda: _measure_reach(character, samples))


def _measure_reach(character, samples: int) -> TrunkReach | None:
    """:func:`trunk_reach`, measured."""
    tracked = character.tracked
    if "pelvis" not in tracked or "neck" not in tracked:
        return None
    model = character.model
    pelvis_f, neck_f = tracked["pelvis"], tracked["neck"]
    root, b = pelvis_f.body_id(model), neck_f.body_id(model)
    joints = []
    while b > 0 and b != root:
        for j in range(model.body_jntadr[b], model.body_jntadr[b] + model.body_jntnum[b]):
            kind = int(model.jnt_type[j])
            if kind == int(mujoco.mjtJoint.mjJNT_BALL):
                return None
            if kind == int(mujoco.mjtJoint.mjJNT_HINGE):
                joints.append(j)
        b = model.body_parentid[b]
    if b != root or not joints:
        return None
    data = character.rest_data()
    rng = np.random.default_rng(0)
    lo = np.array([model.jnt_range[j][0] if model.jnt_limited[j] else -np.pi for j in joints])
    hi = np.array([model.jnt_range[j][1] if model.jnt_limited[j] else np.pi for j in joints])
    pick = rng.integers(0, 3, size=(samples, len(joints)))
    values = np.where(pick == 0, lo, np.where(pick == 1, hi, rng.uniform(lo, hi, size=pick.shape)))
    adr = np.array([model.jnt_qposadr[j] for j in joints])
    rest_q = data.qpos.copy()
    body_root = root

    def direction() -> np.ndarray:
        d = neck_f.position(model, data) - pelvis_f.position(model, data)
        d = data.xmat[body_root].reshape(3, 3).T @ d
        return d / max(float(np.linalg.norm(d)), 1e-12)

    mujoco.mj_kinematics(model, data)
    if np.linalg.norm(neck_f.position(model, data) - pelvis_f.position(model, data)) < 1e-6:
        return None  # the neck on the pelvis: no trunk to lean
    if "left_hip" in tracked and "right_hip" in tracked:
        axis = tracked["left_hip"].position(model, data) - tracked["right_hip"].position(model, data)
        axis = data.xmat[body_root].reshape(3, 3).T @ axis
    else:  # no hips: across the trunk, the body's own sideways axis
        axis = np.cross(direction(), [1.0, 0.0, 0.0])
    if np.linalg.norm(axis) < 1e-9:
        return None
    axis /= np.linalg.norm(axis)
    frame = Rotation.from_matrix(pelvis_f.rotation(model, data))
    body_in_frame = (frame.inv() * Rotation.from_matrix(data.xmat[body_root].reshape(3, 3))).as_quat()
    out = np.empty((samples, 3))
    for k in range(samples):
        data.qpos[:] = rest_q
        data.qpos[adr] = values[k]
        mujoco.mj_kinematics(model, data)
        out[k] = direction()
    return TrunkReach(out, axis, body_in_frame)
