"""Repairing glitches: only the glitched joint on the glitched frames changes.

A spike or flip of 0.15 s or more (``CleanOptions.offset_min_time``) has its offset taken off (the entry
jump and the inverse of the exit jump, interpolated over the span), which brings back the
real motion under it.  Any other rotational glitch (a frozen joint, a joint past its range
of motion, a short spike or flip) is bridged between the joint's last good rotation before
it and its first good one after it by whichever of six estimates rebuilds the joint's
own good motion next to the span best, or their blend (:func:`_bridge`): a cubic Hermite
curve in rotation space, leaving and arriving at the joint's own speed (:mod:`.hermite`),
the joint's motion in the windows of the clip where the whole body moves most like it does around the span
(:class:`_Matcher`: a frozen joint's real motion is lost, the rest of the body still shows
what it was doing), its other side's motion, reflected, in the windows where the body
mirrored left to right moves most like it (half a stride away in a walk), its pose or its
steps regressed on the other joints' rotations (:class:`.regress.Regression`), or the cubic
plus the joint's departure from it regressed on the other joints' departures from theirs
over the same frames (:class:`.regress.Departure`).  Where a point
below the joint stands on the floor next to the span, the bridge is turned so that it goes
on standing there while the rest of the limb can reach it (:func:`_on_contact`: a frozen
thigh keeps its foot planted).  At the clip's ends the nearest good rotation is held.  A
positional glitch (bone stretch, gap, a held position) is bridged by the joint's offset
from its parent turning steadily from its value before to its value after, riding on the
parent's own motion (linear interpolation of the position where the parent is not tracked),
then, where a child of the joint is tracked, moved onto the circle at its two bone lengths
from the parent and the child (:func:`_on_bones`); a stretched bone whose joint keeps moving
on continuously is instead put back at its length along its own direction (:func:`_along_bone`),
and a joint with a tracked child rides on whichever of its parent, its child and the plane of
its parent, child and grandparent rebuilds its own motion next to the span best
(:func:`_judged_position`; one with no tracked child, a hand or a toe's end, on its parent or
on its parent's bone, the plane of its parent, grandparent and great-grandparent);
a left/right swap by trading the two joints' positions back over the span.
Discontinuities (a jump with no return) are reported, not changed: the motion after them
may be the real one.  A rotational repair whose pose leaves a range of motion is re-solved
through the hard-limited IK on an actor-fitted humanoid (:mod:`.resolve`, "re-solved").
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..errors import OptionError
from ..motion import Motion
from ..rotations import Rotation
from .detect import CleanOptions, Glitch, _angle, animated_joints, canonical_joints
from .hermite import curve as hermite_curve, log_between
from .positional import twin as positional_twin, twin_pairs
from .regress import Departure, Regression, spread_mismatch

__all__ = ["BRIDGES", "blend_shares", "correct_glitches"]


#: The rotational bridges :func:`_bridge` chooses among (and averages), as the report names them.
BRIDGES = ("cubic", "matched", "mirrored", "regressed pose", "regressed steps", "regressed departure")

#: Glitch kinds that are repaired (the others are reported only).
REPAIRED = {
    "spike": "rotation",
    "flip": "rotation",
    "frozen": "rotation",
    "anatomical": "rotation",
    "bone_stretch": "position",
    "gap": "position",
}


def _hermite(R: np.ndarray, a: int, b: int) -> np.ndarray:
    """``(b - a - 1, 4)`` rotations strictly between frames ``a`` and ``b`` of ``R (F, 4)``:
    a cubic Hermite curve in the tangent space at ``R[a]`` through both ends
    (:func:`.hermite.curve`), its end velocities the joint's own one-frame motion just outside
    (so a glitch over moving motion is bridged at that motion's speed, not by a pause), or,
    at the clip's ends, the span's mean turn per frame."""
    F, n = len(R), b - a - 1
    p1 = log_between(R[a], R[b])
    v0 = -log_between(R[a], R[a - 1]) if a >= 1 else p1 / (n + 1)
    v1 = (log_between(R[a], R[b + 1]) - p1) if b + 1 < F else p1 / (n + 1)
    return hermite_curve(R[a], p1, v0, v1, n)


#: Bytes of spectra :func:`_correlation` holds at once (a block of joints at a time).
CORRELATION_BLOCK_BYTES = 64 << 20


def _correlation(body: np.ndarray, T: np.ndarray) -> np.ndarray:
    r"""``(F - L + 1,)``: :math:`\sum_{t,k,c} T_{kc}(t)\, B_{kc}(t + x)` for ``body B (F, K,
    9)`` and a template ``T (L, K, 9)``, the correlation summed over its channels: in the
    frequency domain, the channels' products summed before one inverse transform, a block of
    joints at a time (:data:`CORRELATION_BLOCK_BYTES` of spectra), so neither the channels'
    correlations nor the whole body's spectrum are ever held.  A joint whose template is all
    zero is skipped."""
    from scipy import fft

    F, L, K = len(body), len(T), T.shape[1]
    size = fft.next_fast_len(F + L - 1, real=True)
    used = [k for k in range(K) if T[:, k].any()]
    per = max(1, CORRELATION_BLOCK_BYTES // (16 * 9 * (size // 2 + 1)))
    acc = np.zeros(size // 2 + 1, dtype=complex)
    for b0 in range(0, len(used), per):
        cols = used[b0 : b0 + per]
        X = fft.rfft(np.asarray(body[:, cols], dtype=float).reshape(F, -1), size, axis=0)
        Y = fft.rfft(T[::-1, cols].reshape(L, -1), size, axis=0)
        acc += np.einsum("fc,fc->f", X, Y)
    return fft.irfft(acc, size)[L - 1 : F]


class _Matcher:
    r"""Bridging a glitch with the motion the clip itself makes elsewhere.

    A frozen joint (or any long bridged span) hides real motion no curve can guess; the
    rest of the body still shows what it was doing.  For joint :math:`j` over frames
    :math:`s..e` (:math:`n` of them) the template is every animated joint's rotation matrix
    on :math:`s-c .. e+c` (:math:`c` = ``match_context`` times :math:`n` frames each side),
    without the glitched (joint, frame) pairs, joint :math:`j`'s own context frames
    weighted ``match_own_weight`` (its motion into and out of the span says most about it).  A
    window :math:`d` frames away scores :math:`\sum_{t,k} w_{tk}
    \operatorname{tr}(R_k(t)^\top R_k(t+d))` (the squared Frobenius distance up to a
    constant: one FFT correlation over the clip); the ``match_windows`` highest-scoring windows that
    do not overlap the template or each other, and whose joint :math:`j` is clean, lend
    their joint :math:`j` increments :math:`\log(q_j(s-1+d)^{-1} q_j(t+d))`, averaged,
    applied from the last good rotation :math:`q_j(s-1)`; the mismatch left at
    :math:`e+1` is spread linearly over the span in the joint's frame, so both ends join
    exactly.

    Mirrored (``mirror``: each joint's other side and the reflection :math:`M` across the
    body's midplane, :func:`_mirror`), the clip side of the correlation is the body mirrored,
    :math:`M R_{k'}(t) M` for every joint :math:`k` with its other side :math:`k'` (itself on
    the midline; left out where :math:`k'` is glitched), and the windows lend the other
    side's increments reflected, :math:`-Mv` for a rotation vector :math:`v`; they may
    overlap the template (the other leg at the same time, in a jump).  The mirrored body is
    not held: :math:`\operatorname{tr}((M X M)^\top Y) = \operatorname{tr}(X^\top M Y M)`,
    so the plain body is correlated with the template reflected and moved onto the other
    sides' columns instead (:meth:`_mirrored_scores`), the only ``(F, J, 9)`` array held
    being the plain body's (about 1.2 GB for an hour of 38 joints at 120 Hz).
    """

    def __init__(
        self, R: np.ndarray, animated: list[int], bad: np.ndarray, context: float, own_weight: float, best: int,
        mirror: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> None:
        F = len(R)
        self.R, self.animated, self.bad = R, animated, bad
        self.context, self.own_weight, self.best = context, own_weight, best
        self.M = Rotation.from_quat(R[:, animated].reshape(-1, 4)).as_matrix().reshape(F, len(animated), 9)
        self.twin = self.reflect = None
        if mirror is not None:
            # (J,) each joint's other side (itself on the midline), (3, 3)
            self.twin, self.reflect = mirror

    @property
    def mirrors(self) -> bool:
        """Whether the body can be mirrored (the skeleton has left and right sides)."""
        return self.twin is not None

    def _mirrored_scores(self, T: np.ndarray) -> np.ndarray:
        r"""``(F - L + 1,)``: the template ``T (L, A, 9)`` (the animated joints' weighted
        rotation matrices) correlated with the body mirrored, :math:`\sum_{t,k}
        \operatorname{tr}(T_k(t)^\top M R_{k'}(t+x) M)` over the animated joints :math:`k`
        whose other side :math:`k'` is not glitched at :math:`t+x`, without building the
        mirrored body: the template reflected, :math:`M T_k M`, is correlated with the plain
        body's column of :math:`k'` (or, where :math:`k'` is not animated, its own rotation
        matrices), and the glitched pairs' terms are taken off one by one."""
        F, L, A = len(self.R), len(T), len(self.animated)
        S = self.reflect
        Tm = (S @ T.reshape(L, A, 3, 3) @ S).reshape(L, A, 9)
        column = {k: i for i, k in enumerate(self.animated)}
        other = np.array([int(self.twin[k]) for k in self.animated])
        on_body = np.zeros_like(Tm)
        rest = [i for i, c in enumerate(other) if c not in column]
        for i, c in enumerate(other):
            if c in column:
                on_body[:, column[c]] = Tm[:, i]
        score = _correlation(self.M, on_body)
        if rest:  # another side that does not move: its own rotations
            X = Rotation.from_quat(self.R[:, other[rest]].reshape(-1, 4)).as_matrix().reshape(F, len(rest), 9)
            score += _correlation(X, Tm[:, rest])
        frames, cols = np.nonzero(self.bad[:, other])
        lag = np.arange(L)
        for c0 in range(0, len(frames), 4096):  # the glitched pairs' terms, a bounded number at a time
            u, i = frames[c0 : c0 + 4096], cols[c0 : c0 + 4096]
            X = Rotation.from_quat(self.R[u, other[i]]).as_matrix().reshape(-1, 9)
            terms = np.einsum("pc,tpc->pt", X, Tm[:, i])
            x = u[:, None] - lag[None]
            keep = (x >= 0) & (x <= F - L)
            score -= np.bincount(x[keep], weights=terms[keep], minlength=F - L + 1)
        return score

    def _scores(self, j: int, s: int, e: int, hidden: np.ndarray, mirrored: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """``(offsets d, scores)`` of the windows that may lend joint ``j`` motion for
        ``s..e`` (``hidden (F,)``: joint ``j``'s frames not to use, the span included);
        ``mirrored``: windows of the body mirrored left to right (joint ``j``'s other side
        lends its motion, reflected)."""
        F, n = len(self.R), e - s + 1
        c = max(2, int(round(self.context * n)))
        lo, hi = max(0, s - c), min(F, e + 1 + c)
        w = (~self.bad[lo:hi][:, self.animated]).astype(float)
        if j in self.animated:
            col = self.animated.index(j)
            w[:, col] *= self.own_weight * ~hidden[lo:hi]
        T = self.M[lo:hi] * w[..., None]
        if mirrored:
            score = self._mirrored_scores(T)
        else:
            score = _correlation(self.M, T)
        d = np.arange(len(score)) - lo
        src = int(self.twin[j]) if mirrored else j
        ok = (s - 1 + d >= 0) & (e + 1 + d < F)
        if src == j:
            ok &= np.abs(d) >= hi - lo
        cum = np.concatenate([[0], np.cumsum(self.bad[:, src] | (hidden if src == j else False))])
        first, last = np.clip(s - 1 + d, 0, F), np.clip(e + 2 + d, 0, F)
        ok &= cum[last] == cum[first]  # the lending joint's own motion there is clean
        return d[ok], score[ok]

    def bridge(
        self, j: int, s: int, e: int, hidden: np.ndarray | None = None, mirrored: bool = False
    ) -> np.ndarray | None:
        """``(e - s + 1, 4)`` rotations of joint ``j`` on ``s..e``, or None (no window
        fits); ``hidden (F,)`` marks more of joint ``j``'s frames not to use; ``mirrored``:
        the windows of the body mirrored left to right lend the motion of joint ``j``'s other
        side, reflected."""
        from ..rotations import quat_conj, quat_mul

        F, n = len(self.R), e - s + 1
        if s < 1 or e + 1 >= F or (mirrored and not self.mirrors):
            return None
        hide = np.zeros(F, dtype=bool) if hidden is None else hidden.copy()
        hide[s : e + 1] = True
        d, score = self._scores(j, s, e, hide, mirrored)
        picks: list[int] = []
        for k in d[np.argsort(-score, kind="stable")]:
            if all(abs(k - p) > n for p in picks):
                picks.append(int(k))
            if len(picks) == self.best:
                break
        if not picks:
            return None
        lender = int(self.twin[j]) if mirrored else j
        inc = np.zeros((n + 2, 3))
        for k in picks:
            src = self.R[s - 1 + k : e + 2 + k, lender]
            v = Rotation.from_quat(quat_mul(np.broadcast_to(quat_conj(src[0]), src.shape), src)).as_rotvec()
            inc += -v @ self.reflect if mirrored else v  # a rotation vector reflected: -M v
        step = Rotation.from_rotvec(inc / len(picks)).as_quat()
        est = quat_mul(np.broadcast_to(self.R[s - 1, j], step.shape), step)
        return spread_mismatch(est, self.R[e + 1, j])


def _glitched(motion: Motion, glitches: list[Glitch]) -> np.ndarray:
    """``(F, J)`` bool: the (frame, joint) pairs of ``glitches``."""
    names = {n: j for j, n in enumerate(motion.skeleton.names)}
    bad = np.zeros((motion.num_frames, len(names)), dtype=bool)
    for g in glitches:
        bad[g.start : g.end + 1, names[g.joint]] = True
    return bad


def _mirror(motion: Motion, ji: dict[str, int]) -> tuple[np.ndarray, np.ndarray] | None:
    """``(twin (J,), reflection (3, 3))``: each joint's other side (:func:`.positional.twin_pairs`:
    the mapping ``ji``'s ``left_*`` / ``right_*`` joints, and joints named as each other's
    other side; itself on the midline) and the reflection across the body's midplane, its
    normal the mean left-to-right direction of the twin joints' rest positions; None
    without twins."""
    pairs = twin_pairs(motion, ji)
    if not pairs:
        return None
    twin = np.arange(motion.skeleton.num_joints)
    for a, b in pairs:
        twin[a], twin[b] = b, a
    rest = np.asarray(motion.skeleton.rest_positions(), dtype=float)
    d = np.stack([rest[a] - rest[b] for a, b in pairs])
    normal = np.linalg.eigh(d.T @ d)[1][:, -1]
    return twin, np.eye(3) - 2.0 * np.outer(normal, normal)


def _matcher(motion: Motion, glitches: list[Glitch], opt: CleanOptions, ji: dict[str, int]) -> _Matcher:
    """A :class:`_Matcher` over ``motion``'s animated joints, every glitch's frames left out
    (``ji``: its canonical joints, for the left and right sides)."""
    R = np.asarray(motion.rotations, dtype=float)
    bad = _glitched(motion, glitches)
    return _Matcher(R, animated_joints(motion), bad, opt.match_context, opt.match_own_weight, opt.match_windows,
                    _mirror(motion, ji))


def _pseudo_gaps(s: int, e: int, F: int) -> list[int]:
    """First frames of the two pseudo-gaps :func:`_bridge` tests a glitch on frames ``s..e``
    of an ``F``-frame clip on: ``n = e - s + 1`` frames just before the span and just after it
    (one good frame left between, and two outside for the bridges' end speeds); where the
    clip ends on one side, the second is the next ``n`` frames on the other side (one frame
    between them), so a glitch near the clip's ends is judged on as much of its joint's own
    motion as one in the middle."""
    n = e - s + 1

    def fits(a: int) -> bool:
        return a >= 2 and a + n + 1 < F

    before, after = s - 2 - n, e + 3
    if fits(before) and fits(after):
        return [before, after]
    if fits(before):
        return [before, before - n - 1] if fits(before - n - 1) else [before]
    if fits(after):
        return [after, after + n + 1] if fits(after + n + 1) else [after]
    return []


def _blend_name(names: list[str], weights: np.ndarray) -> str:
    """How an average of estimates is reported: ``"blend of mirrored 62% + matched 38%"``,
    each estimate's name and share of the weights, the largest first."""
    share = np.asarray(weights, dtype=float) / float(np.sum(weights))
    order = np.argsort(-share, kind="stable")
    return "blend of " + " + ".join(f"{names[i]} {share[i]:.0%}" for i in order)


def blend_shares(corrected: str) -> dict[str, float]:
    """The estimates a repair's report (``Glitch.corrected``) names, with their shares, the
    largest first: ``"mirrored"`` -> ``{"mirrored": 1.0}``, ``"blend of mirrored 62% + matched
    38%, on contact"`` -> ``{"mirrored": 0.62, "matched": 0.38}`` (what follows a comma says
    what was done after, not how it was estimated)."""
    how = corrected.split(",")[0]
    if not how.startswith("blend of "):
        return {how: 1.0}
    parts = (part.rsplit(" ", 1) for part in how[len("blend of "):].split(" + "))
    return {name: float(share.rstrip("%")) / 100.0 for name, share in parts}


def _bridge(
    R: np.ndarray, j: int, s: int, e: int, matcher: _Matcher | None, blend: float = 3.0, ridge: float = 0.01,
    held: bool = False,
) -> tuple[np.ndarray, str]:
    """Joint ``j``'s rotations over frames ``s..e`` of ``R (F, J, 4)`` from six estimates,
    the Hermite curve, the matched motion and the mirrored matched motion
    (:class:`_Matcher`), the joint's pose and its steps regressed on the other joints'
    rotations (:class:`.regress.Regression`, ridge ``ridge``), and the Hermite curve plus the
    joint's departure from it regressed on the other joints' departures from theirs
    (:class:`.regress.Departure`, the same ridge), judged on the joint's own good
    motion next to the span: each rebuilds the ``n = e - s + 1`` frames just before the span
    (leaving one frame between) and just after it as if they were glitched too
    (:func:`_pseudo_gaps`), its error there the sum of squared rotation errors (infinite
    where it cannot be built on one of them).  A ``held`` glitch (a frozen joint) sums instead
    each pseudo-gap's squared errors divided by those of the joint held still at that gap's
    last good frame before: the share of a freeze's error the estimate leaves there, so a
    pseudo-gap where the joint swings widely, and every estimate is far off, does not outweigh
    one where it moves as little as over the span (the dance's forearm coming to rest, seed 4
    of the benchmark: the swing before picked the cubic, 10.7 degrees RMS off, over estimates
    2.1 off).  Measured on the benchmark's out-of-range bends too, and not adopted there
    (seed 1: 95.7 -> 94.8 % of the error removed).  The estimates within ``blend`` times the best
    one's error are averaged (in the tangent space at the best one), weighted by the inverse
    of their errors: where two rebuild the joint's motion about as well, the test cannot tell
    which is right and their mean is off by less than the wrong one.  Returns the rotations
    and how: the estimate's name (one of :data:`BRIDGES`), or where several were averaged
    their names and weights (:func:`_blend_name`: "blend of mirrored 62% + matched 38%")."""
    from ..rotations import quat_conj, quat_mul

    cubic = _hermite(R[:, j], s - 1, e + 1)
    if matcher is None:
        return cubic, "cubic"
    F, n = len(R), e - s + 1
    regression = Regression(R, matcher.M, matcher.animated, matcher.bad, j, s, e, ridge)
    departure = Departure(R, matcher.animated, matcher.bad, j, s, e, ridge)
    kinds = [False, True] if matcher.mirrors else [False]  # mirrored or not

    def estimates(a: int, b: int, hidden: np.ndarray | None) -> list[np.ndarray | None]:
        """Every estimate but the cubic of frames ``a..b`` (``hidden``: more frames not to use)."""
        found = [matcher.bridge(j, a, b, hidden, mirrored) for mirrored in kinds]
        regressed = regression.estimates(a, b)
        return found + (list(regressed) if regressed is not None else [None, None]) + [departure.estimate(a)]

    names = [name for name in BRIDGES if name != "mirrored" or matcher.mirrors]
    err = np.zeros(len(names))
    tested = np.zeros(len(names), dtype=bool)
    gaps = _pseudo_gaps(s, e, F)
    regression.choose_ridge(gaps, n)
    departure.choose_ridge(gaps)
    for a in gaps:
        b = a + n - 1
        hidden = np.zeros(F, bool)
        hidden[a : b + 1] = True
        truth = R[a : b + 1, j]
        scale = max(float(np.sum(_angle(np.broadcast_to(R[a - 1, j], truth.shape), truth) ** 2)), 1e-12) if held else 1.0
        err[0] += np.sum(_angle(_hermite(R[:, j], a - 1, b + 1), truth) ** 2) / scale
        for i, est in enumerate(estimates(a, b, hidden), start=1):
            if est is None:
                err[i] = np.inf
                continue
            err[i] += np.sum(_angle(est, truth) ** 2) / scale
            tested[i] = True
    err[1:][~tested[1:]] = np.inf
    if not np.isfinite(err[1:]).any():
        return cubic, "cubic"
    found = [cubic] + estimates(s, e, None)
    err = np.array([x if q is not None else np.inf for x, q in zip(err, found)])
    best = int(np.argmin(err))
    near = [i for i in range(len(err)) if np.isfinite(err[i]) and err[i] <= blend * err[best]]
    if len(near) < 2:
        return found[best], names[best]
    w = 1.0 / np.maximum(err[near], 1e-12)
    base = found[best]
    step = sum(wi * Rotation.from_quat(quat_mul(quat_conj(base), found[i])).as_rotvec() for wi, i in zip(w, near))
    return quat_mul(base, Rotation.from_rotvec(step / w.sum()).as_quat()), _blend_name([names[i] for i in near], w)


@dataclasses.dataclass(frozen=True)
class _Ground:
    """What :func:`_stances` reads of the clip: the world positions of the joints below the
    rotational glitches (``positions (F, K, 3)``, ``column``: joint index -> column of it;
    :meth:`~physmocap.motion.Motion.joint_world_positions`, a block of frames at a time) and
    the floor's height (:meth:`~physmocap.motion.Motion.floor_height`)."""

    positions: np.ndarray
    column: dict[int, int]
    floor: float

    @classmethod
    def of(cls, motion: Motion, glitches: list[Glitch]) -> "_Ground":
        """The joints below those of ``glitches`` that are repaired in rotation."""
        parents = np.asarray(motion.skeleton.parents)
        names = {n: j for j, n in enumerate(motion.skeleton.names)}
        tops = {names[g.joint] for g in glitches if REPAIRED.get(g.kind) == "rotation"}
        below = [k for k in range(len(parents)) if _ancestors(parents, k) & tops]
        positions, column = motion.joint_world_positions(below)
        return cls(positions, column, motion.floor_height())

    def at(self, joint: int) -> np.ndarray:
        """``(F, 3)``: the world positions of ``joint``."""
        return self.positions[:, self.column[joint]]


def _ancestors(parents: np.ndarray, k: int) -> set[int]:
    """The joints above joint ``k`` (its parent, the parent's parent, ...)."""
    out = set()
    while parents[k] >= 0:
        k = int(parents[k])
        out.add(k)
    return out


def _contact_points(parents: np.ndarray, ground: _Ground, j: int) -> list[int]:
    """Per child of joint ``j``, the lowest (median height over the clip) joint of its
    subtree (end sites included): the points below ``j`` that may touch the floor."""
    top = {}
    for k in range(j + 1, len(parents)):
        p, c = int(parents[k]), k
        while p > j:
            p, c = int(parents[p]), p
        if p == j:
            top.setdefault(c, []).append(k)
    return [ks[int(np.argmin(np.median(ground.positions[:, [ground.column[k] for k in ks], 2], axis=0)))]
            for ks in top.values()]


def _turn(a: np.ndarray, b: np.ndarray, w: np.ndarray) -> np.ndarray:
    r"""``(n, 4)``: per frame the rotation taking the vectors ``a (n, K, 3)`` onto ``b`` best
    (the ``K`` weighted ``w (n, K)``): the shortest arc where one has weight, the Kabsch
    fit where several have.

    Not :func:`physmocap.markers.functional.kabsch`, whose maths differ in two ways that
    matter here: it fits a rigid motion, rotation and translation, about the weighted
    centroids of the two point sets, where this turn is about a fixed pivot (the joint,
    which its parents place: it can turn, not move), :math:`\min_R \sum_k w_k \|R a_k -
    b_k\|^2` with no centring (the centroids' fit turns about another point and, its
    translation dropped, leaves the points off their targets); and with one point Kabsch is
    undetermined (any turn about the target's direction fits), where the shortest arc is the
    least turn that does.  (It also fits one constellation ``(K, 3)`` to every frame; here
    the vectors change per frame.)"""
    from ..rotations import quat_between

    n = len(a)
    out = np.tile([0.0, 0.0, 0.0, 1.0], (n, 1))
    count = (w > 0).sum(axis=1)
    one = count == 1
    if one.any():
        k = np.argmax(w[one] > 0, axis=1)
        rows = np.flatnonzero(one)
        out[one] = quat_between(a[rows, k], b[rows, k])
    for t in np.flatnonzero(count > 1):
        H = (a[t] * w[t][:, None]).T @ b[t]
        U, _, Vt = np.linalg.svd(H)
        d = np.sign(np.linalg.det(Vt.T @ U.T))
        out[t] = Rotation.from_matrix(Vt.T @ np.diag([1.0, 1.0, d]) @ U.T).as_quat()
    return out


def _stances(
    motion: Motion, R: np.ndarray, ground: _Ground, bad: np.ndarray, j: int, s: int, e: int, q: np.ndarray,
    opt: CleanOptions,
) -> tuple[list[int], np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    r"""Where the points below joint ``j`` stand on the floor over its bridge ``q (n, 4)`` on
    frames ``s..e`` of ``R (F, J, 4)``: ``(points, target (n, K, 3), active (n, K), pos, wr)``,
    the ``K`` contact points (joint indices), where each should stand on each frame of the
    span and on which frames it does, and the forward kinematics of the bridged pose on
    frames ``s - 1 .. e + 1`` (``pos (n + 2, J, 3)``, world rotations ``wr (n + 2, J, 4)``);
    None where nothing stands.

    Below each child of ``j`` the lowest point (median height; a toe, a heel) is a contact
    where, on the good frames just before the span (or just after it), it is within
    ``contact_height`` of the clip's floor and slower than ``contact_speed``
    (``ground``: the clip's world positions and floor; ``bad (F, J)``: the glitched pairs; the
    frames where another glitch moves the point, a joint above it, are no stance).  The stance goes on
    into the span (or back from its end) while the bridged pose keeps the point within
    ``contact_radius`` of where it stood (and ``contact_lever`` of its distance from joint
    ``j``: a short lever, a foot's toe, says less) and the rest of the limb, its rotations
    all good, can still reach it (the distance from joint ``j`` within ``contact_reach``); a
    stance from both ends through the whole span moves its point steadily from where it
    stood before to where it stands after."""
    from ..motion import forward_kinematics

    F, n = len(R), e - s + 1
    if s < 2 or e + 2 >= F:
        return None
    fps = float(motion.fps)
    parents = np.asarray(motion.skeleton.parents)
    low = ground.floor + opt.contact_height
    points = []
    for f in _contact_points(parents, ground, j):
        P = ground.at(f)
        chain = [f]
        while chain[-1] >= 0:
            chain.append(int(parents[chain[-1]]))
        chain = [k for k in chain[:-1] if k != j]
        moved = bad[:, chain].any(axis=1)  # frames another glitch moves the contact point on

        def planted(t0: int, t1: int) -> bool:
            fast = np.linalg.norm(P[t1] - P[t0]) * fps >= opt.contact_speed
            return not (fast or moved[t0] or moved[t1] or P[t0, 2] >= low)

        first, last = planted(s - 2, s - 1), planted(e + 1, e + 2)
        if first or last:
            points.append((f, first, last, ~moved[s : e + 1]))
    if not points:
        return None
    Rt = np.array(R[s - 1 : e + 2], copy=True)
    Rt[1:-1, j] = q
    tr = None if motion.translations is None else np.asarray(motion.translations)[s - 1 : e + 2]
    pos, wr = forward_kinematics(motion.skeleton, Rt, tr, motion.translated)
    pj = pos[1:-1, j]
    target = np.zeros((n, len(points), 3))
    active = np.zeros((n, len(points)), dtype=bool)
    for i, (f, first, last, kept) in enumerate(points):
        P = ground.at(f)
        pc = pos[1:-1, f]
        lever = np.linalg.norm(pc - pj, axis=-1)
        radius = np.minimum(opt.contact_radius, opt.contact_lever * lever)

        def holds(x: np.ndarray) -> np.ndarray:
            reach = np.abs(np.linalg.norm(x - pj, axis=-1) - lever) < opt.contact_reach
            return (np.linalg.norm(pc - x, axis=-1) < radius) & reach & (pc[:, 2] < low) & kept

        if first:
            still = holds(P[s - 1])
            k = int(np.argmin(still)) if not still.all() else n
            target[:k, i] = P[s - 1]
            active[:k, i] = True
        if last:
            still = holds(P[e + 1])
            k = n - (int(np.argmin(still[::-1])) if not still.all() else n)
            end = P[e + 1]
            frac = ((np.arange(k, n) + 1.0) / (n + 1))[:, None]
            both = active[k:, i][:, None]  # one stance through the span: from one end to the other
            target[k:, i] = np.where(both, (1 - frac) * target[k:, i] + frac * end, end)
            active[k:, i] = True
    if not active.any():
        return None
    return [f for f, _, _, _ in points], target, active, pos, wr


def _turn_onto(
    parents: np.ndarray, j: int, q: np.ndarray, points: list[int], target: np.ndarray, active: np.ndarray,
    pos: np.ndarray, wr: np.ndarray, ramp: int,
) -> np.ndarray:
    """Joint ``j``'s bridge ``q (n, 4)`` turned so that the ``points`` below it stand at
    ``target (n, K, 3)`` on the frames where they are ``active (n, K)`` (:func:`_stances`,
    with the bridged pose's world positions ``pos`` and rotations ``wr`` on the span and one
    frame either side): on those frames the world turn about joint ``j`` that takes the
    points there (:func:`_turn`), expressed in the parent's frame and applied before ``q``;
    on the other frames the nearest stance frame's turn, eased out linearly over ``ramp``
    frames."""
    from ..rotations import quat_conj, quat_mul

    n = len(q)
    pj = pos[1:-1, j]
    turn = _turn(pos[1:-1, points] - pj[:, None], target - pj[:, None], active.astype(float))  # world
    on = np.flatnonzero(active.any(axis=1))
    idx = np.arange(n)
    near = on[np.argmin(np.abs(idx[:, None] - on[None]), axis=1)]
    weight = np.clip(1.0 - np.abs(idx - near) / (ramp + 1.0), 0.0, 1.0)
    p = int(parents[j])
    wp = wr[1:-1, p][near] if p >= 0 else np.tile([0.0, 0.0, 0.0, 1.0], (n, 1))
    local = quat_mul(quat_mul(quat_conj(wp), turn[near]), wp)  # the world turn in the parent's frame
    local = Rotation.from_rotvec(Rotation.from_quat(local).as_rotvec() * weight[:, None]).as_quat()
    return quat_mul(local, q)


def _on_contact(
    motion: Motion, R: np.ndarray, ground: _Ground, bad: np.ndarray, j: int, s: int, e: int, q: np.ndarray,
    opt: CleanOptions,
) -> np.ndarray | None:
    """``q (n, 4)``, joint ``j``'s bridge over frames ``s..e`` of ``R (F, J, 4)``, turned so
    that what stands on the floor below the joint stays where it stands, or None where
    nothing does: the stances found (:func:`_stances`; ``ground`` the clip's world
    positions and floor, ``bad (F, J)`` the glitched pairs), joint ``j`` turned onto them
    (:func:`_turn_onto`), the turn easing out over ``contact_ramp`` seconds after the
    stance.  A frozen thigh or knee keeps its foot planted instead of sliding it; in the
    swing nothing holds the foot and the bridge is left as it is."""
    found = _stances(motion, R, ground, bad, j, s, e, q, opt)
    if found is None:
        return None
    ramp = max(1, int(round(opt.contact_ramp * float(motion.fps))))
    return _turn_onto(np.asarray(motion.skeleton.parents), j, q, *found, ramp)


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


def _repair_rotation(
    R: np.ndarray, j: int, g: Glitch, fps: float, matcher: _Matcher | None, opt: CleanOptions
) -> tuple[np.ndarray, str]:
    """Joint ``j``'s rotations over glitch ``g`` in ``R (F, J, 4)`` repaired, and how.

    A glitch over a few frames is bridged best (the offset read off one jump carries that
    frame's real motion); over a longer spike or flip the real motion under the offset is
    worth more than any bridge.  At the clip's ends the nearest good rotation is held."""
    F, n = len(R), g.end - g.start + 1
    a, b = g.start - 1, g.end + 1
    if g.kind in ("spike", "flip") and n >= opt.offset_min_time * fps:
        fixed = _remove_offset(R[:, j], a, b)
        if fixed is not None:
            return fixed, "offset removed"
    if 0 <= a and b < F:
        return _bridge(R, j, g.start, g.end, matcher, opt.blend_ratio, opt.regress_ridge, held=g.kind == "frozen")
    held = R[a, j] if a >= 0 else R[b, j]
    return np.repeat(held[None], n, axis=0), "held"


def _slerp_vectors(u: np.ndarray, v: np.ndarray, w: np.ndarray) -> np.ndarray:
    """``(n, 3)``: the vectors from ``u`` to ``v`` (``(3,)`` each) at the fractions ``w (n, 1)``,
    their direction turned at a steady rate and their length linear."""
    lu, lv = float(np.linalg.norm(u)), float(np.linalg.norm(v))
    length = (1 - w) * lu + w * lv
    if min(lu, lv) < 1e-9:
        return (1 - w) * u + w * v
    du, dv = u / lu, v / lv
    angle = float(np.arccos(np.clip(du @ dv, -1.0, 1.0)))
    if angle < 1e-6 or angle > np.pi - 1e-6:  # the same direction, or no single way round
        d = (1 - w) * du + w * dv
        d /= np.maximum(np.linalg.norm(d, axis=-1, keepdims=True), 1e-12)
    else:
        d = (np.sin((1 - w) * angle) * du + np.sin(w * angle) * dv) / np.sin(angle)
    return d * length


def _neighbour_frames(
    P: np.ndarray, parent: int, child: int, anchor: int, frames: np.ndarray, min_deg: float
) -> np.ndarray | None:
    """``(n, 3, 3)`` orthonormal frames (columns) on ``frames`` of ``P (F, J, 3)``: the first
    axis from joint ``parent`` to ``child``, the third across the plane they make with
    ``anchor`` (the parent's own parent); None where that plane is ill-defined on some frame
    (the two directions from the parent within ``min_deg`` degrees of a line, or a joint
    lost)."""
    o = P[frames, parent]
    x = P[frames, child] - o
    z = np.cross(x, P[frames, anchor] - o)
    lx, lz = np.linalg.norm(x, axis=-1, keepdims=True), np.linalg.norm(z, axis=-1, keepdims=True)
    sine = np.sin(np.radians(min_deg))
    with np.errstate(invalid="ignore"):
        span = sine * lx * np.linalg.norm(P[frames, anchor] - o, axis=-1, keepdims=True)
        if not (np.isfinite(lz).all() and (lz > 0.0).all() and (lz >= span).all()):
            return None
    x, z = x / lx, z / lz
    return np.stack([x, np.cross(z, x), z], axis=-1)


def _among_neighbours(
    P: np.ndarray, j: int, parent: int, child: int, anchor: int, s: int, e: int, min_deg: float
) -> np.ndarray | None:
    """Joint ``j``'s positions on frames ``s..e`` of ``P (F, J, 3)`` riding on its tracked
    neighbours: its offset from ``parent`` in the frame the parent, ``child`` and ``anchor``
    (the parent's parent) make (:func:`_neighbour_frames`), interpolated linearly from the
    good frame before the span to the good frame after, so the joint turns with the limb
    around it (a frozen ankle swings with its knee and toe instead of following the knee
    alone); None where the frames are ill-defined (``min_deg``, :func:`_neighbour_frames`)."""
    if s < 1 or e + 1 >= len(P):
        return None
    frames = np.arange(s - 1, e + 2)
    B = _neighbour_frames(P, parent, child, anchor, frames, min_deg)
    if B is None:
        return None
    ends = np.einsum("fji,fj->fi", B[[0, -1]], P[[s - 1, e + 1], j] - P[[s - 1, e + 1], parent])
    if not np.isfinite(ends).all():
        return None
    w = (np.arange(1, e - s + 2) / (e - s + 2))[:, None]
    local = (1 - w) * ends[0] + w * ends[1]
    return P[s : e + 1, parent] + np.einsum("fij,fj->fi", B[1:-1], local)


def _position_estimates(
    P: np.ndarray, j: int, parent: int, child: int | None, anchor: int | None, s: int, e: int, min_deg: float,
    above: int | None = None,
) -> dict[str, np.ndarray]:
    """Estimates of joint ``j``'s positions on frames ``s..e`` of ``P (F, J, 3)``, by name:
    riding on its parent (its offset from the parent turning steadily, :func:`_repair_position`),
    and, where it has a tracked ``child``, riding on the child the same way and on the plane of
    parent, child and ``anchor`` (the parent's parent, :func:`_among_neighbours`, where that
    plane is well defined); a joint with no tracked child (a hand, a toe's end) rides instead on
    its parent's bone, the plane of the parent, ``anchor`` and ``above`` (the anchor's parent:
    :func:`_among_neighbours` with the anchor in the child's place), so its offset turns with
    the limb above it ("with its parent's bone": a frozen hand swings with the upper arm at the
    elbow's bend interpolated, instead of keeping its world direction)."""
    out = {"parent-relative": _repair_position(P, j, parent, s, e)[0]}
    if child is None:
        ridden = None
        if anchor is not None and above is not None:
            ridden = _among_neighbours(P, j, parent, anchor, above, s, e, min_deg)
        if ridden is not None:
            out["with its parent's bone"] = ridden
        return out
    out["child-relative"] = _repair_position(P, j, child, s, e)[0]
    ridden = None if anchor is None else _among_neighbours(P, j, parent, child, anchor, s, e, min_deg)
    if ridden is not None:
        out["among its neighbours"] = ridden
    return out


def _judged_position(
    P: np.ndarray, bad: np.ndarray, j: int, parent: int, child: int | None, anchor: int | None, s: int, e: int,
    opt: CleanOptions, above: int | None = None,
) -> tuple[np.ndarray, str] | None:
    """Joint ``j``'s positions on frames ``s..e`` of ``P (F, J, 3)`` from the estimate of
    :func:`_position_estimates` that rebuilds the joint's own good motion next to the span
    best, all put at their bone lengths (:func:`_on_bones`) where ``child`` is tracked
    (``above``: the anchor's parent, for a joint with no tracked child): each is tried on the
    pseudo-gaps (:func:`_pseudo_gaps`) where the joints it rides on are tracked and unglitched
    (``bad (F, J)``), as the rotational bridges are judged, its error the mean squared
    distance per frame (m^2) over the pseudo-gaps where it can be built (a plane ill-defined
    on one pseudo-gap, a limb held straight there, leaves the other to judge it); those
    within ``blend_ratio`` times the best one's error are averaged, weighted by the inverse of
    their errors.  One that does
    not move on continuously over the span (:func:`_moves_on`, ``stretch_distance``: a plane
    turning over) is left out.  Returns the positions and how (the estimate's name, or where
    several were averaged their names and weights, :func:`_blend_name`), or None where riding
    on the parent wins or no pseudo-gap can tell."""
    F, n = len(P), e - s + 1
    joints = [j] + [k for k in (parent, child, anchor, above) if k is not None]
    if s < 1 or e + 1 >= F or bad[s - 1 : e + 2, joints[1:]].any():
        return None
    found = _position_estimates(P, j, parent, child, anchor, s, e, opt.plane_min_deg, above)
    names = [k for k, est in found.items() if k == "parent-relative" or _moves_on(P, est, j, s, e, opt.stretch_distance)]
    total, count = np.zeros(len(names)), np.zeros(len(names))
    for a in _pseudo_gaps(s, e, F):
        b = a + n - 1
        if bad[a - 1 : b + 2, joints].any() or not np.isfinite(P[a - 1 : b + 2, joints]).all():
            continue
        trial = _position_estimates(P, j, parent, child, anchor, a, b, opt.plane_min_deg, above)
        for i, k in enumerate(names):
            est = trial.get(k)
            if est is None:
                continue  # its plane is ill-defined there: judged on the other pseudo-gap
            if child is not None:
                est = _on_bones(P, est, j, parent, child, a, b)
            total[i] += np.sum((est - P[a : b + 1, j]) ** 2)
            count[i] += n
    if not count[names.index("parent-relative")]:
        return None
    err = np.where(count > 0, total / np.maximum(count, 1), np.inf)  # m^2 per frame
    best = int(np.argmin(err))
    if names[best] == "parent-relative":
        return None
    near = [i for i in range(len(err)) if np.isfinite(err[i]) and err[i] <= opt.blend_ratio * err[best]]
    w = 1.0 / np.maximum(err[near], 1e-12)
    how = names[best] if len(near) < 2 else _blend_name([names[i] for i in near], w)
    return sum(wi * found[names[i]] for wi, i in zip(w, near)) / w.sum(), how


def _bone_child(P: np.ndarray, parents: np.ndarray, j: int, s: int, e: int, bad: np.ndarray) -> int | None:
    """The child of joint ``j`` of ``P (F, J, 3)`` tracked and unglitched (``bad (F, J)``) on
    frames ``s - 1 .. e + 1`` with the longest bone (median over the clip), or None."""
    lo, hi = max(0, s - 1), min(len(P), e + 2)
    kids = [int(c) for c in np.flatnonzero(parents == j) if np.isfinite(P[lo:hi, c]).all() and not bad[lo:hi, c].any()]
    if not kids:
        return None
    with np.errstate(invalid="ignore"):
        length = [np.nanmedian(np.linalg.norm(P[:, c] - P[:, j], axis=-1)) for c in kids]
    best = int(np.nanargmax(length)) if np.isfinite(length).any() else None
    return None if best is None or not length[best] > 0.0 else kids[best]


def _on_bones(P: np.ndarray, est: np.ndarray, j: int, parent: int, child: int, s: int, e: int) -> np.ndarray:
    """``est (n, 3)``, joint ``j``'s estimated positions on frames ``s..e`` of ``P (F, J, 3)``,
    moved to the nearest point at its two bone lengths (medians over the clip, metres) from
    its parent and from its child there: the circle where the two spheres meet, the bend
    taken from the estimate (on the line between them where the spheres do not meet: a limb
    stretched beyond its length).  A frozen knee during a crouch keeps its place between the
    hip and the ankle instead of riding down with the hip."""
    with np.errstate(invalid="ignore"):
        l1 = float(np.nanmedian(np.linalg.norm(P[:, j] - P[:, parent], axis=-1)))
        l2 = float(np.nanmedian(np.linalg.norm(P[:, child] - P[:, j], axis=-1)))
    p, c = P[s : e + 1, parent], P[s : e + 1, child]
    d = np.linalg.norm(c - p, axis=-1, keepdims=True)
    u = (c - p) / np.maximum(d, 1e-9)
    x = np.clip((d**2 + l1**2 - l2**2) / (2 * np.maximum(d, 1e-9)), -l1, l1)
    centre = p + x * u
    radius = np.sqrt(np.maximum(l1**2 - x**2, 0.0))
    off = est - centre
    off -= np.sum(off * u, axis=-1, keepdims=True) * u
    size = np.linalg.norm(off, axis=-1, keepdims=True)
    moved = centre + radius * off / np.maximum(size, 1e-9)
    return np.where((size > 1e-9) & (d > 1e-9), moved, est)


def _along_bone(
    P: np.ndarray, est: np.ndarray, j: int, parent: int, s: int, e: int, how: str, noise: float
) -> tuple[np.ndarray, str]:
    """A stretched bone put back at its length: joint ``j``'s own positions on frames
    ``s..e`` of ``P (F, J, 3)`` moved along their direction from the parent to the bone's
    length (its median over the clip), the nearest positions at that length (the smallest
    change that makes the bone whole: a joint centre slid along its bone comes back exactly,
    where an interpolation over a long span loses its motion).  Used only where the joint so
    placed moves on continuously: no step from the good frame before the span to the good
    frame after it is more than ``noise`` metres (a marker-based joint centre's soft-tissue
    noise, ``stretch_distance``) beyond the joint's largest step over as many good frames
    next to the span -- a joint thrown off its bone's direction too (a mislabelled marker)
    says nothing of where the bone points, and keeps ``est`` (the interpolation, ``how``), as
    does a span with a lost sample or a joint on its parent.  Returns the positions and how
    ("along its bone" where it was used)."""
    F = len(P)
    if s < 1 or e + 1 >= F:
        return est, how
    with np.errstate(invalid="ignore"):
        length = float(np.nanmedian(np.linalg.norm(P[:, j] - P[:, parent], axis=-1)))
    d = P[s : e + 1, j] - P[s : e + 1, parent]
    size = np.linalg.norm(d, axis=-1, keepdims=True)
    if not (np.isfinite(size).all() and (size > 1e-9).all() and np.isfinite(length) and length > 0.0):
        return est, how
    moved = P[s : e + 1, parent] + d * (length / size)
    return (moved, "along its bone") if _moves_on(P, moved, j, s, e, noise) else (est, how)


def _moves_on(P: np.ndarray, est: np.ndarray, j: int, s: int, e: int, noise: float) -> bool:
    """Whether joint ``j`` of ``P (F, J, 3)`` placed at ``est (n, 3)`` on frames ``s..e``
    moves on continuously: no step from the good frame before the span to the good frame
    after it is more than ``noise`` metres beyond the joint's largest step over as many good
    frames next to the span (False where an end is lost)."""
    F, n = len(P), e - s + 1
    if s < 1 or e + 1 >= F:
        return False
    track = np.concatenate([P[s - 1 : s, j], est, P[e + 1 : e + 2, j]])
    own = [P[max(0, s - 1 - n) : s, j], P[e + 1 : min(F, e + 2 + n), j]]
    with np.errstate(invalid="ignore"):
        usual = max((float(np.nanmax(np.linalg.norm(np.diff(x, axis=0), axis=-1))) for x in own if len(x) > 1), default=0.0)
    return bool(np.linalg.norm(np.diff(track, axis=0), axis=-1).max() <= usual + noise)  # NaN: a lost end


def _repair_position(P: np.ndarray, j: int, parent: int | None, s: int, e: int) -> tuple[np.ndarray, str]:
    """Joint ``j``'s positions over frames ``s..e`` of ``P (F, J, 3)`` rebuilt from its good
    samples just outside (the nearest one held at the clip's ends), and how.

    Where its parent is tracked over the span and at both ends, the joint rides on it: its
    offset from the parent turns from the offset before to the offset after at a steady rate
    (its length linear), added to the parent's own motion ("parent-relative": a lost hand
    goes on moving with the walking body, its bone keeps its length).  Otherwise its world
    position is interpolated linearly ("linear")."""
    F, n = len(P), e - s + 1
    a, b = s - 1, e + 1
    w = (np.arange(1, n + 1) / (n + 1))[:, None]
    ends = [t for t in (a, b) if 0 <= t < F]
    if parent is not None and ends and np.isfinite(P[s : e + 1, parent]).all() and np.isfinite(P[ends, parent]).all():
        before = P[a, j] - P[a, parent] if a >= 0 else P[b, j] - P[b, parent]
        after = P[b, j] - P[b, parent] if b < F else before
        if np.isfinite(before).all() and np.isfinite(after).all():
            return P[s : e + 1, parent] + _slerp_vectors(before, after, w), "parent-relative"
    first = P[a, j] if a >= 0 else P[b, j]  # the good value before, or after at the start
    last = P[b, j] if b < F else P[a, j]
    return (1 - w) * first + w * last, "linear"


#: How :func:`correct_glitches` uses the hard-limited IK re-solve (:mod:`.resolve`).
RESOLVE_MODES = ("never", "limits", "always")


def _resolve_spans(
    motion: Motion, rot: np.ndarray, done: list[Glitch], mode: str, opt: CleanOptions, mapping=None
) -> list[Glitch]:
    """``done`` (the repaired glitch list) with the rotational repairs re-solved through the
    hard-limited IK (:mod:`.resolve`) where ``mode`` asks: "always" wherever the joint can be
    re-solved, "limits" only where the interpolated pose leaves a range of motion
    (:func:`.resolve.beyond_range_mask`: a movement the joint changes beyond its range, the
    performer margin ``rom_soft_margin`` included) and the IK's pose is beyond it on fewer of
    the span's frames.  ``rot (F, J, 4)`` is updated in place."""
    from .detect import canonical_joints
    from .resolve import actor_ik, beyond_range_mask

    names = {n: j for j, n in enumerate(motion.skeleton.names)}
    F = len(rot)
    spans = [
        (i, names[g.joint], g.start, g.end)
        for i, g in enumerate(done)
        if REPAIRED.get(g.kind) == "rotation" and g.corrected and g.start >= 1 and g.end + 1 < F
    ]
    if mode == "never" or not spans:
        return done
    ji = canonical_joints(motion, mapping)
    if mode == "limits":
        beyond = beyond_range_mask(dataclasses.replace(motion, rotations=rot), opt, ji)
        spans = [x for x in spans if beyond[x[2] : x[3] + 1, x[1]].any()]
    actor = actor_ik(motion, ji) if spans else None
    if actor is None:
        return done
    interpolated = rot.copy()
    out = list(done)
    resolved = []
    for i, j, s, e in spans:
        ik = actor.resolve(motion, rot, j, s, e)
        if ik is not None:
            rot[s : e + 1, j] = ik
            out[i] = dataclasses.replace(done[i], corrected="re-solved")
            resolved.append((i, j, s, e))
    if mode == "limits" and resolved:  # keep the IK only where it is within the ranges more often
        after = beyond_range_mask(dataclasses.replace(motion, rotations=rot), opt, ji)
        for i, j, s, e in resolved:
            if after[s : e + 1, j].sum() >= beyond[s : e + 1, j].sum():
                rot[s : e + 1, j] = interpolated[s : e + 1, j]
                out[i] = done[i]
    return out


def correct_glitches(
    motion: Motion, glitches: list[Glitch], options: CleanOptions | None = None, resolve: str = "limits", mapping=None
) -> tuple[Motion, list[Glitch]]:
    """A copy of ``motion`` with the repairable glitches bridged, and the glitch list with
    ``corrected`` filled in ("offset removed", "cubic" (Hermite in rotation space),
    "matched" or "mirrored" (:class:`_Matcher`), "regressed pose" or "regressed steps"
    (:class:`.regress.Regression`), "regressed departure" (:class:`.regress.Departure`), or "blend of ..." where several of those
    were averaged, with their shares ("blend of mirrored 62% + matched 38%", :func:`_bridge`;
    ", on contact" where :func:`_on_contact` then kept a foot standing), "re-solved" (the hard-limited IK on an actor-fitted
    humanoid, :mod:`.resolve`), "held" (the nearest good rotation, at the clip's ends), "parent-relative"
    or "linear" (a position, :func:`_repair_position`), "along its bone" (a stretched bone put
    back at its length, :func:`_along_bone`), "child-relative" or "among its neighbours" (riding
    on the child, or on the plane of its parent, child and grandparent, :func:`_judged_position`),
    "with its parent's bone" (a joint with no tracked child riding on the plane of its parent,
    grandparent and great-grandparent,
    or "blend of ..." of these with their shares;
    ", on bones" where any was then put at its
    bone lengths from its parent and child, :func:`_on_bones`), "swapped back",
    or "" for reported only); ``options`` sets the repair (``offset_min_time``, ``match_*``).

    ``resolve`` (:data:`RESOLVE_MODES`): "limits" re-solves a rotational repair through the
    hard-limited IK where the interpolated pose leaves a range of motion, "never" keeps every
    interpolation, "always" re-solves wherever the joint can be (for measuring it)
    (:func:`_resolve_spans`); ``mapping`` names the source's joints (as
    :func:`.detect.detect_glitches` takes it)."""
    if resolve not in RESOLVE_MODES:
        raise OptionError(f"resolve must be one of {', '.join(RESOLVE_MODES)}, got {resolve!r}")
    opt = options or CleanOptions()
    names = {n: j for j, n in enumerate(motion.skeleton.names)}
    rot = None if motion.rotations is None else np.array(motion.rotations, copy=True)
    pos = None if motion.positions is None else np.array(motion.positions, copy=True)
    F = motion.num_frames
    out = []
    names_of = motion.skeleton.names
    swapped: set[tuple[int, int, int]] = set()
    matcher: _Matcher | None = None
    ground: _Ground | None = None
    bad = _glitched(motion, glitches) if pos is not None else None
    for g in glitches:
        if g.kind == "lr_swap" and pos is not None:
            # trade the pair back (once per pair and span; both joints carry the glitch)
            j = names[g.joint]
            twin = names.get(g.other) if g.other else positional_twin(names_of[j], names)
            key = (min(j, twin), g.start, g.end) if twin is not None else None
            if key is not None and key not in swapped:
                swapped.add(key)
                pos[g.start : g.end + 1, [j, twin]] = pos[g.start : g.end + 1, [twin, j]]
            out.append(dataclasses.replace(g, corrected="swapped back" if key is not None else ""))
            continue
        how = REPAIRED.get(g.kind) if g.repairable else None
        if g.kind == "frozen" and rot is None:
            how = "position"  # a joint-position source's held position
        arr = rot if how == "rotation" else pos if how == "position" else None
        a, b = g.start - 1, g.end + 1
        if arr is None or (a < 0 and b >= F):
            out.append(g)
            continue
        j = names[g.joint]
        if how == "rotation":
            if 0 <= a and b < F:
                matcher = matcher or _matcher(motion, glitches, opt, canonical_joints(motion, mapping))
            fixed_q, curve = _repair_rotation(arr, j, g, float(motion.fps), matcher, opt)
            if curve not in ("offset removed", "held"):  # bridged
                ground = ground or _Ground.of(motion, glitches)
                bad = _glitched(motion, glitches) if bad is None else bad
                planted = _on_contact(motion, arr, ground, bad, j, g.start, g.end, fixed_q, opt)
                if planted is not None:
                    fixed_q, curve = planted, f"{curve}, on contact"
            arr[g.start : g.end + 1, j] = fixed_q
            out.append(dataclasses.replace(g, corrected=curve))
            continue
        parents = np.asarray(motion.skeleton.parents)
        parent = int(parents[j]) if parents[j] >= 0 else None
        est, how = _repair_position(arr, j, parent, g.start, g.end)
        if g.kind == "bone_stretch" and parent is not None:
            est, how = _along_bone(arr, est, j, parent, g.start, g.end, how, opt.stretch_distance)
        child = _bone_child(arr, parents, j, g.start, g.end, bad) if parent is not None else None
        anchor = int(parents[parent]) if parent is not None and parents[parent] >= 0 else None
        above = int(parents[anchor]) if child is None and anchor is not None and parents[anchor] >= 0 else None
        if (child is not None or above is not None) and how == "parent-relative":
            judged = _judged_position(arr, bad, j, parent, child, anchor, g.start, g.end, opt, above)
            if judged is not None:
                est, how = judged
        if child is not None and np.isfinite(arr[g.start : g.end + 1, parent]).all():
            est, how = _on_bones(arr, est, j, parent, child, g.start, g.end), f"{how}, on bones"
        arr[g.start : g.end + 1, j] = est
        out.append(dataclasses.replace(g, corrected=how))
    if rot is not None:
        out = _resolve_spans(motion, rot, out, resolve, opt, mapping)
    fixed = dataclasses.replace(motion, rotations=rot) if rot is not None else motion
    if pos is not None:
        fixed = dataclasses.replace(fixed, positions=pos)
    return fixed, out
