"""IK tasks physmocap adds to mink's.

:class:`SitePositionTask` regulates the world position of a site with a cost
per world axis, so that a planted contact point can hold its horizontal
position and its height with different weights (mink's ``FrameTask`` works in
the frame's local axes and always carries orientation rows).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Sequence

import mink
import mujoco
import numpy as np

if TYPE_CHECKING:
    from ..models.mapping import TrackedFrame

__all__ = ["SitePositionTask", "SitesPositionTask", "SegmentsTask", "BodyPointTask", "FRAME_JAC", "FRAME_XMAT", "FRAME_XPOS"]

#: Per kind of MuJoCo frame (a tracked joint's site or body, a geom): its translational (and
#: rotational) Jacobian function, and the ``MjData`` arrays of its world rotation and position.
FRAME_JAC = {"site": mujoco.mj_jacSite, "body": mujoco.mj_jacBody, "geom": mujoco.mj_jacGeom}
FRAME_XMAT = {"site": "site_xmat", "body": "xmat", "geom": "geom_xmat"}
FRAME_XPOS = {"site": "site_xpos", "body": "xpos", "geom": "geom_xpos"}


class SitePositionTask(mink.Task):
    r"""World-frame position of a site.

    Error :math:`e(q) = x_s(q) - x^*` (metres, world axes) and Jacobian
    :math:`J = \partial x_s / \partial q` (MuJoCo's ``mj_jacSite``, world axes),
    so the QP term is :math:`\| W (J \Delta q + e) \|^2` with
    :math:`W = \mathrm{diag}(c_x, c_y, c_z)` (cost per metre).
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        site: str,
        cost=1.0,
        gain: float = 1.0,
        axes: tuple[int, ...] = (0, 1, 2),
    ) -> None:
        """
        Args:
            model: The MuJoCo model.
            site: Site name.
            cost: Cost per metre, scalar or one per axis in ``axes``.
            gain: Task gain (1 = dead-beat).
            axes: World axes regulated (``(0, 1)`` for the horizontal position only);
                as an equality constraint (mink ``constraints=``) only these rows count.
        """
        self.axes = tuple(int(a) for a in axes)
        self.k = len(self.axes)
        super().__init__(cost=np.zeros(self.k), gain=gain, lm_damping=0.0)
        self.model = model
        self.site_id = model.site(site).id
        self.site = site
        self.target = np.zeros(3)
        self._jacp = np.zeros((3, model.nv))
        self.set_cost(cost)

    def set_cost(self, cost) -> None:
        """Cost per metre: a scalar or one per regulated axis (>= 0)."""
        if isinstance(cost, float):  # a scalar (the planting's, every frame): no temporary array
            if cost < 0:
                raise ValueError("costs must be >= 0")
            self.cost.fill(cost)
            return
        c = np.empty(self.k)
        c[:] = cost  # broadcast and converted to float, as np.broadcast_to(np.asarray(cost, float)) would
        if (c < 0).any():
            raise ValueError("costs must be >= 0")
        self.cost[:] = c

    def set_target(self, target: np.ndarray) -> None:
        self.target = np.array(target, dtype=float)

    def compute_error(self, configuration: mink.Configuration) -> np.ndarray:
        return (configuration.data.site_xpos[self.site_id] - self.target)[list(self.axes)]

    def compute_jacobian(self, configuration: mink.Configuration) -> np.ndarray:
        mujoco.mj_jacSite(self.model, configuration.data, self._jacp, None, self.site_id)
        return self._jacp[list(self.axes)].copy()


class _VectorsTask(mink.Task):
    """``n`` world vectors (metres) with a target and a cost per metre each: the bookkeeping
    :class:`SitesPositionTask` and :class:`SegmentsTask` share (``k = 3 n`` rows)."""

    def __init__(self, model: mujoco.MjModel, n: int, costs, gain: float) -> None:
        self.n = int(n)
        self.k = 3 * self.n
        super().__init__(cost=np.zeros(self.k), gain=gain, lm_damping=0.0)
        self.model = model
        self.targets = np.zeros((self.n, 3))
        self._jac = np.zeros((self.k, model.nv))
        self.set_costs(costs)

    def set_costs(self, costs) -> None:
        c = np.broadcast_to(np.asarray(costs, dtype=float), (self.n,))
        if np.any(c < 0):
            raise ValueError("costs must be >= 0")
        self.cost[:] = np.repeat(c, 3)

    def set_targets(self, targets: np.ndarray) -> None:
        self.targets = np.asarray(targets, dtype=float).reshape(-1, 3)


class SitesPositionTask(_VectorsTask):
    r"""World positions of several sites in one task (position-only tracking).

    Equivalent to one mink ``FrameTask`` per site with a zero orientation cost,
    computed in one pass: error :math:`e = [x_{s_i}(q) - x^*_i]_i` (metres,
    world axes), Jacobian rows from ``mj_jacSite``, cost :math:`c_i` per metre
    for site :math:`i` (0 switches a site off).  Sites with orientation targets
    keep their own ``FrameTask``.
    """

    def __init__(self, model: mujoco.MjModel, sites: list[str], costs, gain: float = 1.0) -> None:
        self.site_ids = np.array([model.site(s).id for s in sites], dtype=int)
        super().__init__(model, len(self.site_ids), costs, gain)

    def compute_error(self, configuration: mink.Configuration) -> np.ndarray:
        return (configuration.data.site_xpos[self.site_ids] - self.targets).reshape(-1)

    def compute_jacobian(self, configuration: mink.Configuration) -> np.ndarray:
        data = configuration.data
        for i, sid in enumerate(self.site_ids):
            mujoco.mj_jacSite(self.model, data, self._jac[3 * i : 3 * i + 3], None, sid)
        return self._jac


class BodyPointTask(mink.Task):
    r"""World-frame position of a point fixed on a body (a foot's corner it stands on).

    The point is :math:`x(q) = p_b(q) + R_b(q)\,\ell` for the body's world position
    :math:`p_b`, rotation :math:`R_b` and the point's body coordinates :math:`\ell`
    (metres); error :math:`e(q) = x(q) - x^*` on the regulated world axes and Jacobian
    :math:`\partial x / \partial q` (MuJoCo's ``mj_jac`` at that point).  The same rows
    as :class:`SitePositionTask`, for a point no site marks.
    """

    def __init__(self, model: mujoco.MjModel, body: int, cost=1.0, gain: float = 1.0,
                 axes: tuple[int, ...] = (0, 1, 2)) -> None:
        """
        Args:
            model: The MuJoCo model.
            body: Body id.
            cost: Cost per metre, scalar or one per axis in ``axes``.
            gain: Task gain (1 = dead-beat).
            axes: World axes regulated.
        """
        self.axes = tuple(int(a) for a in axes)
        self.k = len(self.axes)
        super().__init__(cost=np.zeros(self.k), gain=gain, lm_damping=0.0)
        self.model = model
        self.body = int(body)
        #: the point in the body's frame (metres)
        self.local = np.zeros(3)
        self.target = np.zeros(3)
        self._jacp = np.zeros((3, model.nv))
        self.cost[:] = cost

    def set_target(self, target: np.ndarray) -> None:
        self.target = np.array(target, dtype=float)

    def point(self, data: mujoco.MjData) -> np.ndarray:
        """``(3,)`` the point's world position in the pose of ``data`` (kinematics run)."""
        return data.xpos[self.body] + data.xmat[self.body].reshape(3, 3) @ self.local

    def compute_error(self, configuration: mink.Configuration) -> np.ndarray:
        return (self.point(configuration.data) - self.target)[list(self.axes)]

    def compute_jacobian(self, configuration: mink.Configuration) -> np.ndarray:
        data = configuration.data
        mujoco.mj_jac(self.model, data, self._jacp, None, self.point(data), self.body)
        return self._jacp[list(self.axes)].copy()


class SegmentsTask(_VectorsTask):
    r"""World vectors between pairs of tracked points: limb segments pointing the actor's way.

    For pair :math:`i` of a parent point :math:`p_i(q)` and a child point :math:`c_i(q)` (a site,
    or a body's origin), error :math:`e_i = (c_i(q) - p_i(q)) - v^*_i` (metres, world axes) and
    Jacobian :math:`J_{c_i} - J_{p_i}`, cost :math:`w_i` per metre (0 switches a pair off).
    With :math:`v^*_i` the targets' own vector (child target minus parent target), a segment
    whose parent cannot reach its target (a shoulder at its limit) still points the actor's way
    instead of reaching for its child's absolute position (a forearm folded over the head).
    """

    def __init__(self, model: mujoco.MjModel, pairs: Sequence[tuple["TrackedFrame", "TrackedFrame"]], costs,
                 gain: float = 1.0) -> None:
        """
        Args:
            model: The MuJoCo model.
            pairs: ``(parent, child)`` tracked frames (:class:`~physmocap.models.mapping.TrackedFrame`).
            costs: Cost per metre, one for all or one per pair.
            gain: Task gain (1 = dead-beat).
        """
        #: ``(parent, child)`` of ``(MjData position array name, Jacobian function, id)``
        self.pairs = [tuple((FRAME_XPOS[f.kind], FRAME_JAC[f.kind], f.object_id(model)) for f in pair)
                      for pair in pairs]
        super().__init__(model, len(self.pairs), costs, gain)
        self._a = np.zeros((3, model.nv))
        self._b = np.zeros((3, model.nv))

    def compute_error(self, configuration: mink.Configuration) -> np.ndarray:
        data = configuration.data
        v = np.array([getattr(data, c[0])[c[2]] - getattr(data, p[0])[p[2]] for p, c in self.pairs]).reshape(-1, 3)
        return (v - self.targets).reshape(-1)

    def compute_jacobian(self, configuration: mink.Configuration) -> np.ndarray:
        data, model = configuration.data, self.model
        for n, (p, c) in enumerate(self.pairs):
            p[1](model, data, self._a, None, p[2])
            c[1](model, data, self._b, None, c[2])
            np.subtract(self._b, self._a, out=self._jac[3 * n : 3 * n + 3])
        return self._jac
