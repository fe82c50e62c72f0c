"""Streaming retargeting: one source frame in, the character's pose out, causally.

A :class:`StreamingRetargeter` serves one tracked actor on one character.
Everything it does looks only at the current frame and a short, bounded past:

* **Calibration on the first frame** (on frame 1 if frame 0 turns out to be a
  reference pose the capture jumps away from, as offline retargeting skips it).
  The target builder's one-time
  quantities (root scale, facing, orientation offsets, root start, floor and
  ankle heights; :class:`~physmocap.ik.targets.Calibration`) come from the
  skeleton's rest pose (rotational sources) and the first frame; the floor is
  the lowest foot point of the first frame unless given (``source_floor``).  Offline
  retargeting estimates the floor from the whole clip instead.
* **Targets per frame** with the same maths as offline
  (:func:`~physmocap.ik.targets.build_targets` with the calibration reused).
* **Contacts** from :class:`~physmocap.ik.contacts.ContactStream`: a look-behind
  of a few tens of milliseconds; its labels lag offline detection's
  back-dated ones by about 50 ms.
* **Feet levelled** where the actor stands flat
  (:class:`~physmocap.ik.footlevel.FootLeveller`, the causal counterpart of the
  offline :func:`~physmocap.ik.footlevel.level_feet`): each foot's correction is
  learnt from the flat-stance frames seen so far and eased in after the first
  0.1 s of stance; the toe tips keep the actor's (offline levels them too), and
  a skeleton whose zero-length toe ends offline retargeting extends
  (:mod:`~physmocap.ik.toetips`) keeps them.
* **The per-frame pipeline** (:class:`~physmocap.ik.frame.FrameRetargeter`:
  planting, then the IK) is the one offline retargeting runs, with causal
  anchoring of the feet (offline plans them over the whole clip instead).
  Knees, hands and the pelvis on the floor are detected causally
  (:class:`~physmocap.ik.body_contacts.BodyContactStream`) and held where they
  touch down, eased in and faded out
  (:class:`~physmocap.ik.body_contacts.BodyContactAnchor`), where offline plans
  each contact over its whole interval.
* **Arms stuck on the wrong branch** of their joint ranges
  (:class:`~physmocap.ik.armswitch.ArmSwitch`, ``arm_branches``): an arm found
  more than 30 degrees off the actor's on a branch that cannot reach it, while
  another branch can, is pulled over at its joints' velocity limits (offline
  guides it over, in a second pass, where the two branches meet).

Tracker frames with missing joints go through the causal gap filler
(:class:`~physmocap.sources.gaps.CausalGapFiller`): short gaps hold the last
value with the joint's task off; nothing non-finite reaches the IK.
"""

from __future__ import annotations

import math
import time
from dataclasses import replace
from typing import Any

import numpy as np

from ..errors import InputError, MappingError, OptionError, warn
from ..motion import Motion, Skeleton
from ..trajectory import SolverStats, Trajectory
from .armswitch import ArmSwitch
from .config import RetargetConfig
from .body_contacts import BodyContactAnchor, BodyContactStream, release_kneeling_feet
from .contacts import ContactStream, Contacts, FloorPlane, contact_points
from .footlevel import FootLeveller
from .footplan import body_part_target
from .frame import FrameRetargeter
from .retarget import map_motion
from .targets import Targets, build_targets, character_rest_frames
from .trunkreach import trunk_reach

__all__ = ["StreamingRetargeter", "stream_motion", "STREAMING_DEFAULTS", "streaming_config", "streaming_iterations"]

#: A live frame has a deadline: fewer floor clean-up iterations and a looser constraint
#: tolerance than offline by default (applied when no ``config`` is given).  Eight IK
#: iterations a frame with the smoothness prior: with three (and the prior off: the feet did
#: not settle against it) the stream followed the actor less closely than offline, worst
#: segment medians 10.5-18.5 degrees, and with eight alone joints sat at their velocity caps
#: (PyMO walk 39 % of frames).  Against three iterations without the prior, on the shared
#: clips: PyMO walk worst segment 11.3 -> 7.1 degrees (robot 18.5 -> 8.2), Bandai walk 11.4 ->
#: 7.9 (10.8 -> 8.6), flat-foot frames with a site over 1 cm up 30.7 -> 1.4 % on the Bandai
#: walk, 14.2 -> 1.1 % on the PyMO walk; 10-30 % more CPU time (149-367 frames/s on one core).
#: No ``catch_up`` (offline's second round of iterations on a frame far from its targets): it
#: doubles a live frame's worst case (CMU walk latency p99 8.4 -> 15.1 ms) for little gain on
#: the stream (Bandai punch facing p95 8.0 -> 3.7 degrees, the walks and jumps unchanged).
#: A held foot is turned with the actor's only past 10 degrees of heading error
#: (``pivot_threshold``; offline 2): a stream cannot tell a capture's heading wobble from the
#: start of a pivot, and following every wobble swivelled flat feet on the floor (with 2
#: degrees, foot slip on the dance 1.13 cm/s, geom slip on the PyMO walk 3.4; with 10, 0.44
#: and 0.82), while the turns that matter are tens of degrees (CMU jumps: facing p95 105 -> 0.5).
STREAMING_DEFAULTS = {"max_iterations": 8, "floor_iterations": 2, "constraint_tolerance": 1e-4, "smoothness_cost": 0.5,
                      "catch_up": 0.0, "pivot_threshold": math.radians(10.0)}

#: m/s: how fast the targets' height follows the stance levels the stream learns
#: (:meth:`StreamingRetargeter._follow_stance_levels`): a first frame 4.5 cm above stance
#: is made good in 0.45 s, the body rising with it.
STANCE_LEVEL_SPEED = 0.1

#: Hz.  ``STREAMING_DEFAULTS["max_iterations"]`` is the budget of a frame at this rate; at a
#: lower rate a frame gets as many more as keep the same iterations per second of motion
#: (:func:`streaming_config`), up to :data:`STREAMING_MAX_ITERATIONS`.  Between two 30 fps
#: frames the targets move four times as far as at 120 Hz, and eight iterations did not
#: reach them: the streamed pelvis fell 5-7 cm behind its target through every stance and
#: caught up in one frame (docs/history.md, stop 36).
STREAMING_REFERENCE_RATE = 120.0
#: The most IK iterations a streamed frame gets by default, whatever its rate (a bound on
#: a slow source's worst-case latency; 30 fps gets 32).
STREAMING_MAX_ITERATIONS = 48


def streaming_iterations(fps: float) -> int:
    r"""Default IK iterations a frame for a stream at ``fps`` (frames/s):
    :math:`\min(M, \max(n, \lceil n\,f_0 / f \rceil))` with :math:`n` the budget at the
    reference rate :math:`f_0` (:data:`STREAMING_REFERENCE_RATE`) and :math:`M` =
    :data:`STREAMING_MAX_ITERATIONS`: the same iterations per second of motion as at
    :math:`f_0`, never fewer than :math:`n` a frame."""
    n = int(STREAMING_DEFAULTS["max_iterations"])
    if not (math.isfinite(fps) and fps > 0):
        return n  # no rate to scale by (the retargeter refuses it, naming it)
    need = math.ceil(n * STREAMING_REFERENCE_RATE / float(fps) - 1e-9)
    return int(min(STREAMING_MAX_ITERATIONS, max(n, need)))


def streaming_config(fps: float) -> RetargetConfig:
    """The default configuration of a stream at ``fps``: :data:`STREAMING_DEFAULTS` with
    :func:`streaming_iterations` a frame."""
    return RetargetConfig().with_options(**{**STREAMING_DEFAULTS, "max_iterations": streaming_iterations(fps)})


class StreamingRetargeter:
    """Causal frame-by-frame retargeter for one actor and one character.

    Args:
        character: A :class:`~physmocap.models.Character` (or a path / bundled
            name; None = the default humanoid).
        config: The :class:`~physmocap.ik.config.RetargetConfig`; None takes the
            defaults with :data:`STREAMING_DEFAULTS` (:func:`streaming_config`: more
            iterations a frame below 120 frames/s).  ``config.targets.source_floor``
            is the actor's floor in the source world (metres); None takes it from
            the first frame.
        skeleton: The source skeleton (names, parents, rest offsets).
        fps: The source frame rate.
        joint_indices: Canonical joint -> source joint index (default: the
            naming profiles, or ``profile`` / ``mapping``).
        **options: Flat option names applied on top of ``config``, as for
            :func:`~physmocap.ik.retarget.retarget`.

    Feed frames with :meth:`step`; it returns the character's ``qpos`` (a copy).
    """

    def __init__(
        self,
        character=None,
        config: RetargetConfig | None = None,
        *,
        skeleton: Skeleton,
        fps: float,
        joint_indices: dict[str, int] | None = None,
        profile: str | None = None,
        mapping=None,
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
        if config is None:
            config = streaming_config(self.fps)
        self.config = config.with_options(**options) if options else config
        self.source = str(source)
        self._profile, self._mapping = profile, mapping
        self.joint_indices = None if joint_indices is None else dict(joint_indices)
        self.points: dict[str, int] = {}
        self.frame = 0
        self.calibration = None
        self.pipeline: FrameRetargeter | None = None
        self.contacts: ContactStream | None = None
        self.leveller: FootLeveller | None = None
        self.body_contacts: BodyContactStream | None = None
        self.body_anchors: dict[str, BodyContactAnchor] = {}
        self.latencies: list[float] = []
        self.arms: ArmSwitch | None = None
        self._ankle_start: float | None = None
        self._last_qpos: np.ndarray | None = None
        self.iterations: list[int] = []
        self.relaxations: list[int] = []
        #: mean joint speed (m/s) into frame 1 above which frame 0 is taken for a reference pose
        self.reference_speed = 4.0
        self._first_world: np.ndarray | None = None
        self.labels: list[dict[str, bool]] = []
        #: The last frame's targets as the IK got them (feet levelled, body contacts held): one
        #: frame of :class:`~physmocap.ik.targets.Targets` (None before the first frame).
        self.last_targets: Targets | None = None
        # what depends on the character alone is worked out here, before the first frame
        # (the trunk's reach: tens of milliseconds), not in the first frame's latency
        trunk_reach(self.character)

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
        targets = build_targets(motion, self.joint_indices, self.character, self.config.targets)
        self.calibration = targets.calibration
        self._ankle_start = float(self.calibration.ankle_actor)
        self.calibration.restart_twists()  # step() gives this frame again: learnt once
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
            list(self.points), self.fps, FloorPlane(height=floor, levels=levels), self.config.contacts
        )
        self.leveller = FootLeveller(
            targets.names, targets.has_orientation, character_rest_frames(self.character), self.fps,
            self.config.plant.ease_time,
        )
        canonical = {c: world[j][None] for c, j in self.joint_indices.items()}
        self.body_contacts = BodyContactStream.for_actor(canonical, self.fps, FloorPlane(height=floor), self.config.body_contacts)
        self.body_anchors = {
            part: BodyContactAnchor(
                self.fps, release_time=self.config.plant.anchor_release_time, floor=self.config.solver.floor_height
            )
            for part in self.body_contacts.parts
        }
        self.arms = (ArmSwitch(self.character, targets.names, targets.has_orientation, self.fps, self.config.solver.weights)
                     if self.config.solver.arm_branches else None)
        if keep_solver and self.pipeline is not None and self.pipeline.names == targets.names:
            self.pipeline.restart_contacts()  # a new calibration; the pose and velocity bounds carry on
        else:
            self.pipeline = FrameRetargeter(
                self.character,
                targets.names,
                targets.has_orientation,
                self.fps,
                self.config.solver,
                self.config.plant,
                anchored=True,
            )

    def step(
        self,
        rotations: np.ndarray | None = None,
        translations: np.ndarray | None = None,
        positions: np.ndarray | None = None,
        confidence: np.ndarray | None = None,
        index: int | None = None,
    ) -> np.ndarray:
        """Retarget one frame; returns the character's ``qpos`` ``(nq,)``.

        Args:
            rotations: ``(J, 4)`` local rotations x-y-z-w (rotational sources).
            translations: ``(K, 3)`` local translations of the translated joints.
            positions: ``(J, 3)`` world positions in metres, Z-up (positional sources).
            confidence: ``(J,)`` per-joint confidence for positions.
            index: The frame's number in the source, for messages (default: the number of
                frames stepped before it; a caller that drops late frames gives it).
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
                    f"into frame {self.frame if index is None else index}, the next one streamed): calibrated "
                    f"again there"
                )
                # new calibration; the solver carries on (velocity limits hold across)
                self._start(motion, keep_solver=True)
        if first:
            self._start(motion)
            self._first_world = fk[0][0].copy()
        elif self.frame == 1:
            self._first_world = None
        assert self.pipeline is not None and self.contacts is not None
        targets = build_targets(
            motion, self.joint_indices, self.character, self.config.targets, calibration=self.calibration, kinematics=fk
        )
        world = fk[0][0]
        labels = self.contacts.step(np.array([world[j] for j in self.points.values()]))
        self._follow_stance_levels()
        assert self.leveller is not None
        positions, orientations = self.leveller.step(targets.positions[0], targets.orientations[0], labels)
        assert self.body_contacts is not None
        body = self.body_contacts.step({c: world[j] for c, j in self.joint_indices.items()})
        if self.body_anchors:
            positions, labels = self._hold_body_parts(positions, targets.names, labels, body)
        guide = None
        if self.arms is not None:
            guide = self.arms.guide(self._last_qpos, positions, orientations, targets.valid[0])
        result = self.pipeline.solve(positions, orientations, targets.valid[0], labels, guide)
        self._last_qpos = result.qpos
        self.last_targets = replace(targets, positions=np.array(positions)[None], orientations=np.array(orientations)[None],
                                    source_positions=None, source_recipe=None, calibration=None)
        self.frame += 1
        self.labels.append(labels)
        self.iterations.append(result.iterations)
        self.relaxations.append(result.relaxation)
        self.latencies.append(time.perf_counter() - t0)
        return result.qpos

    def _follow_stance_levels(self) -> None:
        """Move the calibration's ankle height in stance (the height the targets stand the
        actor's ankles on the character's: :class:`~physmocap.ik.targets.Calibration`) by
        as much as the contact stream's learnt heel levels have come down from the first
        frame's (:class:`~physmocap.ik.contacts.StanceLevels`), at most
        :data:`STANCE_LEVEL_SPEED` a second of target height."""
        assert self.contacts is not None and self.calibration is not None
        heels = [i for i, p in enumerate(self.contacts.points) if p.endswith("_heel")]
        if not heels or self._ankle_start is None:
            return
        stance = self.contacts.stance
        want = self._ankle_start - float(np.mean(stance.start[heels] - stance.levels[heels]))
        cal = self.calibration
        step = STANCE_LEVEL_SPEED / (self.fps * max(float(cal.scale), 1e-6))
        cal.ankle_actor = float(cal.ankle_actor + np.clip(want - cal.ankle_actor, -step, step))

    def _hold_body_parts(
        self, positions: np.ndarray, names: tuple[str, ...], labels: dict[str, bool], body: dict[str, bool]
    ) -> tuple[np.ndarray, dict[str, bool]]:
        """Targets with knees, hands and pelvis held on the floor while in contact
        (:class:`~physmocap.ik.body_contacts.BodyContactAnchor`, the causal counterpart of
        the offline plan), and the foot labels of a kneeling leg cleared; the knee labels
        ride along so the planting leaves a kneeling knee's target alone."""
        out = np.array(positions, dtype=float, copy=True)
        col = {n: i for i, n in enumerate(names)}
        for part, anchor in self.body_anchors.items():
            held = body_part_target(positions, col, part)
            if held is not None:
                idx, point = held
                out[idx] += anchor.step(bool(body.get(part, False)), point)
        labels = release_kneeling_feet(labels, body)
        for side in ("left", "right"):
            if body.get(f"{side}_knee", False):
                labels[f"{side}_knee"] = True
        return out, labels


def stream_motion(motion: Motion, character=None, config: RetargetConfig | None = None, **options: Any) -> Trajectory:
    """Feed a whole motion through a :class:`StreamingRetargeter` frame by frame
    (what ``physmocap replay`` does as fast as possible).

    The actor's floor is ``config.targets.source_floor`` (or the
    ``source_floor`` option), else the recording's own (``floor_z`` in its
    metadata), else the first frame's.  Returns the trajectory with the
    targets the IK tracked (its root scale the stream's calibration), the
    streamed contact labels and per-frame solver statistics (latency in
    seconds, the whole frame: targets, contacts and IK)."""
    mapping = options.pop("mapping", None) or motion.meta.get("source_mapping")
    if config is None:
        config = streaming_config(motion.fps)
    if options:
        config = config.with_options(**options)
    if config.targets.source_floor is None and motion.meta.get("floor_z") is not None:
        config = config.with_options(source_floor=float(motion.meta["floor_z"]))
    retargeter = StreamingRetargeter(
        character,
        config,
        skeleton=motion.skeleton,
        fps=motion.fps,
        translated=motion.translated,
        mapping=mapping,
        source=motion.source,
    )
    qpos = np.empty((motion.num_frames, retargeter.character.model.nq))
    tracked = _TargetTrack(motion.num_frames, motion.fps)
    for t in range(motion.num_frames):
        if motion.is_rotational:
            assert motion.rotations is not None and motion.translations is not None
            qpos[t] = retargeter.step(rotations=motion.rotations[t], translations=motion.translations[t])
        else:
            assert motion.positions is not None
            conf = None if motion.confidence is None else motion.confidence[t]
            qpos[t] = retargeter.step(positions=motion.positions[t], confidence=conf)
        assert retargeter.last_targets is not None
        tracked.put(t, retargeter.last_targets)
    labels = {k: np.array([frame[k] for frame in retargeter.labels], dtype=bool) for k in (retargeter.labels[0] if retargeter.labels else {})}
    return Trajectory(
        character=retargeter.character,
        qpos=qpos,
        fps=motion.fps,
        source=motion.source,
        targets=tracked.targets(),
        contacts=Contacts(labels=labels, fps=motion.fps, source="streamed") if labels else None,
        source_motion=motion,
        joint_indices=retargeter.joint_indices,
        solver=SolverStats(
            iterations=np.array(retargeter.iterations, dtype=np.int32),
            relaxation=np.array(retargeter.relaxations, dtype=np.int8),
            latency=np.array(retargeter.latencies),
        ),
    )


class _TargetTrack:
    """The streamed frames' targets gathered into one :class:`Targets` of ``F`` frames, in
    arrays allocated once (a list of per-frame objects would hold about a kilobyte a frame
    more); the root scale is the last calibration's (a stream that calibrates again on frame 1
    tracks with that one)."""

    def __init__(self, frames: int, fps: float) -> None:
        self.frames, self.fps = int(frames), float(fps)
        self.last: Targets | None = None
        self.positions = self.orientations = self.valid = None

    def put(self, t: int, frame: Targets) -> None:
        if self.positions is None:
            n = len(frame.names)
            self.positions = np.empty((self.frames, n, 3))
            self.orientations = np.empty((self.frames, n, 4))
            self.valid = np.empty((self.frames, n), dtype=bool)
        self.positions[t] = frame.positions[0]
        self.orientations[t] = frame.orientations[0]
        self.valid[t] = frame.valid[0]
        self.last = frame

    def targets(self) -> Targets | None:
        if self.last is None:
            return None
        return replace(self.last, positions=self.positions, orientations=self.orientations, valid=self.valid,
                       fps=self.fps)
