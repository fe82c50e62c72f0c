"""Foot planting: contact points hold still on the floor while they are in contact.

A causal state machine per contact site (it only looks at the current frame's
contact label and the previous frame's solution, so the streaming retargeter
uses it as is):

* **Contact begins** (label turns on): the site is *locked* at its horizontal
  position in the previous frame's solution, and its height target is the
  floor.  The height cost ramps in over ``onset_time`` so a foot that lands a
  few millimetres high settles instead of popping.
* **In contact**: a :class:`~physmocap.ik.tasks.SitePositionTask` with costs
  ``(cost_xy, cost_xy, cost_z)`` per metre holds the lock.  These costs are
  orders of magnitude above the tracking costs, so the residual is far below a
  millimetre (the benchmark and tests measure it), while the QP stays feasible
  when targets pull planted feet apart: the pelvis and the other soft
  tracking tasks give way, not the feet.  Hard limits (joint limits, velocity,
  floor) still come first.
* **Release** (label turns off): the lock's cost fades to zero along a smooth
  ramp over ``release_time`` seconds, handing the site back to tracking
  without a pop.

All positions are metres in the character's world (Z-up, floor at ``floor``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Sequence

import mujoco
import numpy as np

from .tasks import SitePositionTask

__all__ = ["PlantOptions", "FootPlanter"]


@dataclass
class PlantOptions:
    """Planting options.

    Attributes:
        plant: Enable planting at all.
        cost_xy: Cost per metre of the horizontal lock.
        cost_z: Cost per metre of the height lock (floor).
        onset_time: Seconds over which the height cost ramps in at contact start.
        release_time: Seconds over which the lock fades out after contact ends.
    """

    plant: bool = True
    cost_xy: float = 400.0
    cost_z: float = 400.0
    onset_time: float = 0.03
    release_time: float = 0.12


def _smooth(x: float) -> float:
    """Smoothstep on [0, 1]."""
    x = min(max(x, 0.0), 1.0)
    return x * x * (3.0 - 2.0 * x)


class FootPlanter:
    """Lock state of every contact site, turned into IK tasks frame by frame."""

    def __init__(
        self,
        model: mujoco.MjModel,
        sites: Sequence[str],
        fps: float,
        options: PlantOptions | None = None,
        floor: float = 0.0,
    ) -> None:
        self.options = opt = options or PlantOptions()
        self.model = model
        self.sites = tuple(sites)
        self.floor = float(floor)
        self.tasks = [SitePositionTask(model, s, cost=0.0) for s in self.sites]
        n = len(self.sites)
        self.locked = np.zeros(n, dtype=bool)
        self.age = np.zeros(n, dtype=int)
        self.release_left = np.zeros(n, dtype=int)
        self.onset_frames = max(1, int(round(opt.onset_time * fps)))
        self.release_frames = max(1, int(round(opt.release_time * fps)))
        self.anchor = np.zeros((n, 3))

    def reset(self) -> None:
        self.locked[:] = False
        self.age[:] = 0
        self.release_left[:] = 0

    def update(self, in_contact: Mapping[str, bool] | np.ndarray, data: mujoco.MjData) -> list[SitePositionTask]:
        """Advance one frame; returns the tasks to add to this frame's QP.

        Args:
            in_contact: Per site, whether it is in contact on this frame
                (a mapping by site name, or a bool array in ``self.sites`` order).
            data: MuJoCo data holding the previous frame's solution (anchors
                are taken from it when a contact begins).
        """
        opt = self.options
        if isinstance(in_contact, Mapping):
            flags = np.array([bool(in_contact.get(s, False)) for s in self.sites])
        else:
            flags = np.asarray(in_contact, dtype=bool)
        active: list[SitePositionTask] = []
        if not opt.plant:
            return active
        for k, task in enumerate(self.tasks):
            if flags[k]:
                if not self.locked[k]:
                    sid = task.site_id
                    self.anchor[k, :2] = data.site_xpos[sid, :2]
                    self.anchor[k, 2] = self.floor
                    self.locked[k] = True
                    self.age[k] = 0
                    self.release_left[k] = 0
                else:
                    self.age[k] += 1
                ramp = _smooth((self.age[k] + 1) / self.onset_frames)
                task.set_cost((opt.cost_xy, opt.cost_xy, opt.cost_z * ramp))
            else:
                if self.locked[k]:
                    self.locked[k] = False
                    self.release_left[k] = self.release_frames
                if self.release_left[k] <= 0:
                    continue
                fade = _smooth(self.release_left[k] / (self.release_frames + 1))
                self.release_left[k] -= 1
                task.set_cost((opt.cost_xy * fade, opt.cost_xy * fade, opt.cost_z * fade))
            task.set_target(self.anchor[k])
            active.append(task)
        return active
