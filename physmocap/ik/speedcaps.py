r"""Joints at their velocity caps eased offline: a last pass spreads their fast moves out in time.

The per-frame IK follows the actor as fast as each joint's velocity bound lets it.  Where the
actor asks for more than the bound, a joint runs at its cap for several frames and the
character lags, then catches up: a robot's shoulder of three hinges near its gimbal lock (the
arm level at the side: the first and last axes align, and a small move of the arm needs the
two to turn fast and opposite ways; the bundled robot's left shoulder pitch at its cap on
12 % of the CMU dance, the G1's joints on 6.5 %), or a knee that straightens to let a leg
pass from one bend plane to the other where the source's thigh turns over (the dance's right
knee, 44 degrees in four frames).  Issue 9 asks that no joint sit at its cap on more than
0.5 % of frames.

Offline the whole clip is known, so the move can start earlier and end later instead.  After
the other passes (:mod:`.branches`, :mod:`.transitions`):

1. **saturated joints**: the hinges and slides that move at
   :data:`~physmocap.metrics.fidelity.SATURATION_RATIO` of their velocity limit or faster
   on some transition (:func:`~physmocap.metrics.fidelity.saturation_matrix`, the report's
   figure), once some joint is held there (:data:`HELD_TRANSITIONS` transitions running) or
   touches it on more than :data:`TOUCH_SHARE` of the transitions: a clip whose joints only
   touch their caps now and then gets no pass;
2. **reference**: each such joint's trajectory :math:`q_t` rate-limited to
   :math:`s = \rho\, \dot q^{max} / f` per frame (:data:`EASE_SPEED` :math:`= \rho`) forwards
   and backwards in time, and the two averaged (:func:`eased_reference`):

   .. math::

       a_t = a_{t-1} + \mathrm{clip}(q_t - a_{t-1}, -s, s), \qquad
       b_t = b_{t+1} + \mathrm{clip}(q_t - b_{t+1}, -s, s), \qquad
       r_t = (a_t + b_t) / 2 .

   :math:`a` lags the joint and :math:`b` leads it by the same frames, so :math:`r` starts a
   move too fast for :math:`s` before the joint does and ends it after, centred on it, never
   faster than :math:`s` per frame; where the joint is slower, :math:`r = q`.  Only the
   stretches of :math:`r \ne q` that hold a saturated transition are kept (a joint that
   nears but does not reach its cap elsewhere keeps its own motion);
3. **last pass**: the clip is retargeted once more with every hinge and slide joint pulled
   (a :class:`~physmocap.ik.branches.Guide`) towards the previous pass with
   :data:`FOLLOW_COST` per radian (metre), and the saturated joints towards their references
   with :data:`EASE_COST`, each frame's iterations starting from the previous pass's pose
   (:attr:`~physmocap.ik.branches.Guide.follow`).  At a gimbal lock the pulled hinges turn
   together, in the directions the arm's targets barely see, before the arm needs them.

The pass is kept only if fewer joint-transitions saturate than before and the solver relaxed
a hard constraint on no more frames; a joint the pass brought to its cap gets one more
(:data:`CAP_PASSES` in all).  On the CMU dance: robot, any joint at its cap on 23.7 %
of frames before, 0.1 % after (the arms' segment medians 0.1-0.5 degrees further from the actor:
the moves that start early move the arm early); humanoid 4.7 -> 0.1 %; the G1 6.5 -> 0.1 %.
Streaming retargeting cannot look ahead and does not do this.  Radians, metres, seconds.
"""

from __future__ import annotations

import math
from typing import Mapping

import mujoco
import numpy as np

from ..sources.gaps import find_runs
from ..spill import release
from .branches import Guide
from .transitions import moving_joints

__all__ = ["eased_reference", "held_at_cap", "CapGuides", "EASE_SPEED", "EASE_COST", "FOLLOW_COST", "HELD_TRANSITIONS", "TOUCH_SHARE", "CAP_PASSES"]

#: Share of a joint's velocity limit its eased reference moves at, at most.
EASE_SPEED = 0.7
#: Cost per radian (metre) of the pull of a saturated joint towards its eased reference (the
#: position tasks weigh 5 per metre; :data:`~physmocap.ik.branches.GUIDE_COST` is 2).
EASE_COST = 5.0
#: Cost per radian (metre) of the pull of every other joint towards the previous pass.
FOLLOW_COST = 2.0
#: Transitions running at the cap from which a joint is held there.  A clip whose joints only
#: touch their caps, one transition at a time (the walks' toes at toe-off, a step at 0.99 of
#: the cap), on at most :data:`TOUCH_SHARE` of the transitions each, gets no pass: it would
#: cost a third more CPU time for nothing that lags.
HELD_TRANSITIONS = 2
#: Share of a clip's transitions on which a joint may touch its cap without a pass (the
#: issue's bound: no joint at its cap on more than 0.5 % of frames).
TOUCH_SHARE = 0.005
#: Passes at most: a pass can bring another joint to its cap (the robot's right hip yaw on the
#: dance, three frames), and the next eases it.
CAP_PASSES = 2


def held_at_cap(saturated: np.ndarray) -> np.ndarray:
    """``(F-1,)`` bool: the ``saturated (F-1,)`` transitions that belong to a run of at least
    :data:`HELD_TRANSITIONS` (a joint that touches its cap on one transition does not lag)."""
    sat = np.asarray(saturated, dtype=bool)
    out = np.zeros_like(sat)
    for s, e in find_runs(sat):
        if e - s + 1 >= HELD_TRANSITIONS:
            out[s : e + 1] = True
    return out


def eased_reference(q: np.ndarray, step: float, saturated: np.ndarray) -> np.ndarray:
    """``q (F,)`` (one joint's trajectory) with its moves faster than ``step`` per frame
    spread out in time: the mean of its rate limits forwards and backwards in time (module
    docstring, item 2), on the stretches where that differs from ``q`` and that hold one of
    the ``saturated (F-1,)`` transitions (``t -> t+1``); ``q`` elsewhere."""
    x = np.asarray(q, dtype=float)
    F = x.shape[0]
    a = x.copy()
    for t in range(1, F):  # within reach, exactly the joint (no rounding creeps in)
        d = x[t] - a[t - 1]
        if abs(d) > step:
            a[t] = a[t - 1] + math.copysign(step, d)
    b = x.copy()
    for t in range(F - 2, -1, -1):
        d = x[t] - b[t + 1]
        if abs(d) > step:
            b[t] = b[t + 1] + math.copysign(step, d)
    r = 0.5 * (a + b)
    out = x.copy()
    hits = np.flatnonzero(np.asarray(saturated, dtype=bool))
    for s, e in find_runs(r != x):
        # transition t touches frames t and t + 1: one of them in the stretch [s, e]
        if np.any((hits >= s - 1) & (hits <= e)):
            out[s : e + 1] = r[s : e + 1]
    return out


class CapGuides:
    """Frame -> the :class:`~physmocap.ik.branches.Guide` of the pass that eases the joints at
    their velocity caps (module docstring).

    Args:
        model: The character's model.
        qpos: ``(F, nq)`` the previous pass (read, not copied; a spilled array's pages are let
            go after each joint's column is read).
        fps: Frame rate.
        limits: Hinge/slide joint name -> velocity limit (rad/s or m/s;
            ``Character.velocity_limits``).
        saturated: ``(F-1, len(limits))`` bool, which joints move at their caps on which
            transitions of ``qpos`` (:func:`~physmocap.metrics.fidelity.saturation_matrix`
            with the character's ``velocity_groups``, the report's figure).
    """

    def __init__(self, model: mujoco.MjModel, qpos: np.ndarray, fps: float, limits: Mapping[str, float],
                 saturated: np.ndarray) -> None:
        self.qpos = qpos
        joints = moving_joints(model)
        self.adr = model.jnt_qposadr[joints].astype(int)
        self.dofs = model.jnt_dofadr[joints].astype(int)
        self.cost = np.full(len(joints), FOLLOW_COST)
        sat = np.asarray(saturated, dtype=bool)
        #: frame -> (columns of ``adr``, their reference values) where a reference differs
        self._eased: dict[int, tuple[list[int], list[float]]] = {}
        column = {int(a): k for k, a in enumerate(self.adr)}
        held = sat.size > 0 and (bool(sat.mean(axis=0).max() > TOUCH_SHARE)
                                 or any(held_at_cap(sat[:, j]).any() for j in range(sat.shape[1])))
        for j, name in enumerate(limits if held else ()):
            if not sat[:, j].any():
                continue
            k = column.get(int(model.jnt_qposadr[model.joint(name).id]))
            if k is None:
                continue
            x = np.array(qpos[:, self.adr[k]], dtype=float)
            release(qpos)
            r = eased_reference(x, EASE_SPEED * float(limits[name]) / fps, sat[:, j])
            self.cost[k] = EASE_COST
            for t in np.flatnonzero(r != x).tolist():
                cols, values = self._eased.setdefault(t, ([], []))
                cols.append(k)
                values.append(float(r[t]))

    def __len__(self) -> int:
        """Frames with a guide: every frame."""
        return int(self.qpos.shape[0])

    @property
    def eased(self) -> bool:
        """Whether some joint's reference differs from the previous pass (a pass is worth it)."""
        return bool(self._eased)

    def get(self, t: int) -> Guide:
        """Frame ``t``'s guide: the previous pass's pose, the saturated joints' references
        where they differ, and that pose to start from."""
        start = np.array(self.qpos[t], dtype=float)
        values = start[self.adr]
        eased = self._eased.get(t)
        if eased is not None:
            values[eased[0]] = eased[1]
        return Guide(self.adr, self.dofs, values, self.cost, start, follow=True)
