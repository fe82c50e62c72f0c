r"""A bridged joint's motion regressed on the rest of the body, learned from the clip itself.

Under a frozen joint the other joints keep moving, and in most captures they say much about
what the lost one was doing (a knee bends with the other leg's swing, the hips' turn, the
foot's roll).  :class:`Regression` fits, over the clip's frames where joint :math:`j` is good,
a ridge regression of :math:`j`'s motion on a feature vector :math:`x(t)`: the rotation
matrices of every other animated joint (9 entries each) and their central differences
:math:`(R_k(t+1) - R_k(t-1)) / 2`, the joints glitched anywhere on the span or next to it left
out, the frames where a joint kept in is glitched (or its neighbours are) left out of the fit.
Features are standardised over the training frames (and clipped to their range there where
they are predicted from: the fit is never extrapolated); with :math:`Z` the standardised
features, :math:`\bar y` the targets' mean and :math:`n` the training frames,

.. math::  W = (Z^\top Z + \lambda n I)^{-1} Z^\top (Y - \bar y), \qquad \hat y(t) = z(t) W + \bar y

(:math:`\lambda` chosen for each target among ``CleanOptions.regress_ridge`` times
:data:`RIDGE_FACTORS` by the pseudo-gaps, :meth:`Regression.choose_ridge`).  Two targets give
two estimates:

* *regressed pose*: :math:`j`'s rotation matrix (9 entries), the prediction projected onto
  the rotations (the nearest one, by SVD), its mismatch with the good rotations at both ends
  of the span (a rotation vector in the joint's frame at each end) faded linearly to zero
  across it, so the bridge joins both ends exactly;
* *regressed steps*: :math:`j`'s frame-to-frame turn :math:`\log(q(t-1)^{-1} q(t))`,
  integrated from the last good rotation, the mismatch left at the first good one spread
  linearly over the span (as the matched bridge's is).

The fit is held as sums over its frames (:math:`n`, :math:`\sum x`, :math:`\sum x x^\top`,
:math:`\sum x y^\top`, :math:`\sum y`), accumulated a block of frames at a time, so a
pseudo-gap (:func:`.correct._pseudo_gaps`) is left out of it by taking its frames' terms off
rather than by fitting again: both estimates of a pseudo-gap are built exactly as those of
the span, from the clip without the frames they rebuild.

:class:`Departure` is a third regressed estimate, local where these are global: the joint's
departure from its own cubic bridge (:mod:`.hermite`) regressed on every other joint's
departure from theirs over the same frames, learnt on the clip's windows of the span's length.
"""

from __future__ import annotations

import numpy as np

from ..rotations import Rotation, quat_conj, quat_mul
from .detect import _angle

__all__ = ["Departure", "Regression", "spread_mismatch"]

#: Frames whose features are built at once (the fit's sums are accumulated block by block).
BLOCK_FRAMES = 4096
#: The ridge penalties tried, as factors of ``CleanOptions.regress_ridge``.
RIDGE_FACTORS = (0.1, 1.0, 10.0)  # the default, 1.0, in the middle
#: Standard deviation over the fitted frames (rotation-matrix entries, and their per-frame
#: changes) below which a feature is left out of the fit: a joint still there to within
#: capture noise (a joint turning 0.1 rad/s at 120 Hz changes its entries by about 1e-3 a frame).
MIN_SPREAD = 1e-5
#: Largest mismatch (degrees) an estimate may have with a good end of its span and still be
#: joined to it by :func:`_faded`: a quarter turn.  The mismatch is spread linearly over the
#: span, which bends every frame towards the known end; an estimate whose own path ends further
#: than this from it (steps integrated into a drift of 170 degrees where the joint hardly turned) has
#: lost the motion, and the spread turns the joint through poses neither it nor the ends hold
#: (the dance's toe over its foot's own flip, seed 5: 107 degrees RMS off, blended in at 23 %).
#: It is no estimate then (None): the pseudo-gap test and the blend go on without it.
MAX_MISMATCH_DEG = 90.0


def spread_mismatch(est: np.ndarray, target: np.ndarray) -> np.ndarray | None:
    r"""``est (n + 2, 4)`` from a good rotation to a predicted one at the far end, with the
    mismatch at the far end, :math:`\log(\hat q_{n+1}^{-1} q)` (``target``), spread linearly
    over it in the joint's frame; returns the ``n`` inner rotations (:func:`_faded` with no
    mismatch at the start), or None where the mismatch is beyond :data:`MAX_MISMATCH_DEG`."""
    return _faded(est, est[0], target)


def _faded(pred: np.ndarray, first: np.ndarray, last: np.ndarray) -> np.ndarray | None:
    r"""``pred (n + 2, 4)`` on the span and its two good ends, its mismatch with the good
    rotations ``first`` and ``last``, :math:`r_0 = \log(\hat q_0^{-1} q_0)` and
    :math:`r_1 = \log(\hat q_{n+1}^{-1} q_{n+1})`, faded linearly across it:
    :math:`\hat q_i \exp((1 - w_i) r_0 + w_i r_1)`, :math:`w_i = i / (n + 1)`; returns the ``n``
    inner rotations, or None where either mismatch is beyond :data:`MAX_MISMATCH_DEG` (the
    estimate has lost the motion)."""
    n = len(pred) - 2
    r0 = Rotation.from_quat(quat_mul(quat_conj(pred[0]), first)).as_rotvec()
    r1 = Rotation.from_quat(quat_mul(quat_conj(pred[-1]), last)).as_rotvec()
    if max(np.linalg.norm(r0), np.linalg.norm(r1)) > np.radians(MAX_MISMATCH_DEG):
        return None
    w = (np.arange(1, n + 1) / (n + 1))[:, None]
    return quat_mul(pred[1:-1], Rotation.from_rotvec((1 - w) * r0 + w * r1).as_quat())


def _nearest_rotation(Y: np.ndarray) -> np.ndarray:
    """``(n, 4)``: the rotations nearest (Frobenius) the ``(n, 9)`` matrices ``Y``."""
    U, _, Vt = np.linalg.svd(Y.reshape(-1, 3, 3))
    U[:, :, -1] *= np.linalg.det(U @ Vt)[:, None]
    return Rotation.from_matrix(U @ Vt).as_quat()


class Regression:
    """Joint ``j``'s motion regressed on the other joints' (module docstring), for a span
    ``s..e`` of ``R (F, J, 4)``; ``M (F, A, 9)`` the rotation matrices of the ``animated``
    joints, ``bad (F, J)`` the glitched (frame, joint) pairs; the ridge penalty :math:`\\lambda`
    is chosen among ``ridge`` times :data:`RIDGE_FACTORS` (:meth:`choose_ridge`)."""

    def __init__(
        self, R: np.ndarray, M: np.ndarray, animated: list[int], bad: np.ndarray, j: int, s: int, e: int, ridge: float
    ) -> None:
        F = len(R)
        self.q, self.M = R[:, j], M
        self.ridges = [ridge * f for f in RIDGE_FACTORS]
        self.chosen = [len(RIDGE_FACTORS) // 2] * 2  # indices into self.ridges, pose and steps
        self._done: dict[tuple[int, int], list[tuple[np.ndarray, np.ndarray]] | None] = {}
        self.cols = [i for i, k in enumerate(animated) if k != j and not bad[max(0, s - 1) : e + 2, k].any()]
        used = bad[:, [animated[i] for i in self.cols]].any(axis=1)
        near = used.copy()
        near[1:] |= used[:-1]
        near[:-1] |= used[1:]
        known = ~bad[:, j]
        self.usable = ~near & known
        self.usable[1:] &= known[:-1]  # a step needs the frame before
        self.usable[[0, F - 1]] = False
        Y = self._targets(np.arange(F))
        self.sums = self._sums(np.flatnonzero(self.usable), Y)
        self._Y = Y
        self.low, self.high = self._ranges(np.flatnonzero(self.usable))

    def _features(self, t: np.ndarray) -> np.ndarray:
        """``(len(t), 18 C)``: the kept joints' rotation matrices on frames ``t`` and their
        central differences (one-sided at the clip's ends)."""
        F = len(self.M)
        now = self.M[t][:, self.cols].reshape(len(t), -1)
        hi, lo = np.minimum(t + 1, F - 1), np.maximum(t - 1, 0)
        up = self.M[hi][:, self.cols].reshape(len(t), -1)
        down = self.M[lo][:, self.cols].reshape(len(t), -1)
        return np.concatenate([now, (up - down) / np.maximum(hi - lo, 1)[:, None]], axis=1)

    def _targets(self, t: np.ndarray) -> np.ndarray:
        """``(len(t), 12)``: joint ``j``'s rotation matrix on frames ``t`` (9) and its turn from
        the frame before, a rotation vector in its own frame (3; zero on frame 0)."""
        q = self.q
        pose = Rotation.from_quat(q[t]).as_matrix().reshape(len(t), 9)
        prev = q[np.maximum(t - 1, 0)]
        step = Rotation.from_quat(quat_mul(quat_conj(prev), q[t])).as_rotvec()
        return np.concatenate([pose, step], axis=1)

    def _sums(self, t: np.ndarray, Y: np.ndarray) -> list:
        """``[n, sum x, sum x x^T, sum x y^T, sum y]`` over frames ``t``, a block at a time."""
        d = 18 * len(self.cols)
        out = [0, np.zeros(d), np.zeros((d, d)), np.zeros((d, Y.shape[1])), np.zeros(Y.shape[1])]
        for b0 in range(0, len(t), BLOCK_FRAMES):
            tb = t[b0 : b0 + BLOCK_FRAMES]
            X, y = self._features(tb), Y[tb]
            out[0] += len(tb)
            out[1] += X.sum(axis=0)
            out[2] += X.T @ X
            out[3] += X.T @ y
            out[4] += y.sum(axis=0)
        return out

    def _ranges(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(low, high)``: each feature's least and greatest value over frames ``t`` (the fit's),
        a block at a time; features are clipped to them where predicted (:meth:`_predict`)."""
        d = 18 * len(self.cols)
        low, high = np.full(d, np.inf), np.full(d, -np.inf)
        for b0 in range(0, len(t), BLOCK_FRAMES):
            X = self._features(t[b0 : b0 + BLOCK_FRAMES])
            np.minimum(low, X.min(axis=0), out=low)
            np.maximum(high, X.max(axis=0), out=high)
        return low, high

    def _predict(self, left_out: np.ndarray, at: np.ndarray, ridges: list[float]) -> list[np.ndarray] | None:
        """``(len(at), 12)`` targets predicted on frames ``at`` by the fit without the frames
        ``left_out``, one per ridge penalty of ``ridges``; None with fewer training frames
        than 10."""
        drop = left_out[self.usable[left_out]]
        n, sx, sxx, sxy, sy = (a - b for a, b in zip(self.sums, self._sums(drop, self._Y)))
        if n < 10 or not self.cols:
            return None
        mu, ym = sx / n, sy / n
        C = sxx / n - np.outer(mu, mu)
        sd = np.sqrt(np.maximum(np.diag(C), 0.0))
        # a channel (nearly) still on every fitted frame carries no information, only its noise
        # standardised up: left out of the fit
        k = np.flatnonzero(sd > MIN_SPREAD)
        if not k.size:
            return None
        mu, sd, C = mu[k], sd[k], C[np.ix_(k, k)]
        Cz, Cy = C / np.outer(sd, sd), (sxy[k] / n - np.outer(mu, ym)) / sd[:, None]
        # not extrapolated: a channel that moves on these frames far beyond its range on the
        # fitted ones (a hand held still all clip, lifted once) would steer the fit
        Z = (np.clip(self._features(at)[:, k], self.low[k], self.high[k]) - mu) / sd
        try:
            return [Z @ np.linalg.solve(Cz + lam * np.eye(len(k)), Cy) + ym for lam in ridges]
        except np.linalg.LinAlgError:  # a singular fit: no estimate (the other bridges stand)
            return None

    def _bridges(self, a: int, b: int) -> list[tuple[np.ndarray, np.ndarray]] | None:
        """``[(pose, steps)]`` per ridge penalty of ``self.ridges``: joint ``j`` on frames
        ``a..b`` (:meth:`estimates`), kept for the next call with the same frames; None where
        it cannot be fitted."""
        if (a, b) in self._done:
            return self._done[a, b]
        F = len(self.q)
        preds = None
        if a >= 1 and b + 1 < F:
            preds = self._predict(np.arange(a - 1, min(F, b + 3)), np.arange(a - 1, b + 2), self.ridges)
        out = None
        if preds is not None:
            out = []
            for pred in preds:
                pose = _faded(_nearest_rotation(pred[:, :9]), self.q[a - 1], self.q[b + 1])
                est = [self.q[a - 1]]
                for v in Rotation.from_rotvec(pred[1:, 9:]).as_quat():  # the steps into a .. b + 1
                    est.append(quat_mul(est[-1], v))
                out.append((pose, spread_mismatch(np.array(est), self.q[b + 1])))
        self._done[a, b] = out
        return out

    def choose_ridge(self, gaps: list[int], n: int) -> None:
        """Each estimate's ridge penalty chosen among ``self.ridges`` by the pseudo-gaps whose
        first frames are ``gaps`` (``n`` frames each; :func:`.correct._pseudo_gaps`): the
        one whose estimate rebuilds the joint's good rotations there with the least summed
        squared angle, per target (pose and steps)."""
        if not gaps:
            return
        err = np.zeros((len(self.ridges), 2))
        for a in gaps:
            found = self._bridges(a, a + n - 1)
            if found is None:
                return
            truth = self.q[a : a + n]
            for i, pair in enumerate(found):
                err[i] += [np.sum(_angle(est, truth) ** 2) if est is not None else np.inf for est in pair]
        self.chosen = [int(k) for k in np.argmin(err, axis=0)]

    def estimates(self, a: int, b: int) -> tuple[np.ndarray | None, np.ndarray | None] | None:
        """``(pose, steps)``, each ``(b - a + 1, 4)``: joint ``j`` on frames ``a..b`` (the span,
        or a pseudo-gap of good frames) regressed by its pose and by its steps, each with its
        chosen ridge penalty (:meth:`choose_ridge`; the middle one of ``self.ridges`` until
        then), fitted without frames ``a - 1 .. b + 2`` (the frames rebuilt, the ends they
        join, and the step into the first good frame after); None where the fit has too few
        frames or the frames ``a - 1`` and ``b + 1`` are not both in the clip, and either of the
        two None where it ends beyond :data:`MAX_MISMATCH_DEG` from a good end (:func:`_faded`)."""
        found = self._bridges(a, b)
        if found is None:
            return None
        return found[self.chosen[0]][0], found[self.chosen[1]][1]


#: Windows of the span's length the departures are learnt on start every this share of it
#: (a quarter: each good frame is seen at four places in a window) ...
WINDOW_STRIDE = 0.25
#: ... or sparser, so that the windows hold at most this many frames in all (a long clip's
#: departures, ``frames x joints x 3`` floats, stay within tens of megabytes).
MAX_WINDOW_FRAMES = 40_000
#: Windows whose departures are computed at once (the Hermite bridges' temporaries).
WINDOW_BLOCK = 256
#: Windows of the clip, at least, that a departure's fit needs (fewer: no estimate).
MIN_WINDOWS = 10


class Departure:
    r"""Joint :math:`j`'s departure from its own cubic bridge, regressed on the other joints'
    departures from theirs over the same frames, learnt on the clip's own good windows of
    the span's length.

    A bridge that follows the joint's speed at both ends (:mod:`.hermite`) misses what the
    joint did in between: the swing of a knee, the turn of the hips.  Over the same frames
    every other joint also leaves its own Hermite bridge, and those departures are known
    under a freeze.  For each window :math:`w` of :math:`n` good frames (every joint kept
    good on it and on the two frames outside each end), every joint :math:`k`'s departure on
    frame :math:`i` is :math:`d_k(w, i) = \log(h_k(w, i)^{-1} q_k(w, i))` (radians, in the
    joint's frame; zero at the window's good ends by construction), and the fit is a ridge
    regression without intercept (a joint on its bridge says nothing)

    .. math::  \hat d_j = z W, \qquad W = (Z^\top Z / N + \lambda I)^{-1} Z^\top D_j / N

    over the :math:`N` window frames, :math:`z` the other joints' departures (3 each) scaled
    by their root mean square.  The estimate is :math:`h_j(i) \exp(\hat d_j(i))`: it joins
    both good ends as the cubic does, plus what the rest of the body's departures say.  Each
    estimate is fitted without the windows meeting the frames it rebuilds or the two good
    frames each side (so a pseudo-gap is rebuilt from the rest of the clip, as the span is);
    the features are clipped to their fitted range, as :class:`Regression`'s are.
    """

    def __init__(
        self, R: np.ndarray, animated: list[int], bad: np.ndarray, j: int, s: int, e: int, ridge: float
    ) -> None:
        F, n = len(R), e - s + 1
        self.n = n
        cols = [k for k in animated if k != j and not bad[max(0, s - 1) : e + 2, k].any()]
        self.q = R[:, [j] + cols]
        self.ridges = [ridge * f for f in RIDGE_FACTORS]
        self.chosen = len(RIDGE_FACTORS) // 2
        self._done: dict[int, list[np.ndarray] | None] = {}
        clean = ~bad[:, [j] + cols].any(axis=1)
        cum = np.concatenate([[0], np.cumsum(~clean)])
        stride = max(1, int(round(WINDOW_STRIDE * n)), -(-F * n // MAX_WINDOW_FRAMES))
        starts = np.arange(2, F - n - 1, stride)
        self.starts = starts[cum[starts + n + 2] == cum[starts - 2]]  # frames a - 2 .. a + n + 1 good
        self.D = None
        if cols and len(self.starts):
            blocks = range(0, len(self.starts), WINDOW_BLOCK)
            self.D = np.concatenate([self._departures(self.starts[b : b + WINDOW_BLOCK])[1] for b in blocks])

    def _departures(self, starts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(bridges (W, n, K, 4), departures (W, n, K, 3))`` of the kept joints (joint ``j``
        first) over the windows starting at ``starts``."""
        from .hermite import log_between, windows

        H = windows(self.q, starts, self.n)
        Q = self.q[np.asarray(starts)[:, None] + np.arange(self.n)]
        return H, log_between(H, Q)

    def _inputs(self, D: np.ndarray) -> np.ndarray:
        """``(W n, 3 (K - 1))``: the features of windows' departures ``D (W, n, K, 3)``, the
        other joints' departures on each frame."""
        return D[:, :, 1:].reshape(D.shape[0] * D.shape[1], -1)

    def _fits(self, a: int) -> list[np.ndarray] | None:
        """Joint ``j`` on frames ``a .. a + n - 1`` per ridge penalty of ``self.ridges`` (kept
        for the next call), or None where too few windows are left to fit on."""
        if a in self._done:
            return self._done[a]
        n, out = self.n, None
        far = (self.starts + n + 1 < a - 2) | (self.starts - 2 > a + n + 1)
        if self.D is not None and 2 <= a and a + n + 1 < len(self.q) and far.sum() >= MIN_WINDOWS:
            D = self.D[far]
            X, Y = self._inputs(D), D[:, :, 0].reshape(-1, 3)
            sd = np.sqrt(np.mean(X**2, axis=0))
            k = np.flatnonzero(sd > MIN_SPREAD)
            if k.size:
                Z = X[:, k] / sd[k]
                G, c = Z.T @ Z / len(Z), Z.T @ Y / len(Z)
                H, d = self._departures(np.array([a]))
                z = np.clip(self._inputs(d)[:, k] / sd[k], Z.min(axis=0), Z.max(axis=0))
                try:
                    preds = [z @ np.linalg.solve(G + lam * np.eye(len(k)), c) for lam in self.ridges]
                    out = [quat_mul(H[0, :, 0], Rotation.from_rotvec(p).as_quat()) for p in preds]
                except np.linalg.LinAlgError:  # a singular fit: no estimate
                    out = None
        self._done[a] = out
        return out

    def choose_ridge(self, gaps: list[int]) -> None:
        """The ridge penalty chosen among ``self.ridges`` by the pseudo-gaps whose first frames
        are ``gaps`` (:func:`.correct._pseudo_gaps`): the one whose estimate rebuilds joint
        ``j``'s good rotations there with the least summed squared angle."""
        err = np.zeros(len(self.ridges))
        for a in gaps:
            found = self._fits(a)
            if found is None:
                return
            truth = self.q[a : a + self.n, 0]
            err += [np.sum(_angle(est, truth) ** 2) for est in found]
        if gaps:
            self.chosen = int(np.argmin(err))

    def estimate(self, a: int) -> np.ndarray | None:
        """``(n, 4)``: joint ``j`` on frames ``a .. a + n - 1`` (the span, or a pseudo-gap of
        good frames), its cubic bridge plus its regressed departure, with the chosen ridge
        penalty (:meth:`choose_ridge`); None where it cannot be fitted."""
        found = self._fits(a)
        return None if found is None else found[self.chosen]
