"""Streaming retargeting: one source frame in, the character's pose out, causally.

A :class:`StreamingRetargeter` serves one tracked actor on one character.
Everything it does looks only at the current frame and a short, bounded past:

* **Calibration on the first frame** (on frame 1 if frame 0 turns out to be a
  reference pose the capture jumps away from, as offline retargeting skips it).
  The target builder's one-time
  quantities (root scale, facing, orientation offsets, root start, floor and
  ankle heights; :class:`~physmocap.ik.targets.Calibration`) come from the
  skeleton's rest pose (rotational sources) and the first frame; the floor is
  the lowest foot point of the first frame unless given (``floor=``).  Offline
  retargeting estimates the floor from the whole clip instead.
* **Targets per frame** with the same maths as offline
  (:func:`~physmocap.ik.targets.build_targets` with the calibration reused).
* **Contacts** from :class:`~physmocap.ik.contacts.ContactStream`: a look-behind
  of a few tens of milliseconds; its labels lag offline detection's
  back-dated ones by about 50 ms.
* **Planting** (:class:`~physmocap.ik.planting.Planting`) and the per-frame IK
  (:class:`~physmocap.ik.solver.FrameSolver`) are causal already and are the
  very objects offline retargeting uses.

Tracker frames with missing joints go through the causal gap filler
(:class:`~physmocap.sources.gaps.CausalGapFiller`): short gaps hold the last
value with the joint's task off; nothing non-finite reaches the IK.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from ..errors import InputError, MappingError, OptionError, warn
from ..motion import Motion, Skeleton
from ..trajectory import Trajectory
from .contacts import ContactOptions, ContactStream, FloorPlane, contact_points
from .planting import Planting
from .retarget import map_motion, plant_options, split_options
from .solver import FrameSolver
from .targets import build_targets

__all__ = ["StreamingRetargeter", "stream_motion"]


class StreamingRetargeter:
    """Causal frame-by-frame retargeter for one actor and one character.

    Args:
        character: A :class:`~physmocap.models.Character` (or a path / bundled
            name; None = the default humanoid).
        skeleton: The source skeleton (names, parents, rest offsets).
        fps: The source frame rate.
        joint_indices: Canonical joint -> source joint index (default: the
            naming profiles, or ``profile`` / ``mapping``).
        floor: The actor's floor height in the source world (metres); None
            takes it from the first frame.
        contact_options: Contact thresholds.
        **options: Target, solver and planting options, as for
            :func:`~physmocap.ik.retarget.retarget`.

    Feed frames with :meth:`step`; it returns the character's ``qpos`` (a copy).
    """

    def __init__(
        self,
        character=None,
        *,
        skeleton: Skeleton,
        fps: float,
        joint_indices: dict[str, int] | None = None,
        profile: str | None = None,
        mapping=None,
        floor: float | None = None,
        contact_options: ContactOptions | None = None,
        translated: np.ndarray | None = None,
        source: str = "<stream>",
        **options: Any,
    ) -> None:
        from ..models import load_character

        if character is None or isinstance(character, (str, bytes)) or hasattr(character, "__fspath__"):
            character = load_character(character)
        if not (np.isfinite(fps) and fps > 0):
            raise OptionError(f"fps must be positive, got {fps}")
        self.character = character
        self.skeleton = skeleton
        self.fps = float(fps)
        self.translated = np.zeros(0, dtype=np.int64) if translated is None else np.asarray(translated, dtype=np.int64)
        # a live frame has a deadline: fewer clean-up iterations than offline by default
        options.setdefault("max_iterations", 3)
        options.setdefault("floor_iterations", 2)
        options.setdefault("constraint_tolerance", 1e-4)
        self.target_options, self.solver_options, rest = split_options(options)
        self.plant_options, rest = plant_options(rest)
        if rest:
            raise OptionError(f"unknown streaming option(s) {sorted(rest)}")
        if self.target_options.source_floor is None and floor is not None:
            self.target_options.source_floor = float(floor)
        self.contact_options = contact_options
        self.source = str(source)
        self._profile, self._mapping = profile, mapping
        self.joint_indices = None if joint_indices is None else dict(joint_indices)
        self.points: dict[str, int] = {}
        self.frame = 0
        self.calibration = None
        self.solver: FrameSolver | None = None
        self.planting: Planting | None = None
        self.contacts: ContactStream | None = None
        self.latencies: list[float] = []
        #: mean joint speed (m/s) into frame 1 above which frame 0 is taken for a reference pose
        self.reference_speed = 4.0
        self._first_world: np.ndarray | None = None
        self.labels: list[dict[str, bool]] = []

    # -- input ----------------------------------------------------------------
    def _motion(self, rotations, translations, positions, confidence) -> Motion:
        J = self.skeleton.num_joints
        if positions is not None:
            pos = np.asarray(positions, dtype=float).reshape(1, J, 3)
            conf = None if confidence is None else np.asarray(confidence, dtype=float).reshape(1, J)
            if not np.all(np.isfinite(pos)):
                ok = np.all(np.isfinite(pos), axis=-1)
                conf = np.where(ok, 1.0 if conf is None else conf, 0.0)
                pos = np.where(ok[..., None], pos, 0.0)
            return Motion(self.skeleton, self.fps, positions=pos, confidence=conf, source=self.source)
        if rotations is None:
            raise InputError("a frame needs rotations (rotational sources) or positions", frame=self.frame)
        rot = np.asarray(rotations, dtype=float).reshape(1, J, 4)
        K = len(self.translated)
        tr = np.zeros((1, K, 3)) if translations is None else np.asarray(translations, dtype=float).reshape(1, K, 3)
        if not (np.all(np.isfinite(rot)) and np.all(np.isfinite(tr))):
            raise InputError("non-finite rotation or translation", frame=self.frame)
        return Motion(
            self.skeleton, self.fps, rotations=rot, translations=tr, translated=self.translated, source=self.source
        )

    # -- the loop ---------------------------------------------------------------
    def _start(self, motion: Motion, keep_solver: bool = False) -> None:
        if self.joint_indices is None:  # names first, the first frame's shape if needed
            try:
                self.joint_indices = map_motion(motion, profile=self._profile, mapping=self._mapping)
            except MappingError as exc:
                raise MappingError(exc.message, path=self.source) from None
        self.points = contact_points(self.joint_indices)
        targets = build_targets(motion, self.joint_indices, self.character, self.target_options)
        self.calibration = targets.calibration
        floor = self.calibration.floor
        world = motion.world_positions()[0]
        # stance level of each point above the floor: its first-frame height, the
        # lower of the two feet (the first frame may be mid-stride)
        heights = {p: float(world[j, 2] - floor) for p, j in self.points.items()}
        levels = {}
        for p, h in heights.items():
            other = ("right_" + p[5:]) if p.startswith("left_") else ("left_" + p[6:])
            levels[p] = max(0.0, min(h, heights.get(other, h)))
        self.contacts = ContactStream(
            list(self.points), self.fps, FloorPlane(height=floor, levels=levels), self.contact_options
        )
        if not (keep_solver and self.solver is not None and self.solver.names == targets.names):
            self.solver = FrameSolver(
                self.character, targets.names, targets.has_orientation, self.fps, self.solver_options
            )
        self.planting = Planting(
            self.character, targets.names, self.fps, self.plant_options, floor=self.solver.options.floor_height
        )

    def step(
        self,
        rotations: np.ndarray | None = None,
        translations: np.ndarray | None = None,
        positions: np.ndarray | None = None,
        confidence: np.ndarray | None = None,
    ) -> np.ndarray:
        """Retarget one frame; returns the character's ``qpos`` ``(nq,)``.

        Args:
            rotations: ``(J, 4)`` local rotations x-y-z-w (rotational sources).
            translations: ``(K, 3)`` local translations of the translated joints.
            positions: ``(J, 3)`` world positions in metres, Z-up (positional sources).
            confidence: ``(J,)`` per-joint confidence for positions.
        """
        t0 = time.perf_counter()
        motion = self._motion(rotations, translations, positions, confidence)
        first = self.frame == 0
        fk = motion.forward_kinematics()
        if self.frame == 1 and self._first_world is not None:
            # frame 0 was a reference pose (a T-pose the capture jumps away from): calibrate again here
            jump = float(np.nanmean(np.linalg.norm(fk[0][0] - self._first_world, axis=-1)))
            if np.isfinite(jump) and jump * self.fps > self.reference_speed:
                warn(
                    f"{self.source}: frame 0 looks like a reference pose (the joints jump {jump * 100:.0f} cm "
                    f"into frame 1): calibrated again on frame 1"
                )
                # new calibration; the solver carries on (velocity limits hold across)
                self._start(motion, keep_solver=True)
        if first:
            self._start(motion)
            self._first_world = fk[0][0].copy()
        elif self.frame == 1:
            self._first_world = None
        assert self.solver is not None and self.planting is not None and self.contacts is not None
        targets = build_targets(
            motion, self.joint_indices, self.character, calibration=self.calibration, kinematics=fk
        )
        world = fk[0][0]
        labels = self.contacts.step(np.array([world[j] for j in self.points.values()]))
        solver = self.solver
        if first:
            solver.set_targets(targets.positions[0], targets.orientations[0], targets.valid[0])
            solver.solve_frame(first=True)
            solver.q_prev = None
        pos = targets.positions[0]
        if self.plant_options.plant:
            pos, solver.extra_tasks, solver.constraints, _ = self.planting.step(
                targets.positions[0], labels, solver.configuration.data
            )
            solver.set_clearance(self.planting.clearance_sites(), self.planting.clearance_bodies())
        solver.set_targets(pos, targets.orientations[0], targets.valid[0])
        q, _, _ = solver.solve_frame(first=False)
        self.frame += 1
        self.labels.append(labels)
        self.latencies.append(time.perf_counter() - t0)
        return q.copy()


def stream_motion(motion: Motion, character=None, **options: Any) -> Trajectory:
    """Feed a whole motion through a :class:`StreamingRetargeter` frame by frame
    (what ``physmocap replay`` does as fast as possible); returns the trajectory
    with per-frame latencies in ``stats["latency"]`` (seconds)."""
    retargeter = StreamingRetargeter(
        character,
        skeleton=motion.skeleton,
        fps=motion.fps,
        translated=motion.translated,
        floor=options.pop("floor", motion.meta.get("floor_z")),
        mapping=options.pop("mapping", None) or motion.meta.get("source_mapping"),
        source=motion.source,
        **options,
    )
    qpos = np.empty((motion.num_frames, retargeter.character.model.nq))
    for t in range(motion.num_frames):
        if motion.is_rotational:
            assert motion.rotations is not None and motion.translations is not None
            qpos[t] = retargeter.step(rotations=motion.rotations[t], translations=motion.translations[t])
        else:
            assert motion.positions is not None
            conf = None if motion.confidence is None else motion.confidence[t]
            qpos[t] = retargeter.step(positions=motion.positions[t], confidence=conf)
    return Trajectory(
        character=retargeter.character,
        qpos=qpos,
        fps=motion.fps,
        source=motion.source,
        stats={"latency": np.array(retargeter.latencies), "labels": retargeter.labels},
    )
