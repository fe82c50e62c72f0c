"""Hard inequality constraints of the per-frame IK that mink does not provide.

Both are :class:`mink.Limit` subclasses: they return ``(G, h)`` such that the
QP's step :math:`\\Delta q` (tangent space) satisfies :math:`G \\Delta q \\le h`.

* :class:`FrameStepLimit` bounds the *frame-to-frame* joint step by the
  joint's velocity limit times the motion's frame interval, however many IK
  iterations the frame takes.  mink's ``VelocityLimit`` bounds each QP step by
  ``v_max * dt`` instead, which would let several iterations add up.
* :class:`FloorLimit` keeps the lowest point of every geom of the character
  (and every declared contact site) above the floor plane ``z = floor``.
* :class:`GroupStepLimit` bounds the frame-to-frame turn of a body moved by several
  hinges at one point (a ball joint written as hinges) along each hinge's axis.
* :class:`RootStepLimit` bounds the free root's motion per frame.
* :class:`SelfCollisionLimit` keeps limb geoms out of each other.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Sequence

import mink
import mujoco
import numpy as np

from ..models.geometry import geom_candidates
from ..models.geometry import is_visual_only
from ..models.hinge_groups import GroupIndex

__all__ = ["FrameStepLimit", "FloorLimit", "GroupStepLimit", "group_box_speeds", "GeomCandidates", "PointJacobians", "RootStepLimit", "SelfCollisionLimit"]


class PointJacobians:
    r"""Translational Jacobians :math:`J(p) = \partial p / \partial q` (world axes, ``(3, nv)``)
    of points fixed to bodies, by ``mj_jac`` (point by point, as the rows were first
    written: the same round-off), into one preallocated buffer (the floor and
    self-collision rows need a few dozen per iteration).

    :meth:`vertical` gives the vertical rows alone, for all points at once, by
    ``mj_jac``'s own formula: with :math:`o = p - c` (:math:`c` the centre of mass of
    the subtree of the body's root, ``subtree_com``) and the motion axes
    :math:`(\omega_j, v_j)` = ``cdof[j]`` (per radian or metre of dof :math:`j`),

    .. math::

        J_z(p)_j = v_{j,z} + (\omega_{j,x} o_y - \omega_{j,y} o_x)

    for the dofs :math:`j` on the body's chain (``dof_parentid`` from the body's last dof,
    fixed bodies taking their parent's), 0 elsewhere: the same products, differences and
    sums as ``mj_jac`` (so the same bits), as ``(k, nv)`` array operations instead of
    ``k`` calls.
    """

    def __init__(self, model: mujoco.MjModel, capacity: int = 32) -> None:
        self.model = model
        self._grow(capacity)
        self._off_chain = ~_dof_chains(model)
        self._root = np.asarray(model.body_rootid, dtype=int)
        roots = np.unique(self._root[1:])
        # one tree (a character): every point's offset is from the same centre of mass
        self._one_root = int(roots[0]) if len(roots) == 1 else None
        self._tmp = np.empty((capacity, model.nv))

    def _grow(self, capacity: int) -> None:
        """A buffer for ``capacity`` points."""
        self._buf = np.zeros((capacity, 3, self.model.nv))
        self._rows = list(self._buf)  # one (3, nv) view per point, made once

    def __call__(self, data: mujoco.MjData, bodies: np.ndarray, points: np.ndarray) -> np.ndarray:
        """``(k, 3, nv)`` Jacobians of points ``(k, 3)`` (metres, world) on ``bodies`` ``(k,)``;
        a view of the buffer, valid until the next call."""
        k = len(bodies)
        if k > len(self._buf):
            self._grow(max(k, 2 * len(self._buf)))
        model, jac = self.model, mujoco.mj_jac
        for row, b, p in zip(self._rows, bodies.tolist(), points):
            jac(model, data, row, None, p, b)
        return self._buf[:k]

    def off_chain(self, bodies: np.ndarray) -> np.ndarray:
        """``(k, nv)`` booleans: the dofs that do not move each of ``bodies`` (:meth:`vertical`'s
        ``off_chain``)."""
        return self._off_chain[bodies]

    def vertical(self, data: mujoco.MjData, bodies: np.ndarray, points: np.ndarray, out: np.ndarray,
                 off_chain: np.ndarray | None = None) -> None:
        """``out`` ``(k, nv)`` := :math:`-J_z` of points ``(k, 3)`` (metres, world) on ``bodies``
        ``(k,)`` (per radian or metre of each dof): ``mj_jac``'s rows negated, to the bit (the
        dofs off a point's chain ``-0.0``, the negated zeros).  ``off_chain``: the bodies'
        :meth:`off_chain`, where the caller keeps it (None: gathered here)."""
        k = len(bodies)
        if k > len(self._tmp):
            self._tmp = np.empty((max(k, 2 * len(self._tmp)), self.model.nv))
        com = data.subtree_com[self._root[bodies] if self._one_root is None else self._one_root]
        off = points - com
        axes, tmp = data.cdof.T, self._tmp[:k]
        np.multiply(off[:, 1:2], axes[0], out=out)
        np.multiply(off[:, 0:1], axes[1], out=tmp)
        np.subtract(out, tmp, out=out)
        np.add(out, axes[5], out=out)
        np.negative(out, out=out)
        np.putmask(out, self._off_chain[bodies] if off_chain is None else off_chain, -0.0)


def _dof_chains(model: mujoco.MjModel) -> np.ndarray:
    """``(nbody, nv)`` booleans: the dofs that move each body, as ``mj_jac`` walks them (a
    body without dofs takes its nearest ancestor's; the world has none)."""
    chain = np.zeros((model.nbody, model.nv), dtype=bool)
    for b in range(model.nbody):
        body = b
        while body and not model.body_dofnum[body]:
            body = int(model.body_parentid[body])
        if not body:
            continue
        i = int(model.body_dofadr[body] + model.body_dofnum[body] - 1)
        while i >= 0:
            chain[b, i] = True
            i = int(model.dof_parentid[i])
    return chain


class FrameStepLimit(mink.Limit):
    r"""Joint step from the previous frame bounded by velocity limits in motion time.

    For every velocity-limited hinge or slide joint :math:`i` with limit
    :math:`\dot q_i^{max}` and frame interval :math:`T`:

    .. math::

        q_i^{prev} - \dot q_i^{max} T \;\le\; q_i + \Delta q_i
        \;\le\; q_i^{prev} + \dot q_i^{max} T

    where :math:`q_i` is the current iterate and :math:`q^{prev}` the previous
    frame's solution.  Call :meth:`set_previous` once per frame.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        velocities: Mapping[str, float],
        frame_interval: float,
        shrink: float = 1e-6,
    ) -> None:
        """
        Args:
            model: The character's MuJoCo model.
            velocities: Joint name -> velocity limit (rad/s or m/s), positive.
            frame_interval: Seconds between two frames of the motion.
            shrink: Margin (rad) taken off each bound so that solver round-off
                never crosses the true limit.
        """
        qadr, dadr, vmax = [], [], []
        for name, v in velocities.items():
            jid = model.joint(name).id
            if int(model.jnt_type[jid]) not in (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE)):
                continue
            qadr.append(int(model.jnt_qposadr[jid]))
            dadr.append(int(model.jnt_dofadr[jid]))
            vmax.append(float(v))
        self.qposadr = np.array(qadr, dtype=int)
        self.dofadr = np.array(dadr, dtype=int)
        self.vmax = np.array(vmax, dtype=float)
        self.frame_interval = float(frame_interval)
        self.shrink = float(shrink)
        self.q_prev: np.ndarray | None = None
        self._bounds: tuple[np.ndarray, np.ndarray] | None = None
        n = len(self.dofadr)
        G = np.zeros((2 * n, model.nv))
        G[np.arange(n), self.dofadr] = 1.0
        G[n + np.arange(n), self.dofadr] = -1.0
        self._G = G

    def set_previous(self, q_prev: np.ndarray | None) -> None:
        """The previous frame's solution (None disables the limit, e.g. on frame 0)."""
        self.q_prev = None if q_prev is None else np.array(q_prev, dtype=float)
        self._bounds = None
        if self.q_prev is not None:
            step = self.vmax * self.frame_interval
            prev = self.q_prev[self.qposadr]
            self._bounds = (prev - step + self.shrink, prev + step - self.shrink)

    def step_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Absolute bounds ``(lo, hi)`` on the limited joints' values this frame (computed
        once per frame by :meth:`set_previous`)."""
        assert self._bounds is not None
        return self._bounds

    def box(self, configuration: mink.Configuration) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        r"""The limit as simple bounds on the step: ``(dofs, lo, hi)`` with
        :math:`lo \le \Delta q_{dofs} \le hi` (rad or m), or None when inactive.

        :math:`hi = \max(q^{prev} + \dot q^{max} T - q, 0)`,
        :math:`lo = -\max(q - (q^{prev} - \dot q^{max} T), 0)`: if an earlier relaxed
        step left :math:`q` outside the band, only moving back is allowed.
        """
        if self.q_prev is None or len(self.dofadr) == 0:
            return None
        lo, hi = self._bounds
        q = configuration.data.qpos[self.qposadr]
        return self.dofadr, -np.maximum(q - lo, 0.0), np.maximum(hi - q, 0.0)

    def compute_qp_inequalities(self, configuration: mink.Configuration, dt: float) -> mink.Constraint:
        del dt  # bounds are in motion time, not the QP's step
        spec = self.box(configuration)
        if spec is None:
            return mink.Constraint()
        _, lo, hi = spec
        return mink.Constraint(G=self._G, h=np.concatenate([hi, -lo]))


class GeomCandidates:
    """Stacked lowest-point candidates of a set of geoms, for vectorised queries."""

    def __init__(self, model: mujoco.MjModel, geoms: Sequence[int], known: Mapping[int, np.ndarray] | None = None) -> None:
        """``known``: geom id -> its :func:`geom_candidates`, where already computed (a mesh's
        convex hull is the costly part of building this)."""
        rows, owner = [], []
        self.geoms = np.array(list(geoms), dtype=int)
        known = known or {}
        for k, gid in enumerate(self.geoms.tolist()):
            cand = known[gid] if gid in known else geom_candidates(model, gid)
            if len(cand) == 0:  # planes and the like have no lowest point
                cand = np.array([[0.0, 0.0, 0.0, -np.inf]])
            rows.append(cand)
            owner.append(np.full(len(cand), k))
        self.local = np.vstack(rows) if rows else np.zeros((0, 4))
        self.owner = np.concatenate(owner) if owner else np.zeros(0, dtype=int)
        self.gid = self.geoms[self.owner] if len(self.owner) else np.zeros(0, dtype=int)
        self.starts = np.flatnonzero(np.r_[True, np.diff(self.owner) != 0]) if len(self.owner) else np.zeros(0, dtype=int)
        # bounding radius of each geom's candidates about its origin (metres)
        reach = np.linalg.norm(self.local[:, :3], axis=1) + np.maximum(self.local[:, 3], 0.0)
        self.radius = np.zeros(len(self.geoms))
        if len(self.owner):
            np.maximum.at(self.radius, self.owner, np.where(np.isfinite(reach), reach, 0.0))
        self._rows_key: bytes | None = None
        self._rows: tuple = ()
        self._all = np.arange(len(self.gid))
        # flat indices into geom_xpos / geom_xmat (a 1-D take is the cheapest gather): the
        # geoms' heights, and per candidate its geom's position and rotation
        self._geom_z = 3 * self.geoms + 2
        self._xpos_at = 3 * self.gid[:, None] + np.arange(3)
        self._xmat_at = 9 * self.gid[:, None] + np.arange(9)

    def points(self, data: mujoco.MjData, below: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Every candidate: ``(z (k,), point (k, 3))``, z being its lowest surface height.

        With ``below``, geoms whose bounding sphere lies wholly above that height are
        skipped (their candidates get ``z = inf``): a robot's mesh links far from the
        floor cost nothing.
        """
        if len(self.gid) == 0:
            return np.zeros(0), np.zeros((0, 3))
        if below is None:
            rows = slice(None)
        else:
            near = data.geom_xpos[self.geoms, 2] - self.radius < below
            if near.all():
                rows = slice(None)
            else:
                rows = np.flatnonzero(near[self.owner])
        z = np.full(len(self.gid), np.inf)
        pts = np.zeros((len(self.gid), 3))
        gid = self.gid[rows]
        R = data.geom_xmat[gid].reshape(-1, 3, 3)
        pts[rows] = data.geom_xpos[gid] + np.einsum("kij,kj->ki", R, self.local[rows, :3])
        z[rows] = pts[rows, 2] - self.local[rows, 3]
        return z, pts

    def _near_rows(self, data: mujoco.MjData, below: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(rows, flat indices of their geoms' heights in geom_xpos, of their geoms' rotations'
        last rows in geom_xmat (k, 3), their local points (k, 3), their radii)``: the
        candidates of the geoms whose bounding sphere reaches below ``below``; kept while the
        same geoms stay near, which they do over many iterations (a walking robot: its feet
        and shins)."""
        near = data.geom_xpos.take(self._geom_z) - self.radius < below
        key = near.tobytes()
        if self._rows_key != key:
            self._rows_key = key
            rows = self._all if near.all() else np.flatnonzero(near[self.owner])
            self._rows = (rows, self._xpos_at[rows, 2], self._xmat_at[rows, 6:], self.local[rows, :3], self.local[rows, 3])
        return self._rows

    def near_z(self, data: mujoco.MjData, below: float, extra: int = 0) -> tuple[np.ndarray, np.ndarray]:
        r"""``(rows (k,), z (k + extra,))``: the candidates of the geoms whose bounding sphere
        reaches below ``below`` (ascending rows) and their lowest surface heights (metres),
        :math:`z = x_{g,z} + R_{g,z} \cdot p - r` (geom position :math:`x_g`, rotation
        :math:`R_g`, local point :math:`p`, radius :math:`r`); ``extra`` entries left
        unset at the end of ``z`` for the caller."""
        rows, z_at, r_at, local, radius = self._near_rows(data, below)
        z = np.empty(len(rows) + extra)
        head = z[: len(rows)]
        np.add(data.geom_xpos.take(z_at), np.einsum("kj,kj->k", data.geom_xmat.take(r_at), local), out=head)
        head -= radius
        return rows, z

    def points_at(self, data: mujoco.MjData, rows: np.ndarray | tuple) -> np.ndarray:
        """World positions ``(len(rows), 3)`` (metres) of the candidates ``rows`` (or of their
        :meth:`gather`): :math:`x_g + R_g p`."""
        xpos_at, xmat_at, local = rows if isinstance(rows, tuple) else self.gather(rows)
        R = data.geom_xmat.take(xmat_at).reshape(-1, 3, 3)
        return data.geom_xpos.take(xpos_at) + np.einsum("kij,kj->ki", R, local)

    def gather(self, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """What :meth:`points_at` reads for the candidates ``rows``: the flat indices of their
        geoms' positions ``(k, 3)`` and rotations ``(k, 9)`` and their local points ``(k, 3)``."""
        return self._xpos_at[rows], self._xmat_at[rows], self.local[rows, :3]

    def lowest(self, data: mujoco.MjData) -> tuple[np.ndarray, np.ndarray]:
        """``(z_low (n,), anchor (n, 3))`` for the geoms, in the order given."""
        n = len(self.geoms)
        if n == 0:
            return np.zeros(0), np.zeros((0, 3))
        z, pts = self.points(data)
        z_low = np.minimum.reduceat(z, self.starts)
        # index of the minimum within each geom's block
        is_min = z == z_low[self.owner]
        first = np.full(n, -1)
        idx = np.flatnonzero(is_min)
        first[self.owner[idx[::-1]]] = idx[::-1]
        return z_low, pts[first]


def group_box_speeds(velocities: Mapping[str, float], groups: Sequence[Sequence[str]]) -> dict[str, float]:
    """``velocities`` with each grouped hinge's limit raised to the largest of its group: the
    :class:`FrameStepLimit` box that keeps a grouped hinge's rate sane where
    :class:`GroupStepLimit` leaves it free (the rates that cancel at a gimbal lock)."""
    out = dict(velocities)
    for g in groups:
        top = max(float(velocities[n]) for n in g)
        for n in g:
            out[n] = top
    return out


#: Halvings of :meth:`GroupStepLimit.project`'s bisection: the scale is found within
#: :math:`2^{-24}` (6e-8) of the step, a few 1e-8 rad for a walk's steps and under 3e-7 rad
#: for the largest a cap allows (122 rad/s at 30 fps: 4 rad a frame), on the bound's side (each round is a kinematics pass: 40 cost a stream 3 ms a frame while its
#: joints catch up at their speed caps).
PROJECT_ROUNDS = 24


class GroupStepLimit(mink.Limit):
    r"""Frame-to-frame turn of a hinge group's body bounded along each hinge's axis
    (:mod:`physmocap.models.hinge_groups`).

    For each group, with :math:`d = q - q^{prev}` its hinges' step from the previous frame,
    :math:`M = A^T A` the Gram matrix of their world axes at the current iterate and
    :math:`b_i = \dot q_i^{max} T - \epsilon` (frame interval :math:`T`, margin
    :math:`\epsilon`):

    .. math::

        -b \;\le\; M (d + \Delta q) \;\le\; b

    as the rows :math:`M \Delta q \le \max(b - M d, 0)` and :math:`-M \Delta q \le
    \max(b + M d, 0)` (a body left outside the band by a relaxed step may only come
    back).  :math:`(M d)_i` is the body's turn along hinge :math:`i`'s axis, linearised at
    the iterate; where the axes are at right angles it is the hinge's own step.  Call
    :meth:`set_previous` once per frame.

    The solver adds the rows only to an iteration whose step without them would cross a
    bound (:meth:`crossed`): the QP's answer is the same (rows a solution satisfies change
    nothing) and most iterations are far from every group's bound.  :meth:`project` makes
    the bound hold on the frame's final pose, not only linearised.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        groups: Sequence[Sequence[str]],
        velocities: Mapping[str, float],
        frame_interval: float,
        shrink: float = 1e-6,
    ) -> None:
        """
        Args:
            model: The character's MuJoCo model.
            groups: Hinge names, group by group (``Character.velocity_groups``).
            velocities: Joint name -> velocity limit (rad/s), positive.
            frame_interval: Seconds between two frames of the motion.
            shrink: Margin (rad) taken off each bound (as :class:`FrameStepLimit`).
        """
        self.index = GroupIndex(model, groups, velocities)
        self.bound = [v * float(frame_interval) - float(shrink) for v in self.index.vmax]
        self.q_prev: np.ndarray | None = None
        rows = sum(len(j) for j in self.index.joints)
        self._G = np.zeros((2 * rows, model.nv))
        self._h = np.zeros(2 * rows)
        # every grouped hinge's qpos address, group after group, and where each group starts
        self._qadr = np.concatenate(self.index.qposadr) if len(self.index) else np.zeros(0, dtype=int)
        self._dadr = np.concatenate(self.index.dofadr) if len(self.index) else np.zeros(0, dtype=int)
        sizes = [len(j) for j in self.index.joints]
        self._starts = np.cumsum([0, *sizes[:-1]]).astype(int)
        self._least = np.array([float(b.min()) for b in self.bound])

    def set_previous(self, q_prev: np.ndarray | None) -> None:
        """The previous frame's solution (None disables the limit, e.g. on frame 0)."""
        self.q_prev = None if q_prev is None else np.array(q_prev, dtype=float)
        self._prev = None if q_prev is None else self.q_prev[self._qadr]

    def crossed(self, configuration: mink.Configuration, v: np.ndarray) -> bool:
        r"""Whether the step ``v`` (tangent, ``(nv,)``) from the current iterate takes some
        group past its bound, linearised as the rows are: :math:`|M (d + \Delta q)|_i > b_i`.
        Only groups whose step sums to their smallest bound or more are checked exactly
        (:math:`|(M d)_i| \le \sum_j |d_j|`, the axes being unit vectors)."""
        if self.q_prev is None or not len(self.index):
            return False
        data = configuration.data
        d = data.qpos[self._qadr] + v[self._dadr] - self._prev
        spread = np.add.reduceat(np.abs(d), self._starts)
        if not (spread > self._least).any():
            return False
        for k in np.flatnonzero(spread > self._least):
            n = len(self.index.joints[k])
            dk = d[self._starts[k] : self._starts[k] + n]
            if np.any(np.abs(self.index.gram(data, k) @ dk) > self.bound[k]):
                return True
        return False

    def compute_qp_inequalities(self, configuration: mink.Configuration, dt: float) -> mink.Constraint:
        del dt  # bounds are in motion time, not the QP's step
        if self.q_prev is None or not len(self.index):
            return mink.Constraint()
        data, G, h = configuration.data, self._G, self._h
        q = data.qpos
        r = 0
        for k, b in enumerate(self.bound):
            qa, dofs = self.index.qposadr[k], self.index.dofadr[k]
            n = len(qa)
            M = self.index.gram(data, k)
            s = M @ (q[qa] - self.q_prev[qa])
            G[r : r + n, dofs] = M
            G[r + n : r + 2 * n, dofs] = -M
            h[r : r + n] = np.maximum(b - s, 0.0)
            h[r + n : r + 2 * n] = np.maximum(b + s, 0.0)
            r += 2 * n
        return mink.Constraint(G=G, h=h)

    def project(self, model: mujoco.MjModel, data: mujoco.MjData, q: np.ndarray, rounds: int = PROJECT_ROUNDS) -> np.ndarray:
        r"""``q`` with each group's step from the previous frame scaled down, as little as
        needed, until :math:`|M(q) d| \le b` holds at ``q`` itself, not only linearised at
        the last iterate (the QP's last step can leave a group a few per cent over).
        A group's Gram matrix depends on its own hinges alone (the axes turn together with
        the parent), so each group's scale :math:`s \in [0, 1]` is found on its own, by
        bisection (``rounds`` halvings, kept on the side within the bound; :math:`s = 0` is
        the previous frame's pose); scaling towards the previous frame keeps the joint
        ranges and the boxes.  ``data`` is scratch (its ``qpos`` and kinematics are
        overwritten).  Returns ``q`` itself where no group is over its bound, else a new array."""
        if self.q_prev is None or not len(self.index):
            return q
        d = np.abs(q[self._qadr] - self.q_prev[self._qadr])
        if not np.any(np.add.reduceat(d, self._starts) > self._least):
            return q  # every |(M d)_i| <= sum_j |d_j| is within its bound: no kinematics needed
        q_in = q
        q = np.array(q, dtype=float)
        steps = [q[qa] - self.q_prev[qa] for qa in self.index.qposadr]

        def over(scales: np.ndarray) -> np.ndarray:
            for k, qa in enumerate(self.index.qposadr):
                q[qa] = self.q_prev[qa] + scales[k] * steps[k]
            data.qpos[:] = q
            mujoco.mj_kinematics(model, data)
            return np.array([np.any(np.abs(self.index.gram(data, k) @ (scales[k] * steps[k])) > b)
                             for k, b in enumerate(self.bound)])

        hi = np.ones(len(self.index))
        bad = over(hi)
        if not bad.any():
            return q_in
        lo = np.where(bad, 0.0, 1.0)
        for _ in range(rounds):
            mid = np.where(bad, 0.5 * (lo + hi), 1.0)
            worse = over(mid) & bad
            hi = np.where(worse, mid, hi)
            lo = np.where(bad & ~worse, mid, lo)
        over(lo)  # the feasible side of every bisection
        return q
        d = np.abs(q[self._qadr] - self.q_prev[self._qadr])
        if not np.any(np.add.reduceat(d, self._starts) > self._least):
            return q  # every |(M d)_i| <= sum_j |d_j| is within its bound: no kinematics needed
        q = np.array(q, dtype=float)
        for _ in range(rounds):
            data.qpos[:] = q
            mujoco.mj_kinematics(model, data)
            over = False
            for k, b in enumerate(self.bound):
                qa = self.index.qposadr[k]
                d = q[qa] - self.q_prev[qa]
                ratio = float(np.max(np.abs(self.index.gram(data, k) @ d) / b))
                if ratio > 1.0:
                    q[qa] = self.q_prev[qa] + d * ((1.0 - 1e-9) / ratio)
                    over = True
            if not over:
                break
        return q


class FloorLimit(mink.Limit):
    r"""Keep the character's geoms and contact sites above the floor.

    For every geom (and site) whose lowest point :math:`z_k(q)` is within
    ``activation`` of the floor, the linearised constraint

    .. math::

        z_k(q) + J_{z,k}(q) \Delta q \;\ge\; z_{floor} + m

    is added, where :math:`J_{z,k}` is the vertical row of the translational
    Jacobian of the point and :math:`m` a small margin that absorbs the
    linearisation error.  Geoms of the world body (the floor itself) are
    skipped.

    Swing clearance: for the contact sites in :attr:`clearance` (set per frame
    by the planting: sites of a foot that is neither in contact nor planted),
    and for every geom point of the bodies in :attr:`swing_bodies` (a foot with
    no contact at all: heel, sole, toes, every corner of a box foot),
    :math:`z_s + J_{z,s} \Delta q \ge \min(z_{floor} + c, z_s + r)`, so a
    swing foot clears the stance band, rising at most ``max_rise`` per frame
    when it starts below it.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        geoms: Sequence[int] | None = None,
        sites: Sequence[int] = (),
        floor: float = 0.0,
        margin: float = 2e-4,
        activation: float = 0.15,
    ) -> None:
        known: dict[int, np.ndarray] = {}
        if geoms is None:
            # visual-only meshes are skipped (a robot model draws every link twice)
            for g in range(model.ngeom):
                if model.geom_bodyid[g] != 0 and not is_visual_only(model, g):
                    cand = geom_candidates(model, g)
                    if len(cand):
                        known[g] = cand
            geoms = list(known)
        self.model = model
        self.geoms = np.array(list(geoms), dtype=int)
        self.sites = np.array(list(sites), dtype=int)
        self.floor = float(floor)
        self.margin = float(margin)
        self.activation = float(activation)
        self.enabled = True
        self._pj = PointJacobians(model)
        self._cand = GeomCandidates(model, self.geoms, known)
        self._bodies = np.concatenate([model.geom_bodyid[self._cand.gid], model.site_bodyid[self.sites]])
        self._site_rows = len(self._cand.gid) + np.arange(len(self.sites))
        self._site_z = 3 * self.sites + 2  # flat indices of the sites' heights in site_xpos
        self._near_idx: tuple = (None, None)  # near geoms' candidate rows -> with the sites' rows
        self._cache: tuple[bytes, tuple] | None = None
        self._zcache: tuple[bytes, tuple[np.ndarray, np.ndarray]] | None = None  # near(), per configuration
        #: site id -> clearance height (metres above the floor) for swing feet; set per frame.
        self.clearance: dict[int, float] = {}
        #: body id -> clearance height for all geom points of a swing foot's bodies; set per frame.
        self.swing_bodies: dict[int, float] = {}
        self.max_rise = 0.004
        self._swing: tuple | None = None  # the two dicts as arrays, see _swing_arrays
        self._plan: tuple = (None, None, None)  # ((active rows' bytes, floor, margin), _swing, _RowsPlan): _rows_plan

    def _swing_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """``(clearance sites, their heights, body id -> clearance or nan (None: no swing
        body))`` of :attr:`clearance` and :attr:`swing_bodies`, rebuilt when either is
        replaced by a new mapping (the solver sets new ones every frame)."""
        if self._swing is None or self._swing[0] is not self.clearance or self._swing[1] is not self.swing_bodies:
            per_body = None
            if self.swing_bodies:
                per_body = np.full(self.model.nbody, np.nan)
                per_body[list(self.swing_bodies)] = list(self.swing_bodies.values())
            sites = np.array(list(self.clearance), dtype=int)
            heights = np.array(list(self.clearance.values()), dtype=float)
            self._swing = (self.clearance, self.swing_bodies, sites, heights, per_body)
        return self._swing[2], self._swing[3], self._swing[4]

    def heights(self, data: mujoco.MjData) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(z (n,), anchor (n, 3), body (n,))`` of all constrained points.

        Every candidate of every geom is a point (both end caps of a capsule,
        every corner of a box): constraining only the current lowest one lets
        a rolling foot swap which cap is lowest between iterations.
        """
        key = data.qpos.tobytes()
        if self._cache is not None and self._cache[0] == key:
            return self._cache[1]
        z_g, a_g = self._cand.points(data, below=self.floor + self.activation)
        z_s = data.site_xpos[self.sites, 2] if len(self.sites) else np.zeros(0)
        a_s = data.site_xpos[self.sites] if len(self.sites) else np.zeros((0, 3))
        out = (np.concatenate([z_g, z_s]), np.vstack([a_g, a_s]), self._bodies)
        self._cache = (key, out)  # the same configuration is queried several times per iteration
        return out

    def near(self, data: mujoco.MjData) -> tuple[np.ndarray, np.ndarray]:
        """``(idx (k,), z (k,))``: the points of :meth:`heights` that can be near the floor
        (the geoms whose bounding sphere reaches into the activation band, and every site),
        ascending, and their heights (metres); cached per configuration.  The points left
        out are above the band: what the rows and the residuals need, without the rest."""
        key = data.qpos.tobytes()
        if self._zcache is not None and self._zcache[0] == key:
            return self._zcache[1]
        rows, z_g = self._cand.near_z(data, self.floor + self.activation, len(self.sites))
        if len(self.sites):
            if self._near_idx[0] is not rows:  # the geoms near the floor changed
                self._near_idx = (rows, np.concatenate([rows, self._site_rows]))
            rows = self._near_idx[1]
            z_g[len(z_g) - len(self.sites) :] = data.site_xpos.take(self._site_z)
        out = (rows, z_g)
        self._zcache = (key, out)
        return out

    def z(self, data: mujoco.MjData) -> np.ndarray:
        """``z (n,)`` of :meth:`heights` alone (metres; ``inf`` beyond the activation
        band for geoms), from :meth:`near`."""
        idx, zn = self.near(data)
        z = np.full(len(self._bodies), np.inf)
        z[idx] = zn
        return z

    def lowest(self, data: mujoco.MjData) -> float:
        """Height of the lowest constrained point (metres; ``inf`` when none is near the floor)."""
        zn = self.near(data)[1]
        return float(zn.min()) if zn.size else float("inf")

    def compute_qp_inequalities(self, configuration: mink.Configuration, dt: float) -> mink.Constraint:
        del dt
        if not self.enabled:
            return mink.Constraint()
        data = configuration.data
        idx, zn = self.near(data)
        inside = zn < self.floor + self.activation
        active = idx[inside]
        if active.size == 0:
            return mink.Constraint()
        n_act = len(active)
        plan = self._rows_plan(active)
        anchor = np.empty((plan.split + len(plan.sites), 3))
        anchor[: plan.split] = self._cand.points_at(data, plan.candidates)
        anchor[plan.split :] = data.site_xpos[plan.sites]
        G = np.empty((len(anchor), self.model.nv))
        h = np.empty(len(anchor))
        self._pj.vertical(data, plan.bodies, anchor, G, plan.off_chain)
        za = zn[inside]
        h[:n_act] = za - self.floor - self.margin
        if plan.swing is not None:
            zs = za[plan.swing]
            h[:n_act][plan.swing] = zs - np.minimum(plan.swing_floor, zs + self.max_rise)
        # swing clearance: z + J dq >= min(floor + clearance, z + max_rise)
        if plan.clear_floor is not None:
            zs = anchor[n_act:, 2]
            h[n_act:] = zs - np.minimum(plan.clear_floor, zs + self.max_rise)
        return mink.Constraint(G=G, h=h)

    def _rows_plan(self, active: np.ndarray) -> "_RowsPlan":
        """The :class:`_RowsPlan` of the rows of the points ``active`` (ascending indices into
        :meth:`heights`' points) and of this frame's clearance sites and swing bodies; kept
        while neither changes (over a frame's iterations, the same points are near the floor)."""
        swing_arrays = self._swing_arrays()
        key = (active.tobytes(), self.floor, self.margin)
        if self._plan[0] == key and self._plan[1] is self._swing:
            return self._plan[2]
        clear_sites, clear_heights, per_body = swing_arrays
        ng = len(self._cand.gid)
        split = int(active.searchsorted(ng))
        # the points: active geom candidates, active contact sites, then the clearance sites
        sites = self.sites[active[split:] - ng]
        if len(clear_sites):
            sites = np.concatenate([sites, clear_sites])
        b = self._bodies[active]
        bodies = np.concatenate([b, self.model.site_bodyid[clear_sites]]) if len(clear_sites) else b
        swing = swing_floor = None
        if per_body is not None:
            c = per_body[b]
            lifted = ~np.isnan(c)
            if lifted.any():
                swing, swing_floor = lifted, self.floor + np.maximum(c[lifted], self.margin)
        plan = _RowsPlan(
            split=split,
            candidates=self._cand.gather(active[:split]),
            sites=sites,
            bodies=bodies,
            off_chain=self._pj.off_chain(bodies),
            swing=swing,
            swing_floor=swing_floor,
            clear_floor=self.floor + clear_heights if len(clear_sites) else None,
        )
        self._plan = (key, self._swing, plan)
        return plan


@dataclass(frozen=True, eq=False)
class _RowsPlan:
    r"""What :meth:`FloorLimit.compute_qp_inequalities` reads for a set of active points, apart
    from the pose: the number of geom candidates among them, the candidates'
    :meth:`GeomCandidates.gather`, the sites (active contact sites, then the clearance sites),
    every row's body and :meth:`PointJacobians.off_chain`, the active points of swing bodies
    (a mask, None: none) with the height they clear, :math:`z_{floor} + \max(c, m)` (metres),
    and the clearance sites' :math:`z_{floor} + c` (None: none)."""

    split: int
    candidates: tuple[np.ndarray, np.ndarray, np.ndarray]
    sites: np.ndarray
    bodies: np.ndarray
    off_chain: np.ndarray
    swing: np.ndarray | None
    swing_floor: np.ndarray | None
    clear_floor: np.ndarray | None


class RootStepLimit(mink.Limit):
    r"""The floating root's motion from the previous frame, bounded in motion time.

    Joints have velocity limits (:class:`FrameStepLimit`); the free root has
    none in mink, so an ill-conditioned QP could throw the whole body away in
    one step.  With :math:`T` the frame interval, per axis:

    .. math::

        |p + \Delta p - p^{prev}| \le v_{max} T, \qquad |\Delta\omega| \le \omega_{max} T

    (translation cumulative over the frame's iterations, rotation per
    iteration).  Defaults (15 m/s, 40 rad/s) are beyond any human motion: a
    safety bound, not a style choice.
    """

    def __init__(self, model: mujoco.MjModel, frame_interval: float, v_max: float = 15.0, w_max: float = 40.0) -> None:
        free = [j for j in range(model.njnt) if int(model.jnt_type[j]) == int(mujoco.mjtJoint.mjJNT_FREE)]
        self.qadr = int(model.jnt_qposadr[free[0]]) if free else -1
        self.dadr = int(model.jnt_dofadr[free[0]]) if free else -1
        self.step_lin = float(v_max) * float(frame_interval)
        self.step_ang = float(w_max) * float(frame_interval)
        self.q_prev: np.ndarray | None = None
        self._dofs = np.arange(self.dadr, self.dadr + 6) if free else np.zeros(0, dtype=int)
        # the rows' right-hand sides without a previous frame: no translation bound
        self._h0 = np.concatenate([np.full(3, np.inf), np.full(3, self.step_ang), np.full(3, np.inf), np.full(3, self.step_ang)])
        if free:
            G = np.zeros((12, model.nv))
            for k in range(6):
                G[k, self.dadr + k] = 1.0
                G[6 + k, self.dadr + k] = -1.0
            self._G = G

    def set_previous(self, q_prev: np.ndarray | None) -> None:
        self.q_prev = None if q_prev is None else np.array(q_prev, dtype=float)

    def _h(self, configuration: mink.Configuration) -> np.ndarray:
        """Right-hand sides of the rows ``+e_k`` (k = 0..5) then ``-e_k``; inf when absent."""
        h = self._h0.copy()
        if self.q_prev is not None:
            p = configuration.data.qpos[self.qadr : self.qadr + 3]
            prev = self.q_prev[self.qadr : self.qadr + 3]
            h[:3] = np.maximum(prev + self.step_lin - p, 0.0)
            h[6:9] = np.maximum(p - (prev - self.step_lin), 0.0)
        return h

    def box(self, configuration: mink.Configuration) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        r"""The limit as simple bounds ``(dofs, lo, hi)`` on the root's six step
        coordinates (:math:`\pm\infty` where absent), or None without a free root."""
        if self.qadr < 0:
            return None
        h = self._h(configuration)
        return self._dofs, -h[6:], h[:6]

    def compute_qp_inequalities(self, configuration: mink.Configuration, dt: float) -> mink.Constraint:
        del dt
        if self.qadr < 0:
            return mink.Constraint()
        h = self._h(configuration)
        keep = np.isfinite(h)
        return mink.Constraint(G=self._G[keep], h=h[keep])



class SelfCollisionLimit(mink.Limit):
    r"""Limb geoms keep out of each other (:func:`physmocap.models.selfcollision.self_collision_pairs`).

    For each geom pair :math:`(a, b)` within ``activation`` of each other, with
    signed distance :math:`d` (``mj_geomDistance``; negative when they overlap),
    nearest points :math:`p_a, p_b` and unit normal :math:`n` from :math:`p_a` to
    :math:`p_b`, the linearised distance must stay at least the margin :math:`m`:

    .. math::

        n^T (J_b(p_b) - J_a(p_a))\,\Delta q \;\ge\;
        \begin{cases} m - d & d \ge m \\ \min(m - d,\ r) & d < m \end{cases}

    so a pair may close up to the margin, and a pair already inside it (or
    overlapping) must move apart, by at most ``recovery`` :math:`r` per
    iteration.  ``activation`` is larger than a fast limb travels in one frame
    (8 cm: 5 m/s at 60 Hz), so no pair is first seen already overlapping; pairs
    whose bounding spheres are farther apart than that are skipped before the
    narrow phase.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        pairs: Sequence[tuple[int, int]],
        margin: float = 0.0,
        activation: float = 0.08,
        recovery: float = 0.005,
    ) -> None:
        self.model = model
        self.recovery = float(recovery)
        self.pairs = np.array(list(pairs), dtype=int).reshape(-1, 2)
        self.margin = float(margin)
        self.activation = float(activation)
        self._rsum = model.geom_rbound[self.pairs[:, 0]] + model.geom_rbound[self.pairs[:, 1]] if len(self.pairs) else np.zeros(0)
        self._cache: tuple[bytes, tuple] | None = None
        self._g1 = self.pairs[:, 0].tolist()
        self._g2 = self.pairs[:, 1].tolist()
        self._bodies = model.geom_bodyid[self.pairs]  # (pairs, 2): the bodies of a and b
        self._pj = PointJacobians(model)
        # flat indices of the pairs' geom positions in geom_xpos (a 1-D take is the cheapest gather)
        self._x1, self._x2 = (3 * self.pairs[:, j, None] + np.arange(3) for j in range(2))
        bound = self._rsum + self.activation
        self._bound2 = bound * bound  # squared reach of each pair's bounding spheres (m^2)
        self._fromto = np.zeros((len(self.pairs), 6))
        self._fromto_rows = list(self._fromto)  # one row view per pair, for mj_geomDistance
        self._far = np.full(len(self.pairs), self.activation)  # every pair at the activation distance

    def near_pairs(self, data: mujoco.MjData) -> np.ndarray:
        """Indices of the pairs whose bounding spheres are within ``activation``."""
        if not len(self.pairs):
            return np.zeros(0, dtype=int)
        xpos = data.geom_xpos
        diff = xpos.take(self._x1) - xpos.take(self._x2)
        return (np.einsum("ij,ij->i", diff, diff) <= self._bound2).nonzero()[0]

    def _close(self, data: mujoco.MjData) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(pair indices (k,), signed distances (k,), fromto (k, 6))`` of the pairs closer
        than ``activation``, cached per configuration (the solver asks several times)."""
        key = data.qpos.tobytes()
        if self._cache is not None and self._cache[0] == key:
            return self._cache[1]
        near = self.near_pairs(data)
        model, act, g1s, g2s, rows, distance = self.model, self.activation, self._g1, self._g2, self._fromto_rows, mujoco.mj_geomDistance
        d = np.array([distance(model, data, g1s[k], g2s[k], act, rows[i]) for i, k in enumerate(near.tolist())], dtype=float)
        keep = d < act
        out = (near[keep], d[keep], self._fromto[: len(near)][keep])
        self._cache = (key, out)
        return out

    def distances(self, data: mujoco.MjData) -> np.ndarray:
        """Signed distances of every pair (capped at ``activation``), metres."""
        out = self._far.copy()
        k, d, _ = self._close(data)
        out[k] = d
        return out

    def compute_qp_inequalities(self, configuration: mink.Configuration, dt: float) -> mink.Constraint:
        del dt
        data = configuration.data
        k, d, fromto = self._close(data)
        if not len(k):
            return mink.Constraint()
        n = fromto[:, 3:] - fromto[:, :3]  # p_b - p_a
        norm = np.sqrt(np.add.reduce(n * n, axis=1))  # what np.linalg.norm(n, axis=1) computes
        ok = norm >= 1e-9
        if not ok.all():
            k, d, fromto, n, norm = k[ok], d[ok], fromto[ok], n[ok], norm[ok]
            if not len(k):
                return mink.Constraint()
        n /= norm[:, None]
        np.negative(n, out=n, where=(d < 0)[:, None])  # overlapping: fromto runs from b's deepest point into a's surface
        # p_a, p_b of each pair in turn: the Jacobians (m, 2, 3, nv) of a's and b's points
        J = self._pj(data, self._bodies[k].ravel(), fromto.reshape(-1, 3)).reshape(len(k), 2, 3, -1)
        G = -np.einsum("ki,kij->kj", n, J[:, 1] - J[:, 0])
        # the distance may shrink to the margin; a pair inside it must move apart, by at
        # most ``recovery`` per iteration (so that the QP stays feasible):
        # h = d - m if d >= m else -min(m - d, r), i.e. max(d - m, -r) (m - d is -(d - m) exactly)
        h = np.maximum(d - self.margin, -self.recovery)
        return mink.Constraint(G=G, h=h)
