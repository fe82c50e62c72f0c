"""Repairing glitches: only the glitched joint on the glitched frames changes.

A spike or flip of 0.15 s or more (``OFFSET_MIN_TIME``) has its offset taken off (the entry
jump and the inverse of the exit jump, interpolated over the span), which brings back the
real motion under it; any other rotational glitch is bridged by a cubic Hermite curve in
rotation space between the joint's last good rotation before it and its first good one
after it, leaving and arriving at the joint's own speed on both sides (at the clip's ends
the nearest good rotation is held), so no new discontinuity appears; a positional one (bone stretch,
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


#: Shortest spike or flip (seconds) repaired by taking its offset off rather than by a curve.
OFFSET_MIN_TIME = 0.15


def _slerp(q0: np.ndarray, q1: np.ndarray, n: int) -> np.ndarray:
    """``(n, 4)`` rotations strictly between ``q0`` and ``q1`` (x-y-z-w)."""
    from scipy.spatial.transform import Slerp

    key = Rotation.from_quat(np.stack([q0, q1]))
    s = Slerp([0.0, 1.0], key)
    return s(np.arange(1, n + 1) / (n + 1)).as_quat()


def _hermite(R: np.ndarray, a: int, b: int) -> np.ndarray:
    """``(b - a - 1, 4)`` rotations strictly between frames ``a`` and ``b`` of ``R (F, 4)``:
    a cubic Hermite curve in the tangent space at ``R[a]`` through both ends, its end
    velocities the joint's own one-frame motion just outside (so a glitch over moving
    motion is bridged at that motion's speed, not by a pause)."""
    from ..rotations import quat_conj, quat_mul

    F, n = len(R), b - a - 1
    base = quat_conj(R[a])

    def log(q):
        return Rotation.from_quat(quat_mul(np.broadcast_to(base, q.shape), q)).as_rotvec()

    p0, p1 = np.zeros(3), log(R[b][None])[0]
    v0 = -log(R[a - 1][None])[0] if a >= 1 else p1 / (n + 1)
    v1 = (log(R[b + 1][None])[0] - p1) if b + 1 < F else p1 / (n + 1)
    span = float(n + 1)
    s = (np.arange(1, n + 1) / span)[:, None]
    h00, h10, h01, h11 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s, -2 * s**3 + 3 * s**2, s**3 - s**2
    p = h00 * p0 + h10 * span * v0 + h01 * p1 + h11 * span * v1
    return quat_mul(np.broadcast_to(R[a], (n, 4)), Rotation.from_rotvec(p).as_quat())


def _remove_offset(R: np.ndarray, a: int, b: int) -> np.ndarray | None:
    """Frames ``a+1 .. b-1`` of ``R (F, 4)`` with the glitch's offset taken off: the entry
    jump :math:`q_{a+1} q_a^{-1}` (or, in the joint's own frame, :math:`q_a^{-1} q_{a+1}`)
    and the exit jump's inverse, interpolated over the span, so the real motion under a
    spike, segment or flip comes back instead of a straight line; the convention is the
    one whose exit undoes its entry best.  None at the clip's ends."""
    from scipy.spatial.transform import Slerp

    from ..rotations import quat_conj, quat_mul

    n = b - a - 1
    if a < 0 or b >= len(R) or n < 1:
        return None
    q = R[a : b + 1]
    inv = quat_conj(q)
    pre_in, pre_out = quat_mul(q[1], inv[0]), quat_mul(q[-2], inv[-1])  # parent frame
    post_in, post_out = quat_mul(inv[0], q[1]), quat_mul(inv[-1], q[-2])  # joint frame
    d_pre = Rotation.from_quat(pre_in).inv() * Rotation.from_quat(pre_out)
    d_post = Rotation.from_quat(post_in).inv() * Rotation.from_quat(post_out)
    pre = d_pre.magnitude() <= d_post.magnitude()
    ends = Rotation.from_quat(np.stack([pre_in, pre_out] if pre else [post_in, post_out]))
    offset = Slerp([0.0, 1.0], ends)(np.linspace(0.0, 1.0, n) if n > 1 else [0.5])
    inner = Rotation.from_quat(q[1:-1])
    return (offset.inv() * inner if pre else inner * offset.inv()).as_quat()


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
    with ``corrected`` filled in ("offset removed", "cubic" (Hermite in rotation space), "slerp" (at the clip's ends), "linear" or "" for reported only)."""
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
            # a glitch over a few frames is bridged best by the curve (the offset read off one
            # jump carries that frame's real motion); over a longer one the real motion under
            # the offset is worth more than any curve
            long_ = n >= OFFSET_MIN_TIME * float(motion.fps)
            fixed_span = _remove_offset(arr[:, j], a, b) if g.kind in ("spike", "flip") and long_ else None
            if fixed_span is not None:
                arr[g.start : g.end + 1, j] = fixed_span
                out.append(dataclasses.replace(g, corrected="offset removed"))
                continue
            arr[g.start : g.end + 1, j] = _hermite(arr[:, j], a, b) if 0 <= a and b < F else _slerp(first, last, n)
        else:
            w = (np.arange(1, n + 1) / (n + 1))[:, None]
            arr[g.start : g.end + 1, j] = (1 - w) * first + w * last
        curve = "cubic" if 0 <= a and b < F else "slerp"
        out.append(dataclasses.replace(g, corrected=curve if how == "rotation" else "linear"))
    fixed = dataclasses.replace(motion, rotations=rot) if rot is not None else motion
    if pos is not None:
        fixed = dataclasses.replace(fixed, positions=pos)
    return fixed, out
