r"""Offline foot plan: one plant location per contact, blended in and out, never dragging the body.

Offline retargeting sees the whole clip, so each foot's targets can be made to
stand still during its contacts without any causal lag (the streaming
retargeter keeps the causal :class:`~physmocap.ik.planting.FootAnchor`).

For one foot with contact points ``p`` (heel: the ankle target; toe: the toe
target) and each contact interval :math:`k = [a_k, b_k]` of a point's label:

* the plant location is the median of that point's (scaled) target over the
  interval horizontally, :math:`A_k = \operatorname{median}_{t \in k} x_p(t)`,
  for the point that touches down first; the other points of the same contact
  get the location the same foot translation gives them (so heel and toe
  agree, :func:`_consistent_anchors`),
  and vertically the height :math:`h_p` at which the character's joint carrying the point
  stands when the point rests on the floor (from its rest pose);
* the interval's offset is :math:`o_k(t) = A_k - x_p(t)` inside it (vertically
  :math:`h_p - z_p(t)`) and is held at its end values outside it;
* its weight :math:`w_k(t)` is 1 inside the interval and falls to 0 along a
  smoothstep over ``ease_time`` seconds before :math:`a_k` and after
  :math:`b_k` (ease-in, ease-out); horizontally, where another point of the foot is down
  across an end, that ramp lies inside the interval instead (the planted point is not
  disturbed); vertically it always lies outside: a heel eased up within its interval
  was planned up to 2 cm above the floor (the actor's stance height less the
  character's) while its label still held it down, and caught up with the plan in one
  frame at toe-off;
* the foot's offset is :math:`o(t) = \sum_k w_k o_k / \max(1, \sum_k w_k)`.

A foot without toe joints (a robot's) cannot roll over its toes: it rolls over its
front edge.  Its toe contact is planned by that edge (:class:`RigidFoot`: horizontally
its front contact site, vertically its lowest material point, both carried by the
ankle's targets), and where its heel is not planned the whole foot moves by the
edge's vertical offset, so the held edge and the targets agree through the roll
instead of the plan holding its ball at its flat-stance height.  Where only that edge is
planned and the leg would not reach the ankle, the foot rises heel first about the edge,
as the actor's hind foot does over its bending toes (:func:`stance_tiptoe`), rather than the
body coming down for it (:func:`pelvis_drop`); what the turn cannot reach the body comes down
for, and the foot is then turned again for the hip where it ends up (the drop is smoothed over
its neighbours' frames, and a foot turned for the hip before it left the leg bent).  Leaving the floor, where
the actor's toes are still bent, such a foot is pitched towards level just enough to clear
the floor (:func:`swing_flatten`).

Offsets are three-dimensional: horizontally the plant location, vertically
the joint's stance height.  Only the foot moves (ankle, toe, toe tip; the knee is re-placed by two-bone
IK so thigh and shank keep their lengths); the pelvis and the rest of the body
stay on the actor's scaled path, so nothing accumulates over a clip.  Because
the whole foot is translated by the offset of the point(s) in contact, it keeps
the actor's rotation: a foot turning on its toe pivots about the toe's plant
location.  With heel and toe both in contact the two offsets are averaged, and
because each is continuous and the weights are, :math:`o(t)` is continuous
(no pop at heel strike or toe-off).  Units: metres, seconds.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import numpy as np

from ..spill import release
from .easing import rounded_above, smoothstep

__all__ = ["FootPlan", "contact_intervals", "ease_weights", "eased_mask", "foot_offsets", "pelvis_drop", "knee_between", "planted_positions", "ToeContact", "RigidFoot", "swing_flatten", "stance_tiptoe", "toe_bend", "turn_foot", "plant_body_contacts", "body_part_target", "BODY_PART_JOINTS"]


def contact_intervals(label: np.ndarray) -> list[tuple[int, int]]:
    """``[(start, end)]`` inclusive frame ranges where ``label (F,)`` is True."""
    x = np.asarray(label, dtype=bool).astype(np.int8)
    d = np.diff(np.concatenate([[0], x, [0]]))
    starts = np.flatnonzero(d == 1)
    ends = np.flatnonzero(d == -1) - 1
    return list(zip(starts.tolist(), ends.tolist()))


def ease_weights(
    num_frames: int, start: int, end: int, ease_frames: int, inside: tuple[bool, bool] = (False, False)
) -> np.ndarray:
    """``(F,)`` weight of interval ``[start, end]``: 1 inside, smoothstep ramps of ``ease_frames``.

    A ramp lies outside the interval (before ``start``, after ``end``) unless
    ``inside`` says otherwise for that end: then it lies within the interval,
    so the weight is 0 outside it (used where another contact point of the foot
    is down across that end and must not be disturbed).
    """
    t = np.arange(num_frames, dtype=float)
    if ease_frames <= 0:
        return ((t >= start) & (t <= end)).astype(float)
    s0 = start + ease_frames if inside[0] else start
    e0 = end - ease_frames if inside[1] else end
    gap = np.maximum(s0 - t, 0.0) + np.maximum(t - e0, 0.0)
    w = smoothstep(1.0 - gap / (ease_frames + 1))
    if inside[0]:
        w[t < start] = 0.0
    if inside[1]:
        w[t > end] = 0.0
    return w



def eased_mask(mask: np.ndarray, ease_frames: int) -> np.ndarray:
    """``(F,)`` 1 on the frames of ``mask (F,)``, eased in before and out after each of its
    intervals (:func:`ease_weights`, the ramps outside), overlapping ramps by their maximum;
    each interval's weights are computed over its own ramps' frames only (an hour-long
    clip's thousands of intervals)."""
    mask = np.asarray(mask, dtype=bool)
    w = np.zeros(len(mask))
    for s, e in contact_intervals(mask):
        a, b = max(0, s - ease_frames - 1), min(len(mask), e + ease_frames + 2)
        np.maximum(w[a:b], ease_weights(b - a, s - a, e - a, ease_frames), out=w[a:b])
    return w

@dataclass(frozen=True)
class FootPlan:
    """The plan of one foot over a clip (metres).

    Attributes:
        xy: ``(F, 2)`` horizontal offset of the whole foot.
        z: Contact point name -> ``(F,)`` vertical offset of the joint carrying it.
        weight: ``(F,)`` how much the foot is in contact, 0..1 (eased).
        z_weight: Contact point name -> ``(F,)`` how much its height is planned, 0..1 (eased).
    """

    xy: np.ndarray
    z: dict[str, np.ndarray]
    weight: np.ndarray
    z_weight: dict[str, np.ndarray]


def foot_offsets(
    points: Mapping[str, np.ndarray],
    labels: Mapping[str, np.ndarray],
    fps: float,
    ease_time: float,
    heights: Mapping[str, float],
) -> FootPlan:
    """The :class:`FootPlan` that plants one foot (see the module docstring).

    Args:
        points: Contact point name -> ``(F, 3)`` target position of the joint
            that carries it (heel: ankle, toe: toe joint).
        labels: The same names -> ``(F,)`` contact labels.
        fps: Frame rate.
        ease_time: Seconds over which each contact's offset eases in and out.
        heights: The same names -> height (metres) of the joint above the floor
            when its contact point rests on the floor (the character's rest pose):
            in contact that joint is held at that height (each joint on its own,
            so a foot with heel and toe down lies flat), neither hovering nor
            pulled into the floor.
    """
    F = next(iter(points.values())).shape[0]
    ease = int(round(max(ease_time, 0.0) * fps))
    num = np.zeros((F, 2))
    den = np.zeros(F)
    z: dict[str, np.ndarray] = {}
    anchors = _consistent_anchors(points, labels)
    down = {name: np.asarray(labels[name], dtype=bool) for name in points}
    z_weight: dict[str, np.ndarray] = {}
    for name, x in points.items():
        x = np.asarray(x, dtype=float)
        z_num = np.zeros(F)
        z_den = np.zeros(F)
        for a, b in contact_intervals(labels[name]):
            # an interval's weights are 0 beyond its ease ramps: only that window is summed
            # (the same sums: whole-clip arrays per interval made planting an hour-long clip
            # take minutes, growing with the square of its length)
            lo, hi = max(0, a - ease - 1), min(F, b + ease + 2)
            anchor = anchors[(name, a)]
            o = np.empty((hi - lo, 3))
            o[a - lo : b + 1 - lo, :2] = anchor - x[a : b + 1, :2]
            o[a - lo : b + 1 - lo, 2] = heights[name] - x[a : b + 1, 2]
            o[: a - lo] = o[a - lo]
            o[b + 1 - lo :] = o[b - lo]
            # another point of the foot already down at the start (still down at the end):
            # ease in (out) within the interval so the planted point is not disturbed
            others = [v for k, v in down.items() if k != name]
            before = any(v[a - 1] for v in others) if a > 0 else False
            after = any(v[b + 1] for v in others) if b + 1 < F else False
            w = ease_weights(hi - lo, a - lo, b - lo, min(ease, (b - a) // 2), (before, after))
            num[lo:hi] += w[:, None] * o[:, :2]
            den[lo:hi] += w
            # heights always ease outside the interval (module docstring)
            wz = ease_weights(hi - lo, a - lo, b - lo, ease)
            z_num[lo:hi] += wz * o[:, 2]
            z_den[lo:hi] += wz
        z[name] = z_num / np.maximum(z_den, 1.0)
        z_weight[name] = np.minimum(z_den, 1.0)
    return FootPlan(xy=num / np.maximum(den, 1.0)[:, None], z=z, weight=np.minimum(den, 1.0), z_weight=z_weight)


def _consistent_anchors(
    points: Mapping[str, np.ndarray], labels: Mapping[str, np.ndarray]
) -> dict[tuple[str, int], np.ndarray]:
    """``(point, interval start) -> (2,)`` plant location of every contact interval.

    Within one contact of the foot (overlapping intervals of its points), the
    point that touches down first is planted at its median position over its
    interval; every other point at the median of where the same foot translation
    puts it over the frames both are down (its own median where they never
    overlap).  So the points' offsets agree while both are down, and a heel
    lifting off hands over to the toe without a slide.
    """
    F = next(iter(points.values())).shape[0]
    down = np.zeros(F, dtype=bool)
    for name in points:
        down |= np.asarray(labels[name], dtype=bool)
    out: dict[tuple[str, int], np.ndarray] = {}
    for ea, eb in contact_intervals(down):
        spans = [
            (a, b, name)
            for name in points
            for a, b in contact_intervals(labels[name])
            if a <= eb and b >= ea
        ]
        spans.sort(key=lambda s: (s[0], list(points).index(s[2])))
        a0, b0, ref = spans[0]
        x0 = np.asarray(points[ref], dtype=float)[:, :2]
        out[(ref, a0)] = np.median(x0[a0 : b0 + 1], axis=0)
        for a, b, name in spans[1:]:
            x = np.asarray(points[name], dtype=float)[:, :2]
            lo, hi = max(a, a0), min(b, b0)
            if lo <= hi:
                out[(name, a)] = np.median(x[lo : hi + 1] + out[(ref, a0)] - x0[lo : hi + 1], axis=0)
            else:
                out[(name, a)] = np.median(x[a : b + 1], axis=0)
    return out


def pelvis_drop(
    hips: np.ndarray, ankles: np.ndarray, weights: np.ndarray, reach: np.ndarray, fps: float, smooth_time: float
) -> np.ndarray:
    r"""``(F,)`` how far (metres, >= 0) the body must come down for planted feet to be reachable.

    For a foot in contact (weight :math:`w > 0`) whose ankle target lies
    farther from its hip than the leg reaches (:math:`\rho`, slightly less
    than thigh plus shank), the hip must come down by
    :math:`\delta = \Delta z - \sqrt{\rho^2 - d_{xy}^2}` (:math:`\Delta z` the hip's
    height above the ankle, :math:`d_{xy}` their horizontal distance).  The
    drop is :math:`\max_{feet} w\,\delta`, then a running maximum over
    ``smooth_time`` and a moving average over it, so the pelvis moves
    smoothly (no pop at toe-off) and never less than it must.

    Args:
        hips, ankles: ``(F, 2, 3)`` per foot (left, right).
        weights: ``(F, 2)`` contact weights.
        reach: ``(2,)`` reach of each leg (metres).
    """
    dz = hips[..., 2] - ankles[..., 2]
    dxy = np.linalg.norm(hips[..., :2] - ankles[..., :2], axis=-1)
    r = reach[None, :]
    need = dz - np.sqrt(np.maximum(r * r - dxy * dxy, 0.0))
    need = np.where(dxy >= r, dz, need)
    drop = np.max(np.maximum(need, 0.0) * weights, axis=1)
    n = max(1, int(round(smooth_time * fps)))
    return rounded_above(drop, n) if n > 1 else drop


def knee_between(
    hip: np.ndarray, ankle: np.ndarray, knee0: np.ndarray, l1: float, l2: float, forward: np.ndarray | None = None
) -> np.ndarray:
    r"""Knee positions ``(F, 3)`` for hips and (moved) ankles, keeping thigh ``l1`` and shank ``l2``.

    Two-bone IK in closed form: with :math:`d = |a - h|` (clamped to the
    reachable range) and :math:`u = (a - h)/d`, the knee is
    :math:`h + x u + y p` where :math:`x = (l_1^2 - l_2^2 + d^2)/(2d)`,
    :math:`y = \sqrt{l_1^2 - x^2}` and :math:`p` the unit direction of the
    original knee ``knee0`` off the hip-ankle line (the knee keeps its plane).

    An actor's straight leg gives no plane (its knee lies on the line, and
    which side it sits on is capture noise), yet the planned ankle may need
    the character's knee to bend: the bend direction is then
    :math:`p \propto w_\perp + \epsilon\, f_\perp`, with :math:`w_\perp` the
    original knee's offset from the line, :math:`f_\perp` the unit ``forward``
    hint (the foot's direction: knees bend over the toes) off the line, and
    :math:`\epsilon = 0.05\, l_1`: a knee bent visibly keeps (mostly) its own
    plane, a straight one bends forward instead of flipping sideways.
    """
    v = ankle - hip
    d = np.linalg.norm(v, axis=-1, keepdims=True)
    u = v / np.maximum(d, 1e-9)
    d = np.clip(d, abs(l1 - l2) + 1e-6, l1 + l2 - 1e-6)
    x = (l1 * l1 - l2 * l2 + d * d) / (2.0 * d)
    y = np.sqrt(np.maximum(l1 * l1 - x * x, 0.0))
    w = knee0 - hip
    p = w - np.sum(w * u, axis=-1, keepdims=True) * u
    if forward is not None:
        f = np.broadcast_to(np.asarray(forward, dtype=float), p.shape)
        f = f - np.sum(f * u, axis=-1, keepdims=True) * u
        fn = np.linalg.norm(f, axis=-1, keepdims=True)
        p = p + 0.05 * l1 * np.where(fn > 1e-9, f / np.maximum(fn, 1e-9), 0.0)
    n = np.linalg.norm(p, axis=-1, keepdims=True)
    knee = hip + x * u + y * p / np.maximum(n, 1e-9)
    degenerate = (n[..., 0] < 1e-9) | (np.linalg.norm(v, axis=-1) < 1e-9)
    return np.where(degenerate[..., None], np.where(np.linalg.norm(v, axis=-1, keepdims=True) < 1e-9, knee0, hip + x * u), knee)


#: The canonical joints a foot's offset moves (the knee is then re-placed by :func:`knee_between`).
FOOT_JOINTS = ("ankle", "toe", "toe_end")


#: Fraction of thigh plus shank that a planted leg may reach (a fully straight knee is a
#: singular IK pose): 0.999 leaves the knee bent at least 5 degrees (0.995 forced 11.5, and
#: an actor standing with straight legs got a character with bent knees and shanks 9 degrees off).
REACH = 0.999


def planted_positions(
    positions: np.ndarray,
    names: tuple[str, ...],
    labels: Mapping[str, np.ndarray],
    fps: float,
    ease_time: float,
    leg_lengths: Mapping[str, tuple[float, float]],
    heights: Mapping[str, float],
    toe_sites: Mapping[str, "ToeContact"] | None = None,
    *,
    rigid_feet: Mapping[str, tuple["RigidFoot", np.ndarray]] | None = None,
    toe_bends: Mapping[str, np.ndarray] | None = None,
    in_place: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """Targets with both feet planted: ``(new positions (F, N, 3), foot offsets (F, 2, 2))``.

    The feet follow their :class:`FootPlan`; where a planted leg could not
    reach its foot, the rest of the body comes down smoothly by
    :func:`pelvis_drop`; the knees are re-placed by :func:`knee_between`.

    A foot with a toe segment (``toe`` and ``toe_end`` targets) and contact
    sites on it (``toe_sites``) is planned by the segment's lowest point
    (:meth:`ToeContact.lowest`): the segment keeps the actor's pitch and is
    only translated, so that its lowest point rests on the floor (a foot
    rolling over its toe tips does so), and the toe joint is never planned
    below its own stance height.  Otherwise the toe joint and the
    toe tip are each held at their stance heights (the toes lie flat).

    Args:
        positions: ``(F, N, 3)`` target positions (not modified, unless ``in_place``).
        names: Canonical joint of each target column.
        labels: ``left_heel``, ``left_toe``, ``right_heel``, ``right_toe`` -> ``(F,)`` bool.
        fps, ease_time: See :func:`foot_offsets`.
        leg_lengths: Side -> (thigh, shank) lengths of the character (metres).
        heights: Canonical joint -> its height above the floor in the character's
            rest pose (metres), for the ankle and toe joints.
        toe_sites: Side -> the :class:`ToeContact` of a foot whose toe segment
            carries contact sites (:meth:`~physmocap.ik.planting.Planting.toe_contacts`);
            None or a missing side: that foot's toes lie flat in contact.
        rigid_feet: Side -> ``(RigidFoot, (F, 4) ankle orientation targets)`` of a foot
            without toe joints: its toe contact is planned by its own front edge
            (:meth:`RigidFoot.toe_point`) and the whole foot moves as one; where only its
            toes are planned it pitches heel up about that edge for its leg to reach it, by
            at most the actor's toe bend (:func:`stance_tiptoe`; the orientation targets are
            turned in place), turned again for the hip as the body's drop leaves it.
        toe_bends: Side -> ``(F,)`` the actor's toe bend (radians, :func:`toe_bend`; a side
            without one: 0, the turn bounded by :data:`TIPTOE_LEAST`); None: rigid feet are
            not pitched.
        in_place: Plan ``positions`` themselves (a writeable float64 array the caller gives
            up; each column is read before it is changed) and return them: one
            ``(F, N, 3)`` copy less, the same numbers.  Positions in a temporary file
            (:mod:`physmocap.spill`, laid out joint by joint) have their pages let go
            as the columns are planned.
    """
    out = positions if in_place else np.array(positions, dtype=float, copy=True)
    F = out.shape[0]
    offsets = np.zeros((F, 2, 2))
    col = {n: i for i, n in enumerate(names)}
    feet = np.zeros(len(names), dtype=bool)
    legs = []
    tiptoes = []  # the rigid feet turned heel up: (orientation targets, arguments of _tiptoe, what it changed)
    for s, side in enumerate(("left", "right")):
        ankle = f"{side}_ankle"
        if ankle not in col:
            continue
        heel_label = np.asarray(labels.get(f"{side}_heel", np.zeros(F, bool)), dtype=bool)
        toe_label = np.asarray(labels.get(f"{side}_toe", np.zeros(F, bool)), dtype=bool)
        toe, tip = f"{side}_toe", f"{side}_toe_end"
        segment = toe_sites.get(side) if toe_sites and toe in col and tip in col else None
        rigid = (rigid_feet or {}).get(side)
        if rigid is not None:  # one rigid body: planned by its ankle and its own front edge
            pts = {ankle: positions[:, col[ankle]], "front": rigid[0].toe_point(positions[:, col[ankle]], rigid[1])}
            lab = {ankle: heel_label, "front": toe_label}
            hts = {ankle: heights[ankle], "front": rigid[0].height}
        elif segment is not None:  # the toe segment's contact sites carry the toe contact
            # held horizontally at the toe tip joint (the lowest candidate may switch ends of
            # the segment), vertically by the segment's lowest point
            site = np.concatenate([positions[:, col[tip], :2], segment.lowest(positions[:, col[toe]], positions[:, col[tip]])[:, 2:]], axis=1)
            pts = {ankle: positions[:, col[ankle]], "toe_sites": site}
            lab = {ankle: heel_label, "toe_sites": toe_label}
            hts = {ankle: heights[ankle], "toe_sites": segment.height}
        else:  # the joints carrying each contact point: heel -> ankle, toe -> toe joint and tip
            group = [j for j in (toe, tip) if j in col] or [ankle]
            pts = {j: positions[:, col[j]] for j in [ankle, *group]}
            lab = {ankle: heel_label, **{j: toe_label for j in group}}
            if group == [ankle]:  # no toe joint: the ankle carries both contact points
                lab[ankle] = heel_label | toe_label
            hts = {j: heights[j] for j in pts}
        plan = foot_offsets(pts, lab, fps, ease_time, hts)

        def own_height(j: str) -> np.ndarray:
            """Joint ``j``'s own vertical plan at its stance height while the toes are down
            (read before the foot's heights move: only its horizontal offset is in yet)."""
            return foot_offsets({j: positions[:, col[j]]}, {j: toe_label}, fps, ease_time, {j: heights[j]}).z[j]

        if segment is not None:  # the toe joint as it was, read before the foot is moved
            own = own_height(toe)
        offsets[:, s] = plan.xy
        moved = [col[f"{side}_{j}"] for j in FOOT_JOINTS if f"{side}_{j}" in col]
        feet[moved] = True
        out[:, moved, :2] += plan.xy[:, None, :]
        if rigid is not None:
            # while the heel is planned, each joint at its own stance height (the foot lies
            # flat, as with toes); where it is not, the whole foot by its front edge's height
            rolled = (1.0 - plan.z_weight[ankle]) * plan.z["front"]
            out[:, col[ankle], 2] += plan.z[ankle] + rolled
            for j in (f"{side}_{k}" for k in FOOT_JOINTS[1:]):
                if j in col:
                    out[:, col[j], 2] += plan.z_weight[ankle] * own_height(j) + rolled
        for j in pts if rigid is None else ():
            if j in col:
                out[:, col[j], 2] += plan.z[j]
        if segment is not None:
            out[:, col[tip], 2] += plan.z["toe_sites"]
            out[:, col[toe], 2] += np.maximum(plan.z["toe_sites"], own)
        hip, knee = f"{side}_hip", f"{side}_knee"
        if side in leg_lengths and hip in col and knee in col:
            feet[col[knee]] = True
            legs.append((side, col[hip], col[knee], col[ankle], leg_lengths[side], plan.weight))
            if rigid is not None and toe_bends is not None:
                args = (out, col, side, rigid, REACH * sum(leg_lengths[side]),
                        plan.z_weight["front"] * (1.0 - plan.z_weight[ankle]), toe_bends.get(side, np.zeros(F)))
                tiptoes.append((rigid[1], args, _tiptoe(*args)))
        release(out)  # positions in a temporary file (physmocap.spill): the pages read leave the memory
    if legs:
        hips = np.stack([out[:, h] for _, h, _, _, _, _ in legs], axis=1)
        ankles = np.stack([out[:, a] for _, _, _, a, _, _ in legs], axis=1)
        weights = np.stack([w for *_, w in legs], axis=1)
        reach = np.array([REACH * (l1 + l2) for *_, (l1, l2), _ in legs])
        drop = pelvis_drop(hips, ankles, weights, reach, fps, ease_time)
        for i in np.flatnonzero(~feet):  # column by column: spilled positions map one in at a time
            out[:, i, 2] -= drop
            release(out)
        for orientation, args, undo in tiptoes:
            # turned again from where they were, for the hips as they came down: the drop is
            # smoothed over its neighbours' frames, and a foot turned for the hip before it
            # left its leg bent (the G1's trailing knee on the CMU walk, 29 degrees where the
            # actor's is 5-14)
            _untiptoe(out, orientation, undo)
            _tiptoe(*args)
        for side, h, k, a, (l1, l2), _ in legs:
            knee0 = positions[:, k] - np.array([0.0, 0.0, 1.0]) * drop[:, None]
            out[:, k] = knee_between(out[:, h], out[:, a], knee0, l1, l2, _foot_forward(out, col, side))
            release(out)
    return out, offsets


def _tiptoe(out: np.ndarray, col: Mapping[str, int], side: str, rigid: tuple["RigidFoot", np.ndarray], reach: float,
            weight: np.ndarray, bend: np.ndarray) -> tuple[np.ndarray, list[int], np.ndarray, np.ndarray]:
    """``side``'s rigid foot targets in ``out`` (and its orientation targets ``rigid[1]``, in
    place) pitched heel up about the front edge where its leg would not reach the hip target
    in ``out`` (:func:`stance_tiptoe`).  Returns what it changed, for :func:`_untiptoe`: the
    rows, the columns, and their points ``(R, K, 3)`` and orientations ``(R, 4)`` before."""
    foot, orientation = rigid
    cols = [col[f"{side}_{j}"] for j in FOOT_JOINTS if f"{side}_{j}" in col]
    turns, pivots = stance_tiptoe(foot, out[:, col[f"{side}_ankle"]], orientation, out[:, col[f"{side}_hip"]], reach,
                                  weight, bend)
    rows = np.flatnonzero(turns[:, 3] < 1.0)
    points = np.asarray(out[rows][:, cols], dtype=float)
    before = (rows, cols, points, np.array(orientation[rows], dtype=float))
    if rows.size:
        # turned about the pivot as turn_foot turns about the ankle
        moved, orientation[rows] = turn_foot(turns[rows], pivots[rows], points, orientation[rows])
        for k, c in enumerate(cols):
            out[rows, c] = moved[:, k]
    return before


def _untiptoe(out: np.ndarray, orientation: np.ndarray, before: tuple[np.ndarray, list[int], np.ndarray, np.ndarray]) -> None:
    """Put back what :func:`_tiptoe` changed in ``out`` and ``orientation``."""
    rows, cols, points, turned_from = before
    for k, c in enumerate(cols):
        out[rows, c] = points[:, k]
    orientation[rows] = turned_from


#: Bisection steps of :func:`swing_flatten` (the turn found to :math:`2^{-20}` of the foot's pitch).
FLATTEN_STEPS = 20


def swing_flatten(foot: "RigidFoot", ankle: np.ndarray, orientation: np.ndarray, weight: np.ndarray,
                  clearance: float, most: np.ndarray | None = None) -> np.ndarray:
    r"""``(F, 4)`` x-y-z-w: the turns that pitch a rigid foot's targets towards level, on its
    swing frames, just enough for the foot to clear the floor at its ankle target (the identity
    elsewhere; applied as ``turn * orientation``, and to the foot's other targets about the
    ankle's: :func:`turn_foot`).

    On a frame where neither of its contact points is labelled the planting keeps every
    collision geom of the foot ``clearance`` above the floor (a hard inequality).  At the actor's
    toe-off pitch (its toes bend as they leave the floor) a rigid foot's targets dip its front
    edge 15-40 mm into the floor (the bundled robot on the Bandai walk, 60-75 degrees toe
    down).  The solver then trades the foot's pitch against its ankle's height, and the trade
    has two branches: a flatter foot reaches less far below the ankle, and so does one pitched
    past the pitch at which that reach is largest; crossing from one branch to the other the
    foot pitched 27 degrees in one frame and overshot its target by 9.  So the foot's target is
    turned about its own lateral axis (its roll kept) towards level by the least angle
    :math:`\beta \in [0, |\theta|]` (:math:`\theta` its pitch) at which its lowest material
    point (:meth:`RigidFoot.toe_point`, floor at 0 as the plan's heights) stands ``clearance``
    up, found by bisection (:data:`FLATTEN_STEPS`; a foot too low even when level is turned level,
    and the solver lifts it the rest of the way), then scaled by ``weight (F,)`` (0 in contact,
    easing to 1 in the swing).  The flatter branch, on every frame: the one the solver takes
    while the foot still clears its pitch of largest reach, so the two agree, and the leg keeps
    the actor's pose instead of being lifted.  Only a foot pitched toe down is turned: the actor's
    heel is the rigid foot's heel, the toes that bend are what it lacks.  ``most (F,)``
    (radians, optional) bounds the turn: the actor's toe bend (:func:`toe_bend`), so that a foot
    the actor points at the floor with its toes in line (a toe drag behind a dancer) keeps its
    pitch and is lifted by the solver instead of flattened 30-40 degrees off the actor.
    ``ankle (F, 3)`` metres, ``orientation (F, 4)``.
    """
    from ..rotations import quat_apply, quat_conj, quat_mul

    orientation = np.asarray(orientation, dtype=float)
    out = np.zeros((len(orientation), 4))
    out[:, 3] = 1.0
    rows = np.flatnonzero(np.asarray(weight) > 0.0)
    if clearance <= 0.0 or not rows.size:
        return out
    a, q, w = np.asarray(ankle, dtype=float)[rows], orientation[rows], np.asarray(weight, dtype=float)[rows]
    R = quat_mul(q, quat_conj(foot.rest_quat))
    f0 = _level_unit(foot.front)
    forward = quat_apply(R, np.broadcast_to(f0, a.shape))
    pitch = np.arcsin(np.clip(forward[:, 2], -1.0, 1.0))
    # the foot's own lateral axis, f x up at rest: turning about it raises f and keeps the roll
    side = quat_apply(R, np.broadcast_to(np.cross(f0, [0.0, 0.0, 1.0]), a.shape))

    def turn(t: np.ndarray) -> np.ndarray:
        """The turns ``t`` (0..1) of the way to level."""
        half = -0.5 * t * pitch  # a foot pitched down (negative) turns up about f x up
        return np.concatenate([side * np.sin(half)[:, None], np.cos(half)[:, None]], axis=1)

    def clear(t: np.ndarray) -> np.ndarray:
        return foot.toe_point(a, quat_mul(turn(t), q))[:, 2] >= clearance

    lo = np.zeros(len(rows))
    # at most the actor's toe bend: the turn stands in for the toes a rigid foot lacks
    hi = np.ones(len(rows)) if most is None else np.clip(np.asarray(most, dtype=float)[rows] / np.maximum(-pitch, 1e-9), 0.0, 1.0)
    hi[clear(lo) | (pitch >= 0.0)] = 0.0  # clear as it is, or heel down: left alone
    for _ in range(FLATTEN_STEPS):
        mid = 0.5 * (lo + hi)
        ok = clear(mid)
        hi = np.where(ok, mid, hi)
        lo = np.where(ok, lo, mid)
    out[rows] = turn(w * hi)
    return out


#: Radians a rigid foot may always rise on its front edge in stance (:func:`stance_tiptoe`),
#: where the actor's toes bend less (or the actor has no toe tips to tell): the character's
#: leg, scaled, is not the actor's, and a straight trailing leg may need a few degrees more
#: heel than the actor's own.  A generous bound, not a fit: on the shared walks the robots
#: needed up to 10 degrees beyond the toe bend (the bundled robot on the CMU walk), and any
#: bound from 10 up gave the same figures there; what it does not reach the body comes down for.
TIPTOE_LEAST = float(np.radians(15.0))


def stance_tiptoe(foot: "RigidFoot", ankle: np.ndarray, orientation: np.ndarray, hip: np.ndarray, reach: float,
                  weight: np.ndarray, most: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    r"""``((F, 4) turns x-y-z-w, (F, 3) pivots)``: a rigid foot on its front edge pitched heel
    up about that edge, just enough for its leg to reach it (the identity elsewhere; applied to
    the foot's targets as :math:`P + r\,(p - P)` and to its orientation as :math:`r\,Q`).

    The actor rolls over its toes in late stance: its heel rises, the toes bend, and its leg
    stays straight.  A rigid foot follows the actor's ankle-to-toe-tip line
    (:mod:`physmocap.ik.rigidfoot`), flatter than the actor's hind foot by the toes' bend, and
    its plan puts the front edge on the floor: its ankle comes out lower than the leg reaches,
    and the whole body came down for it (:func:`pelvis_drop`: the bundled robot on the CMU
    walk, 2-3 cm at every toe-off, its pelvis moving vertically at twice the actor's speed).
    So on the frames where only its toes are planned (``weight (F,)``, 0..1 eased) the foot is
    turned about its front contact point (:meth:`RigidFoot.toe_point`), heel up about its own
    lateral axis, by the least angle :math:`\delta \in [0, b]` at which the ankle target
    ``ankle (F, 3)`` lies within ``reach`` of the hip target ``hip (F, 3)`` (bisection,
    :data:`FLATTEN_STEPS`), then scaled by ``weight``.  The bound :math:`b` is the actor's toe
    bend ``most (F,)`` (radians, :func:`toe_bend`: the turn stands in for the toes the foot
    lacks, as the hind foot's pitch is the toe-tip line's plus the bend), at least
    :data:`TIPTOE_LEAST`; where even :math:`b` does not reach, the foot turns by :math:`b` and
    the body comes down the rest.  A leg that reaches as it is, or that a turn does not bring
    nearer, is left alone.  Metres, radians."""
    from ..rotations import quat_apply, quat_conj, quat_mul

    F = len(orientation)
    turns = np.zeros((F, 4))
    turns[:, 3] = 1.0
    pivots = np.asarray(ankle, dtype=float).copy()
    w = np.asarray(weight, dtype=float)
    b = np.maximum(np.asarray(most, dtype=float), TIPTOE_LEAST)
    a_all, h_all = np.asarray(ankle, dtype=float), np.asarray(hip, dtype=float)
    rows = np.flatnonzero((w > 0.0) & (np.linalg.norm(h_all - a_all, axis=1) > reach))
    if not rows.size:
        return turns, pivots
    a, h, q = a_all[rows], h_all[rows], np.asarray(orientation, dtype=float)[rows]
    p = foot.toe_point(a, q)
    R = quat_mul(q, quat_conj(foot.rest_quat))
    f0 = _level_unit(foot.front)
    side = quat_apply(R, np.broadcast_to(np.cross(f0, [0.0, 0.0, 1.0]), a.shape))

    def turn(angle: np.ndarray) -> np.ndarray:
        """Heel up by ``angle``: toes down about f x up (a positive turn raises the toes)."""
        half = -0.5 * angle
        return np.concatenate([side * np.sin(half)[:, None], np.cos(half)[:, None]], axis=1)

    def distance(angle: np.ndarray) -> np.ndarray:
        return np.linalg.norm(h - (p + quat_apply(turn(angle), a - p)), axis=1)

    hi = b[rows].copy()
    useful = distance(hi) < distance(np.zeros(len(rows)))
    hi[~useful] = 0.0
    lo = np.zeros(len(rows))
    far = distance(hi) > reach  # not reached even at the bound: the bound (the body comes down the rest)
    lo[far] = hi[far]
    for _ in range(FLATTEN_STEPS):
        mid = 0.5 * (lo + hi)
        ok = distance(mid) <= reach
        hi = np.where(ok, mid, hi)
        lo = np.where(ok, lo, mid)
    turns[rows] = turn(hi * w[rows])
    pivots[rows] = p
    return turns, pivots


def toe_bend(ankle: np.ndarray, toe: np.ndarray, toe_end: np.ndarray) -> np.ndarray:
    r"""``(F,)`` radians: how far the toe segment ``toe -> toe_end`` points up from the foot
    segment ``ankle -> toe`` (the difference of their pitches above the horizontal), 0 where
    the toes are in line with the foot or bent down; positions ``(F, 3)`` metres."""
    def pitch(v: np.ndarray) -> np.ndarray:
        return np.arctan2(v[:, 2], np.linalg.norm(v[:, :2], axis=1))

    foot = np.asarray(toe, dtype=float) - np.asarray(ankle, dtype=float)
    toes = np.asarray(toe_end, dtype=float) - np.asarray(toe, dtype=float)
    return np.maximum(pitch(toes) - pitch(foot), 0.0)


def turn_foot(turns: np.ndarray, ankle: np.ndarray, points: np.ndarray, orientation: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    r"""A foot's targets turned about its ankle's: ``points (F, K, 3)`` to
    :math:`T_a + r\,(p - T_a)` and ``orientation (F, 4)`` to :math:`r\,Q` for the turns
    :math:`r` ``(F, 4)`` x-y-z-w (:func:`swing_flatten`); ``ankle (F, 3)`` metres."""
    from ..rotations import quat_apply, quat_mul

    a = np.asarray(ankle, dtype=float)[:, None, :]
    return a + quat_apply(turns[:, None, :], np.asarray(points, dtype=float) - a), quat_mul(turns, orientation)


def _level_unit(v: np.ndarray) -> np.ndarray:
    """``v`` made horizontal and unit length (the foot's rest forward direction)."""
    h = np.array([v[0], v[1], 0.0], dtype=float)
    return h / max(float(np.linalg.norm(h)), 1e-12)


@dataclass(frozen=True)
class ToeContact:
    """The material of one foot's toe segment, in the character's rest pose (metres).

    Attributes:
        direction: Rest toe segment, toe joint to toe tip (world).
        offsets: ``(K, 3)`` rest positions of the segment's lowest-point candidates
            (:func:`~physmocap.models.geometry.geom_candidates` of its collision
            geoms, else its contact sites) from the toe joint (world).
        radii: ``(K,)`` their radii (the material reaches this far below a candidate).
        height: Rest height above the floor of the segment's lowest point (it rests on the floor).
    """

    direction: np.ndarray
    offsets: np.ndarray
    radii: np.ndarray
    height: float

    def lowest(self, toe: np.ndarray, tip: np.ndarray) -> np.ndarray:
        r"""``(F, 3)`` the lowest material point of toe segments with joints ``toe``, ``tip`` ``(F, 3)``.

        Each candidate is carried rigidly by the segment: :math:`x_k = T_{toe} + R\,o_k`
        with :math:`R` the smallest rotation taking the rest direction onto
        :math:`T_{tip} - T_{toe}` (a toe segment has no roll to follow; its
        material lies near its own sagittal plane, where roll barely moves it), and
        the lowest point is :math:`\min_k (x_{k,z} - r_k)`.
        """
        from ..rotations import quat_apply, quat_between

        q = quat_between(np.broadcast_to(self.direction, tip.shape), tip - toe)
        pts = toe[:, None, :] + quat_apply(q[:, None, :], self.offsets[None, :, :])
        low = pts[..., 2] - self.radii[None, :]
        k = np.argmin(low, axis=1)
        out = pts[np.arange(pts.shape[0]), k]
        out[:, 2] = low[np.arange(pts.shape[0]), k]
        return out


@dataclass(frozen=True)
class RigidFoot:
    r"""The material of a foot without toe joints, in the character's rest pose (metres).

    A rigid foot rolls over its front edge where the actor rolls over the toes: its
    toe contact is its lowest material point, carried by the ankle's target frame,
    not the actor's toe joint (which bends).  Offline, such a foot is planned by
    that point (:func:`planted_positions`), so the held front edge and the ankle's
    targets agree all through the roll (:mod:`physmocap.ik.rigidfoot` turns the
    ankle's orientation target with the actor's toe-tip line).

    Attributes:
        rest_quat: ``(4,)`` rest world orientation (x-y-z-w) of the ankle's tracked frame.
        front: ``(3,)`` the foot's front contact site(s) (their mean) from the ankle, rest, world.
        offsets: ``(K, 3)`` its lowest-point candidates
            (:func:`~physmocap.models.geometry.geom_candidates` of its collision geoms,
            else its contact sites) from the ankle, rest, world.
        radii: ``(K,)`` their radii.
        height: Rest height above the floor of the foot's lowest point.
    """

    rest_quat: np.ndarray
    front: np.ndarray
    offsets: np.ndarray
    radii: np.ndarray
    height: float

    def toe_point(self, ankle: np.ndarray, orientation: np.ndarray, block: int = 4096) -> np.ndarray:
        r"""``(F, 3)``: horizontally the front contact point, vertically the lowest
        material point, of the foot whose ankle target is at ``ankle (F, 3)`` with
        orientation target ``orientation (F, 4)``: :math:`x = T + Q\,Q_0^{-1} o`
        (``block`` frames at a time: a mesh foot has many candidates)."""
        from ..rotations import quat_apply, quat_conj, quat_mul

        F = ankle.shape[0]
        out = np.empty((F, 3))
        q0 = quat_conj(self.rest_quat)
        for s in range(0, F, block):
            e = min(F, s + block)
            R = quat_mul(np.asarray(orientation[s:e], dtype=float), q0)
            a = np.asarray(ankle[s:e], dtype=float)
            out[s:e, :2] = (a + quat_apply(R, np.broadcast_to(self.front, a.shape)))[:, :2]
            pts = a[:, None, :] + quat_apply(R[:, None, :], self.offsets[None, :, :])
            out[s:e, 2] = (pts[..., 2] - self.radii[None, :]).min(axis=1)
        return out


def _foot_forward(positions: np.ndarray, col: Mapping[str, int], side: str) -> np.ndarray | None:
    """``(..., 3)`` ankle-to-toe direction of a foot's targets (None without a toe target)."""
    toe = next((f"{side}_{j}" for j in ("toe", "toe_end") if f"{side}_{j}" in col), None)
    if toe is None or f"{side}_ankle" not in col:
        return None
    return positions[..., col[toe], :] - positions[..., col[f"{side}_ankle"], :]


#: Contact part -> the canonical joints its plan moves (the first one is planned).
BODY_PART_JOINTS: dict[str, tuple[str, ...]] = {
    "left_knee": ("left_knee",),
    "right_knee": ("right_knee",),
    "left_hand": ("left_wrist", "left_hand_end"),
    "right_hand": ("right_wrist", "right_hand_end"),
    "pelvis": ("pelvis", "left_hip", "right_hip"),
}


def plant_body_contacts(
    positions: np.ndarray,
    names: tuple[str, ...],
    body_labels: Mapping[str, np.ndarray],
    fps: float,
    ease_time: float,
    floor: float = 0.0,
    *,
    in_place: bool = False,
) -> np.ndarray:
    """Targets ``(F, N, 3)`` with knees, hands and pelvis held on the floor during their contacts.

    Each part's first joint in :data:`BODY_PART_JOINTS` that has a target
    (the mid-hip for the pelvis) is planned like a foot point
    (:func:`foot_offsets`): one location per contact, eased in and out, and
    pulled down to the floor height ``floor``; the part's other joints move
    with it.  The target lies below what the character's geometry allows, so
    the floor constraint decides how low the joint goes: the knee's, hand's or
    pelvis's collision geoms end on the floor, whatever their thickness.

    Args:
        positions: ``(F, N, 3)`` target positions (not modified, unless ``in_place``).
        names: Canonical joint of each target column.
        body_labels: Part (``left_knee``, ``left_hand``, ``pelvis``...) -> ``(F,)`` bool.
        fps, ease_time: See :func:`foot_offsets`.
        floor: Floor height (metres).
        in_place: Plan ``positions`` themselves (a writeable float64 array the caller gives
            up; the parts move disjoint columns, each read before it is moved) and return them.
    """
    out = positions if in_place else np.array(positions, dtype=float, copy=True)
    col = {n: i for i, n in enumerate(names)}
    for part, label in body_labels.items():
        label = np.asarray(label, dtype=bool)
        held = body_part_target(positions, col, part)
        if held is None or not label.any():
            continue
        idx, point = held
        plan = foot_offsets({part: point}, {part: label}, fps, ease_time, {part: floor})
        out[:, idx, :2] += plan.xy[:, None, :]
        out[:, idx, 2] += plan.z[part][:, None]
        release(out)  # positions in a temporary file (physmocap.spill): the pages read leave the memory
    return out


def body_part_target(positions: np.ndarray, col: Mapping[str, int], part: str) -> tuple[list[int], np.ndarray] | None:
    """``(target columns the part moves, its held point (..., 3))`` for a contact part, from
    targets ``positions (..., N, 3)``: the first of :data:`BODY_PART_JOINTS` present (the
    midpoint of the hips for the pelvis); None when the part has no target."""
    idx = [col[j] for j in BODY_PART_JOINTS.get(part, ()) if j in col]
    if not idx:
        return None
    if part == "pelvis":
        if not all(h in col for h in ("left_hip", "right_hip")):
            return None
        return idx, 0.5 * (positions[..., col["left_hip"], :] + positions[..., col["right_hip"], :])
    return idx, positions[..., idx[0], :]
