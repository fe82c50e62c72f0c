"""Repairing glitches: only the glitched joint on the glitched frames changes.

A rotational glitch is replaced by the spherical interpolation between the joint's last
good rotation before it and its first good one after it (at the clip's ends the nearest
good rotation is held), so no new discontinuity appears; a positional one (bone stretch,
gap) by linear interpolation of the joint's position.  Discontinuities (a jump with no
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


def correct_glitches(motion: Motion, glitches: list[Glitch]) -> tuple[Motion, list[Glitch]]:
    """A copy of ``motion`` with the repairable glitches interpolated over, and the glitch list
    with ``corrected`` filled in ("slerp", "linear" or "" for reported only)."""
    names = {n: j for j, n in enumerate(motion.skeleton.names)}
    rot = None if motion.rotations is None else np.array(motion.rotations, copy=True)
    pos = None if motion.positions is None else np.array(motion.positions, copy=True)
    F = motion.num_frames
    out = []
    for g in glitches:
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
