r"""Contact changes smoothed offline: a last pass pulls the joints towards a low-pass of the first.

The per-frame IK can only react.  Where a contact begins or ends, its hard holds
switch on or off in one frame, and what they held back catches up at once: on the
PyMO walk the pelvis trailed a toe held to the end of its label by 2 cm and caught up in
one frame at toe-off (the knee 8.6 degrees in that frame), an ankle rolled 8 degrees in
one frame at heel strike, and the joints' mean acceleration was 1.46 times that of the
same clip without planting (the issue's bound is 1.2).

Offline the whole clip is known.  After the first pass (and the arm passes of
:mod:`.branches`), the clip is retargeted once more with every hinge and slide joint
pulled (a posture pull of ``transition_cost`` per radian or metre, a
:class:`~physmocap.ik.branches.Guide`) towards a reference:

1. **around contact changes** (the frames within ``transition_window`` seconds of a
   change of any contact label: heels, toes, knees, hands, pelvis) the reference is the
   first pass low-passed by a Gaussian of standard deviation ``transition_sigma``
   seconds, :math:`\bar q_j = G_\sigma * q_j` (zero phase; the ends repeat the end
   values), which spreads a one-frame catch-up over the frames around it, before the
   change as well as after;
2. **the actor's own fast motion** is not low-passed: a joint that carries no contact
   (an arm, the trunk, the head, where no hand or knee is labelled) keeps the first
   pass's own pose as its reference on a frame where the same low-pass would move one of
   the targets it carries (on its body or below) by more than ``transition_tolerance``:
   there the motion is the actor's (a punch), not a catch-up, and a pull towards the
   low-pass would lag it.  The legs always take the low-pass: their targets move fast
   exactly at the contact changes;
3. **everywhere else** the reference is the first pass itself: nothing to smooth there,
   and without a pull the last pass drifted in directions the tasks barely see (the
   OptiTrack clip's lumbar rotation, 36 degrees from the first pass's 20 s after the
   last contact change).

Every hard constraint holds as before: the holds still hold, the floor and the limits
still bound.  A swing foot that a hard constraint held off its target in the first pass (the
other leg, through self-collision avoidance) and that snapped back when it was let go has
its targets moved by that offset spread out in time (:func:`eased_offsets`), so it goes
round instead of catching up in one frame (:func:`eased_foot_shifts`).  An arm's own guide
from the arm passes keeps its joints.  Every frame's iterations start from the first
pass's pose on that frame (within the frame's velocity band), not from the previous
frame's: the answer is nearer, so it takes fewer iterations (the PyMO walk: 2.7 a frame
against 4.2) and ends better converged (its acceleration
ratio 1.18 -> 0.99; the Bandai walk's scuffing 2.1 -> 0.6 %, its robot's 4.0 -> 0).
That pose is moved by this pass's offset from the first on the previous frame,
:math:`p_t \oplus (q_{t-1} \ominus p_{t-1})` (:attr:`~physmocap.ik.branches.Guide.follow`,
:meth:`~physmocap.ik.frame.FrameRetargeter.carried`): away from the windows the two passes
differ by an offset that barely changes (the holds' anchors, set near a change, are a
millimetre off the first pass's), and such a frame, which took two QPs, now takes one (QPs
a frame over the whole pass, humanoid: OptiTrack 2.03 -> 1.09, PyMO walk 2.65 -> 1.99, CMU
walk 2.20 -> 1.97; the Bandai walk 6.63 -> 2.67).

Every hinge and slide joint is pulled, the arms too: the trunk's catch-ups move the
shoulders, and arms that keep their hands on their targets jerk with them (the legs
alone left the walks' acceleration ratios at 1.26-1.31).  The pass is kept only if the
solver relaxed a hard constraint (a contact equality softened included) on no more
frames.  A clip without contact changes (``--no-plant``) has no such pass.  Streaming
retargeting cannot look ahead and does not do this.  Radians, metres, seconds.
"""

from __future__ import annotations

from typing import Mapping, Sequence

import mujoco
import numpy as np
from scipy.ndimage import gaussian_filter1d, maximum_filter1d, minimum_filter1d

from ..spill import blocks, release
from .branches import MOVING_TYPES, Guide
from .easing import rounded_above

__all__ = ["change_windows", "moving_joints", "carried_targets", "TransitionGuides", "eased_offsets", "eased_foot_shifts"]

#: Frames of the reference low-passed at a time (a long clip's reference is never whole).
BLOCK_FRAMES = 4096
#: Standard deviations the Gaussian reaches (scipy's ``truncate``).
TRUNCATE = 4.0


def change_windows(labels: Mapping[str, np.ndarray], num_frames: int, window_frames: int) -> np.ndarray:
    """``(F,)`` bool: frames within ``window_frames`` of a change of any label ``(F,)``
    (the frames on both sides of the change included)."""
    near = np.zeros(num_frames, dtype=bool)
    for label in labels.values():
        x = np.asarray(label, dtype=bool)[:num_frames]
        for e in np.flatnonzero(x[1:] != x[:-1]):  # the label changes between e and e + 1
            near[max(0, e - window_frames) : e + window_frames + 2] = True
    return near


def _envelope(x: np.ndarray, step: float, upper: bool) -> np.ndarray:
    r"""The tightest curve on one side of ``x (F,)`` whose slope is at most ``step`` per frame:
    :math:`\max_s (x_s - r|t - s|)` (``upper``) or :math:`\min_s (x_s + r|t - s|)`,
    by one pass each way."""
    y = np.array(x, dtype=float)
    sign = 1.0 if upper else -1.0
    y *= sign
    for t in range(1, len(y)):
        y[t] = max(y[t], y[t - 1] - step)
    for t in range(len(y) - 2, -1, -1):
        y[t] = max(y[t], y[t + 1] - step)
    return sign * y


def eased_offsets(offsets: np.ndarray, fps: float, speed: float, tolerance: float,
                  pinned: np.ndarray | None = None) -> np.ndarray:
    r"""``(F, 3)`` offsets to add to a limb's targets so that it eases into and out of the
    offsets ``(F, 3)`` the first pass left it at (metres; a swing foot held off its target by
    the other leg), instead of jumping there in a frame.

    Per axis, the offset is spread outwards in time at ``speed`` (m/s): where it is positive
    its upper envelope of slope ``speed / fps`` per frame, where negative its lower one
    (:func:`_envelope`), the larger in magnitude; a slowly changing offset is its own
    envelope.  Its corners are then rounded over :data:`ROUND_TIME` either side, its positive
    and negative parts each as a moving average of their running maximum (minimum), which
    is never smaller in magnitude and rises no faster: a rise meeting a fall at a one-frame
    hold turned in one frame (the robot's foot held over its other foot on the Bandai walk,
    a 5 cm pop).  The result is applied only around the frames where it differs from the
    offset by more than ``tolerance`` (metres), faded in and out over as many frames as the
    largest difference takes at ``speed``: elsewhere the targets are the actor's.  On the
    ``pinned (F,)`` frames (a foot in contact, held by its plan) the result is 0, and it
    reaches 0 there at ``speed``: within :math:`k` frames of one it is at most
    :math:`k \cdot speed / fps`."""
    x = np.asarray(offsets, dtype=float)
    F = x.shape[0]
    if F < 3 or speed <= 0:
        return np.zeros_like(x)
    step = speed / fps
    up = np.stack([_envelope(x[:, i], step, True) for i in range(x.shape[1])], axis=1)
    low = np.stack([_envelope(x[:, i], step, False) for i in range(x.shape[1])], axis=1)
    e = np.where(np.abs(up) >= np.abs(low), up, low)
    # rounded (see above): never below the envelope, no steeper, turning over 2n + 1 frames
    n = max(1, int(round(ROUND_TIME * fps)))
    if n > 1:
        e = rounded_above(np.maximum(e, 0.0), n) - rounded_above(np.maximum(-e, 0.0), n)
    if pinned is not None and np.any(pinned):
        # frames to the nearest pinned frame, both ways
        gap = np.full(F, float(F))
        last = -np.inf
        for t in range(F):
            last = t if pinned[t] else last
            gap[t] = t - last
        last = np.inf
        for t in range(F - 1, -1, -1):
            last = t if pinned[t] else last
            gap[t] = min(gap[t], last - t)
        e = np.clip(e, -gap[:, None] * step, gap[:, None] * step)
    differs = np.linalg.norm(e - x, axis=1) > tolerance
    if not differs.any():
        return np.zeros_like(x)
    reach = int(np.ceil(float(np.abs(e - x).max()) / step)) + 1
    # every frame within ``reach`` of one that differs (np.convolve's "same" would return the
    # kernel's length, not the clip's, on a clip shorter than 2 * reach + 1 frames)
    near = maximum_filter1d(differs.astype(np.int8), size=2 * reach + 1, mode="constant") > 0
    weight = gaussian_filter1d(near.astype(float), max(reach / 2.0, 1.0), mode="nearest")
    weight = np.clip(2.0 * weight, 0.0, 1.0)
    return e * weight[:, None]


#: Seconds over which an eased offset's corners are rounded (:func:`eased_offsets`).
ROUND_TIME = 0.05
#: m/s at which a swing foot eases into (and out of) the offset from its target at which the
#: other leg holds it (self-collision avoidance).
EASE_SPEED = 0.25
#: Metres an eased offset must differ from the first pass's before a target moves.
EASE_TOLERANCE = 0.005
#: m/s: a held-off foot's offset that changes faster than this anywhere from the frame before
#: its hold to the one after snaps (the robot's left foot on the PyMO walk: 7.4 m/s); a hold
#: whose offset changes more slowly is left alone.
SNAP_SPEED = 2.0
#: Metres: an offset that changes by more than this in one frame snaps too, whatever the
#: frame rate (a visible jump, the fidelity figures' pop: at 30 Hz :data:`SNAP_SPEED` alone
#: lets a foot jump 6.7 cm in a frame; the robot's left foot on the Bandai walk was held
#: 3-4 cm behind and above its target by the other foot for one frame, twice).  At 120 Hz
#: :data:`SNAP_SPEED` is the tighter test (1.7 cm a frame).
SNAP_STEP = 0.02


def _snapping_runs(offsets: np.ndarray, held: np.ndarray, fps: float) -> np.ndarray:
    """``(F,)`` bool: the frames of the runs of ``held`` whose ``offsets (F, 3)`` (zero off the
    runs) change faster than :data:`SNAP_SPEED`, or by more than :data:`SNAP_STEP` in a frame,
    somewhere from the frame before the run to the one after it (a foot that slides past the
    other leg's geom and snaps off it while still at the margin, the bundled robot's left foot
    on the CMU walk, frame 77)."""
    F = len(held)
    out = np.zeros(F, dtype=bool)
    speed = np.zeros(F + 1)
    speed[1:F] = np.linalg.norm(np.diff(offsets, axis=0), axis=1) * fps  # speed[t]: frames t-1 -> t
    edges = np.flatnonzero(np.diff(np.concatenate([[0], held.astype(np.int8), [0]])))
    for a, b in zip(edges[::2], edges[1::2]):  # the run is frames a .. b-1
        if float(speed[a : b + 1].max()) > min(SNAP_SPEED, SNAP_STEP * fps):
            out[a:b] = True
    return out


def eased_foot_shifts(traj, labels: Mapping[str, np.ndarray], options) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per swing foot that the other leg held off its target in ``traj`` (one of its collision
    geoms at the self-collision margin, within a millimetre) and that snapped (its offset
    changing faster than :data:`SNAP_SPEED`, or by more than :data:`SNAP_STEP` in a frame,
    somewhere in the hold or at its ends), ``((F, 3) shift, columns)``: its ankle's offsets from
    its target on those frames (horizontal, and upwards), eased in time
    (:func:`eased_offsets`; zero on the frames the foot is labelled in contact), for its
    ankle, toe and toe tip targets.  The foot then goes round the other leg instead of
    sliding along it behind its target and snapping back when it clears it (the robot's left
    foot on the PyMO walk, 6 cm in one frame).  ``traj``: a
    :class:`~physmocap.trajectory.Trajectory` with its targets; ``options``: its
    :class:`~physmocap.ik.solver.SolverOptions`.  The trajectory and its targets are read
    :data:`~physmocap.spill.BLOCK_ROWS` frames at a time (a spilled clip's pages let go after
    each block)."""
    if not options.self_collision:
        return []
    from ..models.geometry import foot_bodies
    from ..models.selfcollision import pair_distances, self_collision_pairs

    character = traj.character
    model = character.model
    names = list(traj.targets.names)
    feet = foot_bodies(model, character.contacts)
    pairs = self_collision_pairs(character)
    sides = {}
    for side in ("left", "right"):
        ankle = f"{side}_ankle"
        mine = [p for p in pairs if {int(model.geom_bodyid[g]) for g in p} & set(feet.get(side, ()))]
        if ankle in names and ankle in character.tracked and mine:
            sides[side] = (character.tracked[ankle], mine)
    if not sides:
        return []
    data = mujoco.MjData(model)
    F = traj.qpos.shape[0]
    where = {side: np.empty((F, 3)) for side in sides}
    blocked = {side: np.zeros(F, dtype=bool) for side in sides}
    for s, rows in blocks(traj.qpos):
        for t, q in enumerate(rows, start=s):
            data.qpos[:] = q
            mujoco.mj_kinematics(model, data)
            for side, (frame, mine) in sides.items():
                i = frame.object_id(model)
                where[side][t] = data.site_xpos[i] if frame.kind == "site" else data.xpos[i]
                blocked[side][t] = float(pair_distances(model, data, mine).min()) <= options.self_collision_margin + 1e-3
    out = []
    for side in sides:
        if not blocked[side].any():
            continue
        ankle = f"{side}_ankle"
        col = names.index(ankle)
        offsets = where[side]
        for s, rows in blocks(traj.targets.positions):
            offsets[s : s + rows.shape[0]] -= rows[:, col]
        # upwards too (a foot held up over the other foot eases up to it: the robot's on the
        # Bandai walk), never down (the floor and the swing clearance already hold it up)
        offsets[:, 2] = np.maximum(offsets[:, 2], 0.0)
        down = np.zeros(F, dtype=bool)
        for part in ("heel", "toe"):
            if f"{side}_{part}" in labels:
                down |= np.asarray(labels[f"{side}_{part}"], dtype=bool)[:F]
        offsets[~blocked[side] | down] = 0.0
        offsets[~_snapping_runs(offsets, blocked[side] & ~down, traj.fps)] = 0.0
        shift = eased_offsets(offsets, traj.fps, EASE_SPEED, EASE_TOLERANCE, pinned=down)
        if shift.any():
            cols = np.array([names.index(n) for n in (ankle, f"{side}_toe", f"{side}_toe_end") if n in names], dtype=int)
            out.append((shift, cols))
    return out


def moving_joints(model: mujoco.MjModel) -> list[int]:
    """The hinge and slide joints (ids, ascending): a free root's motion is left to the
    tasks (and a ball joint, which a posture value per coordinate cannot pull)."""
    return [j for j in range(model.njnt) if int(model.jnt_type[j]) in MOVING_TYPES]


def _up(model: mujoco.MjModel, body: int) -> set[int]:
    """``body`` and the bodies above it, up to (not including) the world."""
    out = set()
    while body > 0:
        out.add(body)
        body = int(model.body_parentid[body])
    return out


def carried_targets(character, names: Sequence[str], joints: Sequence[int], contacts: Sequence[str]) -> list[np.ndarray]:
    """Per joint, the target columns (of canonical ``names``) whose fast motion keeps it on the
    first pass's own pose instead of the low-pass: those whose tracked frame is on the joint's
    body or below it; none for a joint that carries one of the ``contacts`` (canonical joints
    of the parts in contact: its catch-ups at their changes are what the low-pass is for)."""
    model = character.model
    above = [_up(model, character.tracked[n].body_id(model)) for n in names]
    touching = set().union(*(above[names.index(c)] for c in contacts if c in names))
    return [
        np.zeros(0, dtype=int) if int(model.jnt_bodyid[j]) in touching
        else np.array([k for k, up in enumerate(above) if int(model.jnt_bodyid[j]) in up], dtype=int)
        for j in joints
    ]


class TransitionGuides:
    """Frame -> the :class:`~physmocap.ik.branches.Guide` of the last pass (module docstring).

    Every frame pulls the hinge and slide ``joints`` with ``cost`` per radian (metre): on
    the frames within ``window`` seconds of a label change towards ``qpos`` low-passed by a
    Gaussian of ``sigma`` seconds (a joint only where the same low-pass moves none of the
    target ``positions`` it carries by more than ``tolerance``), elsewhere towards
    ``qpos`` itself; ``arms`` (frame -> guide of the arm passes) keep their joints.  The
    reference is low-passed :data:`BLOCK_FRAMES` at a time as the pass reaches them (the same
    numbers as the whole clip at once), so an hour-long clip holds one block, and the pages of
    spilled arrays it reads are let go block by block (:func:`~physmocap.spill.release`;
    frames are asked for in order).

    Args:
        model: The character's model.
        qpos: ``(F, nq)`` the pass to smooth (read, not copied).
        positions: ``(F, N, 3)`` the targets it tracked (metres; read, not copied).
        fps: Frame rate.
        labels: Contact name -> ``(F,)`` bool.
        joints: The joints pulled (ids; :func:`moving_joints`).
        carried: Per joint, the target columns it carries (:func:`carried_targets`).
        window, sigma: Seconds.
        cost: Cost per radian (metre) of the pull.
        tolerance: Metres.
        arms: Frame -> arm guide (:mod:`.branches`).
        valid: ``(F, N)`` which targets are tracked (None: all); a target lost within the
            low-pass's reach of a frame is not fast motion there (its stand-in position jumps).
    """

    def __init__(self, model: mujoco.MjModel, qpos: np.ndarray, positions: np.ndarray, fps: float,
                 labels: Mapping[str, np.ndarray], joints: Sequence[int], carried: Sequence[np.ndarray],
                 window: float, sigma: float, cost: float, tolerance: float,
                 arms: Mapping[int, Guide] | None = None, valid: np.ndarray | None = None) -> None:
        self.qpos = qpos
        self.positions = positions
        self.valid = valid
        self.near = change_windows(labels, qpos.shape[0], int(round(window * fps)))
        joints = [int(j) for j in joints]
        if not joints or cost <= 0.0:
            self.near[:] = False  # nothing to pull: no pass
        self.adr = model.jnt_qposadr[joints].astype(int)
        self.dofs = model.jnt_dofadr[joints].astype(int)
        self.carried = [np.asarray(c, dtype=int) for c in carried]
        self.sigma = float(sigma) * float(fps)
        self.cost = float(cost)
        self.tolerance = float(tolerance)
        self.arms = dict(arms or {})
        self._block = -1
        self._reference = np.zeros((0, len(joints)))
        self._keep = np.zeros((0, len(joints)), dtype=bool)

    def __len__(self) -> int:
        """Frames with a guide: every frame."""
        return int(self.qpos.shape[0])

    def _low_pass(self, x: np.ndarray) -> np.ndarray:
        """``x`` low-passed along its first axis (mode "nearest": the clip's end values repeat)."""
        if self.sigma <= 0:
            return x
        return gaussian_filter1d(x, self.sigma, axis=0, mode="nearest", truncate=TRUNCATE)

    def _block_at(self, t: int) -> int:
        """Low-pass the block of frame ``t`` (the reference and which joints are pulled) if it
        is not the current one; returns ``t``'s row in it."""
        b = t // BLOCK_FRAMES
        if b != self._block:
            F = self.qpos.shape[0]
            pad = int(TRUNCATE * self.sigma + 0.5) + 1  # inside the clip the pad is real data
            lo, hi = max(0, b * BLOCK_FRAMES - pad), min(F, (b + 1) * BLOCK_FRAMES + pad)
            rows = slice(b * BLOCK_FRAMES - lo, b * BLOCK_FRAMES - lo + BLOCK_FRAMES)
            self._reference = self._low_pass(np.asarray(self.qpos[lo:hi][:, self.adr], dtype=float))[rows]
            x = np.asarray(self.positions[lo:hi], dtype=float)
            moved = np.linalg.norm(self._low_pass(x) - x, axis=-1)[rows]  # (block, N) metres
            fast = moved > self.tolerance
            if self.valid is not None:  # a lost target (held at a stand-in) is no fast motion
                reach = int(TRUNCATE * self.sigma + 0.5)
                tracked = minimum_filter1d(np.asarray(self.valid[lo:hi], dtype=np.uint8), 2 * reach + 1, axis=0,
                                           mode="nearest")[rows]
                fast &= tracked.astype(bool)
            self._keep = np.stack([~fast[:, c].any(axis=1) for c in self.carried], axis=1) if self.carried else \
                np.ones((len(moved), 0), dtype=bool)
            self._block = b
            for array in (self.qpos, self.positions, self.valid):  # spilled: the pages read leave the memory
                release(array)
        return t - b * BLOCK_FRAMES

    def get(self, t: int) -> Guide:
        """Frame ``t``'s guide: the reference (module docstring), the arm passes' guide for
        its joints, and the first pass's pose to start from."""
        r = self._block_at(t)  # each block once, in order: the spilled pages let go as it goes
        start = np.array(self.qpos[t], dtype=float)
        values = start[self.adr]
        if self.near[t]:
            values = np.where(self._keep[r], self._reference[r], values)
        arm = self.arms.get(t)
        if arm is None:
            return Guide(self.adr, self.dofs, values, self.cost, start, follow=True)
        mine = ~np.isin(self.adr, arm.qpos)
        return Guide(
            qpos=np.concatenate([self.adr[mine], arm.qpos]),
            dofs=np.concatenate([self.dofs[mine], arm.dofs]),
            values=np.concatenate([values[mine], arm.values]),
            cost=np.concatenate([np.full(int(mine.sum()), self.cost), np.broadcast_to(arm.cost, arm.qpos.shape)]),
            start=start,
            follow=True,
        )
