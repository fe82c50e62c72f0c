r"""Finding capture glitches in a motion's own skeleton.

Detectors (all thresholds in :class:`CleanOptions`, in seconds and degrees, never frames):

* **Jumps** (spikes, flips, discontinuities) on every animated joint's local rotation
  :math:`q_j(t)`.  The frame-to-frame angle :math:`\omega(t) = \angle(q(t-1), q(t))`
  (sign-invariant: a quaternion sign flip is not a rotation) is a *jump* where it exceeds
  ``jump_deg`` and ``jump_ratio`` times the median of its neighbours over
  ``context_time`` (fast real motion, a kick or a spin, moves every frame, a glitch
  moves in one).  A jump followed, within ``max_glitch_time``, by a jump that undoes it
  (to within ``return_ratio``), both faster than ``pair_speed`` degrees per second, marks
  the frames between as a ``flip`` (a jump of 150 degrees or more) or, if the joint holds
  there poses it takes nowhere else in the clip (``novelty_ratio``), a ``spike``; any other
  jump faster than ``max_speed`` in both its local rotation and its world orientation is a
  ``discontinuity`` (reported on its frame).
* **Frozen** joints: a joint whose rotation stays exactly the same for ``frozen_time`` or
  longer while it moves before and after and the rest of the body moves meanwhile; a value
  held in several separate runs is a limit the capture's own solver clamps to, not a freeze,
  unless one run outlasts every other hold of it and ends with the joint catching up (a joint
  frozen as it leaves its limit): past the limit's longest other hold, that run is frozen.
* **Positional sources** (:mod:`.positional`): bone stretch, gaps, frozen joints and
  left/right swaps.
* **Anatomical**: a knee, elbow, hip or trunk angle beyond its range of motion
  (:mod:`.anatomy`), named by movement and plane ("left knee hyperextension",
  sagittal); spans longer than ``max_glitch_time`` are reported only.

Each :class:`Glitch` names its type, the joint, the frames (inclusive, in the motion's
numbering) and a severity (degrees or metres).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Callable, Sequence

import numpy as np

from ..motion import Motion
from .options import CleanOptions

__all__ = ["CleanOptions", "Glitch", "detect_glitches", "anatomical_glitches", "joint_angles_step"]


@dataclass(frozen=True)
class Glitch:
    """One glitch: ``kind`` on ``joint`` over frames ``start..end`` (inclusive).

    ``movement`` and ``plane`` name the anatomical movement of an ``anatomical`` glitch
    ("left knee hyperextension", "sagittal"); ``other`` the joint an ``lr_swap`` traded
    places with; ``repairable`` is False for one the correction must leave alone (an
    out-of-range span too long to be a glitch)."""

    kind: str
    joint: str
    start: int
    end: int
    severity: float
    unit: str = "deg"
    corrected: str = field(default="", compare=False)
    movement: str = ""
    plane: str = ""
    repairable: bool = field(default=True, compare=False)
    other: str = ""

    def as_dict(self) -> dict:
        return asdict(self)


def _angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle (degrees) between unit quaternions ``(..., 4)``, sign-invariant."""
    d = np.abs(np.sum(a * b, axis=-1))
    return np.degrees(2.0 * np.arccos(np.clip(d, 0.0, 1.0)))


def joint_angles_step(rotations: np.ndarray) -> np.ndarray:
    """``(F, J)`` frame-to-frame rotation angle in degrees (0 on frame 0)."""
    out = np.zeros(rotations.shape[:2])
    out[1:] = _angle(rotations[1:], rotations[:-1])
    return out


def _neighbour_median(x: np.ndarray, half: int) -> np.ndarray:
    """Median of ``x (F,)`` over ``t - half .. t + half`` excluding ``t`` and its direct
    neighbours (a glitch's own jumps); edges repeat the nearest value."""
    from scipy.ndimage import median_filter

    footprint = np.ones(2 * half + 1, dtype=bool)
    footprint[half - 1 : half + 2] = False
    return median_filter(x, footprint=footprint, mode="nearest")


@dataclass(frozen=True)
class Limb:
    r"""What a joint's rotation moves, to tell its own jumps from a solver's redistribution.

    Attributes:
        world: ``(F, 4)`` the joint's world orientation (x-y-z-w).
        carried: ``(F,)`` degrees: the largest world-orientation step of its animated
            children on each frame (None: it has none; a leaf carries nothing to compare).
        reach: ``(F,)`` metres: the largest step of its descendants' positions relative
            to the joint, :math:`\max_d |(p_d - p_j)(t) - (p_d - p_j)(t-1)|` (None: no
            descendants).
    """

    world: np.ndarray
    carried: np.ndarray | None = None
    reach: np.ndarray | None = None


def limbs(motion: Motion, positions: np.ndarray, world: np.ndarray, joints: list[int]) -> dict[int, Limb]:
    """:class:`Limb` of each of ``joints`` from the world ``positions (F, J, 3)`` and
    ``world`` rotations ``(F, J, 4)`` of ``motion``."""
    sk = motion.skeleton
    F = len(world)
    out = {}
    for j in joints:
        kids = [c for c in sk.children(j) if not sk.end_site[c] and c in joints]
        carried = None
        if kids:
            carried = np.zeros(F)
            carried[1:] = np.max(_angle(world[1:, kids], world[:-1, kids]), axis=1)
        below = _descendants(sk.parents, j)
        reach = None
        if below:
            rel = positions[:, below] - positions[:, [j]]
            reach = np.zeros(F)
            reach[1:] = np.max(np.linalg.norm(rel[1:] - rel[:-1], axis=-1), axis=1)
        out[j] = Limb(world[:, j], carried, reach)
    return out


def _descendants(parents: np.ndarray, j: int) -> list[int]:
    """Every joint below ``j`` (end sites included)."""
    out, todo = [], [j]
    while todo:
        kids = np.flatnonzero(parents == todo.pop()).tolist()
        out += kids
        todo += kids
    return out


@dataclass(frozen=True)
class _Steps:
    """One joint's frame-to-frame motion as the jump tests read it (all ``(F,)``).

    Attributes:
        step: Degrees its local rotation turns from the frame before.
        wstep: Degrees its world orientation turns (``step`` when nothing says).
        own: Its own motion next to each frame: the median step over ``context_time``
            before or after, whichever is larger (degrees).
        entry, exit: Jumps that can start a glitch (5 times the motion before them: a step
            that only continues an acceleration is no entry) and end one (the motion after).
        jumps: Frame indices of every jump (``jump_deg`` and ``jump_ratio`` times its
            neighbours' median), none within the reference pose's exit.
        half: Frames in ``context_time``.
    """

    step: np.ndarray
    wstep: np.ndarray
    own: np.ndarray
    entry: np.ndarray
    exit: np.ndarray
    jumps: np.ndarray
    half: int


def _joint_steps(rot: np.ndarray, fps: float, opt: CleanOptions, skip: int, limb: Limb | None) -> _Steps:
    """The :class:`_Steps` of a joint's local rotations ``rot (F, 4)`` (``limb``: its world
    orientation, if known; ``skip``: the reference pose's exit steps)."""
    from numpy.lib.stride_tricks import sliding_window_view

    F = len(rot)
    step = np.zeros(F)
    step[1:] = _angle(rot[1:], rot[:-1])
    wstep = step
    if limb is not None:
        wstep = np.zeros(F)
        wstep[1:] = _angle(limb.world[1:], limb.world[:-1])
    half = max(2, int(round(opt.context_time * fps)))
    ref = _neighbour_median(step, half)
    is_jump = (step > opt.jump_deg) & (step > opt.jump_ratio * ref)
    is_jump[: skip + 1] = False
    # one side of a glitch's entry (the frames before it) and of its exit (the frames after)
    # is the joint's real motion: a step that only continues an acceleration is no entry
    win = sliding_window_view(np.pad(step, half, mode="edge"), half)
    before = np.median(win[:F], axis=1)  # t-half .. t-1
    after = np.median(win[half + 1 : half + 1 + F], axis=1)  # t+1 .. t+half
    own = np.maximum(before, after)  # the joint's own motion next to a jump, on its busier side
    entry = is_jump & (step > opt.jump_ratio * before)
    exit_ = is_jump & (step > opt.jump_ratio * after)
    return _Steps(step, wstep, own, entry, exit_, np.flatnonzero(is_jump), half)


def _pair_jumps(rot: np.ndarray, s: _Steps, fps: float, opt: CleanOptions) -> tuple[list[tuple[int, int]], list[int]]:
    r"""``(pairs, unpaired)``: each jump that can start a glitch paired with the first later
    one (within ``max_glitch_time``) that can end it and *undoes* it, both faster than
    ``pair_speed`` (:func:`_jumps`); the jumps left, in frame order."""
    from ..rotations import quat_conj, quat_mul

    step, jumps = s.step, s.jumps
    inv = quat_conj(rot)
    D = np.zeros_like(rot)
    E = np.zeros_like(rot)
    D[1:] = quat_mul(rot[1:], inv[:-1])  # q_t q_{t-1}^-1
    E[1:] = quat_mul(inv[:-1], rot[1:])  # q_{t-1}^-1 q_t
    identity = np.array([0.0, 0.0, 0.0, 1.0])
    longest = max(1, int(round(opt.max_glitch_time * fps)))
    used: set[int] = set()
    pairs: list[tuple[int, int]] = []
    unpaired: list[int] = []
    for a in jumps:
        if a in used:
            continue
        back = None
        for b in jumps[(jumps > a) & (jumps <= a + longest)] if s.entry[a] else ():
            if b in used or not s.exit[b]:
                continue
            # what is left of the entry after the exit: the joint's own motion on those two frames
            tol = min(opt.return_ratio * min(step[a], step[b]), 2.0 * (s.own[a] + s.own[b]) + opt.return_deg)
            undo = min(float(_angle(quat_mul(D[b], D[a]), identity)), float(_angle(quat_mul(E[a], E[b]), identity)))
            if undo <= tol or _angle(rot[b], rot[a - 1]) <= tol:
                back = b
                break
        if back is not None and min(step[a], step[back]) * fps > opt.pair_speed:
            used.update((int(a), int(back)))
            pairs.append((int(a), int(back)))
        else:
            used.add(int(a))
            unpaired.append(int(a))
    return pairs, unpaired


def _classify_pairs(
    rot: np.ndarray,
    s: _Steps,
    pairs: list[tuple[int, int]],
    single: Callable[[int], bool],
    opt: CleanOptions,
    joint: str,
    skip: int,
    limb: Limb | None,
) -> list[Glitch]:
    """Each paired span a ``flip`` (a jump of ``flip_deg`` or more), a ``spike`` (carried by
    the segment and its children, to poses the joint takes nowhere else unless both jumps are
    impossible on their own), or else each of its jumps that is a discontinuity on its own
    (``single``, :func:`_single_jump`)."""
    F = len(rot)
    step, wstep = s.step, s.wstep
    # the poses the joint takes elsewhere: not its reference pose nor any candidate span (two
    # glitches of one joint do not vouch for each other)
    elsewhere = np.ones(F, dtype=bool)
    elsewhere[: skip + 1] = False
    for a, b in pairs:
        n = max(2, b - a)
        elsewhere[max(0, a - n) : b + n] = False
    out: list[Glitch] = []
    for a, b in pairs:
        size = float(np.max(_angle(rot[a:b], rot[a - 1])))
        carried = limb is None or all(_carried(step, wstep, limb.carried, t, opt.carry_ratio) for t in (a, b))
        # two impossible jumps that undo each other are a spike wherever they go
        familiar = not (single(a) and single(b)) and _novelty(rot[a:b], rot[elsewhere]) < opt.novelty_ratio * step[a]
        if step[a] < opt.flip_deg and (not carried or familiar):
            # a pop to a pose the joint takes anyway, or one the next joint undoes: each jump on its own
            out += [Glitch("discontinuity", joint, t, t, float(step[t])) for t in (a, b) if single(t)]
            continue
        kind = "flip" if size >= opt.flip_deg else "spike"
        out.append(Glitch(kind, joint, a, b - 1, size))
    return out


def _jumps(rot: np.ndarray, fps: float, opt: CleanOptions, joint: str, skip: int = 0, limb: Limb | None = None) -> list[Glitch]:
    r"""Spikes, flips and discontinuities of one joint's local rotation ``(F, 4)``.

    A *jump* is a step :math:`\omega(t)` above ``jump_deg`` and ``jump_ratio`` times its
    neighbours' median (:func:`_joint_steps`).  A jump at :math:`a` is paired with the
    first later jump at :math:`b` (within ``max_glitch_time``) that *undoes* it
    (:func:`_pair_jumps`): the exit step composed with the entry step is the identity up
    to ``return_ratio`` of the jump, in either convention (an offset applied in the
    parent's frame, :math:`D_b D_a \approx 1` with :math:`D_t = q_t q_{t-1}^{-1}`, or in
    the joint's own, :math:`E_a E_b \approx 1` with :math:`E_t = q_{t-1}^{-1} q_t`), or the
    joint is back where it was before :math:`a`.  This does not depend on how far the real
    joint moves during a long glitch, and two unrelated jumps of a noisy joint (a toe
    snapping at two landings) do not pair.  A paired glitch needs both jumps faster than
    ``pair_speed`` (lower than the single-jump limit: real motion seldom jumps out and
    back) and (:func:`_classify_pairs`), unless it is a flip, poses that the joint takes
    nowhere else in the clip (``novelty_ratio``, :func:`_novelty`; not asked when both
    jumps are discontinuities on their own) and both jumps carried by its segment and
    children (:func:`_carried`, when ``limb`` says what it carries); an unpaired jump (or
    one whose pair fails those) is a ``discontinuity`` only if it is faster than
    ``max_speed`` both in the joint's local rotation and in its world orientation (a local
    jump its parent's jump cancels, a solver moving a twist from one joint to the next,
    moves no segment), and moves the limb below the joint ``jump_distance`` metres farther
    than the limb's own motion on the neighbouring frames (:func:`_single_jump`).
    """
    s = _joint_steps(rot, fps, opt, skip, limb)
    if not len(s.jumps):
        return []
    single = _single_jump(s.step, s.wstep, limb, s.half, opt.max_speed / fps, opt.jump_distance)
    pairs, unpaired = _pair_jumps(rot, s, fps, opt)
    out = [Glitch("discontinuity", joint, a, a, float(s.step[a])) for a in unpaired if single(a)]
    out += _merge_overlapping(_classify_pairs(rot, s, pairs, single, opt, joint, skip, limb))
    return sorted(out, key=lambda g: g.start)


def _merge_overlapping(glitches: list[Glitch]) -> list[Glitch]:
    """Spikes and flips of one joint whose spans overlap are one glitch: a jump spread over
    two frames (a clip resampled above its capture rate interpolates a 180-degree flip's
    entry and exit through 90 degrees) pairs twice.  The union span, a flip if either is,
    the larger severity; the other glitches unchanged, in order."""
    spans = sorted((g for g in glitches if g.kind in ("spike", "flip")), key=lambda g: g.start)
    merged: list[Glitch] = []
    for g in spans:
        if merged and g.start <= merged[-1].end:
            m = merged[-1]
            kind = "flip" if "flip" in (m.kind, g.kind) else "spike"
            merged[-1] = Glitch(kind, m.joint, m.start, max(m.end, g.end), max(m.severity, g.severity))
        else:
            merged.append(g)
    if len(merged) == len(spans):
        return glitches
    return [g for g in glitches if g.kind not in ("spike", "flip")] + merged


def _carried(step: np.ndarray, wstep: np.ndarray, carried: np.ndarray | None, t: int, ratio: float) -> bool:
    """Does the jump on frame ``t`` turn the joint's segment and what it carries: its world
    step at least ``ratio`` of its local ``step`` (the parent does not turn it back), and
    some child's world step (``carried``, None for a joint that carries none) at least
    ``ratio`` of its world step (the children do not turn it back)?"""
    return bool(wstep[t] >= ratio * step[t] and (carried is None or carried[t] >= ratio * wstep[t]))


def _single_jump(step: np.ndarray, wstep: np.ndarray, limb: Limb | None, half: int, most: float, distance: float):
    """Predicate on a frame ``t``: is the jump there a discontinuity on its own?  Faster than
    ``most`` degrees per frame in the local ``step`` and the world ``wstep``, and moving the
    limb (``limb.reach``) ``distance`` metres farther than its median step over ``half``
    frames each side."""
    excess = None
    if limb is not None and limb.reach is not None:
        excess = limb.reach - _neighbour_median(limb.reach, half)

    def single(t: int) -> bool:
        return bool(min(step[t], wstep[t]) > most and (excess is None or excess[t] > distance))

    return single


def _novelty(span: np.ndarray, elsewhere: np.ndarray) -> float:
    """Median over the rotations ``span (n, 4)`` of the angle (degrees) to the nearest of the
    rotations ``elsewhere (m, 4)`` (180 when there are none)."""
    if not len(elsewhere):
        return 180.0
    # |<q_t, q>| is largest for the nearest rotation: one matrix product for the whole span
    dots = np.abs(span @ elsewhere.T).max(axis=1)
    return float(np.median(np.degrees(2.0 * np.arccos(np.clip(dots, 0.0, 1.0)))))


def _held_runs(values: np.ndarray) -> tuple[list[tuple[int, int]], list[tuple]]:
    """``(runs, held)``: the ``[first, last]`` frames of every run of at least two frames over
    which ``values (F, k)`` stay exactly the same, and the value each run holds (rounded to 1e-9,
    as a hashable tuple)."""
    same = np.zeros(len(values), dtype=bool)
    same[1:] = np.all(values[1:] == values[:-1], axis=1)
    d = np.diff(np.concatenate([[0], same.astype(np.int8), [0]]))
    runs = [(s - 1, e) for s, e in zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1) - 1)]  # run's first frame too
    return runs, [tuple(np.round(values[a], 9)) for a, _ in runs]


def _frozen(
    values: np.ndarray, step: np.ndarray, moving: np.ndarray, fps: float, opt: CleanOptions, joint: str, still: float,
    twin_runs: Sequence[tuple[tuple[int, int], tuple]] = (), undone: frozenset[int] = frozenset(),
) -> list[Glitch]:
    """Runs where a joint's ``values (F, k)`` (a rotation, or a position) stay exactly the same
    while the body moves (``moving (F,)``), or that end with the joint catching up: its first
    ``step (F,)`` after the run (degrees or metres per frame) ``jump_ratio`` times its median
    step over the ``context_time`` after (a joint that really stops starts again smoothly;
    one whose value stopped updating jumps to where it had got to; steps below ``still``, per
    frame, count as that: the capture's noise floor).

    A value held in several separate runs, by the joint or by its other side (``twin_runs``:
    the ``(run, value)`` pairs :func:`_held_runs` finds on the twin joint), is a limit the
    capture's solver clamps to (CMU's knees at full extension, the identity, in every stance),
    not a freeze: a clip cut to one stride has one such run of each knee, and the two knees hold
    the same value.  Unless the run ends catching up and lasts longer than every other run of
    that value: a joint that stops updating while it is held at its limit (a knee frozen just as
    it leaves full extension) holds the limit on, and its data jumps to where it got to when it
    comes back.  The clamp is then taken to last as long as its longest other run, and the rest
    of the run, if ``frozen_time`` or longer, is frozen.  A jump out of the limit into a span
    that comes back (a spike or flip of the joint starting on a frame of ``undone``) is that
    glitch's, not a catch-up."""
    F = len(values)
    if F < 2 or np.all(values[1:] == values[:-1]):  # never animated: not a glitch
        return []
    half = max(2, int(round(opt.context_time * fps)))
    shortest = max(3, int(round(opt.frozen_time * fps)))
    runs, held = _held_runs(values)
    out = []
    for i, ((start, e), v) in enumerate(zip(runs, held)):
        inside = start > 0 and e < F - 1  # moving before and after: a joint left still is not frozen
        if not inside or e - start + 1 < shortest:
            continue
        later = step[e + 2 : e + 2 + half]
        later = later[np.isfinite(later)]
        after = max(float(np.median(later)), still) if len(later) else np.inf
        catch_up = step[e + 1] > opt.jump_ratio * after
        clamp = [b - a + 1 for k, ((a, b), w) in enumerate(zip(runs, held)) if k != i and w == v]
        clamp += [b - a + 1 for (a, b), w in twin_runs if w == v]
        if clamp:  # a limit the capture clamps to: frozen only past its longest other hold, catching up
            start += max(clamp) - 1  # the last frame of the limit's longest hold: the last good one
            if not catch_up or e + 1 in undone or e - start + 1 < shortest:
                continue
        elif moving[start : e + 1].mean() <= 0.5 and not catch_up:
            continue
        out.append(Glitch("frozen", joint, int(start + 1), int(e), float((e - start) / fps), unit="s"))
    return out


def reference_exit(motion: Motion, opt: CleanOptions, positions: np.ndarray | None = None) -> int:
    """How many of the clip's first frame-to-frame steps are the capture leaving a reference
    pose (CMU's T-pose on frame 0), not motion: 0 if frame 0 is part of the performance.

    The steps counted are the leading ones in which the body's pose (every joint's position
    relative to the root, ``positions (F, J, 3)`` or the forward kinematics, averaged) moves
    ``jump_ratio`` times faster than its median over the ``context_time`` after, and together
    they must move it ``jump_distance`` metres or more.  A duration and a distance, not a frame
    count: resampled to 240 Hz, the jump out of CMU's T-pose spreads over two frames; at 24 Hz
    it is one frame among much larger steps of real motion.  The retargeter's own test
    (:func:`physmocap.ik.retarget.default_start`, one frame) is kept where it says more."""
    import warnings

    from ..ik.retarget import default_start

    with warnings.catch_warnings():  # the retargeter's warning about skipping it does not apply
        warnings.simplefilter("ignore")
        least = default_start(motion)
    P = np.asarray(motion.world_positions() if positions is None else positions, dtype=float)
    F = len(P)
    if F < 3:
        return least
    rel = P - P[:, :1]
    with np.errstate(invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # a frame with every joint lost
        step = np.nanmean(np.linalg.norm(rel[1:] - rel[:-1], axis=-1), axis=1)  # step k: frame k -> k+1
    half = max(2, int(round(opt.context_time * float(motion.fps))))
    count = 0
    while count < F - 2:
        later = step[count + 1 : count + 1 + half]
        later = later[np.isfinite(later)]
        if not (len(later) and step[count] > opt.jump_ratio * float(np.median(later))):
            break
        count += 1
    if not count or not np.sum(step[:count]) >= opt.jump_distance:
        count = 0
    return max(least, count)


def animated_joints(motion: Motion) -> list[int]:
    """Indices of ``motion``'s joints (not end sites) whose rotation changes at some frame."""
    R = np.asarray(motion.rotations)
    return [j for j in range(R.shape[1]) if not motion.skeleton.end_site[j] and np.ptp(R[:, j], axis=0).max() > 0]


def detect_glitches(motion: Motion, options: CleanOptions | None = None, mapping=None) -> list[Glitch]:
    """Every glitch found in ``motion`` (sorted by frame, then joint); ``mapping``: a source
    mapping file or dict (:func:`physmocap.sources.profiles.map_skeleton`) naming its joints,
    as ``retarget --source-map`` takes."""
    opt = options or CleanOptions()
    ji = canonical_joints(motion, mapping)  # once: mapping a long clip takes a good part of the time
    names = motion.skeleton.names
    glitches: list[Glitch] = []
    fps = float(motion.fps)
    if motion.is_rotational and motion.rotations is not None:
        R = np.asarray(motion.rotations, dtype=float)
        steps = joint_angles_step(R)
        animated = animated_joints(motion)
        P, W = motion.forward_kinematics()
        skip = reference_exit(motion, opt, P)  # a reference pose the capture jumps away from (CMU's T-pose)
        limb = limbs(motion, np.asarray(P, dtype=float), np.asarray(W, dtype=float), animated)
        undone: dict[int, frozenset[int]] = {}  # per joint, the first frames of its spikes and flips
        for j in animated:
            found = _jumps(R[:, j], fps, opt, names[j], skip, limb[j])
            undone[j] = frozenset(g.start for g in found if g.kind in ("spike", "flip"))
            glitches += found
        # the body moves on a frame where the median joint moves
        moving = np.median(steps[:, animated], axis=1) > opt.still_speed / fps if animated else np.zeros(len(R), bool)
        from .positional import twin_pairs  # positional imports this module

        twin = dict(p for a, b in twin_pairs(motion, ji) for p in ((a, b), (b, a)))
        for j in animated:
            twin_runs = list(zip(*_held_runs(R[:, twin[j]]))) if j in twin else ()
            glitches += _frozen(R[:, j], steps[:, j], moving, fps, opt, names[j], opt.still_speed / fps, twin_runs, undone[j])
    if motion.positions is not None:
        from .positional import positional_glitches

        glitches += positional_glitches(motion, opt, ji)
    glitches = _merge_anatomical(glitches, anatomical_glitches(motion, opt, ji, glitches), motion, ji)
    glitches = _drop_boundary_jumps(glitches)
    return sorted(glitches, key=lambda g: (g.start, g.joint, g.kind))


def _drop_boundary_jumps(glitches: list[Glitch]) -> list[Glitch]:
    """A discontinuity on the first frame of a glitch span of the same joint, or on the
    frame right after it, is that span's own entry or exit (a frozen joint catching up,
    a bend past the range of motion snapping back), not a second glitch."""
    spans: dict[str, list[tuple[int, int]]] = {}
    for g in glitches:
        if g.kind != "discontinuity":
            spans.setdefault(g.joint, []).append((g.start, g.end))
    return [
        g
        for g in glitches
        if g.kind != "discontinuity" or not any(s == g.start or e + 1 == g.start for s, e in spans.get(g.joint, ()))
    ]


def _movement_joints(motion: Motion, ji: dict[str, int], movement) -> set[int]:
    """Source joints whose local rotation can change an anatomical angle: the ancestors
    of the joint centres it is read from, except those common to all of them (which
    move them rigidly together); on a joint-position source, those joint centres
    themselves and the ones the pelvis frame is read from."""
    from .anatomy import ANCHORS

    parents = motion.skeleton.parents
    chains = []
    for c in ANCHORS.get(movement.key.replace("left_", "").replace("right_", ""), ()):
        c = c.format(side=movement.key.split("_", 1)[0])
        if c not in ji:
            continue
        if not motion.is_rotational:
            chains.append({ji[c]})
            continue
        up, p = set(), int(parents[ji[c]])
        while p >= 0:
            up.add(p)
            p = int(parents[p])
        chains.append(up)
    if not chains:
        return set()
    if not motion.is_rotational:  # and the pelvis frame they are read in: the hips and the trunk's top
        top = next((c for c in ("neck", "chest", "spine") if c in ji), None)
        return set().union(*chains) | {ji[c] for c in ("left_hip", "right_hip", top) if c in ji}
    return set().union(*chains) - set.intersection(*chains)


def canonical_joints(motion: Motion, mapping=None) -> dict[str, int]:
    """Canonical joint -> source joint index of ``motion`` (the retargeter's name mapping),
    without its warnings; empty when the skeleton cannot be mapped (the anatomical checks
    are then skipped and said so, the other detectors still run).  A ``mapping`` the user
    gives (a file or dict) is applied as given, every joint it names checked, none required.

    Raises:
        MappingError, InputError: ``mapping`` names a joint the skeleton does not have, or
            cannot be read.
    """
    import warnings

    from ..errors import MappingError
    from ..ik.retarget import map_motion

    if mapping is not None:
        from ..sources.profiles import map_skeleton

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return dict(map_skeleton(motion, mapping=mapping, required=()).indices)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return map_motion(motion)
    except MappingError:
        return {}


#: Glitches that move a joint far enough to put an anatomical angle read from it out of range.
EXPLAIN_ANATOMICAL = ("spike", "flip", "frozen", "lr_swap", "bone_stretch", "gap")


def _merge_anatomical(
    glitches: list[Glitch], anatomical: list[Glitch], motion: Motion, ji: dict[str, int]
) -> list[Glitch]:
    """An out-of-range span inside a spike, flip, frozen, swap, stretch or gap span of the
    same joint, or of a joint that moves that anatomical angle (a clavicle's spike tilts the
    shoulder line the trunk angles are read from; a knee centre swapped with the other
    bends both legs), is that glitch's anatomical
    movement, not a second glitch: name the movement on it instead (``ji``: the
    :func:`canonical_joints` of ``motion``)."""
    import dataclasses

    from .anatomy import MOVEMENTS

    names = motion.skeleton.names
    by_name = {m.where: m for m in MOVEMENTS}
    out = list(glitches)
    for a in anatomical:
        related = {a.joint}
        if ji:
            m = next((m for w, m in by_name.items() if a.movement.startswith(w + " ")), None)
            if m is not None:
                related |= {names[j] for j in _movement_joints(motion, ji, m)}
        for i, g in enumerate(out):
            if g.joint in related and g.kind in EXPLAIN_ANATOMICAL and g.start <= a.start and a.end <= g.end:
                if not g.movement and g.joint == a.joint:
                    out[i] = dataclasses.replace(g, movement=a.movement, plane=a.plane)
                break
        else:
            out.append(a)
    return out


def anatomical_glitches(
    motion: Motion, options: CleanOptions | None = None, ji: dict[str, int] | None = None,
    others: list[Glitch] | None = None,
) -> list[Glitch]:
    """Spans where an anatomical angle (:mod:`.anatomy`) leaves its range of motion
    (``ji``: the :func:`canonical_joints` of ``motion`` if the caller has them; ``others``:
    the glitches the other detectors found, whose frames the angles are not calibrated on,
    :func:`.anatomy.motion_angles`).

    A skeleton whose limbs cannot be mapped to the canonical joints gets one warning
    naming the joints whose ranges cannot be checked; the other detectors still run."""
    from ..errors import warn
    from .anatomy import MOVEMENTS, beyond_range, motion_angles, movement_range

    opt = options or CleanOptions()
    ji = canonical_joints(motion) if ji is None else ji
    unreliable = np.zeros(motion.num_frames, dtype=bool)
    for g in others or []:
        unreliable[g.start : g.end + 1] = True
    angles, _ = motion_angles(motion, ji, unreliable)
    unchecked = sorted({m.joint for m in MOVEMENTS if m.key not in angles})
    if unchecked:
        warn(f"{motion.source}: cannot check ranges of motion for joints {', '.join(unchecked)} (not mapped)")
    names = motion.skeleton.names
    out: list[Glitch] = []
    longest = opt.max_glitch_time * float(motion.fps)
    for m in MOVEMENTS:
        if m.key not in angles:
            continue
        carrier = m.joint if m.joint != "spine" else next((c for c in ("chest", "spine") if c in ji), None)
        if carrier is None or carrier not in ji:
            continue
        lo, hi = movement_range(m, opt.rom_soft_margin)
        for start, end, direction, excess in beyond_range(angles[m.key], lo, hi):
            name = m.positive if direction == "positive" else m.negative
            out.append(
                Glitch(
                    "anatomical",
                    names[ji[carrier]],
                    start,
                    end,
                    excess,
                    movement=f"{m.where} {name}",
                    plane=m.plane,
                    repairable=end - start + 1 <= longest,
                )
            )
    return out
