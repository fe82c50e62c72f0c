r"""Hinges that turn one body about one point, and the speed of that body along each hinge's axis.

A ball joint written as two or three hinges of one body at one anchor (the humanoid's
shoulder: flexion, abduction, rotation) turns the body, relative to its parent, with the
angular velocity

.. math::

    \omega = \sum_{j \in g} a_j\, \dot q_j

where :math:`a_j` is hinge :math:`j`'s world axis (MuJoCo's ``xaxis``, which follows the
hinges before it in the body).  The hinge *rates* :math:`\dot q_j` are coordinates: where
the middle hinge nears 90 degrees the first and last axes align (gimbal lock) and the
rates needed to move the arm a little grow without bound, in opposite directions.  A
human's peak joint speeds (:mod:`.velocity`) are physical angular speeds, so a group's
velocity limits bound the components of :math:`\omega` instead:

.. math::

    |a_i^T \omega| \;=\; \Big|\sum_{j \in g} (a_i^T a_j)\, \dot q_j\Big| \;\le\; \dot q_i^{max}
    \qquad (i \in g),

which is the per-hinge bound wherever the axes are orthogonal (the rest pose) and stays
a bound on the body's motion at the gimbal lock.  A robot's hinges are motors whose
rates are physical: :func:`hinge_groups` groups only the hinges a caller names (the
character loader: those whose limit is a human joint speed, none from a mapping file).

Used by the solver's frame-to-frame bound (:class:`~physmocap.ik.limits.GroupStepLimit`)
and by the metrics that check it (:func:`joint_speeds`).
"""

from __future__ import annotations

from typing import Collection, Mapping, Sequence

import mujoco
import numpy as np

__all__ = ["hinge_groups", "GroupIndex", "joint_speeds"]


def hinge_groups(model: mujoco.MjModel, joints: Collection[str]) -> tuple[tuple[str, ...], ...]:
    """Every set of three or more hinges of one body sharing one anchor (``jnt_pos`` equal to
    1e-9 m), in model order, all of whose hinges are in ``joints``; a body with a hinge not
    in ``joints`` at that anchor gives no group.

    Two hinges are left out: the second axis turns about the first, so :math:`a_1^T a_2`
    never changes and, for axes at right angles (every hinge pair of the humanoid: ankles,
    wrists, elbow and forearm, clavicles), the body's speeds along them are the rates."""
    by_anchor: dict[tuple, list[int]] = {}
    for j in range(model.njnt):
        if int(model.jnt_type[j]) == int(mujoco.mjtJoint.mjJNT_HINGE):
            key = (int(model.jnt_bodyid[j]), *np.round(model.jnt_pos[j], 9).tolist())
            by_anchor.setdefault(key, []).append(j)
    out = []
    for ids in by_anchor.values():
        names = tuple(model.joint(j).name for j in ids)
        if len(ids) >= 3 and all(n in joints for n in names):
            out.append(names)
    return tuple(out)


class GroupIndex:
    """The groups of a model as index arrays: joint ids, qpos and dof addresses, and each
    hinge's velocity limit (rad/s), group by group.

    Attributes:
        joints, qposadr, dofadr, vmax: One array per group.
        grouped: Names of every grouped hinge.
    """

    def __init__(self, model: mujoco.MjModel, groups: Sequence[Sequence[str]], limits: Mapping[str, float]) -> None:
        self.joints = [np.array([model.joint(n).id for n in g], dtype=int) for g in groups]
        self.qposadr = [model.jnt_qposadr[j].astype(int) for j in self.joints]
        self.dofadr = [model.jnt_dofadr[j].astype(int) for j in self.joints]
        self.vmax = [np.array([float(limits[n]) for n in g]) for g in groups]
        self.grouped = frozenset(n for g in groups for n in g)

    def __len__(self) -> int:
        return len(self.joints)

    def gram(self, data: mujoco.MjData, k: int) -> np.ndarray:
        r"""``(n, n)`` :math:`M = A^T A` of group ``k``: :math:`M_{ij} = a_i^T a_j` with
        the hinges' world axes in ``data`` (kinematics done); :math:`a_i^T\omega = (M \dot q)_i`."""
        A = data.xaxis[self.joints[k]]
        return A @ A.T


def joint_speeds(
    model: mujoco.MjModel, qpos: np.ndarray, fps: float, names: Sequence[str],
    groups: Sequence[Sequence[str]] = (), limits: Mapping[str, float] | None = None,
) -> np.ndarray:
    r"""``(F-1, len(names))`` speed of each named hinge/slide joint on each transition
    ``t -> t+1`` (rad/s or m/s): :math:`|q_{t+1} - q_t|\,f`, or, for a hinge of one of
    ``groups``, the body's angular speed along that hinge's axis
    :math:`|(M (q_{t+1} - q_t))_i|\,f` with the axes of frame :math:`t+1` (the solver's
    bound at its last iterate).

    The grouped components need the kinematics of frame :math:`t+1`; they are computed only
    on transitions where they can reach ``limits`` (:math:`|a_i^T\omega| \le \sum_j
    |\dot q_j|`, so a group whose rates sum below its smallest limit keeps its raw rates,
    which are then below every limit too); with ``limits`` None, on every transition.
    """
    qpos = np.asarray(qpos, dtype=float)
    F = qpos.shape[0]
    adr = np.array([int(model.joint(n).qposadr[0]) for n in names], dtype=int)
    speed = np.abs(np.diff(qpos[:, adr], axis=0)) * fps if F > 1 else np.zeros((0, len(names)))
    if F < 2 or not groups:
        return speed
    col = {n: i for i, n in enumerate(names)}
    used = [(k, np.array([col[n] for n in g], dtype=int)) for k, g in enumerate(groups) if all(n in col for n in g)]
    if not used:
        return speed
    index = GroupIndex(model, groups, limits or {n: 0.0 for g in groups for n in g})
    rates = {k: np.diff(qpos[:, index.qposadr[k]], axis=0) * fps for k, _ in used}  # (F-1, n), signed
    need = {
        k: np.abs(rates[k]).sum(axis=1) >= index.vmax[k].min() if limits is not None else np.ones(F - 1, dtype=bool)
        for k, _ in used
    }
    data = mujoco.MjData(model)
    for t in np.flatnonzero(np.any([need[k] for k, _ in used], axis=0)):
        data.qpos[:] = qpos[t + 1]
        mujoco.mj_kinematics(model, data)
        for k, cols in used:
            if need[k][t]:
                speed[t, cols] = np.abs(index.gram(data, k) @ rates[k][t])
    return speed
