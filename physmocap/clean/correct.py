"""Repairing glitches: only the glitched joint on the glitched frames changes.

A rotational glitch is replaced by the spherical interpolation between the joint's last
good rotation before it and its first good one after it (at the clip's ends the nearest
good rotation is held), so no new discontinuity appears; a positional one (bone stretch,
gap) by linear interpolation of the joint's position; a left/right swap by trading the
two joints' positions back over the span.  Discontinuities (a jump with no
return) are reported, not changed: the motion after them may be the real one.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..motion import Motion
from ..rotations import Rotation
from .detect import Glitch

__all__ = ["correct_glitches"]

#: Glitch kinds that are repaired (the others are reported only).
REPAIRED = {
    "spike": "rotation",
    "flip": "rotation",
    "frozen": "rotation",
    "anatomical": "rotation",
    "bone_stretch": "position",
    "gap": "position",
}


def _slerp(q0: np.ndarray, q1: np.ndarray, n: int) -> np.ndarray:
    """``(n, 4)`` rotations strictly between ``q0`` and ``q1`` (x-y-z-w)."""
    from scipy.spatial.transform import Slerp

    key = Rotation.from_quat(np.stack([q0, q1]))
    s = Slerp([0.0, 1.0], key)
    return s(np.arange(1, n + 1) / (n + 1)).as_quat()


def _twin(name: str, names: dict[str, int]) -> int | None:
    """Index of the joint named like ``name`` with the other side (``Left``/``Right``,
    ``left_``/``right_``, ``L``/``R`` prefixes), or None."""
    import re

    swaps = [("Left", "Right"), ("left", "right"), ("LEFT", "RIGHT"), ("L", "R"), ("l", "r")]
    for a, b in swaps:
        for x, y in ((a, b), (b, a)):
            for pattern in (rf"^{x}(?=[_A-Z\d]|$)", rf"(?<=[_\s]){x}(?=[_\s]|$)", rf"^{x}_"):
                other = re.sub(pattern, y, name, count=1)
                if other != name and other in names:
                    return names[other]
    return None


def correct_glitches(motion: Motion, glitches: list[Glitch]) -> tuple[Motion, list[Glitch]]:
    """A copy of ``motion`` with the repairable glitches interpolated over, and the glitch list
    with ``corrected`` filled in ("slerp", "linear" or "" for reported only)."""
    names = {n: j for j, n in enumerate(motion.skeleton.names)}
    rot = None if motion.rotations is None else np.array(motion.rotations, copy=True)
    pos = None if motion.positions is None else np.array(motion.positions, copy=True)
    F = motion.num_frames
    out = []
    names_of = motion.skeleton.names
    swapped: set[tuple[int, int, int]] = set()
    for g in glitches:
        if g.kind == "lr_swap" and pos is not None:
            # trade the pair back (once per pair and span; both joints carry the glitch)
            j = names[g.joint]
            twin = _twin(names_of[j], names)
            key = (min(j, twin), g.start, g.end) if twin is not None else None
            if key is not None and key not in swapped:
                swapped.add(key)
                pos[g.start : g.end + 1, [j, twin]] = pos[g.start : g.end + 1, [twin, j]]
            out.append(dataclasses.replace(g, corrected="swapped back" if key is not None else ""))
            continue
        how = REPAIRED.get(g.kind) if g.repairable else None
        arr = rot if how == "rotation" else pos if how == "position" else None
        a, b = g.start - 1, g.end + 1
        if arr is None or (a < 0 and b >= F):
            out.append(g)
            continue
        j = names[g.joint]
        n = g.end - g.start + 1
        first = arr[a, j] if a >= 0 else arr[b, j]  # the good value before, or after at the start
        last = arr[b, j] if b < F else arr[a, j]
        if how == "rotation":
            arr[g.start : g.end + 1, j] = _slerp(first, last, n)
        else:
            w = (np.arange(1, n + 1) / (n + 1))[:, None]
            arr[g.start : g.end + 1, j] = (1 - w) * first + w * last
        out.append(dataclasses.replace(g, corrected="slerp" if how == "rotation" else "linear"))
    fixed = dataclasses.replace(motion, rotations=rot) if rot is not None else motion
    if pos is not None:
        fixed = dataclasses.replace(fixed, positions=pos)
    return fixed, out
