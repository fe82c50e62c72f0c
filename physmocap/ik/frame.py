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

from .planting import PlantOptions, Planting
from .solver import ContactHolds, FrameSolver, SolverOptions

__all__ = ["FrameResult", "FrameRetargeter"]


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
        self.restart_contacts()

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
        self.frame += 1
        return FrameResult(q.copy(), int(iterations), int(level), time.perf_counter() - t0)
