r"""Glitches of joint-position sources (trackers, marker joint centres, any motion with
``positions``): left/right swaps, gaps, frozen joints and bone-length changes.

* **Left/right swaps** (:func:`lr_swaps`): a left joint and its right twin (by canonical
  mapping or by name, :func:`twin`) trading places: the labelling of the clip that follows
  the two tracks best, each change of labelling costing ``swap_min_distance``.
* **Gaps** (:func:`gaps`): runs where the tracker's confidence is zero or the position is
  missing.
* **Frozen** joints: a position held exactly for ``frozen_time`` or longer while the body
  moves (its median joint faster than ``still_velocity``) or ending with the joint catching
  up (:func:`physmocap.clean.detect._frozen`, the same test as for rotations).
* **Bone stretch** (:func:`bone_stretch`): a bone whose length departs from its median by
  more than ``stretch_ratio`` of it and ``stretch_distance``, reported on the joint that
  moved (:func:`_culprits`), not on every bone it touches; bones explained by a swap or a
  freeze of one of their joints are not reported again.
"""

from __future__ import annotations

import re

import numpy as np

from ..motion import Motion
from .detect import Glitch, _frozen
from .options import CleanOptions

__all__ = ["positional_glitches", "lr_swaps", "gaps", "bone_stretch", "twin", "twin_pairs"]


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """``(start, end)`` (inclusive) of the runs of True in ``mask (F,)``."""
    d = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return [(int(s), int(e)) for s, e in zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1) - 1)]


def twin(name: str, names: dict[str, int]) -> int | None:
    """Index of the joint named like ``name`` with the other side (``Left``/``Right``,
    ``left_``/``right_``, ``L``/``R`` prefixes, ``_L``/``_R`` suffixes), or None."""
    swaps = [("Left", "Right"), ("left", "right"), ("LEFT", "RIGHT"), ("L", "R"), ("l", "r")]
    for a, b in swaps:
        for x, y in ((a, b), (b, a)):
            for pattern in (rf"^{x}(?=[_A-Z\d]|$)", rf"(?<=[_\s]){x}(?=[_\s]|$)", rf"^{x}_"):
                other = re.sub(pattern, y, name, count=1)
                if other != name and other in names:
                    return names[other]
    return None


def twin_pairs(motion: Motion, ji: dict[str, int]) -> list[tuple[int, int]]:
    """Every (left, right) joint pair of ``motion``: the canonical ``left_*`` / ``right_*``
    joints of the mapping ``ji``, and any other two joints named as each other's other side
    (:func:`twin`: fingers, toes and end sites no canonical joint names)."""
    names = {n: j for j, n in enumerate(motion.skeleton.names)}
    pairs = {(ji[c], ji["right_" + c[5:]]) for c in ji if c.startswith("left_") and "right_" + c[5:] in ji}
    for n, j in names.items():
        t = twin(n, names)
        if t is not None and t != j:
            pairs.add((min(j, t), max(j, t)))
    seen: set[frozenset] = set()
    out = []
    for a, b in sorted(pairs):
        if a != b and frozenset((a, b)) not in seen:
            seen.add(frozenset((a, b)))
            out.append((a, b))
    return out


#: Frames of residuals computed at a time (bounded memory on hour-long clips).
BLOCK = 4096


def _swap_residuals(L: np.ndarray, R: np.ndarray, t0: int, t1: int) -> np.ndarray:
    r"""``(K, t1 - t0, 8)``: for the pairs ``L, R (K, F, 3)``, how far (metres, both joints
    summed) the samples of frames ``t0 .. t1 - 1`` (``t0 >= 2``) land from where the two
    tracks were heading, for every labelling of that frame and the two before (index
    :math:`4 s_{t-2} + 2 s_{t-1} + s_t`, :math:`s = 1` traded):
    :math:`|X_t(s_t) - 2 X_{t-1}(s_{t-1}) + X_{t-2}(s_{t-2})|` (constant velocity; 0 for
    every labelling where a sample of the three frames is missing: no evidence, so the
    labelling holds across a gap)."""
    seg_l, seg_r = L[:, t0 - 2 : t1], R[:, t0 - 2 : t1]
    X = np.stack([np.stack([seg_l, seg_r], axis=2), np.stack([seg_r, seg_l], axis=2)], axis=2)  # (K, n+2, s, side, 3)
    out = np.empty((L.shape[0], t1 - t0, 8))
    for code in range(8):
        s2, s1, s0 = code >> 2, (code >> 1) & 1, code & 1
        miss = X[:, 2:, s0] - 2.0 * X[:, 1:-1, s1] + X[:, :-2, s2]  # (K, n, side, 3)
        out[..., code] = np.linalg.norm(miss, axis=-1).sum(axis=-1)
    out[~np.isfinite(out)] = 0.0  # a sample missing on one of the three frames: no evidence either way
    return out


def _swapped_frames(L: np.ndarray, R: np.ndarray, margin: float, start: int = 0) -> np.ndarray:
    """``(K, F)`` True on the frames where the positions ``L, R (K, F, 3)`` of a left joint and
    its right twin (``K`` pairs) are traded: the labelling of the whole clip that follows the
    two tracks best, i.e. with the smallest sum of :func:`_swap_residuals` plus ``margin``
    metres for each change of labelling (a trade must explain the motion better by that
    much), found exactly by dynamic programming (Viterbi, over the labellings of two
    consecutive frames).  The labels before ``start`` + 2 (a reference pose the capture jumps
    away from, and the two frames a heading needs) are taken as they are."""
    K, F = L.shape[:2]
    out = np.zeros((K, F), dtype=bool)
    first = start + 2
    if F <= first:
        return out
    # state (s_{t-1}, s_t) = 2 s_{t-1} + s_t; before ``first`` every label is kept
    best = np.full((K, 4), np.inf)
    best[:, 0] = 0.0
    back = np.zeros((F, K, 4), dtype=np.int8)
    codes = np.arange(8)
    prev_state, next_state = codes >> 1, codes & 3  # (s2, s1) and (s1, s0) of each code
    switch = margin * ((codes & 1) != ((codes >> 1) & 1))
    ends = [np.flatnonzero(next_state == st) for st in range(4)]  # the two codes ending in each state
    rows = np.arange(K)
    for t in range(first, F):
        if (t - first) % BLOCK == 0:
            cost, t0 = _swap_residuals(L, R, t, min(F, t + BLOCK)), t
        total = best[:, prev_state] + cost[:, t - t0] + switch  # (K, 8)
        new = np.empty((K, 4))
        for st, cand in enumerate(ends):
            pick = cand[np.argmin(total[:, cand], axis=1)]
            new[:, st] = total[rows, pick]
            back[t, :, st] = prev_state[pick]
        best = new
    state = np.argmin(best, axis=1)
    for t in range(F - 1, first - 1, -1):
        out[:, t] = (state & 1).astype(bool)
        state = back[t, rows, state]
    return out


def lr_swaps(
    motion: Motion, P: np.ndarray, opt: CleanOptions, ji: dict[str, int], start: int = 0
) -> list[Glitch]:
    """Spans where a left joint and its right twin (:func:`twin_pairs`) trade places in the
    positions ``P (F, J, 3)`` (:func:`_swapped_frames`, the margin ``swap_min_distance``: a
    labeller trading two markers, a tracker flipping the body), on both joints, from frame
    ``start`` on; severity the pair's median distance (metres)."""
    names = motion.skeleton.names
    out: list[Glitch] = []
    pairs = twin_pairs(motion, ji)
    if not pairs:
        return out
    left, right = (np.moveaxis(P[:, [p[k] for p in pairs]], 1, 0) for k in (0, 1))  # (K, F, 3)
    swapped = _swapped_frames(left, right, opt.swap_min_distance, start)
    for (jl, jr), traded in zip(pairs, swapped):
        apart = np.linalg.norm(P[:, jl] - P[:, jr], axis=1)
        for a, b in _runs(traded):
            size = float(np.nanmedian(apart[a : b + 1]))
            for j, k in ((jl, jr), (jr, jl)):
                out.append(Glitch("lr_swap", names[j], a, b, size, unit="m", other=names[k]))
    return out


def lost_samples(motion: Motion, P: np.ndarray) -> np.ndarray:
    """``(F, J)`` True where a joint is not tracked: confidence zero or a missing position."""
    lost = ~np.isfinite(P).all(axis=-1)
    if motion.confidence is not None:
        lost |= np.asarray(motion.confidence) <= 0.0
    return lost


def gaps(motion: Motion, P: np.ndarray) -> list[Glitch]:
    """Runs of :func:`lost_samples`, per joint; severity their duration (seconds)."""
    fps = float(motion.fps)
    lost = lost_samples(motion, P)
    names = motion.skeleton.names
    return [
        Glitch("gap", names[j], s, e, float((e - s + 1) / fps), unit="s")
        for j in range(P.shape[1])
        for s, e in _runs(lost[:, j])
    ]


def frozen_positions(motion: Motion, P: np.ndarray, opt: CleanOptions) -> list[Glitch]:
    """Joints whose position is held exactly while the body moves (the body moves on a frame
    where its median joint is faster than ``still_velocity``), or that catch up after the hold
    (:func:`physmocap.clean.detect._frozen`)."""
    fps = float(motion.fps)
    P = np.where(lost_samples(motion, P)[..., None], np.nan, P)  # a lost joint is not frozen, whatever is written there
    step = np.full(P.shape[:2], np.nan)
    step[1:] = np.linalg.norm(P[1:] - P[:-1], axis=-1)
    still = opt.still_velocity / fps
    with np.errstate(invalid="ignore"):
        tracked = np.isfinite(step).any(axis=0)
        cols = step[:, tracked]
        median = np.full(len(P), np.nan)
        rows = np.isfinite(cols).any(axis=1)
        median[rows] = np.nanmedian(cols[rows], axis=1)
        moving = median > still
    names = motion.skeleton.names
    out: list[Glitch] = []
    for j in np.flatnonzero(tracked):
        out += _frozen(P[:, j], step[:, j], moving, fps, opt, names[j], still)
    return out


def _bones(motion: Motion, P: np.ndarray) -> tuple[list[tuple[int, int]], np.ndarray, np.ndarray]:
    """The bones ``(parent, joint)`` of ``motion``'s skeleton that have a length (median over
    the clip above a micrometre: not two names for one point), their lengths ``(F, B)``
    (metres) and medians ``(B,)``."""
    parents = motion.skeleton.parents
    bones, lengths, medians = [], [], []
    for j, p in enumerate(parents):
        if p < 0:
            continue
        length = np.linalg.norm(P[:, j] - P[:, p], axis=1)
        if not np.isfinite(length).any():
            continue
        med = float(np.nanmedian(length))
        if med > 1e-6:
            bones.append((int(p), j))
            lengths.append(length)
            medians.append(med)
    if not bones:
        return [], np.zeros((len(P), 0)), np.zeros(0)
    return bones, np.stack(lengths, axis=1), np.asarray(medians)


def _culprits(bones: list[tuple[int, int]], bad: np.ndarray, J: int) -> np.ndarray:
    """``(F, J)``: the joint that moved, for every bad bone of ``bad (F, B)``.

    A joint that leaves its place changes the length of every bone it ends that does not
    happen to turn about it; a bone ``(p, j)`` is blamed on its parent end ``p`` when another
    bone of ``p`` is bad on that frame and no bone below ``j`` is, else on ``j`` (a displaced
    joint's child bones are blamed on it, not on the children)."""
    F = bad.shape[0]
    incident = np.zeros((F, J), dtype=int)  # bad bones ending at each joint
    below = np.zeros((F, J), dtype=bool)  # a bad bone from the joint to a child
    for b, (p, j) in enumerate(bones):
        incident[:, p] += bad[:, b]
        incident[:, j] += bad[:, b]
        below[:, p] |= bad[:, b]
    out = np.zeros((F, J), dtype=bool)
    for b, (p, j) in enumerate(bones):
        parent_end = bad[:, b] & (incident[:, p] > 1) & ~below[:, j]
        out[:, p] |= parent_end
        out[:, j] |= bad[:, b] & ~parent_end
    return out


def bone_stretch(
    motion: Motion, P: np.ndarray, opt: CleanOptions, explained: np.ndarray | None = None
) -> list[Glitch]:
    """Spans where a joint's bones change length by more than ``stretch_ratio`` of their
    median and ``stretch_distance`` (:func:`_culprits` says which joint moved); ``explained
    (F, J)`` marks the (frame, joint) samples already reported by another glitch (a swap, a
    freeze), whose bones are not reported again.  Severity: the largest departure (metres)."""
    bones, length, med = _bones(motion, P)
    if not bones:
        return []
    J = P.shape[1]
    with np.errstate(invalid="ignore"):
        dev = np.abs(length - med)
        bad = dev > np.maximum(opt.stretch_ratio * med, opt.stretch_distance)
    if explained is not None:
        for b, (p, j) in enumerate(bones):
            bad[:, b] &= ~(explained[:, p] | explained[:, j])
    blamed = _culprits(bones, bad, J)
    worst = np.zeros((len(P), J))
    for b, (p, j) in enumerate(bones):
        d = np.where(bad[:, b], dev[:, b], 0.0)
        worst[:, p] = np.maximum(worst[:, p], d)
        worst[:, j] = np.maximum(worst[:, j], d)
    names = motion.skeleton.names
    return [
        Glitch("bone_stretch", names[j], s, e, float(worst[s : e + 1, j].max()), unit="m")
        for j in range(J)
        for s, e in _runs(blamed[:, j])
    ]


def positional_glitches(motion: Motion, opt: CleanOptions, ji: dict[str, int]) -> list[Glitch]:
    """Swaps, gaps, frozen joints and bone stretch of ``motion.positions`` (``ji``: its
    canonical joints, for the left/right pairs)."""
    from .detect import reference_exit

    P = np.asarray(motion.positions, dtype=float)
    names = {n: j for j, n in enumerate(motion.skeleton.names)}
    start = reference_exit(motion, opt, P)  # a reference pose the capture jumps away from (CMU's T-pose)
    found = lr_swaps(motion, P, opt, ji, start) + gaps(motion, P) + frozen_positions(motion, P, opt)
    explained = lost_samples(motion, P)
    for g in found:
        explained[g.start : g.end + 1, names[g.joint]] = True
    return found + bone_stretch(motion, P, opt, explained)
