"""Rules that complete a name-based or shape-based mapping.

Applied in this order to the canonical joints nobody set explicitly:

1. **Lone head joint is the neck.**  When ``neck`` is unmapped but ``head``
   is (PyMO's ``Spine -> Head -> end``), the head joint is the only joint
   between the upper trunk and the top of the head; it pivots the whole neck,
   so it maps to ``neck`` (required) and ``head`` stays unmapped.
2. **Spine and chest by position** (:func:`spine_chest`).
3. **Segment tips from end sites.**  ``head_end`` is the end site below the
   head (or, with no head, the neck), ``<side>_hand_end`` the end site below
   the wrist, ``<side>_toe_end`` the one below the ball of the foot (or, with
   no ball, the ankle).  End sites at their parent's place (zero offsets, as
   Bandai Namco writes them) are not tips and are skipped.
4. **Pelvis from the hips.**  With no pelvis joint (OpenNI / NITE), the
   pelvis, defined as the centre between the hip joints, is their midpoint: a
   *derived* joint, with a position but no rotation.
"""

from __future__ import annotations

import itertools

import numpy as np

from .structure import SkeletonView

__all__ = [
    "SPINE_FRACTION",
    "CHEST_FRACTION",
    "spine_chest",
    "complete",
    "facing",
    "side_check",
]

#: Where the canonical ``spine`` (lumbar, L3/L4) and ``chest`` (T12/L1) joints
#: sit along the pelvis-to-neck-base chain, as fractions of its length.  From
#: the Xsens MVN biomechanical model (joint centres jL5S1, jL4L3, jL1T12,
#: jT9T8 at 0.18, 0.38, 0.56, 0.74 of the hip-centre-to-jT1C7 length in an
#: MVN BVH export); ``spine`` takes the middle of the lumbar region L5/S1-L3.
SPINE_FRACTION = 0.30
CHEST_FRACTION = 0.56


def spine_chest(v: SkeletonView, pelvis: int, neck: int, taken: set[int]) -> dict[str, int]:
    """Pick ``spine`` and ``chest`` among the joints between pelvis and neck.

    The candidates are the joints strictly between the two on the chain, one
    per place (the first of joints at one place; none at the pelvis' or the
    neck's place), not already mapped.  Each gets its fraction ``f`` of the
    chain length from the pelvis.  With two or more candidates, the pair
    ``a`` below ``b`` minimising ``(f_a - 0.30)^2 + (f_b - 0.56)^2`` becomes
    ``spine``, ``chest``; a single candidate becomes whichever of the two its
    fraction is nearer.  So CMU (``Spine`` 0.35, ``Spine1`` 0.70) gives
    ``Spine``/``Spine1``; Xsens ``Chest``..``Chest4`` (0.18, 0.38, 0.56, 0.74)
    gives ``Chest2``/``Chest3``; PyMO's single ``Spine`` (0.38) is ``spine``.
    """
    if not v.is_ancestor(pelvis, neck) or pelvis == neck:
        return {}
    nodes = v.path(pelvis, neck)
    arc = v.arc(nodes)
    total = arc[-1]
    if total < v.eps:
        return {}
    cands: list[tuple[int, float]] = []
    last = pelvis
    for j, a in zip(nodes[1:-1], arc[1:-1]):
        if v.same_place(j, last):
            continue
        last = j
        if v.same_place(j, neck) or j in taken:
            continue
        cands.append((j, a / total))
    if not cands:
        return {}
    if len(cands) == 1:
        j, f = cands[0]
        key = "spine" if abs(f - SPINE_FRACTION) <= abs(f - CHEST_FRACTION) else "chest"
        return {key: j}
    best = min(
        itertools.combinations(cands, 2),
        key=lambda p: (p[0][1] - SPINE_FRACTION) ** 2 + (p[1][1] - CHEST_FRACTION) ** 2,
    )
    return {"spine": best[0][0], "chest": best[1][0]}


_TIPS = (
    ("head_end", ("head", "neck")),
    ("left_hand_end", ("left_wrist",)),
    ("right_hand_end", ("right_wrist",)),
    ("left_toe_end", ("left_toe", "left_ankle")),
    ("right_toe_end", ("right_toe", "right_ankle")),
)


def complete(
    v: SkeletonView,
    explicit: dict[str, int],
    fixed: set[str] = frozenset(),  # type: ignore[assignment]
) -> tuple[dict[str, int], dict[str, tuple[tuple[int, float], ...]], list[str]]:
    """Apply the module's rules to ``explicit`` (canonical -> joint index).

    Args:
        v: The skeleton view.
        explicit: Joints set by names, shape or the user.
        fixed: Canonical joints the user set or switched off; no rule touches them.

    Returns:
        ``(indices, derived, notes)``.
    """
    idx = dict(explicit)
    notes: list[str] = []
    names = v.skeleton.names
    if "neck" not in idx and "neck" not in fixed and "head" in idx and "head" not in fixed:
        idx["neck"] = idx.pop("head")
        notes.append(
            f"neck: {names[idx['neck']]} is the only joint between the trunk and the top of the "
            "head, so it is the neck; head is left unmapped"
        )
    if not ({"spine", "chest"} & (set(idx) | set(fixed))) and "pelvis" in idx and "neck" in idx:
        sc = spine_chest(v, idx["pelvis"], idx["neck"], set(idx.values()))
        idx.update(sc)
        if sc:
            notes.append(
                "spine/chest chosen by position along the pelvis-to-neck chain: "
                + ", ".join(f"{k} = {names[j]}" for k, j in sc.items())
            )
    taken = set(idx.values())
    for tip, anchors in _TIPS:
        if tip in idx or tip in fixed:
            continue
        anchor = next((a for a in anchors if a in idx), None)
        if anchor is None:
            continue
        ends = [e for e in v.end_sites_of(idx[anchor]) if e not in taken]
        if ends:
            idx[tip] = ends[0]
            taken.add(ends[0])
    derived: dict[str, tuple[tuple[int, float], ...]] = {}
    if "pelvis" not in idx and "pelvis" not in fixed and "left_hip" in idx and "right_hip" in idx:
        derived["pelvis"] = ((idx["left_hip"], 0.5), (idx["right_hip"], 0.5))
        notes.append(
            f"pelvis: no pelvis joint; using the midpoint of {names[idx['left_hip']]} and "
            f"{names[idx['right_hip']]}"
        )
    return idx, derived, notes


def facing(v: SkeletonView, idx: dict[str, int]) -> np.ndarray | None:
    """Unit horizontal facing direction from the mapped feet (tip minus ankle), or None."""
    vecs = []
    for side in ("left", "right"):
        ankle = idx.get(f"{side}_ankle")
        tip = idx.get(f"{side}_toe", idx.get(f"{side}_toe_end"))
        if ankle is None or tip is None:
            continue
        d = v.pose[tip, :2] - v.pose[ankle, :2]
        if np.all(np.isfinite(d)):
            vecs.append(d)
    if not vecs:
        return None
    fwd = np.mean(vecs, axis=0)
    n = float(np.linalg.norm(fwd))
    if n < 0.02 * v.scale:
        return None
    return fwd / n


def side_check(v: SkeletonView, idx: dict[str, int]) -> str | None:
    """A message when the mapped left/right joints sit on the wrong sides, else None.

    The character's left is ``up x forward`` with the facing direction from
    the feet (:func:`facing`).  Hips and shoulders are compared; nothing is
    said when the pose shows no facing direction.
    """
    fwd = facing(v, idx)
    if fwd is None:
        return None
    left_axis = np.array([-fwd[1], fwd[0]])
    bad = []
    for stem in ("hip", "shoulder"):
        a, b = idx.get(f"left_{stem}"), idx.get(f"right_{stem}")
        if a is None or b is None:
            continue
        d = float((v.pose[a, :2] - v.pose[b, :2]) @ left_axis)
        if d < -0.02 * v.scale:
            bad.append(stem)
    if not bad:
        return None
    names = v.skeleton.names
    pairs = ", ".join(
        f"left_{s} = {names[idx[f'left_{s}']]} is right of right_{s} = {names[idx[f'right_{s}']]}"
        for s in bad
    )
    return (
        f"left and right look swapped: with the feet pointing forward, {pairs}; check the "
        "source's side convention (a mirrored tracker?) or give a mapping file"
    )
