"""Map a skeleton by its shape alone, for joint names no profile knows.

Works on one upright pose (:func:`.structure.standing_pose`), Z up:

1. **Feet and pelvis.**  The lowest leaf is one foot; the other foot is the
   lowest leaf whose common ancestor with the first lies at least a quarter of
   the body height above it (toes of one foot branch just above the floor).
   That ancestor ``H`` joins the legs.
2. **Facing and sides.**  Toes point forward: the facing direction is the mean
   horizontal offset of each foot tip from the leg joint at mid-leg height;
   the character's left is ``up x forward``.  Without a usable foot (tips
   straight below), left is taken as +X, the BVH convention (a warning says so).
3. **Arms.**  Of the remaining leaves, the most lateral on each side are
   hands; their common ancestor ``U`` is the upper trunk where the arms
   branch.  Each arm follows the leaf of its branch farthest from ``U``, the
   tip of the longest finger.
4. **Head.**  The highest remaining leaf; the first joint above ``U`` on its
   chain is the neck, the common ancestor of the leaves beyond the neck is
   the head (the head's parent joint when that ancestor is an end site).
5. **Pelvis** is the common ancestor of ``H`` and the head chain's base: the
   root-most joint where the legs and the spine part.

Along each limb, joints at the same place are one point (the first is kept).
Legs: the hip is the last point within a quarter of the leg's height from
the pelvis (helpers such as Daz's ``lButtock`` come before it), the ankle ends the last
mostly vertical segment, the knee is the point halfway (by length) between
them, then the ball of the foot and the toe tip.  Arms: the shoulder, elbow
and wrist are the three points whose segment lengths best match human
proportions (forearm/upper arm 0.785, shoulder-to-midline/upper arm 0.70,
hand/upper arm 0.58 (a wrist ending the chain costs as much as a hand off by a
factor two), from the segment lengths as fractions of height in
Winter, *Biomechanics and Motor Control of Human Movement*, fig. 4.1, after
Drillis and Contini 1966); a point before the shoulder is the clavicle, and
the point nearest halfway along the hand is the hand end.

``spine`` and ``chest`` are left to the shared rule in :mod:`.rules`.
"""

from __future__ import annotations

import itertools
import math

import numpy as np

from .structure import SkeletonView, is_upright

__all__ = ["topology_map", "ARM_RATIOS"]

#: Expected ratios to the upper-arm length (Winter fig. 4.1: upper arm 0.186 H,
#: forearm 0.146 H, hand 0.108 H, shoulder width 0.259 H).
ARM_RATIOS = {"forearm": 0.146 / 0.186, "shoulder_offset": 0.259 / 2 / 0.186, "hand": 0.108 / 0.186}
_ARM_WEIGHTS = {"forearm": 1.0, "shoulder_offset": 0.5, "hand": 0.25}
#: Hand term of a wrist with nothing beyond it (as if the hand were off by 2x).
NO_HAND_COST = math.log(2.0) ** 2
#: The hip is the last leg joint closer to the pelvis than this fraction of the
#: leg's height (skips helpers such as Daz's lButtock between pelvis and thigh).
HIP_REACH = 0.25
#: An end site closer than this fraction of the body size to its joint does
#: not end a segment; its joint is the tip (Mixamo's HeadTop_End).
SHORT_TIP = 0.03


def _log_sq(value: float, expected: float) -> float:
    return math.log(max(value, 1e-9) / expected) ** 2


def _feet(v: SkeletonView) -> tuple[int, int, int] | None:
    """``(foot_leaf_a, foot_leaf_b, H)`` or None."""
    z = v.pose[:, 2]
    leaves = [j for j in v.leaves() if np.all(np.isfinite(v.pose[j]))]
    if len(leaves) < 2:
        return None
    height = float(np.nanmax(z) - np.nanmin(z))
    leaves.sort(key=lambda j: (z[j], j))
    f1 = leaves[0]
    for f2 in leaves[1:]:
        h = v.lca(f1, f2)
        if h >= 0 and h not in (f1, f2) and z[h] - z[f1] > 0.25 * height:
            return f1, f2, h
    return None


def _forward(v: SkeletonView, h: int, feet: tuple[int, int]) -> np.ndarray | None:
    """Unit horizontal facing direction from the feet, or None."""
    vecs = []
    for f in feet:
        nodes = v.path(h, f)
        zmid = 0.5 * (v.pose[h, 2] + v.pose[f, 2])
        ref = min(nodes[1:-1] or nodes, key=lambda j: abs(v.pose[j, 2] - zmid))
        vecs.append(v.pose[f, :2] - v.pose[ref, :2])
    fwd = np.mean(vecs, axis=0)
    n = float(np.linalg.norm(fwd))
    if n < 0.02 * v.scale:
        return None
    return fwd / n


def _leg(v: SkeletonView, h: int, foot: int) -> dict[str, int]:
    pts = v.points(v.path(h, foot))
    out: dict[str, int] = {}
    if not pts:
        return out
    leg_height = float(v.pose[h, 2] - min(v.pose[j, 2] for j in pts))
    near = [k for k, j in enumerate(pts) if v.dist(h, j) < HIP_REACH * leg_height]
    hip_k = near[-1] if near else 0
    out["hip"] = pts[hip_k]
    ankle_k = None
    for k in range(hip_k + 1, len(pts)):
        d = v.pose[pts[k]] - v.pose[pts[k - 1]]
        if abs(d[2]) >= np.linalg.norm(d[:2]) and not v.is_end(pts[k]):
            ankle_k = k
    if ankle_k is None:
        return out
    out["ankle"] = pts[ankle_k]
    between = pts[hip_k + 1:ankle_k]
    if between:
        arc = v.arc([pts[hip_k]] + between + [pts[ankle_k]])
        half = arc[-1] / 2
        out["knee"] = between[int(np.argmin(np.abs(arc[1:-1] - half)))]
    rest = pts[ankle_k + 1:]
    if len(rest) >= 2:
        out["toe"] = rest[0]
        out["toe_end"] = rest[-1]
    elif len(rest) == 1:
        out["toe_end" if v.is_end(rest[0]) else "toe"] = rest[0]
    return out


def _arm(v: SkeletonView, u: int, leaf: int, lateral: np.ndarray) -> dict[str, int]:
    pts = v.points(v.path(u, leaf))
    if len(pts) < 3:
        return {}
    arc = v.arc([u] + pts)[1:]
    mid = float(v.pose[u, :2] @ lateral)
    best, best_cost = None, math.inf
    for i, j, k in itertools.combinations(range(len(pts)), 3):
        if v.is_end(pts[k]):
            continue
        ua = arc[j] - arc[i]
        fa = arc[k] - arc[j]
        hand = arc[-1] - arc[k]
        if ua <= 0 or fa <= 0:
            continue
        off = abs(float(v.pose[pts[i], :2] @ lateral) - mid)
        cost = (
            _ARM_WEIGHTS["forearm"] * _log_sq(fa / ua, ARM_RATIOS["forearm"])
            + _ARM_WEIGHTS["shoulder_offset"] * _log_sq(off / ua, ARM_RATIOS["shoulder_offset"])
            + _ARM_WEIGHTS["hand"] * (
                _log_sq(hand / ua, ARM_RATIOS["hand"]) if hand > v.eps else NO_HAND_COST
            )
        )
        if cost < best_cost - 1e-12:
            best, best_cost = (i, j, k), cost
    if best is None:
        return {}
    i, j, k = best
    out = {"shoulder": pts[i], "elbow": pts[j], "wrist": pts[k]}
    if i > 0:
        out["clavicle"] = pts[0]
    after = pts[k + 1:]
    if after:
        d = arc[k + 1:] - arc[k]
        out["hand_end"] = after[int(np.argmin(np.abs(d - 0.5 * (arc[-1] - arc[k]))))]
    return out


def topology_map(v: SkeletonView) -> tuple[dict[str, int], list[str]]:
    """Canonical joint -> joint index found from the skeleton's shape, and notes.

    ``spine`` and ``chest`` are not set (see :mod:`.rules`).  Joints that
    cannot be found are absent; the notes say why.
    """
    notes: list[str] = []
    if not is_upright(v.pose):
        return {}, ["topology: the skeleton's pose is not a standing body (pass the Motion, "
                    "not its Skeleton, so an animated frame can be used)"]
    found = _feet(v)
    if found is None:
        return {}, ["topology: no two leg chains reach the floor in the pose"]
    f1, f2, h = found
    legs = [v.child_toward(h, f1), v.child_toward(h, f2)]
    leg_sets = [set(v.subtree(c)) for c in legs]

    fwd = _forward(v, h, (f1, f2))
    if fwd is None:
        lateral = np.array([1.0, 0.0])
        notes.append("topology: the feet show no facing direction; assumed the character's left is +X")
    else:
        lateral = np.array([-fwd[1], fwd[0]])  # up x forward, horizontal part

    def lat(j: int) -> float:
        return float(v.pose[j, :2] @ lateral)

    out: dict[str, int] = {}
    # -- legs, left first by lateral position of the hip
    leg_maps = [_leg(v, h, f) for f in (f1, f2)]
    hips = [m.get("hip") for m in leg_maps]
    if hips[0] is not None and hips[1] is not None and lat(hips[0]) < lat(hips[1]):
        leg_maps.reverse()
    for side, m in zip(("left", "right"), leg_maps):
        for k, j in m.items():
            out[f"{side}_{k}"] = j

    # -- arms
    upper = [j for j in v.leaves() if not any(j in s for s in leg_sets)]
    upper = [j for j in upper if np.all(np.isfinite(v.pose[j]))]
    centre = lat(h)
    margin = 0.05 * v.scale
    left_c = [j for j in upper if lat(j) - centre > margin]
    right_c = [j for j in upper if centre - lat(j) > margin]
    base = None
    if left_c and right_c:
        a_l = max(left_c, key=lambda j: (lat(j), -j))
        a_r = min(right_c, key=lambda j: (lat(j), j))
        u = v.lca(a_l, a_r)
        if u >= 0 and not any(u in s for s in leg_sets):
            arm_sets = []
            for side, leaf in (("left", a_l), ("right", a_r)):
                if leaf == u:
                    continue
                root = v.child_toward(u, leaf)
                sub = v.subtree(root)
                tips = [j for j in sub if not v.children[j]]
                far = max(tips, key=lambda j: (round(v.dist(u, j) / v.eps), -j))
                arm_sets.append(set(sub))
                for k, j in _arm(v, u, far, lateral).items():
                    out[f"{side}_{k}"] = j
            base = u
            upper = [j for j in upper if not any(j in s for s in arm_sets)]
        else:
            notes.append("topology: the hands' common ancestor is in a leg")
    else:
        notes.append("topology: found no leaves to both sides of the body (no arms)")

    # -- head
    if upper and base is not None:
        top = max(upper, key=lambda j: (v.pose[j, 2], -j))
        base = v.lca(base, top)
        if base >= 0 and base != top:
            pts = v.points(v.path(base, top))
            interior = [j for j in pts if not (v.is_end(j) and j == top)]
            if interior:
                neck = interior[0]
                out["neck"] = neck
                tips = [j for j in v.subtree(neck) if not v.children[j]]
                tips = [j for j in tips if not (v.is_end(j) and v.same_place(j, int(v.parents[j])))]
                head = v.lca(*tips) if tips else neck
                tip = tips[0] if len(tips) == 1 else None
                if v.is_end(head):
                    head = int(v.parents[head])
                if (
                    tip is not None
                    and v.is_end(tip)
                    and head != neck
                    and v.dist(tip, head) < SHORT_TIP * v.scale
                ):
                    tip, head = head, int(v.parents[head])
                if head != neck and v.is_ancestor(neck, head):
                    out["head"] = head
                if tip is not None and (v.is_end(tip) or tip != head):
                    out["head_end"] = tip
            elif base != h:
                out["neck"] = base
    elif base is not None:
        notes.append("topology: found no head chain")

    # -- pelvis
    if base is not None and base >= 0:
        pelvis = v.lca(h, base)
        out["pelvis"] = pelvis if pelvis >= 0 else h
    else:
        out["pelvis"] = h
    # a joint maps to one canonical joint only
    seen: dict[int, str] = {}
    for name in list(out):
        j = out[name]
        if j in seen:
            del out[name]
        else:
            seen[j] = name
    return out, notes
