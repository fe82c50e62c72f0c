r"""The per-frame IK's quadratic program, assembled into preallocated arrays and solved by ``daqp``.

One IK iteration solves, for the tangent-space step :math:`\Delta q \in \mathbb{R}^{n_v}`
(radians for hinges, metres and radians for the free root),

.. math::

    \min_{\Delta q}\; \tfrac12 \Delta q^T H \Delta q + c^T \Delta q
    \quad\text{s.t.}\quad l \le \Delta q \le u,\quad G \Delta q \le h,\quad A \Delta q = b

with the same :math:`H, c, G, h, A, b` as ``mink.build_ik`` (the test
``tests/test_qp.py`` checks it), built without its per-call allocations:

* **Objective.**  Every task :math:`k` with error :math:`e_k` (its units),
  Jacobian :math:`J_k`, cost vector :math:`w_k` (per unit of error), gain
  :math:`\alpha_k` and LM damping :math:`\lambda_k` contributes the weighted rows
  :math:`W_k = \mathrm{diag}(w_k) J_k` and :math:`\epsilon_k = -\alpha_k\,
  w_k \odot e_k`, written in place into one stacked matrix :math:`W`; then

  .. math::

      H = W^T W + \Big(\mu + \sum_k \lambda_k \|\epsilon_k\|^2\Big) I + D_p,
      \qquad c = -W^T \epsilon + d_p

  where :math:`\mu` is the global Levenberg-Marquardt damping.  The posture
  task (:math:`J = I` with the free joint's columns zeroed, error
  :math:`q \ominus q_{rest}`, cost :math:`w_p`) is the diagonal
  :math:`D_p = \mathrm{diag}(w_p^2)` and :math:`d_p = \alpha_p w_p^2 \odot e_p`
  instead of :math:`n_v` dense rows.  Jacobians come from ``mj_jacSite`` /
  ``mj_jacBody`` written into preallocated buffers; ``FrameTask`` SE(3) errors
  and their Jacobians :math:`-J_{\log}(T_{tb})\,\mathrm{Ad}_{T_{fw}} J` use
  mink's compiled Lie-group operations (the same ones ``FrameTask`` uses).
* **Simple bounds.**  The limits whose rows are :math:`\pm` identity rows are
  intersected into :math:`l \le \Delta q \le u`: the trust region
  :math:`|\Delta q_i| \le \rho`, mink ``ConfigurationLimit`` (hinge/slide:
  :math:`g (q_{min} \ominus q) \le \Delta q \le g (q_{max} \ominus q)`),
  :class:`~physmocap.ik.limits.FrameStepLimit` and
  :class:`~physmocap.ik.limits.RootStepLimit` (their :meth:`box`).  daqp takes
  simple bounds natively, which is much cheaper than :math:`2 n_v` rows.
* **General inequalities** :math:`G, h`: every other limit (floor,
  self-collision, a ball joint's angle) through its ``compute_qp_inequalities``.
* **Equalities** :math:`A = J_c`, :math:`b = -\alpha_c e_c` for the planted
  contacts (daqp constraint sense 5).

:func:`solve` calls ``daqp.solve`` directly (no qpsolvers conversion).
"""

from __future__ import annotations

from ctypes import c_int
from dataclasses import dataclass
from typing import Sequence

import daqp
import mink
import mujoco
import numpy as np

from .limits import FrameStepLimit, RootStepLimit
from .tasks import FRAME_JAC as _JAC, FRAME_XMAT as _XMAT, FRAME_XPOS as _XPOS, SitePositionTask, SitesPositionTask

try:  # mink's compiled SE(3) operations (what FrameTask uses when present)
    from mink.lie import _lie_ops_c as _native
except ImportError:  # pragma: no cover - pure-Python mink
    _native = None

__all__ = ["QP", "QPBuilder", "WarmSolver", "solve", "INFINITY"]

#: What daqp reads as an absent bound.
INFINITY = 1e30

#: daqp's constraint sense array type (a C ``int``).
_SENSE = np.dtype(c_int)


def _weighted_residual(task: mink.Task, configuration: mink.Configuration) -> tuple[np.ndarray, np.ndarray]:
    r"""``(W_k, e_k)`` of a mink task: :math:`W_k = \mathrm{diag}(w) J`, :math:`e_k = -\mathrm{diag}(w)\,g\,e`
    (weights :math:`w`, gain :math:`g`, error :math:`e`, Jacobian :math:`J`), as mink's
    ``compute_qp_objective`` builds them; mink releases without ``compute_qp_residual``
    (1.0.0, the lowest supported) get the same rows from the error and Jacobian."""
    residual = getattr(task, "compute_qp_residual", None)
    if residual is not None:
        Wk, ek, _ = residual(configuration)
        return Wk, ek
    e = -task.gain * np.atleast_1d(task.compute_error(configuration))
    cost = np.broadcast_to(np.asarray(task.cost, dtype=float), e.shape)
    return cost[:, None] * task.compute_jacobian(configuration), cost * e


@dataclass

class QP:
    r"""One QP: :math:`\min \frac12 x^T H x + c^T x` s.t. ``lb <= x <= ub``, ``G x <= h``, ``A x = b``.

    ``H`` ``(nv, nv)``, ``c`` ``(nv,)``, ``lb``/``ub`` ``(nv,)`` (``±INFINITY`` when
    unbounded), ``G`` ``(m, nv)``, ``h`` ``(m,)``, ``A`` ``(p, nv)``, ``b`` ``(p,)``.
    The arrays may be views of the builder's buffers: valid until the next build.
    """

    H: np.ndarray
    c: np.ndarray
    lb: np.ndarray
    ub: np.ndarray
    G: np.ndarray
    h: np.ndarray
    A: np.ndarray
    b: np.ndarray


class QPBuilder:
    """Assembles the IK QP of a model into preallocated arrays (see the module docstring).

    Args:
        model: The character's MuJoCo model.
    """

    def __init__(self, model: mujoco.MjModel) -> None:
        self.model = model
        nv = self.nv = int(model.nv)
        self.H = np.zeros((nv, nv))
        self.c = np.zeros(nv)
        self.lb = np.zeros(nv)
        self.ub = np.zeros(nv)
        self._W = np.zeros((64, nv))  # stacked weighted Jacobians, grown on demand
        self._eps = np.zeros(64)
        self._frame_plans: dict[tuple, tuple] = {}  # frame tasks' ids -> their frames and Jacobian rows
        self._jacS = np.zeros((8, 3, nv))  # SitePositionTasks' site Jacobians
        self._task_plans: dict[tuple, tuple] = {}  # task ids -> runs, rows, spans
        self._site_plans: dict[tuple, tuple] = {}  # task ids -> rows' owners, axes, sites, targets (this frame)
        self._frame_costs: dict[tuple, tuple] = {}  # frame tasks' ids -> their targets, costs, gains (this frame)
        self._dq = np.zeros(nv)
        self._dq2 = np.zeros(nv)
        self._Hdiag = np.einsum("ii->i", self.H)  # a writable view of H's diagonal
        self._postures: dict[int, tuple] = {}  # id(posture task) -> (task, its costs' bytes, weights)
        self._views: dict[tuple, tuple] = {}
        self._box: tuple | None = None  # (config limit, dofs, qpos addresses) of hinge/slide joints
        self._spans: dict[int, tuple] = {}  # id(box limit's dofs) -> (the dofs, their _span)

    # -- objective ----------------------------------------------------------------
    def _rows(self, m: int) -> None:
        if m > len(self._eps):
            size = max(m, 2 * len(self._eps))
            self._W = np.zeros((size, self.nv))
            self._eps = np.zeros(size)

    def _frame_rows(self, tasks: Sequence[mink.FrameTask], data: mujoco.MjData, W: np.ndarray, eps: np.ndarray) -> None:
        r"""Rows of consecutive ``FrameTask`` s, 6 each: :math:`W_k = -\mathrm{diag}(w_k)
        J_{\log}(T_{tb}) \mathrm{Ad}_{T_{fw}} J_k`, :math:`\epsilon_k = -\alpha_k\, w_k \odot
        \log(T_{bt})` (metres, radians), :math:`J_k` the frame's ``(6, nv)`` Jacobian in world
        axes (``mj_jacSite``/``mj_jacBody``).  The SE(3) terms are mink's compiled operations,
        task by task; the products are batched ``matmul`` s (a stack of matrices gives each
        product the same bits as one ``matmul`` per task)."""
        n = len(tasks)
        model = self.model
        jlog, inverse_multiply, adjoint = _native.se3_jlog, _native.se3_inverse_multiply, _native.se3_rotation_adjoint_from_xmat
        to_se3, rminus = _native.xmat_xpos_to_wxyz_xyz, _native.se3_rminus
        logs, adjoints, errors = [], [], []
        frames, jacobians = self._frames(tasks, data)
        targets, C, negC, negg = self._frame_weights(tasks)
        for target, (jac, fid, xmat, xpos, Jp, Jr) in zip(targets, frames):
            frame = to_se3(xmat, xpos)
            jac(model, data, Jp, Jr, fid)
            logs.append(jlog(inverse_multiply(target, frame)))
            adjoints.append(adjoint(xmat))
            errors.append(rminus(target, frame))
        M = np.matmul(np.array(logs), np.array(adjoints))
        M *= negC
        np.matmul(M, jacobians, out=W.reshape(n, 6, self.nv))
        np.multiply(C, negg * np.array(errors), out=eps.reshape(n, 6))

    def _frame_weights(self, tasks: Sequence[mink.FrameTask]) -> tuple[list[np.ndarray], np.ndarray, np.ndarray, np.ndarray]:
        r"""``(targets, C, -C, -g)`` of a run of ``FrameTask`` s: their targets' ``wxyz_xyz``,
        their costs ``(n, 6)`` (per metre, per radian), the negated costs shaped ``(n, 6, 1)``
        and negated gains ``(n, 1)``, read at the first call after :meth:`new_frame` (the
        solver sets targets and changes costs only between frames)."""
        key = tuple(map(id, tasks))
        w = self._frame_costs.get(key)
        if w is None:
            for t in tasks:
                if t.transform_target_to_world is None:
                    raise mink.TargetNotSet(type(t).__name__)
            targets = [t.transform_target_to_world.wxyz_xyz for t in tasks]
            C = np.array([t.cost for t in tasks])
            g = np.array([[t.gain] for t in tasks])
            # the tasks are kept so that their ids stay theirs until new_frame
            w = self._frame_costs[key] = (tuple(tasks), targets, C, -C[:, :, None], -g)
        return w[1], w[2], w[3], w[4]

    def _frames(self, tasks: Sequence[mink.FrameTask], data: mujoco.MjData) -> tuple[list[tuple], np.ndarray]:
        """Per task ``(Jacobian function, frame id, xmat row, xpos row, translation and rotation
        rows of its Jacobian)``, and the ``(n, 6, nv)`` Jacobians buffer those rows belong to,
        resolved once per run of tasks (the rows are views into ``data``: they follow its
        kinematics)."""
        key = tuple(map(id, tasks))  # the plan keeps the tasks alive: their ids stay theirs
        plan = self._frame_plans.get(key)
        if plan is None or plan[1] is not data:
            if len(self._frame_plans) > 64:
                self._frame_plans.clear()
            J = np.zeros((len(tasks), 6, self.nv))
            frames = []
            for i, task in enumerate(tasks):
                kind = task.frame_type
                fid = _resolve(self.model, task.frame_name, kind)
                xmat, xpos = getattr(data, _XMAT[kind])[fid], getattr(data, _XPOS[kind])[fid]
                frames.append((_JAC[kind], fid, xmat, xpos, J[i, :3], J[i, 3:]))
            plan = self._frame_plans[key] = (tuple(tasks), data, frames, J)
        return plan[2], plan[3]

    def _sites_rows(self, task: SitesPositionTask, data: mujoco.MjData, W: np.ndarray, eps: np.ndarray, r: int) -> None:
        r"""``SitesPositionTask`` rows: :math:`W = \mathrm{diag}(w) J`, :math:`J` the sites' stacked
        ``mj_jacSite`` rows, :math:`\epsilon = -\alpha\, w \odot (x - x^*)` (metres)."""
        views = self._views.get((id(task), r))
        if views is None or views[0] is not task.site_ids or views[1] is not self._W:
            # the same rows of the same buffer from one call to the next: their views are kept
            views = self._views[(id(task), r)] = (
                task.site_ids, self._W, [(W[3 * i : 3 * i + 3], int(sid)) for i, sid in enumerate(task.site_ids)],
            )
        model = self.model
        for view, sid in views[2]:
            mujoco.mj_jacSite(model, data, view, None, sid)
        W *= task.cost[:, None]
        np.multiply(task.cost, -task.gain * (data.site_xpos[task.site_ids] - task.targets).reshape(-1), out=eps)

    def new_frame(self) -> None:
        """Forget the targets, gains and costs of the ``SitePositionTask`` s and ``FrameTask`` s
        read so far (see :meth:`site_terms`, :meth:`_frame_weights`): call
        it whenever they may have changed (a new frame's targets and holds)."""
        self._site_plans.clear()
        self._frame_costs.clear()

    def site_terms(self, tasks: Sequence[SitePositionTask], data: mujoco.MjData) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        r"""``(J, e, w)`` of consecutive ``SitePositionTask`` s, one row per regulated axis in task
        order: :math:`J` the site's world-position Jacobian row (``mj_jacSite``, ``(k, nv)``),
        :math:`e = -\alpha (x_s - x^*)` (metres, ``(k,)``) and the cost :math:`w` (per metre),
        what ``compute_jacobian``, ``-gain * compute_error`` and ``cost`` give task by task.
        The tasks' targets, gains and costs are read at the first call after :meth:`new_frame`."""
        key = tuple(map(id, tasks))
        plan = self._site_plans.get(key)
        if plan is None:
            # per row (task, axis): its task, axis, site, target coordinate and negated gain
            rows = [(j, a, t.site_id, t.target[a], -t.gain) for j, t in enumerate(tasks) for a in t.axes]
            owner, axes, row_sites, target, gain = (
                np.array([row[c] for row in rows], dtype=dtype) for c, dtype in enumerate((int, int, int, float, float))
            )
            cost = np.concatenate([t.cost for t in tasks])
            sites = [t.site_id for t in tasks]
            # flat indices (a 1-D take is the cheapest gather): the rows' Jacobian rows in the
            # (tasks, 3, nv) buffer seen as (3 * tasks, nv), and their coordinates in site_xpos;
            # the tasks are kept so that their ids stay theirs until new_frame
            plan = self._site_plans[key] = (tuple(tasks), 3 * owner + axes, 3 * row_sites + axes, sites, target, gain, cost)
        _, jac_rows, xpos_at, sites, target, gain, cost = plan
        jac, model = self._jacS, self.model
        if len(sites) > len(jac):
            jac = self._jacS = np.zeros((max(len(sites), 2 * len(jac)), 3, self.nv))
        for j, sid in enumerate(sites):
            mujoco.mj_jacSite(model, data, jac[j], None, sid)
        return jac.reshape(-1, self.nv).take(jac_rows, axis=0), gain * (data.site_xpos.take(xpos_at) - target), cost

    def objective(
        self,
        configuration: mink.Configuration,
        tasks: Sequence[mink.Task],
        damping: float,
        posture: Sequence[mink.PostureTask] = (),
    ) -> tuple[np.ndarray, np.ndarray]:
        r"""``(H, c)`` of ``tasks`` plus the diagonal posture terms (see the module docstring).

        ``H`` and ``c`` are the builder's buffers, overwritten by the next call.  Consecutive
        tasks of one kind (``FrameTask``, ``SitePositionTask``) are written together.
        """
        data = configuration.data
        runs, m, spans = self._task_plan(tasks)
        self._rows(m)
        W, eps = self._W, self._eps
        r = 0
        for kind, run in runs:
            if kind is mink.FrameTask:
                k = 6 * len(run)
                self._frame_rows(run, data, W[r : r + k], eps[r : r + k])
            elif kind is SitePositionTask:
                Jk, ek, cost = self.site_terms(run, data)
                k = len(ek)
                np.multiply(cost[:, None], Jk, out=W[r : r + k])
                np.multiply(cost, ek, out=eps[r : r + k])
            elif type(run[0]) is SitesPositionTask:
                k = run[0].k
                self._sites_rows(run[0], data, W[r : r + k], eps[r : r + k], r)
            else:  # any other mink task: its own weighted residual
                Wk, ek = _weighted_residual(run[0], configuration)
                k = len(ek)
                W[r : r + k] = Wk
                eps[r : r + k] = ek
            r += k
        mu = 0.0  # sum of lambda_k |eps_k|^2 over the tasks with LM damping, in task order
        for t, r0, k in spans:
            if t.lm_damping:
                mu += t.lm_damping * float(eps[r0 : r0 + k] @ eps[r0 : r0 + k])
        H, c = self.H, self.c
        Wm = W[:r]
        np.matmul(Wm.T, Wm, out=H)
        np.matmul(eps[:r], Wm, out=c)
        np.negative(c, out=c)
        self._Hdiag += damping + mu
        for p in posture:
            self._posture(configuration, p)
        return H, c

    def _task_plan(self, tasks: Sequence[mink.Task]) -> tuple[list, int, list[tuple[mink.Task, int, int]]]:
        """``(runs, rows, spans)`` of a sequence of tasks: its :func:`_runs`, its number of rows
        and each task's ``(task, first row, rows)``, kept per sequence (with the tasks, so
        that their ids stay theirs)."""
        key = tuple(map(id, tasks))
        plan = self._task_plans.get(key)
        if plan is None:
            if len(self._task_plans) > 256:
                self._task_plans.clear()
            spans, r = [], 0
            for t in tasks:
                k = t.k if hasattr(t, "k") else len(t.cost)
                spans.append((t, r, k))
                r += k
            plan = self._task_plans[key] = (_runs(tasks), r, spans)
        return plan

    def _posture(self, configuration: mink.Configuration, posture: mink.PostureTask) -> None:
        r"""Adds the posture task: :math:`H \mathrel{+}= \mathrm{diag}(w^2)`,
        :math:`c \mathrel{+}= \alpha w^2 \odot (q \ominus q^*)`, free-joint columns excluded."""
        e = self._dq
        mujoco.mj_differentiatePos(self.model, e, 1.0, posture.target_q, configuration.data.qpos)
        w, w2, free = self._posture_weights(posture)
        if free is not None:
            e[free] = 0.0
        eps = w * (-posture.gain * e)
        if posture.lm_damping:
            self._Hdiag += w2 + posture.lm_damping * float(eps @ eps)
        else:  # w^2 + 0.0 is w^2 (a square is never -0.0)
            self._Hdiag += w2
        self.c -= eps * w

    def _posture_weights(self, posture: mink.PostureTask) -> tuple[np.ndarray, np.ndarray, slice | np.ndarray | None]:
        """``(w, w^2, free-joint dofs or None)`` of a posture task, its costs with the free
        joint's zeroed (the dofs a slice where consecutive); recomputed when the costs change."""
        cached = self._postures.get(id(posture))
        key = posture.cost.tobytes()
        if cached is None or cached[0] is not posture or cached[1] != key:
            w = posture.cost.copy()
            free = None
            if posture._v_ids is not None:
                w[posture._v_ids] = 0.0
                free = _span(np.sort(posture._v_ids))  # the free joint's dofs: a slice
            cached = self._postures[id(posture)] = (posture, key, (w, w * w, free))
        return cached[2]

    # -- constraints --------------------------------------------------------------
    def bounds(
        self,
        configuration: mink.Configuration,
        trust: float | np.ndarray | None,
        config_limit: mink.ConfigurationLimit | None,
        boxes: Sequence[FrameStepLimit | RootStepLimit] = (),
    ) -> tuple[np.ndarray, np.ndarray]:
        r"""Simple bounds :math:`l \le \Delta q \le u`: the intersection of the trust region
        :math:`\pm\rho` (None: none), the configuration limit (hinge and slide joints;
        :math:`g (q_{min} \ominus q)` to :math:`g (q_{max} \ominus q)`) and each box limit's
        :meth:`box`.  Unbounded coordinates get :data:`INFINITY`."""
        lb, ub = self.lb, self.ub
        if trust is None:
            lb.fill(-INFINITY)
            ub.fill(INFINITY)
        else:
            ub[:] = trust
            np.negative(ub, out=lb)
        if config_limit is not None and config_limit.projection_matrix is not None:
            if self._box is None or self._box[0] is not config_limit:
                idx = np.asarray(config_limit.indices, dtype=int)
                qadr = self.model.jnt_qposadr[self.model.dof_jntid[idx]]
                self._box = (config_limit, _span(idx), _span(qadr), config_limit.upper[qadr], config_limit.lower[qadr])
            _, idx, qadr, upper, lower = self._box
            # hinge and slide joints: q_max ⊖ q = q_max - q (what mj_differentiatePos computes)
            q, g = configuration.data.qpos[qadr], config_limit.gain
            _tighten(lb, ub, idx, -(g * (q - lower)), g * (upper - q))
        for box in boxes:
            spec = box.box(configuration)
            if spec is None:
                continue
            dofs, lo, hi = spec
            _tighten(lb, ub, self._dofs_span(dofs), lo, hi)
        return lb, ub

    def _dofs_span(self, dofs: np.ndarray) -> slice | np.ndarray:
        """:func:`_span` of a box limit's dof indices, kept per array (a limit returns the
        same one every time)."""
        kept = self._spans.get(id(dofs))
        if kept is None or kept[0] is not dofs:
            if len(self._spans) > 16:
                self._spans.clear()
            kept = self._spans[id(dofs)] = (dofs, _span(dofs))
        return kept[1]

    def build(
        self,
        configuration: mink.Configuration,
        tasks: Sequence[mink.Task],
        damping: float,
        posture: Sequence[mink.PostureTask] = (),
        trust: float | np.ndarray | None = None,
        config_limit: mink.ConfigurationLimit | None = None,
        boxes: Sequence[FrameStepLimit | RootStepLimit] = (),
        limits: Sequence[mink.Limit] = (),
        constraints: Sequence[mink.Task] = (),
    ) -> QP:
        r"""The whole QP of one iteration.

        Args:
            configuration: Current configuration :math:`q` (kinematics and ``mj_comPos`` done).
            tasks: Cost terms (mink tasks), in order.
            damping: Global Levenberg-Marquardt damping :math:`\mu`.
            posture: Posture-like tasks (rest pose, smoothness prior), each added as a diagonal.
            trust: Trust region :math:`\rho` (rad or m), scalar or ``(nv,)``; None: none.
            config_limit: Joint-range limit folded into the bounds (its ball-joint rows,
                if any, become general rows).
            boxes: Limits with a ``box`` method, folded into the bounds.
            limits: Other limits: general rows :math:`G \Delta q \le h`.
            constraints: Equality tasks: :math:`J \Delta q = -\alpha e`.
        """
        H, c = self.objective(configuration, tasks, damping, posture)
        lb, ub = self.bounds(configuration, trust, config_limit, boxes)
        Gs, hs = [], []
        # ball joints' limits (mink >= 1.1) stay general rows; mink 1.0 has none
        if config_limit is not None and len(getattr(config_limit, "_ball_qposadr", ())):
            con = config_limit.compute_qp_inequalities(configuration, 1.0)
            n = 0 if config_limit.projection_matrix is None else 2 * len(config_limit.indices)
            Gs.append(con.G[n:])
            hs.append(con.h[n:])
        for limit in limits:
            con = limit.compute_qp_inequalities(configuration, 1.0)
            if not con.inactive:
                Gs.append(con.G)
                hs.append(con.h)
        G = np.concatenate(Gs) if Gs else np.zeros((0, self.nv))
        h = np.concatenate(hs) if hs else np.zeros(0)
        A, b = self.equalities(configuration, constraints)
        return QP(H, c, lb, ub, G, h, A, b)

    def equalities(self, configuration: mink.Configuration, constraints: Sequence[mink.Task]) -> tuple[np.ndarray, np.ndarray]:
        r"""``(A, b)``: the rows :math:`J_c \Delta q = -\alpha_c e_c` of the equality tasks, in order
        (runs of ``SitePositionTask`` s by :meth:`site_terms`)."""
        if not constraints:
            return np.zeros((0, self.nv)), np.zeros(0)
        As, bs = [], []
        for kind, run in _runs(constraints):
            if kind is SitePositionTask:
                Jk, ek, _ = self.site_terms(run, configuration.data)
            else:
                Jk, ek = run[0].compute_jacobian(configuration), -run[0].gain * run[0].compute_error(configuration)
            As.append(Jk)
            bs.append(ek)
        if len(As) == 1:
            return As[0], bs[0]
        return np.concatenate(As), np.concatenate(bs)


def _batched(task: mink.Task) -> type | None:
    """The kind of rows ``task`` is written with in a run of its kind, or None (alone)."""
    kind = type(task)
    if kind is mink.FrameTask:
        return kind if _native is not None else None
    return kind if kind is SitePositionTask else None


def _runs(tasks: Sequence[mink.Task]) -> list[tuple[type | None, list[mink.Task]]]:
    """``tasks`` split into maximal runs of one batched kind (:func:`_batched`); any other
    task is a run of its own, of kind None."""
    runs: list[tuple[type | None, list]] = []
    last = None
    for t in tasks:
        kind = _batched(t)
        if kind is not None and kind is last:
            runs[-1][1].append(t)
        else:
            runs.append((kind, [t]))
        last = kind
    return runs


def _span(idx: np.ndarray) -> slice | np.ndarray:
    """``idx`` (ascending integers) as the equivalent slice when they are consecutive (a
    slice indexes a view: no gather, no scatter), else unchanged."""
    idx = np.asarray(idx, dtype=int)
    if len(idx) and bool((np.diff(idx) == 1).all()):
        return slice(int(idx[0]), int(idx[-1]) + 1)
    return idx


def _tighten(lb: np.ndarray, ub: np.ndarray, idx: slice | np.ndarray, lo: np.ndarray, hi: np.ndarray) -> None:
    """``lb[idx] = max(lb[idx], lo)``, ``ub[idx] = min(ub[idx], hi)``, in place."""
    if isinstance(idx, slice):
        u, l = ub[idx], lb[idx]
        np.minimum(u, hi, out=u)
        np.maximum(l, lo, out=l)
    else:
        ub[idx] = np.minimum(ub[idx], hi)
        lb[idx] = np.maximum(lb[idx], lo)


def _resolve(model: mujoco.MjModel, name: str | int, kind: str) -> int:
    """Id of a body, geom or site given by name or id."""
    if isinstance(name, (int, np.integer)):
        return int(name)
    obj = {"site": mujoco.mjtObj.mjOBJ_SITE, "body": mujoco.mjtObj.mjOBJ_BODY, "geom": mujoco.mjtObj.mjOBJ_GEOM}[kind]
    fid = mujoco.mj_name2id(model, obj, name)
    if fid < 0:
        raise mink.InvalidFrame(frame_name=name, frame_type=kind, model=model)
    return int(fid)


def _stack(qp: QP) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """daqp's ``(A, bupper, blower, sense)``: simple bounds first, then :math:`G`, then :math:`A` (sense 5)."""
    nv, m, p = qp.c.size, qp.h.size, qp.b.size
    sense = np.zeros(nv + m + p, dtype=_SENSE)
    if not (m or p):
        return np.zeros((0, nv)), qp.ub, qp.lb, sense
    sense[nv + m :] = 5
    Atot = np.ascontiguousarray(np.concatenate([qp.G, qp.A]) if (m and p) else (qp.G if m else qp.A))
    bupper = np.concatenate([qp.ub, qp.h, qp.b])
    blower = np.concatenate([qp.lb, qp.h, qp.b])
    blower[nv : nv + m] = -INFINITY
    return Atot, bupper, blower, sense


def solve(qp: QP, dual_start: np.ndarray | None = None) -> np.ndarray:
    r"""Solve ``qp`` with ``daqp.solve`` (bounds first, then :math:`G`, then :math:`A` with sense 5).

    ``dual_start``: a guess of the multipliers of every constraint (daqp's order), which
    only sets daqp's initial active set.  Returns :math:`\Delta q` ``(nv,)``; raises
    ``mink.NoSolutionFound`` if daqp reports no solution (infeasible, iteration limit) or a
    non-finite one.
    """
    return _solve(qp, dual_start)[0]


def _solve(qp: QP, dual_start: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    Atot, bupper, blower, sense = _stack(qp)
    x, _, exitflag, info = daqp.solve(qp.H, qp.c, Atot, bupper, blower, sense, dual_start=dual_start)
    if exitflag <= 0 or x is None or not np.isfinite(x).all():
        raise mink.NoSolutionFound("daqp")
    return np.asarray(x), info["lam"]


class WarmSolver:
    r"""``daqp`` with the previous solution's active simple bounds as the next start.

    The QP is strictly convex (:math:`H \succ 0` by the damping), so its minimiser is
    unique and the starting active set changes only how quickly daqp reaches it (to
    round-off, about 1e-15); consecutive IK iterations mostly keep the same joints at
    their range or velocity bounds, which roughly halves daqp's time.  The general rows
    (floor, self-collision) change from one iteration to the next and start inactive.
    If a warm start ever fails, the QP is solved again from a cold start, so a warm start
    never makes a feasible QP look infeasible.
    """

    def __init__(self, nv: int) -> None:
        self.nv = int(nv)
        self._lam: np.ndarray | None = None

    def reset(self) -> None:
        """Forget the previous active set (the next solve starts cold)."""
        self._lam = None

    def solve(self, qp: QP) -> np.ndarray:
        """Solve ``qp`` (see :func:`solve`), warm-started from the previous solve's bounds."""
        start = None
        if self._lam is not None:
            start = np.zeros(self.nv + qp.h.size + qp.b.size)
            start[: self.nv] = self._lam
        try:
            x, lam = _solve(qp, start)
        except mink.NoSolutionFound:
            if start is None:
                self._lam = None
                raise
            try:
                x, lam = _solve(qp)
            except mink.NoSolutionFound:
                self._lam = None
                raise
        self._lam = lam[: self.nv].copy()
        return x
