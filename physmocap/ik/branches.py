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
   velocity limits.  Forward it runs to :data:`TAIL_TIME` after the run;
4. **second pass**: the clip is retargeted again with a posture pull of
   :data:`GUIDE_COST` per radian towards the continued arm on those frames (a guide,
   :class:`~physmocap.ik.solver.FrameSolver`'s ``guide``): the IK takes the other
   branch where the two meet, within its velocity bounds and every constraint.

The second pass is kept only where it brings the guided arms closer to the actor.
Streaming retargeting cannot look ahead and does not do this.  Radians, metres.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np
from scipy.optimize import least_squares

from ..rotations import Rotation
from .targets import weight_of

__all__ = ["ArmChain", "arm_chains", "Guide", "plan_guides", "STUCK_DEG"]

#: Degrees: an arm segment further than this from the actor's is stuck.
STUCK_DEG = 30.0
#: Random starts of the arm's own solve on a run's worst frame.
SEEDS = 24
#: Degrees: the continued arm has met the first pass's when every joint is this close.
MEET_DEG = 5.0
#: Seconds: how far back the continuation looks for the point where it meets the first pass.
REACH_TIME = 2.0
#: Share of a joint's velocity limit at which the guide passes from one branch to the other.
PASS_SPEED = 0.5
#: Seconds the guide lasts after a run of stuck frames.
TAIL_TIME = 0.1
#: Posture cost per radian of the guide (the position tasks weigh 5 per metre).
GUIDE_COST = 2.0
#: Arm segments of the fidelity figures -> side.
ARM_SEGMENTS = {"left": ("left_upper_arm", "left_forearm"), "right": ("right_upper_arm", "right_forearm")}
#: Joint types an arm's own solve moves (a hinge or a slide: one coordinate each).
_MOVING = (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))
#: Canonical joints whose targets the arm's own solve follows.
ARM_JOINTS = ("clavicle", "shoulder", "elbow", "wrist", "hand_end")


@dataclass(frozen=True)
class ArmChain:
    """One arm of the character: its joints and targets.

    Attributes:
        side: ``"left"`` or ``"right"``.
        qpos: ``(K,)`` qpos addresses of the arm's hinge and slide joints.
        dofs: ``(K,)`` their dof addresses.
        lower, upper: ``(K,)`` their ranges (radians; infinite where unlimited).
        targets: ``(M,)`` target columns of the arm's canonical joints.
    """

    side: str
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
                       if int(model.jnt_type[j]) in _MOVING]
            b = int(model.body_parentid[b])
        if b != top or not joints:
            continue  # the arm does not hang from the torso's body
        joints.sort()
        limited = model.jnt_limited[joints].astype(bool)
        chains.append(ArmChain(
            side=side,
            qpos=model.jnt_qposadr[joints].astype(int),
            dofs=model.jnt_dofadr[joints].astype(int),
            lower=np.where(limited, model.jnt_range[joints, 0], -np.inf),
            upper=np.where(limited, model.jnt_range[joints, 1], np.inf),
            targets=np.array([names.index(n) for n in tracked], dtype=int),
        ))
    return chains


def _joints(model: mujoco.MjModel, chain: ArmChain) -> np.ndarray:
    """Joint ids of an arm's coordinates."""
    return np.array([int(np.flatnonzero(model.jnt_qposadr == a)[0]) for a in chain.qpos], dtype=int)


@dataclass(frozen=True)
class Guide:
    """A posture pull for one frame of the second pass: ``(nq,)`` target configuration and
    ``(nv,)`` cost per radian (0 off the guided arms)."""

    qpos: np.ndarray
    cost: np.ndarray


class _ArmFit:
    """The arm's own least-squares solve on one frame, the rest of the body held."""

    def __init__(self, character, chain: ArmChain, targets, weights: dict) -> None:
        self.model = character.model
        self.data = mujoco.MjData(self.model)
        self.chain = chain
        self.targets = targets
        self.frames = [character.tracked[targets.names[k]] for k in chain.targets]
        w = [weights.get(targets.names[k], weight_of(targets.names[k])) for k in chain.targets]
        self.pos_w = np.array([p for p, _ in w])
        self.rot_w = np.array([o if targets.has_orientation[k] else 0.0 for (_, o), k in zip(w, chain.targets)])

    def _pose(self, tf) -> tuple[np.ndarray, np.ndarray]:
        d, m = self.data, self.model
        if tf.kind == "site":
            s = m.site(tf.name).id
            return d.site_xpos[s], d.site_xmat[s]
        b = m.body(tf.name).id
        return d.xpos[b], d.xmat[b]

    def residual(self, x: np.ndarray, q: np.ndarray, t: int) -> np.ndarray:
        """Weighted position (metres) and orientation (radians) errors of the arm's targets
        on frame ``t`` with the arm's joints at ``x`` and the rest at ``q``."""
        d = self.data
        d.qpos[:] = q
        d.qpos[self.chain.qpos] = x
        mujoco.mj_kinematics(self.model, d)
        pos = self.targets.positions[t]
        ori = self.targets.orientations[t]
        valid = self.targets.valid[t]
        out = []
        for tf, k, pw, ow in zip(self.frames, self.chain.targets, self.pos_w, self.rot_w):
            if not valid[k]:
                out.append(np.zeros(6))
                continue
            p, mat = self._pose(tf)
            r = np.zeros(3)
            if ow > 0.0:
                r = ow * (Rotation.from_matrix(mat.reshape(3, 3)).inv() * Rotation.from_quat(ori[k])).as_rotvec()
            out.append(np.concatenate([pw * (p - pos[k]), r]))
        return np.concatenate(out)

    def cost(self, x: np.ndarray, q: np.ndarray, t: int) -> float:
        r = self.residual(x, q, t)
        return 0.5 * float(r @ r)

    def solve(self, x0: np.ndarray, q: np.ndarray, t: int) -> tuple[np.ndarray, float]:
        """The arm's joints nearest ``x0`` that best reach frame ``t``'s targets, and the cost."""
        c = self.chain
        x0 = np.clip(x0, c.lower + 1e-9, c.upper - 1e-9)
        fit = least_squares(self.residual, x0, bounds=(c.lower, c.upper), args=(q, t), xtol=1e-6, ftol=1e-8)
        return fit.x, float(fit.cost)


def _runs(frames: np.ndarray, gap: int) -> list[tuple[int, int]]:
    """Runs ``[start, end]`` of sorted frame numbers, joined across gaps of ``gap`` frames."""
    if frames.size == 0:
        return []
    breaks = np.flatnonzero(np.diff(frames) > gap + 1)
    starts = np.concatenate([[frames[0]], frames[breaks + 1]])
    ends = np.concatenate([frames[breaks], [frames[-1]]])
    return list(zip(starts.tolist(), ends.tolist()))


def _continue_back(fit: _ArmFit, qpos: np.ndarray, x: np.ndarray, t: int, stop: int) -> tuple[dict[int, np.ndarray], int]:
    """The arm solution ``x`` of frame ``t`` followed back frame by frame (each solve started
    from the later frame's) down to ``stop``, and the frame where the first pass's arm
    can pass over to it at the least cost (:func:`_crossing_cost`; the latest among
    equals), or where the two meet.  Returns (frame -> arm joints, ``t`` excluded; that
    frame)."""
    meet = math.radians(MEET_DEG)
    path: dict[int, np.ndarray] = {}
    costs: list[tuple[float, int]] = []
    for f in range(t - 1, stop - 1, -1):
        x, _ = fit.solve(x, qpos[f], f)
        path[f] = x
        first = qpos[f, fit.chain.qpos]
        if float(np.abs(x - first).max()) < meet:
            costs.append((0.0, -f))
            break
        costs.append((_crossing_cost(fit, first, x, qpos[f], f), -f))
    return path, (-min(costs)[1] if costs else t)


def _pass_over(fit: _ArmFit, qpos: np.ndarray, path: dict[int, np.ndarray], cross: int, speed: np.ndarray,
               fps: float) -> dict[int, np.ndarray]:
    r"""The guide's arm per frame: the first pass's arm blended into ``path`` around frame
    ``cross`` over as many frames as the largest joint change takes at ``speed`` (rad/s per
    joint: :data:`PASS_SPEED` of the velocity limits), weight :math:`3s^2 - 2s^3`, then
    ``path``."""
    c = fit.chain
    gap = np.abs(path[cross] - qpos[cross, c.qpos])
    n = max(1, int(math.ceil(float(np.max(gap / speed)) * fps)))
    first = cross - n // 2
    out = {}
    for f in sorted(path):
        if f < first:
            continue
        s = min(1.0, (f - first + 1) / n)
        w = s * s * (3.0 - 2.0 * s)
        out[f] = (1.0 - w) * qpos[f, c.qpos] + w * path[f]
    return out


#: Points along the way from one arm to the other where :func:`_crossing_cost` looks.
_CROSSING = (0.25, 0.5, 0.75)


def _crossing_cost(fit: _ArmFit, a: np.ndarray, b: np.ndarray, q: np.ndarray, t: int) -> float:
    """How far from frame ``t``'s targets the arm goes on the straight way (in joint
    space) from joints ``a`` to ``b``: the largest cost above the two ends' on the way.
    Near a shoulder's gimbal lock two branches are one pose, and the way between them
    leaves the pose in place."""
    ends = max(fit.cost(a, q, t), fit.cost(b, q, t))
    return max(fit.cost(a + w * (b - a), q, t) for w in _CROSSING) - ends


def plan_guides(traj, segment_errors: dict[str, np.ndarray], weights: dict | None = None) -> dict[int, Guide]:
    """Second-pass guides for the arms the first pass left on a branch that cannot reach
    the actor (module docstring): frame -> :class:`Guide`; empty when none is stuck.

    Args:
        traj: The first pass's :class:`~physmocap.trajectory.Trajectory` (its targets).
        segment_errors: Segment name -> ``(F,)`` direction error in degrees
            (:func:`~physmocap.metrics.fidelity.segment_direction_errors`).
        weights: The solver's task weight overrides (``SolverOptions.weights``).
    """
    targets = traj.targets
    qpos = np.asarray(traj.qpos)
    F = qpos.shape[0]
    model = traj.character.model
    reach = max(1, int(round(REACH_TIME * traj.fps)))
    tail = max(1, int(round(TAIL_TIME * traj.fps)))
    guided: dict[int, dict[int, np.ndarray]] = {}  # frame -> chain index -> arm joints
    chains = arm_chains(traj.character, tuple(targets.names))
    limits = traj.character.velocity_limits
    speed = [PASS_SPEED * np.array([limits.get(model.joint(int(j)).name, math.inf) for j in _joints(model, c)]) for c in chains]
    for ci, chain in enumerate(chains):
        errs = [segment_errors.get(s) for s in ARM_SEGMENTS[chain.side]]
        errs = [np.nan_to_num(e, nan=0.0) for e in errs if e is not None]
        if not errs:
            continue
        worst = np.max(errs, axis=0)
        fit = _ArmFit(traj.character, chain, targets, weights or {})
        for s, e in _runs(np.flatnonzero(worst > STUCK_DEG), gap=max(1, int(0.1 * traj.fps))):
            t = s + int(np.argmax(worst[s : e + 1]))
            now = fit.cost(qpos[t, chain.qpos], qpos[t], t)
            rng = np.random.default_rng(t)
            lo = np.where(np.isfinite(chain.lower), chain.lower, -math.pi)
            hi = np.where(np.isfinite(chain.upper), chain.upper, math.pi)
            starts = [qpos[t, chain.qpos]] + [rng.uniform(lo, hi) for _ in range(SEEDS)]
            best, best_cost = None, now
            for x0 in starts:
                x, c = fit.solve(x0, qpos[t], t)
                if c < best_cost - 1e-12:
                    best, best_cost = x, c
            if best is None or best_cost > 0.5 * now:
                continue  # no other branch reaches the actor better: a pose out of reach
            path, cross = _continue_back(fit, qpos, best, t, max(0, s - reach))
            path[t] = x = best
            for f in range(t + 1, min(F - 1, e + tail) + 1):  # through the run (the arm stays there after)
                path[f] = x = fit.solve(x, qpos[f], f)[0]
            for f, x in _pass_over(fit, qpos, path, cross, speed[ci], traj.fps).items():
                guided.setdefault(f, {})[ci] = x
    guides = {}
    for f in sorted(guided):
        q = qpos[f].copy()
        cost = np.zeros(model.nv)
        for ci, x in guided[f].items():
            q[chains[ci].qpos] = x
            cost[chains[ci].dofs] = GUIDE_COST
        guides[f] = Guide(q, cost)
    return guides
