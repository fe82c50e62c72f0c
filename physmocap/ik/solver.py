"""Per-frame differential IK with mink: one QP per iteration, hard limits in every QP.

For each frame the solver iterates, from the previous frame's solution (or
the rest pose on the first frame),

.. math::

    \\min_{\\Delta q}\\; \\sum_k \\| W_k (J_k \\Delta q + e_k) \\|^2
      + \\| W_p (\\Delta q + q \\ominus q_{rest}) \\|^2 + \\lambda \\|\\Delta q\\|^2

subject to joint limits (mink ``ConfigurationLimit``), the frame-to-frame
velocity bound (:class:`~physmocap.ik.limits.FrameStepLimit`), the floor
(:class:`~physmocap.ik.limits.FloorLimit`) and, when given, equality
constraints (planted feet), then integrates :math:`q \\leftarrow q \\oplus
\\Delta q` until the step is below ``tolerance`` or ``max_iterations`` is hit.
The tasks :math:`k` are mink ``FrameTask``s, one per tracked site, with position
cost per metre and orientation cost per radian; :math:`\\lambda` is the
Levenberg-Marquardt damping.  The QP is the one ``mink.build_ik`` would build,
assembled by :mod:`physmocap.ik.qp` into preallocated arrays (the posture term
as a diagonal; joint ranges, velocity and root steps and the trust region as
simple bounds) and solved by ``daqp`` directly.  Forward kinematics run on
every move; ``mj_comPos`` (needed by Jacobians only) once before each QP, so a
line search's trial poses cost ``mj_kinematics`` alone.

**Relaxation order** when a QP is infeasible or the backend fails (each level
is tried in turn, and the frame is reported):

1. soften the equality constraints (planted contacts) into high-cost tasks;
2. drop the frame-to-frame velocity bound;
3. drop the floor and the self-collision constraint;
4. keep only the joint limits, with extra damping;
5. hold the previous frame's pose.

Joint limits are never relaxed, and the solver never returns a non-finite
configuration.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Mapping, Sequence

import mink
import mujoco
import numpy as np
import qpsolvers

from ..errors import OptionError
from ..options import check_fields
from ..rotations import xyzw_to_wxyz
from .limits import FloorLimit, FrameStepLimit, GroupStepLimit, RootStepLimit, SelfCollisionLimit, group_box_speeds
from .qp import QP, QPBuilder, WarmSolver
from .tasks import FRAME_XPOS, SegmentsTask, SitePositionTask, SitesPositionTask
from .targets import weight_of

__all__ = ["SolverOptions", "ContactHolds", "FrameSolver", "RELAXATION_LEVELS"]

#: Frame rate (Hz) at which ``SolverOptions.smoothness_cost`` is stated.
SMOOTHNESS_RATE = 120.0
#: Arm segments (parent, child canonical joints) of ``SolverOptions.segment_cost``: the upper
#: arm and the forearm (the hand's own vector, wrist to hand end, added joint acceleration: the
#: humanoid's on the dance 80 rad/s^2 against 76.5 without it, both at cost 5).
ARM_SEGMENTS = (("shoulder", "elbow"), ("elbow", "wrist"))

#: Rounds of floor projection and hinge-group projection at the end of a frame
#: (:meth:`FrameSolver._project_groups`).
GROUP_FLOOR_ROUNDS = 4

RELAXATION_LEVELS = (
    "all constraints",
    "contact equalities softened",
    "velocity limits dropped",
    "floor and self-collision dropped",
    "joint limits only",
    "previous pose held",
)


@dataclass
class SolverOptions:
    r"""Options of the per-frame IK.

    Attributes:
        max_iterations: QP iterations per frame (warm-started from the previous frame).
        first_frame_iterations: Iterations for frame 0, which starts from the rest pose.
        tolerance: Stop iterating when the largest joint step is below this (rad or m).
        damping: Levenberg-Marquardt damping added to the QP Hessian's diagonal.
        task_lm_damping: mink per-task LM damping (scales with the squared error).
        posture_cost: Cost of the PostureTask that pulls towards the rest pose.
        segment_cost: Cost per metre of each arm segment's world vector (shoulder to elbow,
            elbow to wrist) against its targets' (:class:`~physmocap.ik.tasks.SegmentsTask`),
            on top of the joints' own position tasks: an arm whose shoulder sits at a limit
            of its range keeps its forearm pointing the actor's way instead of folding it to
            reach for the wrist's position (the G1's left forearm over its head on the CMU
            dance).  3 (the position tasks weigh 5): 5 made the humanoid's shoulder chatter
            along its gimbal lock (joint acceleration +30 % on the dance).  0 disables.
        velocity_limits: Bound frame-to-frame steps by the joints' velocity limits.
        floor: Keep all geoms and contact sites above ``floor_height``.
        floor_height: Height of the floor plane (metres).
        floor_margin: Clearance the linearised floor constraint aims for (metres).
        floor_iterations: Extra iterations allowed when the last step left a
            point below the floor or a planted contact off its anchor
            (linearisation error).
        constraint_tolerance: Planted contacts further than this (metres) from
            their anchor trigger those extra iterations.
        contact_overshoot: Metres.  A line-search trial is accepted while its planted
            contacts are within this of their anchors, even if it moved them further off
            than the step started from (the floor is still held to that).  The QP holds the
            contacts' linearised equalities, so a full step leaves only their second-order
            error, which the next QP removes (quadratically, as in Newton's method); refusing
            it halves the whole step (every joint's, not only the legs') and stalls the frame
            at its iteration cap: on the 120 Hz walks a full step's second-order error is
            typically 0.1-0.5 mm, and the 0.05 mm bound refuses 57 % of the PyMO walk
            humanoid's first-pass steps.  A frame still ends within ``constraint_tolerance``
            (or takes its extra iterations); millimetre overshoots near a singular pose are
            still halved.  Off (0) by default: the default output is unchanged.  With 5e-4
            the whole retarget takes 4.95 instead of 6.42 QPs a frame on the PyMO walk
            humanoid (CMU walk 4.97 instead of 5.57; Bandai walk 6.6 instead of 13.0; x1.25
            the throughput on the PyMO walk humanoid, x1.0 on the CMU walk),
            failed line searches fall from 2.7 to 0.1 a frame, no planted contact ends a
            first-pass frame above ``constraint_tolerance`` and the Bandai clips and the PyMO
            walk humanoid track their targets more closely (Bandai punch humanoid 0.90 -> 0.68
            cm; the OptiTrack humanoid 0.55 -> 0.58, PyMO robot 1.09 -> 1.11, the others
            equal); but the answers change: joint
            acceleration rises by up to 12 % (frames converge instead of stopping short at the
            iteration cap), the Bandai punch robot's left elbow reaches its velocity cap on
            3 % of frames (it follows the jab), geom slip rises on the Bandai clips and the
            robot's neck turns another way on half the PyMO walk (docs/history.md, "Step
            acceptance (stop 31)").
        trust_region: Largest change of any coordinate in one QP step (rad or m).
        self_collision: Keep the limbs' collision geoms out of each other and out of
            the trunk (:class:`~physmocap.ik.limits.SelfCollisionLimit`, pairs from
            :func:`~physmocap.models.selfcollision.self_collision_pairs`).
        self_collision_margin: Gap (metres) those geoms keep (5 mm: the linearised
            constraint of two boxes sliding along each other, feet brushing, can
            overshoot by about that much in one frame; 0 lets them touch).
        limit_gain: mink ConfigurationLimit gain in (0, 1].
        weights: Canonical joint -> (position cost, orientation cost) overrides.
        solver: QP solver: ``daqp`` (called directly, warm-started) or any other
            qpsolvers backend name (the same problem through qpsolvers).
        second_order_correction: When a full step leaves the planted contacts off their
            anchors (the equalities' second-order error), first try the step of the same
            QP with that error subtracted (:meth:`FrameSolver._corrected`) before halving
            it.  Off by default (the default output is unchanged); on, far fewer line
            searches fail on takes with planted feet under straight knees.
        smoothness_cost: Cost per radian (metre for slides) of a joint's deviation from its
            constant-velocity prediction :math:`q_{t-1} \oplus (q_{t-1} \ominus q_{t-2})`, a
            diagonal term like the posture's, stated at :data:`SMOOTHNESS_RATE` and scaled by
            :math:`(f / 120)^2` at other rates so that it weighs the same joint acceleration
            (the deviation is :math:`\ddot q / f^2`).  Without it the solver wandered in
            directions the tasks barely see (thoracic flexion against clavicle elevation)
            and left frame-to-frame chatter: the PyMO walk's spine alternated by 5 degrees
            frame to frame, joints sat at their velocity caps on 3-20 % of frames.  The free
            joint is left out.  0 disables.
        upper_body_follows_pelvis: The targets above the chest (neck, head, clavicles,
            arms) move with the pelvis where it lags its own target
            (:class:`~physmocap.ik.frame.FrameRetargeter`), so a body that cannot reach
            its target (a robot's stance ankle at its roll limit under a leaning actor)
            keeps its arms in the actor's pose instead of twisting them to reach hand
            targets placed for a body elsewhere.
        extrapolate_start: Start a frame's iterations from the constant-velocity prediction
            (the smoothness prior's target, clipped to the joint ranges and the velocity band)
            instead of the previous frame's pose, when the two previous frames converged
            (last step below ``tolerance`` with every hard constraint held: an unconverged
            pose's lag would be extrapolated too).  A frame that needs a relaxation on the
            way is solved again from the previous pose.  Off by default (the default output
            is unchanged); on, the 120 Hz walks need 20-35 % fewer QPs a frame and track as
            well or better, but the answers change and resting feet slip more (docs/history.md,
            "Speed stop 23": CMU walk humanoid 0.17 -> 0.37 cm/s).
        catch_up: Metres.  A frame that has not converged after ``max_iterations`` with a
            position-only target still farther than this from its joint, or any position
            target (an oriented one too) that far behind a target that moved farther than
            this since the previous frame, gets up to ``max_iterations`` more (0: never): a
            fast limb at a low frame rate (a jab at 30 fps moves the wrist 15-20 cm a frame)
            otherwise lags its target by a hand's breadth for several frames.  Frames that
            converge, or track within it, are unchanged.
        catch_up_overshoot: Metres.  In the catch-up iterations behind such a fast target, a
            line-search trial that leaves the planted contacts within this of their anchors
            is accepted (as ``contact_overshoot`` does on every iteration; the iterations go
            on until the contacts are back within ``constraint_tolerance``).  Without it a
            30 fps swing foot's step (0.1-0.2 rad) leaves the stance leg's contacts 1-2 mm off
            by second order, is halved three times, and the foot moves an eighth of the way
            per iteration: it lagged its target by 10 cm and then jumped 18 cm in one frame
            (the G1 on the Bandai walk, frames 117-118; 2.9 cm now).  Only behind a fast
            target: on every catch-up (the 120 Hz clips' too) it set the PyMO walk humanoid's
            toes flapping after toe-off, and taking oriented targets' lags everywhere turned
            the G1's left wrist 90 degrees from the actor's on the dance.
        arm_branches: Where an arm is left far from the actor's on a branch of its joint
            ranges that cannot reach it while another can: offline, retarget again with
            that arm guided onto the other where the two meet
            (:mod:`physmocap.ik.branches`); streaming, pull the arm over to the other once
            it is found stuck, at the joints' velocity limits
            (:mod:`physmocap.ik.armswitch`).
        ease_caps: Offline only: where joints sit at their velocity caps (a robot shoulder
            near its gimbal lock), retarget again with their fast moves spread out in
            time, started earlier and ended later (:mod:`physmocap.ik.speedcaps`).
            Streaming retargeting cannot look ahead and ignores it.
    """

    max_iterations: int = 4
    first_frame_iterations: int = 150
    tolerance: float = 1e-3
    damping: float = 1e-4
    task_lm_damping: float = 0.0
    posture_cost: float = 0.02
    segment_cost: float = 3.0
    velocity_limits: bool = True
    floor: bool = True
    floor_height: float = 0.0
    floor_margin: float = 2e-4
    floor_iterations: int = 4
    constraint_tolerance: float = 5e-5
    contact_overshoot: float = 0.0
    trust_region: float = 0.5
    limit_gain: float = 0.95
    self_collision: bool = True
    self_collision_margin: float = 0.005
    weights: dict[str, tuple[float, float]] = field(default_factory=dict)
    solver: str = "daqp"
    second_order_correction: bool = False
    upper_body_follows_pelvis: bool = True
    smoothness_cost: float = 0.5
    extrapolate_start: bool = False
    catch_up: float = 0.05
    catch_up_overshoot: float = 1e-3
    arm_branches: bool = True
    ease_caps: bool = True

    def __post_init__(self) -> None:
        check_fields(
            self,
            "solver",
            signed=("floor_height",),
            counts=("max_iterations", "first_frame_iterations", "floor_iterations"),
            positive=("max_iterations", "first_frame_iterations", "trust_region", "limit_gain"),
        )
        if self.limit_gain > 1.0:
            raise OptionError(f"solver option limit_gain must be in (0, 1], got {self.limit_gain!r}")


@dataclass(frozen=True)
class ContactHolds:
    """One frame's contact holds, from the planting (:class:`~physmocap.ik.planting.Planting`).

    Attributes:
        tasks: Soft tasks (contact points pulled onto the floor).
        constraints: Hard equalities (planted contact points held in place).
        clearance_sites: Site id -> height (metres) a swing foot's contact site keeps above the floor.
        clearance_bodies: Body id -> height every geom point of a swing foot's bodies keeps.
    """

    tasks: tuple = ()
    constraints: tuple = ()
    clearance_sites: Mapping[int, float] = field(default_factory=dict)
    clearance_bodies: Mapping[int, float] = field(default_factory=dict)


class FrameSolver:
    """Solves one frame at a time for a character; holds the warm start.

    Args:
        character: A :class:`physmocap.models.Character`.
        names: Canonical joints that have targets, in target order.
        has_orientation: ``(N,)`` which of them have orientation targets.
        fps: Frame rate of the motion (for the velocity bound).
        options: :class:`SolverOptions`.
    """

    def __init__(
        self,
        character,
        names: Sequence[str],
        has_orientation: np.ndarray,
        fps: float,
        options: SolverOptions | None = None,
    ) -> None:
        self.options = opt = options or SolverOptions()
        self._catching_up = False  # in the catch-up iterations of a fast target (catch_up_overshoot applies)
        self._last_targets: np.ndarray | None = None  # the previous frame's target positions
        self._target_steps = np.zeros(len(names))
        self.character = character
        self.model = model = character.model
        self.names = tuple(names)
        self.configuration = mink.Configuration(model, np.array(character.rest_qpos, dtype=float))
        # Sites with an orientation target (and bodies) get a mink FrameTask each;
        # position-only sites share one SitesPositionTask (same maths, one pass).
        self.tasks: list[mink.Task] = []
        self.frame_tasks: list[tuple[int, mink.FrameTask, float, float]] = []
        #: per frame task: its frame's world-position array in ``MjData`` and its id (:meth:`_lagging`)
        self._frame_xpos: list[tuple[str, int]] = []
        point_idx, point_sites, point_costs = [], [], []
        for k, (name, oriented) in enumerate(zip(self.names, has_orientation)):
            pc, oc = opt.weights.get(name, weight_of(name))
            oc = oc if oriented else 0.0
            tf = character.tracked[name]
            if oc > 0.0 or tf.kind != "site":
                task = mink.FrameTask(
                    frame_name=tf.name,
                    frame_type=tf.kind,
                    position_cost=pc,
                    orientation_cost=oc,
                    lm_damping=opt.task_lm_damping,
                )
                self.frame_tasks.append((k, task, pc, oc))
                self._frame_xpos.append((FRAME_XPOS[tf.kind], tf.object_id(model)))
                self.tasks.append(task)
            else:
                point_idx.append(k)
                point_sites.append(tf.name)
                point_costs.append(pc)
        self._point_idx = np.array(point_idx, dtype=int)
        self._point_costs = np.array(point_costs, dtype=float)
        self.points = SitesPositionTask(model, point_sites, point_costs) if point_sites else None
        if self.points is not None:
            self.tasks.append(self.points)
        self.segments, self._segment_idx = self._segments_task(character, opt.segment_cost)
        if self.segments is not None:
            self.tasks.append(self.segments)
        self._task_on = [True] * len(self.frame_tasks)
        self._points_on = np.ones(len(point_idx), dtype=bool)
        self.posture = mink.PostureTask(model, cost=opt.posture_cost)
        self.posture.set_target(np.array(character.rest_qpos, dtype=float))
        #: pull towards the constant-velocity prediction from the two previous frames
        self.momentum = mink.PostureTask(model, cost=max(opt.smoothness_cost * (fps / SMOOTHNESS_RATE) ** 2, 1e-12))
        #: a frame's posture pull towards a planned configuration (:mod:`physmocap.ik.branches`)
        self.guide = mink.PostureTask(model, cost=0.0)
        self._guided = False
        self._q_prev2: np.ndarray | None = None
        self._converged = (False, False)  # whether the two previous frames' iterations converged
        self.config_limit = mink.ConfigurationLimit(model, gain=opt.limit_gain)
        groups = tuple(getattr(character, "velocity_groups", ()))
        self.step_limit = FrameStepLimit(model, group_box_speeds(character.velocity_limits, groups), 1.0 / fps)
        #: a ball joint written as hinges: its body's turn along each axis (None: no group)
        self.group_limit = GroupStepLimit(model, groups, character.velocity_limits, 1.0 / fps) if groups else None
        self._grouped = False  # a step of the current frame needed the groups' rows (see _step)
        self.root_limit = RootStepLimit(model, 1.0 / fps)
        self._trust = np.full(model.nv, float(opt.trust_region))
        contact_sites = [model.site(s).id for side in character.contacts.values() for s in side]
        # Points further above the floor than a fast foot travels in one frame
        # (3 m/s) cannot reach it this frame: leave them out of the QP.
        self.floor_limit = FloorLimit(
            model,
            sites=contact_sites,
            floor=opt.floor_height,
            margin=opt.floor_margin,
            activation=max(0.03, 3.0 / fps),
        )
        self.self_limit = None
        self._first = False
        if opt.self_collision:
            from ..models.selfcollision import self_collision_pairs

            pairs = self_collision_pairs(character)
            if pairs:
                self.self_limit = SelfCollisionLimit(model, pairs, margin=opt.self_collision_margin)
        # hinge/slide joints with limits, for the final clamp
        lim = (model.jnt_limited.astype(bool)) & np.isin(
            model.jnt_type, [mujoco.mjtJoint.mjJNT_HINGE, mujoco.mjtJoint.mjJNT_SLIDE]
        )
        self._lim_qadr = model.jnt_qposadr[lim]
        self._lim_range = model.jnt_range[lim]
        self.q_prev: np.ndarray | None = None
        self._builder = QPBuilder(model)
        self._daqp = WarmSolver(model.nv)
        self._com_stale = False  # kinematics current, mj_comPos (Jacobians) not yet
        self._residual: float | None = None
        self._res_cache: tuple[bytes, tuple[float, float]] | None = None
        self._constraints: list[mink.Task] = []
        self._hold_rows: tuple[np.ndarray, np.ndarray] | None = None
        self._extra_tasks: list[mink.Task] = []
        self._qp: QP | None = None  # the last QP with contact equalities (second_order_correction)

    # -- targets ----------------------------------------------------------------
    def _set_targets(self, positions: np.ndarray, orientations: np.ndarray, valid: np.ndarray) -> None:
        """Targets for the next frame: ``(N, 3)`` metres, ``(N, 4)`` xyzw, ``(N,)`` bool."""
        here = np.asarray(positions, dtype=float)
        last, self._last_targets = self._last_targets, here.copy()
        moved = np.zeros(len(here)) if last is None or last.shape != here.shape else np.linalg.norm(here - last, axis=1)
        #: metres each target moved since the previous frame (0 where unknown; :meth:`_lagging`)
        self._target_steps = np.where(np.isfinite(moved) & np.asarray(valid, dtype=bool), moved, 0.0)
        # every target's (w, x, y, z, x, y, z) in one new array: each task gets its own row
        # (what FrameTask.set_target's copy would make; the rows are never written again)
        poses = np.concatenate([xyzw_to_wxyz(orientations), positions], axis=1)
        flags = np.asarray(valid, dtype=bool).tolist()
        for j, (k, task, pc, oc) in enumerate(self.frame_tasks):
            on = flags[k]
            if on:
                task.transform_target_to_world = mink.SE3(wxyz_xyz=poses[k])
            else:
                task.set_target_from_configuration(self.configuration)
            if on != self._task_on[j]:
                task.set_position_cost(pc if on else 0.0)
                task.set_orientation_cost(oc if on else 0.0)
                self._task_on[j] = on
        if self.segments is not None:
            a, b = self._segment_idx[:, 0], self._segment_idx[:, 1]
            self.segments.set_targets(positions[b] - positions[a])
            on = np.asarray(valid, dtype=bool)
            self.segments.set_costs(np.where(on[a] & on[b], self.options.segment_cost, 0.0))
        if self.points is not None:
            self.points.set_targets(positions[self._point_idx])
            on = np.asarray(valid, dtype=bool)[self._point_idx]
            if (on != self._points_on).any():
                self.points.set_costs(np.where(on, self._point_costs, 0.0))
                self._points_on = on

    def _segments_task(self, character, cost: float) -> tuple[SegmentsTask | None, np.ndarray]:
        """The arm segments' task (:data:`ARM_SEGMENTS` whose two joints have targets) and
        its ``(pairs, 2)`` target columns, or ``(None, empty)`` with ``cost`` 0 or no arm."""
        pairs, idx = [], []
        for side in ("left", "right"):
            for parent, child in ARM_SEGMENTS:
                a, b = f"{side}_{parent}", f"{side}_{child}"
                if cost <= 0.0 or a not in self.names or b not in self.names:
                    continue
                pairs.append((character.tracked[a], character.tracked[b]))
                idx.append((self.names.index(a), self.names.index(b)))
        if not pairs:
            return None, np.zeros((0, 2), dtype=int)
        return SegmentsTask(self.model, pairs, cost), np.array(idx, dtype=int)

    def _set_holds(self, holds: "ContactHolds") -> None:
        """This frame's contact holds; their tasks' targets and costs are read from here on
        (:meth:`QPBuilder.new_frame`), so a change to them needs a new call."""
        self._builder.new_frame()
        self._extra_tasks = list(holds.tasks)
        self._constraints = list(holds.constraints)
        # the planted contacts' residual rows at once: site coordinate, target (metres)
        self._hold_rows = None
        if self._constraints and all(type(t) is SitePositionTask for t in self._constraints):
            rows = [(t.site_id, a, t.target[a]) for t in self._constraints for a in t.axes]
            sites, axes, target = zip(*rows)
            # flat indices into site_xpos (a 1-D take is the cheapest gather)
            self._hold_rows = (3 * np.array(sites, dtype=int) + np.array(axes, dtype=int), np.array(target, dtype=float))
        self.floor_limit.clearance = dict(holds.clearance_sites)
        self.floor_limit.swing_bodies = dict(holds.clearance_bodies)

    def _postures(self) -> tuple:
        """The posture term, the smoothness prior once two previous frames exist, and the
        frame's guide if it has one."""
        guide = (self.guide,) if self._guided else ()
        if self.options.smoothness_cost > 0 and self.q_prev is not None and self._q_prev2 is not None and not self._first:
            return (self.posture, self.momentum, *guide)
        return (self.posture, *guide)

    def _set_guide(self, guide) -> None:
        """This frame's guide (:class:`~physmocap.ik.branches.Guide`: some joints pulled to
        given values), or None."""
        self._guided = guide is not None and len(guide.qpos) > 0
        if self._guided:
            target = self.configuration.data.qpos.copy()
            target[guide.qpos] = guide.values
            cost = np.zeros(self.model.nv)
            cost[guide.dofs] = guide.cost
            self.guide.set_target(target)
            self.guide.set_cost(cost)

    def _predict(self) -> None:
        r"""Target of the smoothness prior: :math:`q_{t-1} \oplus (q_{t-1} \ominus q_{t-2})`."""
        if self.q_prev is None or self._q_prev2 is None:
            return
        v = np.zeros(self.model.nv)
        mujoco.mj_differentiatePos(self.model, v, 1.0, self._q_prev2, self.q_prev)
        q = self.q_prev.copy()
        mujoco.mj_integratePos(self.model, q, v, 1.0)
        self.momentum.set_target(q)
        self._prediction = q

    def _start_from(self, start: np.ndarray) -> None:
        """Move to ``start`` (a configuration: the constant-velocity prediction of
        :meth:`_predict` with ``SolverOptions.extrapolate_start``, or a guide's), kept inside
        the joint ranges and the frame's velocity band."""
        q = np.array(start, dtype=float)
        q[self._lim_qadr] = np.clip(q[self._lim_qadr], self._lim_range[:, 0], self._lim_range[:, 1])
        if self.options.velocity_limits and self.step_limit.q_prev is not None and len(self.step_limit.qposadr):
            lo, hi = self.step_limit.step_bounds()
            qa = self.step_limit.qposadr
            q[qa] = np.clip(q[qa], lo, hi)
        self._set_q(q)

    def forget_previous(self) -> None:
        """Keep the current pose as the warm start but drop the previous frame, so the
        next frame has no velocity bound (after the first frame's settling solve)."""
        self.q_prev = None
        self._q_prev2 = None

    def reset(self, q: np.ndarray | None = None) -> None:
        """Start over from ``q`` (default: the rest pose) with no previous frame."""
        q0 = self.character.rest_qpos if q is None else q
        self.configuration.update(np.array(q0, dtype=float))
        self._com_stale = False
        self._daqp.reset()
        self.q_prev = None
        self._q_prev2 = None
        self._last_targets = None
        self._converged = (False, False)

    # -- solving ----------------------------------------------------------------
    def _limits(self, level: int) -> tuple[list, list[mink.Limit]]:
        """``(boxes, general)`` limits at relaxation ``level``: those folded into the QP's
        simple bounds (root step, frame-to-frame step; the joint ranges always are) and
        those that are general rows (floor, self-collision)."""
        opt = self.options
        boxes: list = [self.root_limit]
        general: list[mink.Limit] = []
        if level <= 2 and opt.velocity_limits and self.q_prev is not None:
            boxes.append(self.step_limit)
        if level <= 3 and opt.floor:
            general.append(self.floor_limit)
        if level <= 3 and self.self_limit is not None and not self._first:
            general.append(self.self_limit)
        return boxes, general

    # -- kinematics: mj_kinematics on every move, mj_comPos only before a QP ------------
    def _set_q(self, q: np.ndarray) -> None:
        """Move to ``q``: forward kinematics only (positions for the residuals)."""
        self.configuration.data.qpos[:] = q
        mujoco.mj_kinematics(self.model, self.configuration.data)
        self._com_stale = True

    def _integrate(self, v: np.ndarray, alpha: float) -> None:
        r""":math:`q \leftarrow q \oplus \alpha v`, forward kinematics only."""
        data = self.configuration.data
        mujoco.mj_integratePos(self.model, data.qpos, v, alpha)
        mujoco.mj_kinematics(self.model, data)
        self._com_stale = True

    def _sync(self) -> None:
        """Complete the kinematics for Jacobians (``mj_comPos``) if a move left them stale."""
        if self._com_stale:
            mujoco.mj_comPos(self.model, self.configuration.data)
            if self.model.neq > 0:
                mujoco.mj_makeConstraint(self.model, self.configuration.data)
            self._com_stale = False

    def _solve(self, problem: QP) -> np.ndarray:
        """Solve with daqp directly, or with another qpsolvers backend (``options.solver``)."""
        if self.options.solver == "daqp":
            return self._daqp.solve(problem)
        G, A = (problem.G, problem.h), (problem.A, problem.b)
        result = qpsolvers.solve_problem(
            qpsolvers.Problem(
                problem.H, problem.c,
                G[0] if len(G[1]) else None, G[1] if len(G[1]) else None,
                A[0] if len(A[1]) else None, A[1] if len(A[1]) else None,
                problem.lb, problem.ub,
            ),
            solver=self.options.solver,
        )
        v = result.x
        if not result.found or v is None or not np.all(np.isfinite(v)):
            raise mink.NoSolutionFound(self.options.solver)
        return v

    def _step(self, level: int) -> np.ndarray:
        """One QP step at relaxation ``level`` (:data:`RELAXATION_LEVELS`), see :mod:`~physmocap.ik.qp`."""
        opt = self.options
        self._sync()
        tasks = [*self.tasks, *self._extra_tasks]
        constraints = self._constraints if level == 0 else []
        if level >= 1:  # equalities softened into high-cost tasks
            tasks += self._constraints
        damping = opt.damping if level < 4 else max(opt.damping, 1e-2)
        boxes, general = self._limits(level)

        def build(limits: list[mink.Limit]) -> QP:
            return self._builder.build(
                self.configuration,
                tasks,
                damping,
                posture=self._postures(),
                trust=self._trust,
                config_limit=self.config_limit,
                boxes=boxes,
                limits=limits,
                constraints=constraints,
            )

        grouping = self.step_limit in boxes and self.group_limit is not None
        if grouping and self._grouped:
            # an earlier step of this frame needed the groups' rows: the next most likely
            # does too (a body turning at its speed cap), so they go in at once; where they
            # leave no solution they are not tried again below (the same rows fail the same way)
            grouping = False
            try:
                problem = build([*general, self.group_limit])
                v = self._solve(problem)
                self._qp = problem if constraints and opt.second_order_correction else None
                return v
            except (mink.NoSolutionFound, ValueError, np.linalg.LinAlgError):
                pass
        problem = build(general)
        v = self._solve(problem)
        if grouping and self.group_limit.crossed(self.configuration, v):
            # the same QP with the hinge groups' rows; where the rows (degenerate at a gimbal
            # lock) leave no solution, the step without them stands and the frame's end
            # projection (GroupStepLimit.project) bounds the groups: no relaxation for them
            self._grouped = True
            grouped = build([*general, self.group_limit])
            try:
                v, problem = self._solve(grouped), grouped
            except (mink.NoSolutionFound, ValueError, np.linalg.LinAlgError):
                problem = build(general)
        self._qp = problem if constraints and opt.second_order_correction else None
        return v

    def _settle_from_rest(self) -> None:
        """First stage of frame 0: converge with a strong pull towards the rest pose.

        Three-hinge joints (shoulders, hips) have two branches near gimbal lock
        (a T-pose puts the shoulders there); converging first with a posture
        cost of 1 picks the branch nearest the anatomical rest pose, and the
        normal iterations then refine from it.
        """
        opt = self.options
        self.posture.set_cost(max(1.0, opt.posture_cost))
        try:
            for _ in range(max(1, opt.first_frame_iterations // 3)):
                try:
                    v = self._step(1)
                except (mink.NoSolutionFound, ValueError, np.linalg.LinAlgError):
                    break
                self._integrate(v, 1.0)
                if np.abs(v).max() < opt.tolerance:
                    break
        finally:
            self.posture.set_cost(opt.posture_cost)

    def _project_groups(self, q: np.ndarray, level: int) -> np.ndarray:
        """``q`` with the hinge groups' steps within their bounds
        (:meth:`~physmocap.ik.limits.GroupStepLimit.project`), and back above the floor
        where scaling a group's step down lowered a body part into it: the floor projection
        with the groups' rows, then the groups' projection again, for at most
        :data:`GROUP_FLOOR_ROUNDS` rounds (both sets hold the previous frame's pose, and a
        group's step is scaled, not moved, so they meet in a round or two)."""
        out = self.group_limit.project(self.model, self.configuration.data, q)
        if out is q or not self.options.floor:
            return out
        for _ in range(GROUP_FLOOR_ROUNDS):
            self._set_q(out)
            if self._floor_ok():
                break
            self._project_floor(level, extra=(self.group_limit,))
            out = self.group_limit.project(self.model, self.configuration.data, self.configuration.data.qpos.copy())
        return out

    def _project_floor(self, level: int, extra: Sequence[mink.Limit] = ()) -> None:
        """Smallest step that puts every point back above the floor.

        Tasks can pull against the floor until the iterations run out; this
        solves :math:`\\min \\|\\Delta q\\|^2` under the hard constraints alone
        (same limits as ``level``, and ``extra``), a few times, which converges quickly.
        """
        for _ in range(5):
            self._sync()
            boxes, general = self._limits(level)
            general = [*general, *extra]
            try:
                v = self._solve(
                    self._builder.build(
                        self.configuration,
                        [],
                        1e-6,
                        config_limit=self.config_limit,
                        boxes=boxes,
                        limits=general,
                        constraints=self._constraints if level == 0 else (),
                    )
                )
            except (mink.NoSolutionFound, ValueError, np.linalg.LinAlgError):
                return
            self._integrate(v, 1.0)
            if self._floor_ok():
                return

    def _residuals(self, contacts: float | None = None) -> tuple[float, float]:
        """``(contacts, floor)``: how far the planted contacts are off their anchors
        and the lowest point below the floor (metres), cached per configuration
        (``contacts``: the first, when just computed by :meth:`_contact_residual`)."""
        key = self.configuration.data.qpos.tobytes()
        if self._res_cache is not None and self._res_cache[0] == key:
            return self._res_cache[1]
        rc = self._contact_residual() if contacts is None else contacts
        rf = 0.0
        if self.options.floor:
            rf = max(0.0, self.options.floor_height - self.floor_limit.lowest(self.configuration.data))
        self._res_cache = (key, (rc, rf))
        return rc, rf

    def _contact_residual(self) -> float:
        """How far (metres, largest coordinate) the planted contacts are off their anchors."""
        rc = 0.0
        if self._hold_rows is not None:
            rc = max(rc, float(np.abs(self._contact_errors()).max()))
        else:
            for task in self._constraints:
                rc = max(rc, float(np.max(np.abs(task.compute_error(self.configuration)))))
        return rc

    def _hard_residual(self) -> float:
        """Largest violation of the hard constraints that are linearised: planted
        contacts (metres off their anchor) and the floor (metres below it)."""
        return max(self._residuals())

    def _line_search(self, v: np.ndarray, tol: float = 5e-5) -> None:
        """Take the step ``v``, halving it while it makes the hard constraints worse.

        The QP satisfies the linearised constraints exactly, but near a
        singular pose (a straight knee under a planted foot) a full step can
        overshoot by millimetres and the next step undo it, forever.  Backtracking
        on the hard-constraint residual removes that oscillation; a trial that leaves the
        planted contacts within ``contact_overshoot`` of their anchors is not refused for
        them (:meth:`_accept`), so a full step's sub-millimetre second-order error does not
        halve it.  With
        ``second_order_correction`` a refused full step is first corrected
        (:meth:`_corrected`) before it is halved.
        """
        if not self._constraints and not self.options.floor:
            self._integrate(v, 1.0)
            return
        q0 = self.configuration.data.qpos.copy()
        r0 = self._residual if self._residual is not None else self._hard_residual()
        bound = max(r0, tol)
        qpos = self.configuration.data.qpos
        qp, self._qp = self._qp, None
        e0 = self._contact_errors() if qp is not None else None
        alpha = 1.0
        for _ in range(4):
            self._integrate(v, alpha)
            if self._accept(bound):
                return
            if alpha == 1.0 and e0 is not None and self._corrected(qp, v, q0, e0, bound):
                return
            alpha *= 0.5
            qpos[:] = q0  # the next trial integrates from q0 (its kinematics are not needed)
        self._integrate(v, alpha)
        r1 = self._hard_residual()
        if r1 > max(r0, tol) + 1e-3:  # still clearly worse: reject the step
            self._set_q(q0)
            r1 = r0
        self._residual = r1

    def _contact_errors(self) -> np.ndarray | None:
        """The planted contacts' errors :math:`e(q)` (metres, the equality rows' order), or None
        when the constraints are not all :class:`SitePositionTask` s."""
        if self._hold_rows is None:
            return None
        at, target = self._hold_rows
        return self.configuration.data.site_xpos.take(at) - target

    def _corrected(self, qp: QP, v: np.ndarray, q0: np.ndarray, e0: np.ndarray, bound: float) -> bool:
        r"""Second-order correction of a full step :math:`v` that left the planted contacts
        off their anchors (Nocedal & Wright, *Numerical Optimization*, 15.6).

        The QP held :math:`A v = b` (:math:`b = -\alpha e(q)`), but the contacts moved by
        :math:`e(q \oplus v) - e(q) = A v + s`, :math:`s` the second-order term.  The same QP
        with :math:`A \Delta q = b - s` gives a step whose contacts' error is third order.
        Takes it from ``q0`` and returns True if its hard-constraint residual is within
        ``bound``; otherwise leaves the configuration at ``q0`` (kinematics not updated)."""
        s = self._contact_errors() - e0 - qp.A @ v
        try:
            w = self._solve(dataclasses.replace(qp, b=qp.b - s))
        except (mink.NoSolutionFound, ValueError, np.linalg.LinAlgError):
            self.configuration.data.qpos[:] = q0
            return False
        self.configuration.data.qpos[:] = q0
        self._integrate(w, 1.0)
        if self._accept(bound):
            return True
        self.configuration.data.qpos[:] = q0
        return False

    def _accept(self, bound: float) -> bool:
        """True (and the residual kept) if the current trial's hard-constraint residuals are
        within ``bound``, the planted contacts' within ``SolverOptions.contact_overshoot`` if that
        is larger (their second-order error, which the next QP removes): the contacts' residual
        first, so that when it alone is too large the trial is refused without the floor's."""
        rc = self._contact_residual()
        overshoot = self.options.contact_overshoot
        if self._catching_up:
            overshoot = max(overshoot, self.options.catch_up_overshoot)
        if rc > max(bound, overshoot):
            return False
        rf = self._residuals(rc)[1]
        if rf > bound:
            return False
        self._residual = max(rc, rf)
        return True

    def _constraints_ok(self, tol: float | None = None) -> bool:
        """True if every equality constraint (planted contact) holds within ``tol`` metres.

        The equalities are linearised too: a large last step leaves a
        second-order residual, and the solver iterates again to remove it.
        """
        tol = self.options.constraint_tolerance if tol is None else tol
        return not self._constraints or self._residuals()[0] <= tol

    def _apart_ok(self) -> bool:
        """True if no self-collision pair is more than 1 mm inside its margin (the
        constraint is linearised too; the solver then iterates again)."""
        if self.self_limit is None or self._first:
            return True
        d = self.self_limit.distances(self.configuration.data)
        return not d.size or float(d.min()) >= self.options.self_collision_margin - 1e-3

    def _floor_ok(self) -> bool:
        """True if no constrained point is below the floor by more than 0.1 mm.

        The floor constraint is linearised, so a large last step can leave a
        point a few millimetres below the floor (second-order error); the
        solver then iterates again, up to ``floor_iterations`` more times.
        """
        return not self.options.floor or self._residuals()[1] <= 1e-4

    def _lagging(self) -> tuple[bool, bool]:
        """``(lagging, fast)``: whether some position-only target with a cost is farther than
        ``catch_up`` (metres) from its site in the current configuration, and whether some
        position target (a point's or a frame task's) is that far behind a target that itself
        moved farther than ``catch_up`` since the previous frame: a fast limb
        (:attr:`SolverOptions.catch_up`, :attr:`SolverOptions.catch_up_overshoot`)."""
        c = self.options.catch_up
        if c <= 0:
            return False, False
        data = self.configuration.data
        quick = self._target_steps > c
        lagging = fast = False
        if self.points is not None:
            p = self.points
            d = data.site_xpos[p.site_ids] - p.targets
            far = (np.einsum("ij,ij->i", d, d) > c * c) & (p.cost[::3] > 0)
            lagging = bool(far.any())
            fast = bool((far & quick[self._point_idx]).any())
        for j, (k, task, pc, _) in enumerate(self.frame_tasks):
            if fast:
                break
            if pc > 0 and self._task_on[j] and quick[k]:
                array, i = self._frame_xpos[j]
                d = getattr(data, array)[i] - task.transform_target_to_world.translation()
                fast = float(d @ d) > c * c
        return lagging or fast, fast

    def _iterate(self, total: int, iters: int, base: int) -> tuple[int, int, bool]:
        """The frame's QP iterations from the current configuration: ``iters``, then up to
        ``total`` while a hard constraint is off; ``(iterations, worst relaxation level,
        converged)``, converged when the last step was below ``tolerance`` with every hard
        constraint held."""
        opt = self.options
        worst = 0
        it = 0
        self._residual = None  # hard-constraint residual, cached between line searches
        self._res_cache = None  # the constraints may have changed since the last frame
        for it in range(1, total + 1):
            if it > iters and self._floor_ok() and self._constraints_ok() and self._apart_ok():
                return it - 1, worst, False
            level = base
            v = None
            while level < 5:
                try:
                    v = self._step(level)
                    break
                except (mink.NoSolutionFound, ValueError, np.linalg.LinAlgError):
                    level += 1
            if level > base:
                worst = max(worst, level)
            if v is None:
                return it, 5, False
            self._line_search(v)
            if np.abs(v).max() < opt.tolerance and self._floor_ok() and self._constraints_ok() and self._apart_ok():
                return it, worst, True
        return it, worst, False

    def solve_frame(
        self,
        positions: np.ndarray,
        orientations: np.ndarray,
        valid: np.ndarray,
        holds: ContactHolds | None = None,
        first: bool = False,
        guide=None,
    ) -> tuple[np.ndarray, int, int]:
        """Solve one frame, warm-started from the previous one; returns
        ``(q, iterations, relaxation level)`` (``q`` a new array; the inputs are not modified).

        Args:
            positions: ``(N, 3)`` target positions (metres), in target order.
            orientations: ``(N, 4)`` target orientations (x-y-z-w).
            valid: ``(N,)`` False turns a target's task off for this frame.
            holds: This frame's contact holds (:class:`ContactHolds`); none by default.
            first: Converge from the rest pose (``first_frame_iterations``)
                instead of taking ``max_iterations`` from the previous frame.
            guide: A posture pull for this frame (:class:`~physmocap.ik.branches.Guide`), or None.

        The relaxation level is the index in :data:`RELAXATION_LEVELS` of the
        strongest relaxation any iteration needed (0 = none).
        """
        self._set_targets(positions, orientations, valid)
        self._set_holds(holds or ContactHolds())
        self._set_guide(guide)
        # converging from the rest pose is no motion: the limbs may pass each other on the way
        # (from the next frame on, a pair left overlapping is pushed apart)
        self._first = bool(first)
        opt = self.options
        self.step_limit.set_previous(self.q_prev)
        self._grouped = False  # no step of this frame has needed the hinge groups' rows yet
        if self.group_limit is not None:
            self.group_limit.set_previous(self.q_prev)
        self.root_limit.set_previous(self.q_prev)
        self._prediction = None
        self._predict()
        start = None  # the previous frame's pose when the iterations start from the prediction
        warm = guide.start if guide is not None and getattr(guide, "start", None) is not None else None
        if warm is None and opt.extrapolate_start and not first and self._prediction is not None and all(self._converged):
            warm = self._prediction
        if warm is not None and not first:
            start = self.configuration.data.qpos.copy()
            self._start_from(warm)
        iters = opt.first_frame_iterations if first else opt.max_iterations
        if first:
            self._settle_from_rest()
        base = 0 if self._constraints else 1
        extra = opt.floor_iterations if opt.floor else 0
        extra = max(extra, opt.floor_iterations if (self._constraints or self.self_limit is not None) else 0)
        it, worst, converged = self._iterate(iters + extra, iters, base)
        if start is not None and worst > 0:
            # a relaxation was needed on the way from the predicted start: the frame again,
            # from the previous frame's pose (as without extrapolate_start)
            self._set_q(start)
            it, worst, converged = self._iterate(iters + extra, iters, base)
        lagging, fast = self._lagging() if not converged and worst < 5 and not first else (False, False)
        if lagging:
            # behind a fast target, the contacts' second-order error is accepted on the way
            # (the iterations go on until they are back within constraint_tolerance): a step
            # halved for it three times moves a limb an eighth of the way per iteration
            self._catching_up = fast
            try:
                more, worst2, converged = self._iterate(iters + extra, iters, base)
            finally:
                self._catching_up = False
            it, worst = it + more, max(worst, worst2)
        self._converged = (self._converged[1], converged)
        if opt.floor and worst < 3 and not self._floor_ok():
            self._project_floor(base)
        q = self.configuration.data.qpos.copy()
        if worst == 5 or not np.isfinite(q).all():
            worst = 5
            q = (self.q_prev if self.q_prev is not None else np.array(self.character.rest_qpos)).copy()
        # remove solver round-off outside the joint ranges (the QP keeps within ~1e-9)
        q[self._lim_qadr] = np.clip(q[self._lim_qadr], self._lim_range[:, 0], self._lim_range[:, 1])
        if self.q_prev is not None and opt.velocity_limits and worst < 2:
            lo, hi = self.step_limit.step_bounds()
            qa = self.step_limit.qposadr
            q[qa] = np.clip(q[qa], lo - self.step_limit.shrink, hi + self.step_limit.shrink)
            if self.group_limit is not None:
                q = self._project_groups(q, base)
        self.configuration.update(q)
        self._com_stale = False
        self._q_prev2 = self.q_prev
        self.q_prev = q.copy()
        return q, it, worst
