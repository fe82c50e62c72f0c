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

import dataclasses
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Mapping, Sequence

import mujoco
import numpy as np

from ..canonical import canonical_parent
from .planting import PlantOptions, Planting
from .solver import ContactHolds, FrameSolver, SolverOptions

if TYPE_CHECKING:
    from .branches import Guide

__all__ = ["FrameResult", "FrameRetargeter", "PELVIS_LAG_FREE", "PELVIS_LAG_TIME"]

#: Metres of the pelvis's lag behind its target that the upper body does *not* follow:
#: ordinary tracking error, left to the arms' own tasks (following every centimetre fed
#: the solver's frame-to-frame fluctuations back into the arms: measured on a first version
#: that followed the chest, the Bandai walk's joint acceleration rose 28 %).  Both constants
#: were chosen on the shared clips (issue 13's G1 walk against the humanoid's figures).
PELVIS_LAG_FREE = 0.02
#: Seconds: time constant of the low-pass on the pelvis's lag that the upper body follows.
PELVIS_LAG_TIME = 0.05


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
        self.has_orientation = np.asarray(has_orientation, dtype=bool)
        self.plant_options = plant
        self.anchored = bool(anchored)
        self.planting: Planting | None = None
        self.frame = 0
        self._upper = self._upper_body(character, self.names)
        #: ``(3,)`` the pelvis's low-passed offset from its target up to the previous frame (metres)
        self._lag = np.zeros(3)
        #: ``(target index, the pelvis's world position (a view of the solver's data), low-pass
        #: gain)`` for :meth:`_measure_lag`, or None when the upper body has nothing to follow
        self._pelvis: tuple[int, np.ndarray, float] | None = None
        if "pelvis" in self.names and self._upper.size:
            tracked = character.tracked["pelvis"]
            x = tracked.position(character.model, self.solver.configuration.data)
            self._pelvis = (self.names.index("pelvis"), x, 1.0 - np.exp(-1.0 / (PELVIS_LAG_TIME * self.fps)))
        #: the followed pass's answer on the last frame (``(nq,)``; a guide that follows
        #: another pass, :attr:`~physmocap.ik.branches.Guide.follow`), or None
        self._followed: np.ndarray | None = None
        self.restart_contacts()

    @staticmethod
    def _upper_body(character, names: tuple[str, ...]) -> np.ndarray:
        """Indices of the targets above the highest tracked torso joint (``chest``, else
        ``spine``): neck, head, clavicles, arms; empty without either."""
        torso = next((t for t in ("chest", "spine") if t in names and t in character.tracked), None)
        if torso is None:
            return np.zeros(0, dtype=int)
        present = set(names)
        upper = []
        for i, n in enumerate(names):
            p = canonical_parent(n, present)
            while p is not None and p != torso:
                p = canonical_parent(p, present)
            if p == torso:
                upper.append(i)
        return np.array(upper, dtype=int)

    def _follow_pelvis(self, positions: np.ndarray) -> np.ndarray:
        r"""``positions`` with the upper-body targets moved by the body's lag: with
        :math:`e` the low-passed offset of the character's pelvis from its target up to
        the previous frame (:data:`PELVIS_LAG_TIME`), the targets above the chest move by
        :math:`e\,(1 - f/|e|)` where :math:`|e| > f` (:data:`PELVIS_LAG_FREE`), so the arms
        keep their pose relative to a body that cannot reach its target (a new array;
        ``SolverOptions.upper_body_follows_pelvis``)."""
        if not self.solver.options.upper_body_follows_pelvis or not self._upper.size:
            return positions
        n = float(np.linalg.norm(self._lag))
        if n <= PELVIS_LAG_FREE:
            return positions
        out = np.array(positions, dtype=float, copy=True)
        out[self._upper] += self._lag * (1.0 - PELVIS_LAG_FREE / n)
        return out

    def _measure_lag(self, positions: np.ndarray, valid: np.ndarray) -> None:
        r"""Update the low-passed offset :math:`e` of the pelvis from the target the solver was
        given (after the planting's shift: a stream's body following its planted feet is not
        a lag) after this frame's solve: :math:`e \leftarrow e + a (x - T - e)`, :math:`a = 1 - e^{-1/(\tau f)}`."""
        if self._pelvis is None:
            return
        i, x, a = self._pelvis
        if not bool(valid[i]):
            self._lag = np.zeros(3)
            return
        self._lag = self._lag + a * (x - positions[i] - self._lag)

    def restart_contacts(self) -> None:
        """Forget every anchor and lock (a stream calibrating again); the pose is kept."""
        plant = self.plant_options
        self.planting = (
            Planting(self.character, self.names, self.fps, plant, floor=self.solver.options.floor_height,
                     anchored=self.anchored, has_orientation=self.has_orientation)
            if plant is not None and plant.plant
            else None
        )

    def carried(self, guide: Guide | None) -> Guide | None:
        r"""``guide`` with its start moved by this pass's offset from the pass it follows
        (:attr:`~physmocap.ik.branches.Guide.follow`) on the previous frame,
        :math:`p_t \oplus (q_{t-1} \ominus p_{t-1})`, :math:`p` that pass's answers and
        :math:`q` this pass's (radians, metres; :func:`mujoco.mj_differentiatePos`, so a free
        joint's rotation is carried on its quaternion): where the two passes differ by an
        offset that changes slowly (a foot held a millimetre from where the earlier pass
        held it), the iterations start at the answer instead of one step from it.  ``guide``
        itself where it follows no pass or on the first frame that does."""
        q, p = self.solver.q_prev, self._followed
        if guide is None or not guide.follow or q is None or p is None:
            return guide
        model = self.character.model
        v = np.empty(model.nv)
        mujoco.mj_differentiatePos(model, v, 1.0, p, q)
        start = np.array(guide.start, dtype=float)
        mujoco.mj_integratePos(model, start, v, 1.0)
        return dataclasses.replace(guide, start=start)

    def _solve_guided(self, positions: np.ndarray, orientations: np.ndarray, valid: np.ndarray,
                      holds: ContactHolds | None, guide: Guide | None,
                      first: bool = False) -> tuple[np.ndarray, int, int]:
        """:meth:`~physmocap.ik.solver.FrameSolver.solve_frame` with the guide's start
        :meth:`carried`; keeps the followed pass's answer on this frame for the next."""
        out = self.solver.solve_frame(positions, orientations, valid, holds=holds, first=first, guide=self.carried(guide))
        self._followed = np.array(guide.start, dtype=float) if guide is not None and guide.follow else None
        return out

    def solve(
        self,
        positions: np.ndarray,
        orientations: np.ndarray,
        valid: np.ndarray,
        labels: Mapping[str, bool] | None = None,
        guide=None,
    ) -> FrameResult:
        """Retarget the next frame.

        Args:
            positions: ``(N, 3)`` target positions (metres).
            orientations: ``(N, 4)`` target orientations (x-y-z-w).
            valid: ``(N,)`` which targets are tracked on this frame.
            labels: Contact label -> in contact on this frame (``left_heel``,
                ``left_toe``, ``right_heel``, ``right_toe``); None: no planting.
            guide: A posture pull for this frame (:class:`~physmocap.ik.branches.Guide`;
                offline second passes), or None.
        """
        t0 = time.perf_counter()
        first = self.frame == 0
        solver = self.solver
        positions = self._follow_pelvis(positions)
        aimed = positions  # the targets the solver is given (streaming: shifted onto the planted feet)
        if self.planting is None or labels is None:
            q, iterations, level = self._solve_guided(positions, orientations, valid, None, guide, first)
        else:
            if first:  # converge on the targets alone, then plant the feet where they are
                solver.solve_frame(positions, orientations, valid, first=True)
                solver.forget_previous()
            shifted, tasks, hard, _ = self.planting.step(positions, labels, solver.configuration.data, valid=valid,
                                                         orientations=orientations)
            holds = ContactHolds(
                tuple(tasks), tuple(hard), self.planting.clearance_sites(), self.planting.clearance_bodies()
            )
            q, iterations, level = self._solve_guided(shifted, orientations, valid, holds, guide)
            aimed = shifted
        self._measure_lag(aimed, valid)
        self.frame += 1
        return FrameResult(q.copy(), int(iterations), int(level), time.perf_counter() - t0)
