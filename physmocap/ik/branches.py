r"""Arms caught on the wrong branch of their joint ranges, guided onto the one that reaches.

A shoulder of three hinges (the humanoid's flexion, abduction and rotation; a robot's
pitch, roll and yaw) reaches most arm attitudes two ways.  Which one the frame-by-frame IK
takes is decided where the two meet (an arm hanging, or level at the side) and it keeps
it: velocity bounds allow no jump to the other.  When the actor then raises the arm and
bends or twists it, the branch taken may end at a joint limit that the other does not
have: the arm stays straight up or out to the side, 50-80 degrees off the actor's, for as
long as the actor holds the pose (the CMU dance, both characters), although a pose within
every range matches the actor's to a few millimetres.

Offline the whole clip is known, so after the first pass:

1. **stuck frames**: an arm segment (upper arm or forearm) more than :data:`STUCK_DEG`
   off the actor's (:mod:`physmocap.metrics.fidelity`'s segment directions);
2. **the other branch**: on the worst frame of each run of stuck frames the arm's
   joints (everything between the torso and the hand) are solved on their own, the rest
   of the body as the first pass left it, for the arm's targets with the IK's weights
   (bounded least squares from the first pass's arm and :data:`SEEDS` seeds drawn
   within the ranges, a generator seeded by the frame: deterministic).  A run whose
   best arm does not halve the first pass's cost is a pose the character cannot take:
   left alone;
3. **continuation**: that solution is followed frame by frame, each frame's solve
   started from its neighbour's: back to where it meets the first pass's arm (every joint
   within :data:`MEET_DEG`), or, within :data:`REACH_TIME` seconds, to the frame where the
   first pass's arm can pass over to it with the least change of pose (near a shoulder's
   gimbal lock the two branches are one pose: the way between them in joint space keeps
   the arm where it is); the guide passes over there, at :data:`PASS_SPEED` of the joints'
   velocity limits.  Forward it runs through the run and :data:`TAIL_TIME` beyond, and the
   arm stays on its new branch;
4. **second pass**: the clip is retargeted again with a posture pull of
   :data:`GUIDE_COST` per radian towards the continued arm on those frames (a guide,
   :class:`~physmocap.ik.solver.FrameSolver`'s ``guide``): the IK takes the other
   branch where the two meet, within its velocity bounds and every constraint.  An arm
   can stick on its new branch later; the same steps on the second pass's result make a
   third (at most :data:`MAX_PASSES` in all).

A pass is kept, for the whole clip, only if fewer frames have an arm segment more than
:data:`STUCK_DEG` off the actor's than the best before it (then if the arm segments'
errors sum lower), and the solver relaxed a hard constraint on no more frames.
Streaming retargeting cannot look ahead: :mod:`.armswitch` moves a stuck arm over when
it finds it stuck, with the same arm solve (:class:`ArmFit`).  Radians, metres.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

from ..progress import Progress
from ..rotations import xyzw_to_wxyz
from ..sources.gaps import find_runs
from .targets import weight_of

__all__ = ["ArmChain", "arm_chains", "Guide", "plan_guides", "STUCK_DEG"]

#: Degrees: an arm segment further than this from the actor's is stuck.
STUCK_DEG = 30.0
#: Random starts of the arm's own solve on a run's worst frame.
SEEDS = 24
#: Degrees: the continued arm has met the first pass's when every joint is this close.
MEET_DEG = 5.0
#: Seconds: how far before a run the continuation looks for the point where it meets the
#: first pass.
REACH_TIME = 2.0
#: Share of a joint's velocity limit at which the guide passes from one branch to the other.
PASS_SPEED = 0.5
#: Seconds the guide lasts after a run of stuck frames.
TAIL_TIME = 0.1
#: Passes at most (the first included): an arm guided onto another branch may stick on it
#: later, and the next pass guides it off.
MAX_PASSES = 3
#: Posture cost per radian of the guide (the position tasks weigh 5 per metre).
GUIDE_COST = 2.0
#: Arm segments of the fidelity figures -> side.
ARM_SEGMENTS = {"left": ("left_upper_arm", "left_forearm"), "right": ("right_upper_arm", "right_forearm")}
#: Joint types an arm's own solve moves (a hinge or a slide: one coordinate each).
MOVING_TYPES = (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))
#: Canonical joints whose targets the arm's own solve follows.
ARM_JOINTS = ("clavicle", "shoulder", "elbow", "wrist", "hand_end")


@dataclass(frozen=True)
class ArmChain:
    """One arm of the character: its joints and targets.

    Attributes:
        side: ``"left"`` or ``"right"``.
        joints: ``(K,)`` ids of the arm's hinge and slide joints.
        qpos: ``(K,)`` their qpos addresses.
        dofs: ``(K,)`` their dof addresses.
        lower, upper: ``(K,)`` their ranges (radians; infinite where unlimited).
        targets: ``(M,)`` target columns of the arm's canonical joints.
    """

    side: str
    joints: np.ndarray
    qpos: np.ndarray
    dofs: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    targets: np.ndarray


def arm_chains(character, names: tuple[str, ...]) -> list[ArmChain]:
    """The character's arms: the hinge and slide joints on the bodies between the torso
    and the arm's last tracked frame (its hand), for each side with a shoulder, an elbow
    and a wrist among ``names``."""
    model = character.model
    torso = next((t for t in ("chest", "spine", "pelvis") if t in names), None)
    if torso is None:
        return []
    top = character.tracked[torso].body_id(model)
    chains = []
    for side in ("left", "right"):
        tracked = [f"{side}_{j}" for j in ARM_JOINTS if f"{side}_{j}" in names]
        if not all(f"{side}_{j}" in tracked for j in ("shoulder", "elbow", "wrist")):
            continue
        b = character.tracked[tracked[-1]].body_id(model)
        joints = []
        while b > 0 and b != top:
            joints += [j for j in range(model.body_jntadr[b], model.body_jntadr[b] + model.body_jntnum[b])
                       if int(model.jnt_type[j]) in MOVING_TYPES]
            b = int(model.body_parentid[b])
        if b != top or not joints:
            continue  # the arm does not hang from the torso's body
        joints.sort()
        limited = model.jnt_limited[joints].astype(bool)
        chains.append(ArmChain(
            side=side,
            joints=np.array(joints, dtype=int),
            qpos=model.jnt_qposadr[joints].astype(int),
            dofs=model.jnt_dofadr[joints].astype(int),
            lower=np.where(limited, model.jnt_range[joints, 0], -np.inf),
            upper=np.where(limited, model.jnt_range[joints, 1], np.inf),
            targets=np.array([names.index(n) for n in tracked], dtype=int),
        ))
    return chains


@dataclass(frozen=True)
class Guide:
    """A posture pull on some hinge and slide joints for one frame of a later pass.

    Attributes:
        qpos: ``(K,)`` the joints' qpos addresses.
        dofs: ``(K,)`` their dof addresses.
        values: ``(K,)`` where they are pulled (radians or metres).
        cost: Cost per radian (metre) of the pull, one for all or ``(K,)`` joint by joint.
        start: ``(nq,)`` a configuration the frame's iterations start from (kept within the
            ranges and the frame's velocity band), or None: the previous frame's pose.
        follow: ``start`` is the answer, on this frame, of an earlier pass that this one
            follows: the iterations start from it moved by this pass's offset from that pass
            on the previous frame (:meth:`~physmocap.ik.frame.FrameRetargeter.carried`).
    """

    qpos: np.ndarray
    dofs: np.ndarray
    values: np.ndarray
    cost: float | np.ndarray = GUIDE_COST
    start: np.ndarray | None = None
    follow: bool = False

    def arm(self, chain: ArmChain) -> np.ndarray | None:
        """The values this guide pulls ``chain``'s joints to, or None if it does not pull them."""
        hit = np.flatnonzero(np.isin(self.qpos, chain.qpos))
        return self.values[hit] if hit.size == chain.qpos.size else None


class ArmFit:
    r"""The arm's own least-squares solve on one frame, the rest of the body held.

    The residual stacks, for each of the arm's targets, the weighted position error
    :math:`w_p (p - \hat p)` (metres) and, where the target has an orientation, the
    weighted rotation from the frame to its target as a rotation vector in the frame,
    :math:`\phi = w_o\,\log(R^\top \hat R)` (radians); :meth:`solve` minimises half its
    squared norm within the joints' ranges by Levenberg-Marquardt on the analytic Jacobians
    (``mj_jac``; the rotation rows :math:`-w_o J_l^{-1}(\phi / w_o) R^\top J_r`, with
    :math:`J_l^{-1}` the inverse left Jacobian of SO(3)), the joints at a bound that the
    gradient pushes out of it held there.
    """

    #: Levenberg-Marquardt iterations at most, and the relative cost decrease below which
    #: the solve stops.
    ITERATIONS = 60
    FTOL = 1e-8

    def __init__(self, character, chain: ArmChain, targets, weights: dict) -> None:
        self.model = character.model
        self.data = mujoco.MjData(self.model)
        self.chain = chain
        self.targets = targets
        self.frames = [character.tracked[targets.names[k]] for k in chain.targets]
        self.ids = [tf.object_id(self.model) for tf in self.frames]
        self.bodies = [tf.body_id(self.model) for tf in self.frames]
        w = [weights.get(targets.names[k], weight_of(targets.names[k])) for k in chain.targets]
        self.pos_w = np.array([p for p, _ in w])
        self.rot_w = np.array([o if targets.has_orientation[k] else 0.0 for (_, o), k in zip(w, chain.targets)])
        self._jacp = np.zeros((3, self.model.nv))
        self._jacr = np.zeros((3, self.model.nv))

    def _pose(self, tf, i: int) -> tuple[np.ndarray, np.ndarray]:
        d = self.data
        if tf.kind == "site":
            return d.site_xpos[i], d.site_xmat[i].reshape(3, 3)
        return d.xpos[i], d.xmat[i].reshape(3, 3)

    def pose(self, x: np.ndarray, q: np.ndarray) -> None:
        """Set the fit's data to ``q`` with the arm's joints at ``x``, kinematics done."""
        d = self.data
        d.qpos[:] = q
        d.qpos[self.chain.qpos] = x
        mujoco.mj_kinematics(self.model, d)

    def residual(self, x: np.ndarray, q: np.ndarray, t: int, jacobian: bool = False):
        """Weighted position (metres) and orientation (radians) errors of the arm's targets
        on frame ``t`` with the arm's joints at ``x`` and the rest at ``q``; with
        ``jacobian`` also their ``(rows, K)`` derivatives in the arm's joints."""
        m, d = self.model, self.data
        self.pose(x, q)
        if jacobian:
            mujoco.mj_comPos(m, d)
        pos = self.targets.positions[t]
        goal = xyzw_to_wxyz(np.asarray(self.targets.orientations[t]))
        valid = self.targets.valid[t]
        n = len(self.frames)
        out = np.zeros((n, 6))
        jac = np.zeros((n, 6, self.chain.dofs.size)) if jacobian else None
        now = np.empty(4)
        for r, (tf, i, b, k, pw, ow) in enumerate(zip(self.frames, self.ids, self.bodies, self.chain.targets,
                                                         self.pos_w, self.rot_w)):
            if not valid[k]:
                continue
            p, R = self._pose(tf, i)
            out[r, :3] = pw * (p - pos[k])
            if jacobian:
                mujoco.mj_jac(m, d, self._jacp, self._jacr, p, b)
                jac[r, :3] = pw * self._jacp[:, self.chain.dofs]
            if ow > 0.0:  # the rotation from the frame to its target, as a rotation vector (radians)
                mujoco.mju_mat2Quat(now, R.reshape(-1))
                mujoco.mju_subQuat(out[r, 3:], goal[k], now)
                out[r, 3:] *= ow
                if jacobian:
                    jac[r, 3:] = -(_left_jacobian_inverse(out[r, 3:] / ow) @ (ow * R.T)) @ self._jacr[:, self.chain.dofs]
        if jacobian:
            return out.reshape(-1), jac.reshape(6 * n, -1)
        return out.reshape(-1)

    def cost(self, x: np.ndarray, q: np.ndarray, t: int) -> float:
        r = self.residual(x, q, t)
        return 0.5 * float(r @ r)

    def solve(self, x0: np.ndarray, q: np.ndarray, t: int) -> tuple[np.ndarray, float]:
        """The arm's joints nearest ``x0`` that best reach frame ``t``'s targets, and the cost
        (a local minimum within the ranges: class docstring)."""
        c = self.chain
        x = np.clip(x0, c.lower, c.upper)
        r, J = self.residual(x, q, t, jacobian=True)
        cost = 0.5 * float(r @ r)
        lam = 1e-3
        for _ in range(self.ITERATIONS):
            g = J.T @ r
            free = ~(((x <= c.lower) & (g > 0.0)) | ((x >= c.upper) & (g < 0.0)))
            if not free.any():
                break
            H = (J.T @ J)[np.ix_(free, free)]
            step = np.zeros_like(x)
            try:
                step[free] = -np.linalg.solve(H + lam * (np.diag(np.diag(H)) + 1e-9 * np.eye(H.shape[0])), g[free])
            except np.linalg.LinAlgError:  # exactly singular even damped: stop here
                break
            if not np.isfinite(step).all():  # a residual or Jacobian not finite (solve does not raise)
                break
            xn = np.clip(x + step, c.lower, c.upper)
            rn, Jn = self.residual(xn, q, t, jacobian=True)
            cn = 0.5 * float(rn @ rn)
            if cn < cost:
                done = cost - cn <= self.FTOL * max(cost, 1e-12) or float(np.abs(xn - x).max()) < 1e-7
                x, r, J, cost = xn, rn, Jn, cn
                lam = max(lam * 0.3, 1e-9)
                if done:
                    break
            else:
                lam *= 10.0
                if lam > 1e8:
                    break
        return x, cost


def _left_jacobian_inverse(phi: np.ndarray) -> np.ndarray:
    r"""``(3, 3)`` inverse left Jacobian of SO(3) at the rotation vector ``phi`` (radians):
    :math:`I - \tfrac12[\phi]_\times + \big(\tfrac{1}{\theta^2} - \tfrac{1 + \cos\theta}{2\theta\sin\theta}\big)[\phi]_\times^2`,
    :math:`\theta = |\phi|` (the series' limit :math:`\tfrac{1}{12}` near 0), so that
    :math:`\log(e^{[\delta]} e^{[\phi]}) \approx \phi + J_l^{-1}(\phi)\,\delta`.
    (mink's ``SO3.ljacinv`` is the same formula but divides by zero near 1e-8 rad and loses
    half its digits near 1e-5: an arm solve's rotation errors start there.)"""
    theta = float(np.linalg.norm(phi))
    K = np.array([[0.0, -phi[2], phi[1]], [phi[2], 0.0, -phi[0]], [-phi[1], phi[0], 0.0]])
    if theta < 1e-6:
        c = 1.0 / 12.0
    else:
        c = 1.0 / theta**2 - (1.0 + math.cos(theta)) / (2.0 * theta * math.sin(theta)) if theta < math.pi - 1e-6 else 1.0 / theta**2
    return np.eye(3) - 0.5 * K + c * (K @ K)


def _runs(worst: np.ndarray, gap: int) -> list[tuple[int, int]]:
    """Runs ``[start, end]`` of frames over :data:`STUCK_DEG`, joined across gaps of up to
    ``gap`` frames."""
    runs: list[tuple[int, int]] = []
    for s, e in find_runs(worst > STUCK_DEG):
        if runs and s - runs[-1][1] - 1 <= gap:
            runs[-1] = (runs[-1][0], e)
        else:
            runs.append((s, e))
    return runs


def _continue(fit: ArmFit, qpos: np.ndarray, x: np.ndarray, frames: range, after: int) -> tuple[dict[int, np.ndarray], int | None]:
    """The arm solution ``x`` followed over ``frames`` (in that order, each solve started from
    the previous frame's), and the frame beyond ``after`` (past it in the direction of
    travel) where it and the first pass's arm are nearest in pose: where they meet (every
    joint within :data:`MEET_DEG`: the walk stops there) or the least
    :func:`_crossing_cost` (the nearest to the start among equals); None if no frame is
    beyond ``after``.  Returns (frame -> arm joints, that frame)."""
    meet = math.radians(MEET_DEG)
    step = frames.step
    path: dict[int, np.ndarray] = {}
    best: tuple[float, int] | None = None
    for f in frames:
        x = path[f] = fit.solve(x, qpos[f], f)[0]
        if (f - after) * step <= 0:
            continue
        first = qpos[f, fit.chain.qpos]
        if float(np.abs(x - first).max()) < meet:
            return path, f
        cost = _crossing_cost(fit, first, x, qpos[f], f)
        if best is None or cost < best[0]:
            best = (cost, f)
    return path, None if best is None else best[1]


def _blend(fit: ArmFit, qpos: np.ndarray, path: dict[int, np.ndarray], cross: int, speed: np.ndarray,
           fps: float, into: bool) -> dict[int, np.ndarray]:
    r"""The guide's arm on the frames of ``path``: the first pass's arm blended into ``path``
    around frame ``cross`` (``into``; out of it with ``into`` False) over as many frames as
    the largest joint change takes at ``speed`` (rad/s per joint: :data:`PASS_SPEED` of the
    velocity limits), weight :math:`3s^2 - 2s^3`; only ``path`` on its side of the blend,
    nothing on the other."""
    c = fit.chain
    gap = np.abs(path[cross] - qpos[cross, c.qpos])
    n = max(1, int(math.ceil(float(np.max(gap / speed)) * fps)))
    first = cross - n // 2
    out = {}
    for f in sorted(path):
        s = min(1.0, max(0.0, (f - first + 1) / n))
        w = s * s * (3.0 - 2.0 * s)
        w = w if into else 1.0 - w
        if w > 0.0:
            out[f] = (1.0 - w) * qpos[f, c.qpos] + w * path[f]
    return out


#: Points along the way from one arm to the other where :func:`_crossing_cost` looks.
_CROSSING = (0.25, 0.5, 0.75)


def _crossing_cost(fit: ArmFit, a: np.ndarray, b: np.ndarray, q: np.ndarray, t: int) -> float:
    """How far from frame ``t``'s targets the arm goes on the straight way (in joint
    space) from joints ``a`` to ``b``: the largest cost above the two ends' on the way.
    Near a shoulder's gimbal lock two branches are one pose, and the way between them
    leaves the pose in place."""
    ends = max(fit.cost(a, q, t), fit.cost(b, q, t))
    return max(fit.cost(a + w * (b - a), q, t) for w in _CROSSING) - ends


def _other_branch(fit: ArmFit, qpos: np.ndarray, t: int) -> np.ndarray | None:
    """The arm's joints on frame ``t`` from the best of the first pass's arm and
    :data:`SEEDS` starts within the ranges (a generator seeded by ``t``), or None unless
    they halve the first pass's cost (module docstring, step 2)."""
    c = fit.chain
    now = fit.cost(qpos[t, c.qpos], qpos[t], t)
    rng = np.random.default_rng(t)
    lo = np.where(np.isfinite(c.lower), c.lower, -math.pi)
    hi = np.where(np.isfinite(c.upper), c.upper, math.pi)
    best, best_cost = None, now
    for x0 in [qpos[t, c.qpos]] + [rng.uniform(lo, hi) for _ in range(SEEDS)]:
        x, cost = fit.solve(x0, qpos[t], t)
        if cost < best_cost - 1e-12:
            best, best_cost = x, cost
    return best if best is not None and best_cost <= 0.5 * now else None


def plan_guides(traj, segment_errors: dict[str, np.ndarray], weights: dict | None = None,
                progress: bool | None = None, previous: dict[int, Guide] | None = None) -> dict[int, Guide]:
    """Guides for the next pass, for the arms ``traj`` left on a branch that cannot reach
    the actor (module docstring): frame -> :class:`Guide`; empty when none is stuck.

    Args:
        traj: The last pass's :class:`~physmocap.trajectory.Trajectory` (its targets).
        segment_errors: Segment name -> ``(F,)`` direction error in degrees
            (:func:`~physmocap.metrics.fidelity.segment_direction_errors`).
        weights: The solver's task weight overrides (``SolverOptions.weights``).
        progress: Draw a progress bar over the stuck frames on stderr.
        previous: The guides ``traj`` was retargeted with: kept where no new run is
            guided (an arm guided off a branch stays guided), else replaced arm by arm.
    """
    targets = traj.targets
    qpos = traj.qpos
    F = qpos.shape[0]
    model = traj.character.model
    reach = max(1, int(round(REACH_TIME * traj.fps)))
    tail = max(1, int(round(TAIL_TIME * traj.fps)))
    guided: dict[int, dict[int, np.ndarray]] = {}  # frame -> chain index -> arm joints
    chains = arm_chains(traj.character, tuple(targets.names))
    limits = traj.character.velocity_limits
    work = []
    for ci, chain in enumerate(chains):
        errs = [np.nan_to_num(segment_errors[s], nan=0.0) for s in ARM_SEGMENTS[chain.side] if s in segment_errors]
        if errs:
            work += [(ci, s, e) for s, e in _runs(np.max(errs, axis=0), gap=max(1, int(0.1 * traj.fps)))]
    if not work:
        return {}
    for f, g in (previous or {}).items():
        for ci, chain in enumerate(chains):
            x = g.arm(chain)
            if x is not None:
                guided.setdefault(f, {})[ci] = x
    with Progress(sum(e - s + 1 for _, s, e in work), "arms", enabled=progress) as bar:
        for ci, s, e in work:
            chain = chains[ci]
            fit = ArmFit(traj.character, chain, targets, weights or {})
            speed = PASS_SPEED * np.array([limits.get(model.joint(int(j)).name, math.inf) for j in chain.joints])
            worst = np.max([np.nan_to_num(segment_errors[n][s : e + 1], nan=0.0)
                            for n in ARM_SEGMENTS[chain.side] if n in segment_errors], axis=0)
            t = s + int(np.argmax(worst))
            best = _other_branch(fit, qpos, t)
            if best is not None:
                back, into = _continue(fit, qpos, best, range(t - 1, max(0, s - reach) - 1, -1), t)
                ahead, _ = _continue(fit, qpos, best, range(t + 1, min(F - 1, e + tail) + 1), F)
                arm = _blend(fit, qpos, {**back, t: best}, into if into is not None else t, speed, traj.fps, into=True)
                arm.update(ahead)  # the arm stays on that branch after the run: a later pass takes it off if it sticks
                for f, x in arm.items():
                    guided.setdefault(f, {})[ci] = x
            bar.update(e - s + 1)
    guides = {}
    for f in sorted(guided):
        arms = [(chains[ci], x) for ci, x in sorted(guided[f].items())]
        guides[f] = Guide(
            np.concatenate([c.qpos for c, _ in arms]), np.concatenate([c.dofs for c, _ in arms]),
            np.concatenate([x for _, x in arms]),
        )
    return guides
