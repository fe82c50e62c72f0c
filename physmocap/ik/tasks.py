"""IK tasks physmocap adds to mink's.

:class:`SitePositionTask` regulates the world position of a site with a cost
per world axis, so that a planted contact point can hold its horizontal
position and its height with different weights (mink's ``FrameTask`` works in
the frame's local axes and always carries orientation rows).
"""

from __future__ import annotations

import mink
import mujoco
import numpy as np

__all__ = ["SitePositionTask"]


class SitePositionTask(mink.Task):
    r"""World-frame position of a site.

    Error :math:`e(q) = x_s(q) - x^*` (metres, world axes) and Jacobian
    :math:`J = \partial x_s / \partial q` (MuJoCo's ``mj_jacSite``, world axes),
    so the QP term is :math:`\| W (J \Delta q + e) \|^2` with
    :math:`W = \mathrm{diag}(c_x, c_y, c_z)` (cost per metre).
    """

    k: int = 3

    def __init__(self, model: mujoco.MjModel, site: str, cost=(1.0, 1.0, 1.0), gain: float = 1.0) -> None:
        super().__init__(cost=np.zeros(3), gain=gain, lm_damping=0.0)
        self.model = model
        self.site_id = model.site(site).id
        self.site = site
        self.target = np.zeros(3)
        self._jacp = np.zeros((3, model.nv))
        self.set_cost(cost)

    def set_cost(self, cost) -> None:
        c = np.broadcast_to(np.asarray(cost, dtype=float), (3,))
        if np.any(c < 0):
            raise ValueError("costs must be >= 0")
        self.cost[:] = c

    def set_target(self, target: np.ndarray) -> None:
        self.target = np.array(target, dtype=float)

    def compute_error(self, configuration: mink.Configuration) -> np.ndarray:
        return configuration.data.site_xpos[self.site_id] - self.target

    def compute_jacobian(self, configuration: mink.Configuration) -> np.ndarray:
        mujoco.mj_jacSite(self.model, configuration.data, self._jacp, None, self.site_id)
        return self._jacp.copy()
