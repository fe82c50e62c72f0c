r"""Arms caught on the wrong branch of their joint ranges, moved onto one that reaches: causally.

The streaming counterpart of :mod:`.branches`.  Offline, the whole clip is known: a
second pass guides a stuck arm onto the other branch where the two meet, before the run
of stuck frames.  A stream sees only the frames so far, so it moves the arm over when it
finds it stuck, within its velocity bounds:

1. **stuck**: on the last frame's answer an arm segment (upper arm or forearm) points
   more than :data:`~.branches.STUCK_DEG` away from its target segment (the direction from
   one target to the next, as the actor's), :data:`STUCK_TIME` seconds in a row;
2. **is it its branch?** the arm's own solve (:class:`~.branches.ArmFit`: the arm's
   joints alone, the rest of the body as the last frame left it) started from the arm's
   joints: if the arm's own branch reaches the targets (no segment of that solve still
   more than ``STUCK_DEG`` off) the arm is only lagging, and nothing is done;
3. **the other branch**: :data:`~.branches.SEEDS` starts within the ranges (a generator
   seeded by the frame number: deterministic), :data:`SEEDS_PER_FRAME` of them a frame so
   that no frame pays for the whole search, the best kept and solved again on each frame
   for that frame's targets, the search ended early by a start that costs less than
   :data:`CLEAR_RATIO` of the own branch; if the best halves the cost of the arm's own
   branch, the switch begins, else the arm is left alone for :data:`RETRY_TIME` seconds;
4. **switch**: every frame the goal (the other branch) is solved again from its last
   value for the new frame's targets, and the IK gets a guide
   (:class:`~.branches.Guide`, :data:`~.branches.GUIDE_COST` per radian) that pulls the
   arm's joints to values moving from where the arm was towards the goal at
   :data:`~.branches.PASS_SPEED` of the joints' velocity limits (as offline; at the whole
   limit the streamed dance's arms were more than 45 degrees off on fewer frames, robot
   7.3 % instead of 9.2, but at the price of more pops, 47 instead of 42, and a joint at its
   cap on 10.2 % of frames instead of 6.0); done when every arm joint is within
   :data:`~.branches.MEET_DEG` of the goal (the IK keeps the branch from there), given up
   after :data:`SWITCH_TIME` seconds.

The arm's targets are moved with its first target onto the character's joint (a stream
shifts the targets onto its planted feet; the branch is a matter of the arm's shape).
Radians, metres, seconds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..metrics.fidelity import SEGMENTS, angle_deg
from .branches import ARM_SEGMENTS, GUIDE_COST, MEET_DEG, PASS_SPEED, SEEDS, STUCK_DEG, ArmChain, ArmFit, Guide, arm_chains

__all__ = ["ArmSwitch", "STUCK_TIME", "SEEDS_PER_FRAME", "CLEAR_RATIO", "RETRY_TIME", "SWITCH_TIME"]

#: Seconds an arm segment stays more than ``STUCK_DEG`` off before the arm is looked at.
STUCK_TIME = 0.05
#: Starts of the other branch's search tried on one frame.
SEEDS_PER_FRAME = 3
#: A start whose solve costs less than this share of the arm's own branch ends the search
#: early (the branch to take is clear; the switch still needs it to halve the own
#: branch's cost on the frame it begins).
CLEAR_RATIO = 0.1
#: Seconds a stuck arm is left alone after a search found no branch that halves its cost
#: (or after a switch that was given up).
RETRY_TIME = 0.25
#: Seconds a switch may take before it is given up.
SWITCH_TIME = 1.0


@dataclass
class _FrameTargets:
    """One frame of targets in the layout :class:`~.branches.ArmFit` reads (frame 0)."""

    names: tuple[str, ...]
    has_orientation: np.ndarray
    positions: np.ndarray = field(init=False)
    orientations: np.ndarray = field(init=False)
    valid: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        n = len(self.names)
        self.positions = np.zeros((1, n, 3))
        self.orientations = np.zeros((1, n, 4))
        self.valid = np.zeros((1, n), dtype=bool)


@dataclass
class _Arm:
    """One arm's state: frames stuck, the search under way, the switch under way."""

    chain: ArmChain
    fit: ArmFit
    speed: np.ndarray  # (K,) rad/s the pulled values move at
    segments: list[tuple[int, int]]  # target columns of each arm segment's two ends
    stuck: int = 0
    wait: int = 0  # frames left before the arm is looked at again
    rng: np.random.Generator | None = None
    seeds_left: int = 0
    own: float = math.inf  # the cost of the arm's own branch when the search began
    best: np.ndarray | None = None
    best_cost: float = math.inf
    goal: np.ndarray | None = None  # the other branch, while switching
    pulled: np.ndarray | None = None
    switching: int = 0  # frames the switch has taken


class ArmSwitch:
    """Guides for a stream's arms stuck on a branch that cannot reach (module docstring).

    Args:
        character: The :class:`~physmocap.models.Character`.
        names: Canonical joints that have targets, in target order.
        has_orientation: ``(N,)`` which of them carry an orientation target.
        fps: The stream's frame rate (frames/s).
        weights: The solver's task weight overrides (``SolverOptions.weights``).
    """

    def __init__(self, character, names: tuple[str, ...], has_orientation: np.ndarray, fps: float,
                 weights: dict | None = None) -> None:
        self.fps = float(fps)
        self.frames = _FrameTargets(tuple(names), np.asarray(has_orientation, dtype=bool))
        self.model = character.model
        self.tracked = character.tracked
        limits = character.velocity_limits
        col = {n: i for i, n in enumerate(names)}
        self.arms: list[_Arm] = []
        for chain in arm_chains(character, tuple(names)):
            segments = []
            for seg in ARM_SEGMENTS[chain.side]:
                a, b = SEGMENTS[seg]
                if a in col and b in col:
                    segments.append((col[a], col[b]))
            speed = PASS_SPEED * np.array([limits.get(self.model.joint(int(j)).name, math.inf) for j in chain.joints])
            self.arms.append(_Arm(chain, ArmFit(character, chain, self.frames, weights or {}),
                                  np.where(np.isfinite(speed), speed, 2.0 * math.pi), segments))
        self.frame = 0

    def guide(self, q: np.ndarray | None, positions: np.ndarray, orientations: np.ndarray, valid: np.ndarray) -> Guide | None:
        """The guide for the next frame (None: no arm is being moved), given the last
        frame's answer ``q`` (``(nq,)``; None before the first) and the next frame's
        targets (``(N, 3)`` metres, ``(N, 4)`` x-y-z-w, ``(N,)`` bool)."""
        frame = self.frame
        self.frame += 1
        if q is None or not self.arms:
            return None
        pulls = []
        for arm in self.arms:
            self.set_targets(arm, q, positions, orientations, valid)
            pull = self._step(arm, q, frame)
            if pull is not None:
                pulls.append((arm.chain, pull))
        if not pulls:
            return None
        return Guide(np.concatenate([c.qpos for c, _ in pulls]), np.concatenate([c.dofs for c, _ in pulls]),
                     np.concatenate([x for _, x in pulls]), GUIDE_COST)

    # -- one arm, one frame --------------------------------------------------------
    def set_targets(self, arm: _Arm, q: np.ndarray, positions, orientations, valid) -> None:
        """Load the frame's targets (``(N, 3)``, ``(N, 4)`` x-y-z-w, ``(N,)``) where ``arm``'s
        fit reads them, the arm's moved with its first target onto the character's joint at
        ``q`` (module docstring); each arm's in turn (they share the frame)."""
        f = self.frames
        f.positions[0] = positions
        f.orientations[0] = orientations
        f.valid[0] = valid
        first = int(arm.chain.targets[0])
        if valid[first]:
            fit = arm.fit
            fit.pose(q[arm.chain.qpos], q)
            here = self.tracked[f.names[first]].position(self.model, fit.data)
            f.positions[0, arm.chain.targets] += here - f.positions[0, first]

    def worst_segment_deg(self, arm: _Arm, x: np.ndarray, q: np.ndarray) -> float:
        """The arm's worst segment direction error (degrees) against the loaded targets
        (:meth:`set_targets`) with its joints at ``x`` and the rest of the body at ``q``."""
        fit = arm.fit
        fit.pose(x, q)
        f = self.frames
        worst = 0.0
        for a, b in arm.segments:
            if not (f.valid[0, a] and f.valid[0, b]):
                continue
            pa = self.tracked[f.names[a]].position(self.model, fit.data)
            pb = self.tracked[f.names[b]].position(self.model, fit.data)
            off = float(angle_deg(pb - pa, f.positions[0, b] - f.positions[0, a]))
            worst = max(worst, off) if np.isfinite(off) else worst  # NaN: a degenerate segment
        return worst

    def _step(self, arm: _Arm, q: np.ndarray, frame: int) -> np.ndarray | None:
        fit, c = arm.fit, arm.chain
        now = q[c.qpos]
        if arm.goal is not None:
            return self._switch(arm, q, now)
        if arm.wait > 0:
            arm.wait -= 1
            return None
        if arm.rng is None:
            arm.stuck = arm.stuck + 1 if self.worst_segment_deg(arm, now, q) > STUCK_DEG else 0
            if arm.stuck < max(1, int(round(STUCK_TIME * self.fps))):
                return None
            own, arm.own = fit.solve(now, q, 0)
            if self.worst_segment_deg(arm, own, q) <= STUCK_DEG:
                arm.stuck = 0  # lagging on a branch that reaches
                return None
            arm.rng, arm.seeds_left = np.random.default_rng(frame), SEEDS
            arm.best, arm.best_cost = None, math.inf
        elif arm.best is not None:  # the best so far, on this frame's targets
            arm.best, arm.best_cost = fit.solve(arm.best, q, 0)
        lo = np.where(np.isfinite(c.lower), c.lower, -math.pi)
        hi = np.where(np.isfinite(c.upper), c.upper, math.pi)
        for _ in range(min(SEEDS_PER_FRAME, arm.seeds_left)):
            x, cost = fit.solve(arm.rng.uniform(lo, hi), q, 0)
            if cost < arm.best_cost - 1e-12:
                arm.best, arm.best_cost = x, cost
        arm.seeds_left -= SEEDS_PER_FRAME
        if arm.seeds_left > 0 and arm.best_cost > CLEAR_RATIO * arm.own:
            return None
        found = arm.best is not None and arm.best_cost <= 0.5 * fit.solve(now, q, 0)[1]
        arm.rng, arm.stuck = None, 0
        if not found:
            arm.wait = int(round(RETRY_TIME * self.fps))
            return None
        arm.goal, arm.pulled, arm.switching = arm.best, now.copy(), 0
        return self._switch(arm, q, now, solved=True)

    def _switch(self, arm: _Arm, q: np.ndarray, now: np.ndarray, solved: bool = False) -> np.ndarray | None:
        """The pulled values of an arm switching branches; None (and the switch over) once
        it is there or given up."""
        if not solved:
            arm.goal = arm.fit.solve(arm.goal, q, 0)[0]
        arm.switching += 1
        if float(np.abs(now - arm.goal).max()) < math.radians(MEET_DEG) or arm.switching > SWITCH_TIME * self.fps:
            if arm.switching > SWITCH_TIME * self.fps:
                arm.wait = int(round(RETRY_TIME * self.fps))
            arm.goal = arm.pulled = None
            return None
        step = arm.speed / self.fps
        arm.pulled = arm.pulled + np.clip(arm.goal - arm.pulled, -step, step)
        return arm.pulled

