"""Missing tracker samples: fill short gaps, mask long ones, hold lost frames.

A tracker sample (joint ``j`` at frame ``f``) is *invalid* when any coordinate
is not finite or its confidence is below ``min_confidence`` (or zero).  For
each joint, a maximal run of invalid frames ``[s, e]`` is handled so:

* **filled**: the run has valid frames on both sides and lasts at most
  ``max_gap_frames``: positions are interpolated linearly between frames
  ``s-1`` and ``e+1``,

  .. math:: x_f = x_{s-1} + \\frac{f - (s-1)}{e + 1 - (s-1)} (x_{e+1} - x_{s-1}),

  and the confidence likewise (so it stays > 0: the IK tracks it);
* **masked**: otherwise (a long run, or one touching the start or end of the
  clip): the position holds the last valid value (the next one for a run at
  the start) with confidence 0, so the joint's IK task is switched off for
  those frames instead of being fed a guess;
* **held**: a *lost frame* (no joint valid at all) that no interpolation
  covered holds the whole previous pose, confidences included, so the
  character keeps its last pose rather than dropping tasks.

A joint that is never valid sits on its parent's (filled) position with
confidence 0.  The result has finite positions everywhere and a confidence
that is 0 exactly where a joint's task must be off.  Every run is listed in
:attr:`GapReport.gaps` (JSON-serialisable; frames are 0-based, ``end``
inclusive); runs of lost frames are listed once with ``joint`` ``"*"``.

:class:`CausalGapFiller` applies the same policy frame by frame for live
streams, where no later frame is known yet: every gap is handled as a long
one (held and masked), and lost frames hold the previous pose.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["GapReport", "fill_gaps", "find_runs", "invalid_samples", "CausalGapFiller"]


@dataclass
class GapReport:
    """Output of :func:`fill_gaps`.

    Attributes:
        positions: ``(F, J, 3)`` finite positions.
        confidence: ``(F, J)`` confidence in [0, 1]; 0 where the joint is masked.
        lost: ``(F,)`` True for frames where the tracker lost every joint.
        gaps: One dict per gap: ``joint``, ``start``, ``end`` (inclusive),
            ``frames`` and ``action`` (``"filled"``, ``"masked"`` or ``"held"``).
    """

    positions: np.ndarray
    confidence: np.ndarray
    lost: np.ndarray
    gaps: list[dict] = field(default_factory=list)

    @property
    def valid(self) -> np.ndarray:
        """``(F, J)`` True where the joint's task is on (confidence > 0)."""
        return self.confidence > 0.0

    def summary(self) -> dict:
        """Counts of gap runs and of samples by action (JSON-serialisable)."""
        out: dict = {"runs": len(self.gaps)}
        for action in ("filled", "masked", "held"):
            runs = [g for g in self.gaps if g["action"] == action]
            out[f"{action}_runs"] = len(runs)
        out["lost_frames"] = int(self.lost.sum())
        out["masked_samples"] = int((self.confidence <= 0.0).sum())
        return out


def find_runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """Maximal runs of True in a 1-D bool array as ``(start, end)`` inclusive pairs."""
    m = np.asarray(mask, dtype=bool).reshape(-1)
    if m.size == 0:
        return []
    d = np.diff(np.concatenate([[0], m.astype(np.int8), [0]]))
    starts = np.flatnonzero(d == 1)
    ends = np.flatnonzero(d == -1) - 1
    return [(int(s), int(e)) for s, e in zip(starts, ends)]


def invalid_samples(
    positions: np.ndarray, confidence: np.ndarray | None, min_confidence: float
) -> np.ndarray:
    """``(F, J)`` True where a sample is unusable: non-finite, or confidence
    below ``min_confidence`` or not positive."""
    bad = ~np.all(np.isfinite(positions), axis=-1)
    if confidence is not None:
        c = np.asarray(confidence, dtype=float)
        with np.errstate(invalid="ignore"):
            bad |= ~(c >= min_confidence) | ~(c > 0.0)
    return bad


def fill_gaps(
    positions: np.ndarray,
    confidence: np.ndarray | None,
    names: tuple[str, ...] | list[str],
    max_gap_frames: int,
    min_confidence: float = 0.5,
    parents: np.ndarray | None = None,
) -> GapReport:
    """Apply the gap policy of the module docstring.

    Args:
        positions: ``(F, J, 3)`` positions; invalid samples may be NaN.
        confidence: ``(F, J)`` confidence in [0, 1], or None (all 1 where finite).
        names: Joint names, for the gap list.
        max_gap_frames: Longest run (in frames) that is interpolated.
        min_confidence: Samples below this confidence are invalid.
        parents: ``(J,)`` parent indices (parents first), used to place joints
            that are never valid; without it they go to the mean of the others.
    """
    pos_in = np.asarray(positions, dtype=float)
    F, J = pos_in.shape[:2]
    if max_gap_frames < 0:
        raise ValueError(f"max_gap_frames must be >= 0, got {max_gap_frames}")
    bad = invalid_samples(pos_in, confidence, min_confidence)
    conf_in = (
        np.ones((F, J))
        if confidence is None
        else np.clip(np.nan_to_num(np.asarray(confidence, dtype=float), nan=0.0), 0.0, 1.0)
    )
    lost = bad.all(axis=1) if J else np.zeros(F, dtype=bool)
    pos = np.where(bad[..., None], 0.0, pos_in)
    conf = np.where(bad, 0.0, conf_in)
    action = np.zeros((F, J), dtype=np.int8)  # 0 valid, 1 filled, 2 masked, 3 held
    gaps: list[dict] = []
    never: list[int] = []

    for j in range(J):
        runs = find_runs(bad[:, j])
        if runs == [(0, F - 1)]:
            never.append(j)
            action[:, j] = 2
            continue
        for s, e in runs:
            n = e - s + 1
            if s > 0 and e < F - 1 and n <= max_gap_frames:
                w = (np.arange(s, e + 1) - (s - 1)) / float(n + 1)
                pos[s : e + 1, j] = pos[s - 1, j] + w[:, None] * (pos[e + 1, j] - pos[s - 1, j])
                conf[s : e + 1, j] = conf[s - 1, j] + w * (conf[e + 1, j] - conf[s - 1, j])
                action[s : e + 1, j] = 1
                kind = "filled"
            else:
                hold = pos[s - 1, j] if s > 0 else pos[e + 1, j]
                pos[s : e + 1, j] = hold
                # Lost frames at the head of the run keep the previous confidence
                # (the whole pose is held); from the first frame where only this
                # joint is missing on, the task is off.
                seg_lost = lost[s : e + 1]
                head = int(np.argmin(seg_lost)) if not seg_lost.all() else n
                if s > 0 and head > 0:
                    conf[s : s + head, j] = conf[s - 1, j]
                    action[s : s + head, j] = 3
                off = s + (head if s > 0 else 0)
                conf[off : e + 1, j] = 0.0
                action[off : e + 1, j] = 2
                kind = "masked"
            if not lost[s : e + 1].all():
                gaps.append({"joint": str(names[j]), "start": s, "end": e, "frames": n, "action": kind})

    # Joints the tracker never saw sit on their parent (or the others' mean).
    for j in never:
        p = -1 if parents is None else int(parents[j])
        if p >= 0:
            pos[:, j] = pos[:, p]
        else:
            others = [k for k in range(J) if k not in never]
            pos[:, j] = pos[:, others].mean(axis=1) if others else 0.0
        conf[:, j] = 0.0
        gaps.append({"joint": str(names[j]), "start": 0, "end": F - 1, "frames": F, "action": "masked"})

    for s, e in find_runs(lost):
        acts = action[s : e + 1]
        if (acts == 1).all():
            kind = "filled"
        elif (acts == 3).any():
            kind = "held"
        else:
            kind = "masked"
        gaps.append({"joint": "*", "start": s, "end": e, "frames": e - s + 1, "action": kind})

    order = {str(n): i for i, n in enumerate(names)}
    gaps.sort(key=lambda g: (g["start"], order.get(g["joint"], -1), g["end"]))
    return GapReport(positions=pos, confidence=conf, lost=lost, gaps=gaps)


class CausalGapFiller:
    """Frame-by-frame gap policy for live streams (no look-ahead, no latency).

    :meth:`step` takes one frame and returns finite positions and confidences:
    a valid sample passes through; an invalid one holds the joint's last
    output position with confidence 0 (its task off); a lost frame (no valid
    joint) holds the whole previous output pose, confidences included; a
    joint not seen yet sits on its parent's output (or the mean of the valid
    joints) with confidence 0.

    Args:
        num_joints: ``J``.
        min_confidence: Samples below this confidence are invalid.
        parents: ``(J,)`` parent indices (parents first), or None.
    """

    def __init__(self, num_joints: int, min_confidence: float = 0.5, parents: np.ndarray | None = None) -> None:
        self.num_joints = int(num_joints)
        self.min_confidence = float(min_confidence)
        self.parents = None if parents is None else np.asarray(parents, dtype=np.int64)
        self.reset()

    def reset(self) -> None:
        self._pos: np.ndarray | None = None
        self._conf: np.ndarray | None = None
        self._seen = np.zeros(self.num_joints, dtype=bool)
        self.lost_frames = 0

    def step(self, positions: np.ndarray, confidence: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """One frame: ``positions (J, 3)`` (NaN where lost), ``confidence (J,)`` or None."""
        pos = np.asarray(positions, dtype=float).reshape(self.num_joints, 3)
        conf = None if confidence is None else np.asarray(confidence, dtype=float).reshape(self.num_joints)
        bad = invalid_samples(pos[None], None if conf is None else conf[None], self.min_confidence)[0]
        c_in = np.ones(self.num_joints) if conf is None else np.clip(np.nan_to_num(conf, nan=0.0), 0.0, 1.0)
        if bad.all() and self._pos is not None:
            self.lost_frames += 1
            assert self._conf is not None
            return self._pos.copy(), self._conf.copy()
        out = np.where(bad[:, None], 0.0, pos)
        out_c = np.where(bad, 0.0, c_in)
        self._seen |= ~bad
        good = ~bad
        mean = out[good].mean(axis=0) if good.any() else np.zeros(3)
        for j in np.flatnonzero(bad):
            if self._pos is not None and self._seen[j]:
                out[j] = self._pos[j]
            elif self.parents is not None and self.parents[j] >= 0:
                out[j] = out[self.parents[j]]
            else:
                out[j] = mean
        self._pos, self._conf = out, out_c
        return out.copy(), out_c.copy()
