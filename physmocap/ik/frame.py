"""One frame of the retargeting pipeline, shared by offline and streaming retargeting.

Given one frame's targets and contact labels, :class:`FrameRetargeter`

1. on the very first frame, converges from the rest pose on the targets alone
   (no planting), so the feet start where the actor's are;
2. asks the planting (:class:`~physmocap.ik.planting.Planting`) for this
   frame's contact holds: soft pulls onto the floor, hard equalities holding
   planted points, swing clearances (and, for a causal stream, the targets
   shifted onto the anchored feet);
3. solves the frame (:class:`~physmocap.ik.solver.FrameSolver`), warm-started
   from the previous one.

Offline retargeting (:func:`~physmocap.ik.retarget.solve_targets`) calls it
once per frame with targets already planned over the whole clip
(``anchored=False``); the streaming retargeter
(:class:`~physmocap.ik.stream.StreamingRetargeter`) with causal targets and
labels (``anchored=True``).  Inputs are arguments and are never modified; the
result is a :class:`FrameResult`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from ..canonical import canonical_parent
from .planting import PlantOptions, Planting
from .solver import ContactHolds, FrameSolver, SolverOptions

__all__ = ["FrameResult", "FrameRetargeter", "CHEST_LAG_FREE", "CHEST_LAG_TIME"]

#: Metres of the chest's lag behind its target that the upper body does *not* follow:
#: ordinary tracking error, left to the arms' own tasks (following every centimetre fed
#: the solver's frame-to-frame fluctuations back into the arms: the Bandai walk's joint
#: acceleration rose 28 %).
CHEST_LAG_FREE = 0.02
#: Seconds: time constant of the low-pass on the chest's lag that the upper body follows.
CHEST_LAG_TIME = 0.05


@dataclass(frozen=True)
class FrameResult:
    """The character's pose on one frame and how it was found.

    Attributes:
        qpos: ``(nq,)`` the character's generalised position (quaternions w-x-y-z).
        iterations: QP iterations used.
        relaxation: Strongest relaxation needed (index into
            :data:`~physmocap.ik.solver.RELAXATION_LEVELS`; 0: every constraint held).
        latency: Wall time of the frame (seconds).
    """

    qpos: np.ndarray
    iterations: int
    relaxation: int
    latency: float


class FrameRetargeter:
    """Frame-by-frame IK with contact holds for one character (see the module docstring).

    Args:
        character: A :class:`~physmocap.models.Character`.
        names: Canonical joints that have targets, in target order.
        has_orientation: ``(N,)`` which of them have orientation targets.
        fps: Frame rate (velocity bounds, planting time constants).
        solver: IK options.
        plant: Planting options; None or ``plant=False``: no contact holds.
        anchored: True for causal targets (streaming: the planting anchors the
            feet and shifts their targets), False for targets planned offline.
    """

    def __init__(
        self,
        character,
        names: Sequence[str],
        has_orientation: np.ndarray,
        fps: float,
        solver: SolverOptions | None = None,
        plant: PlantOptions | None = None,
        anchored: bool = True,
    ) -> None:
        self.character = character
        self.names = tuple(names)
        self.fps = float(fps)
        self.solver = FrameSolver(character, self.names, has_orientation, fps, solver)
        self.plant_options = plant
        self.anchored = bool(anchored)
        self.planting: Planting | None = None
        self.frame = 0
        self._chest, self._upper = self._upper_body(character, self.names)
        #: ``(3,)`` the chest's (or spine's) offset from its target on the previous frame (metres)
        self._chest_lag = np.zeros(3)
        self.restart_contacts()

    @staticmethod
    def _upper_body(character, names: tuple[str, ...]) -> tuple[str | None, np.ndarray]:
        """The highest tracked torso joint (``chest``, else ``spine``) and the indices of the
        targets whose canonical ancestors include it (neck, head, clavicles, arms);
        ``(None, [])`` without either."""
        torso = next((t for t in ("chest", "spine") if t in names and t in character.tracked), None)
        if torso is None:
            return None, np.zeros(0, dtype=int)
        present = set(names)
        upper = []
        for i, n in enumerate(names):
            p = canonical_parent(n, present)
            while p is not None and p != torso:
                p = canonical_parent(p, present)
            if p == torso:
                upper.append(i)
        return torso, np.array(upper, dtype=int)

    def _follow_chest(self, positions: np.ndarray) -> np.ndarray:
        r"""``positions`` with the upper-body targets moved by the chest's lag: with
        :math:`e` the low-passed offset of the character's chest from its target up to
        the previous frame (:data:`CHEST_LAG_TIME`), the targets above the chest move by
        :math:`e\,(1 - f/|e|)` where :math:`|e| > f` (:data:`CHEST_LAG_FREE`), so the arms
        keep their pose relative to a torso that cannot reach its target (a new array;
        ``SolverOptions.upper_body_follows_chest``)."""
        if self._chest is None or not self.solver.options.upper_body_follows_chest or not self._upper.size:
            return positions
        out = np.array(positions, dtype=float, copy=True)
        lag = self._chest_lag
        n = float(np.linalg.norm(lag))
        if n > CHEST_LAG_FREE:
            out[self._upper] += lag * (1.0 - CHEST_LAG_FREE / n)
        return out

    def _measure_chest(self, positions: np.ndarray, valid: np.ndarray) -> None:
        r"""Update the low-passed offset of the chest from its (unmoved) target after this
        frame's solve (the first-order filter :math:`e \leftarrow e + a (x - T - e)`,
        :math:`a = 1 - e^{-1/(\tau f)}`)."""
        i = None if self._chest is None else self.names.index(self._chest)
        if i is None or not bool(valid[i]):
            self._chest_lag = np.zeros(3)
            return
        tracked = self.character.tracked[self._chest]
        data = self.solver.configuration.data
        x = data.site(tracked.name).xpos if tracked.kind == "site" else data.body(tracked.name).xpos
        a = 1.0 - np.exp(-1.0 / (CHEST_LAG_TIME * self.fps))
        self._chest_lag = self._chest_lag + a * (np.asarray(x, dtype=float) - positions[i] - self._chest_lag)

    def restart_contacts(self) -> None:
        """Forget every anchor and lock (a stream calibrating again); the pose is kept."""
        plant = self.plant_options
        self.planting = (
            Planting(self.character, self.names, self.fps, plant, floor=self.solver.options.floor_height, anchored=self.anchored)
            if plant is not None and plant.plant
            else None
        )

    def solve(
        self,
        positions: np.ndarray,
        orientations: np.ndarray,
        valid: np.ndarray,
        labels: Mapping[str, bool] | None = None,
    ) -> FrameResult:
        """Retarget the next frame.

        Args:
            positions: ``(N, 3)`` target positions (metres).
            orientations: ``(N, 4)`` target orientations (x-y-z-w).
            valid: ``(N,)`` which targets are tracked on this frame.
            labels: Contact label -> in contact on this frame (``left_heel``,
                ``left_toe``, ``right_heel``, ``right_toe``); None: no planting.
        """
        t0 = time.perf_counter()
        first = self.frame == 0
        solver = self.solver
        given = positions
        positions = self._follow_chest(positions)
        if self.planting is None or labels is None:
            q, iterations, level = solver.solve_frame(positions, orientations, valid, first=first)
        else:
            if first:  # converge on the targets alone, then plant the feet where they are
                solver.solve_frame(positions, orientations, valid, first=True)
                solver.forget_previous()
            shifted, tasks, hard, _ = self.planting.step(positions, labels, solver.configuration.data)
            holds = ContactHolds(
                tuple(tasks), tuple(hard), self.planting.clearance_sites(), self.planting.clearance_bodies()
            )
            q, iterations, level = solver.solve_frame(shifted, orientations, valid, holds=holds)
        self._measure_chest(given, valid)
        self.frame += 1
        return FrameResult(q.copy(), int(iterations), int(level), time.perf_counter() - t0)
