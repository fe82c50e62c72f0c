r"""Foot contact detection on the actor's motion.

Which foot points touch the floor on which frames, from the actor's joint
positions alone.  The retargeter plants the character's contact sites on these
frames and the quality report measures hovering on them.

**Points.**  Per side, the *heel* is the ankle joint (canonical ``*_ankle``),
the *toe* is the ball joint (canonical ``*_toe``) together with the toe end
(``*_toe_end``) where the skeleton has them.  Labels are reported per foot
point: ``left_heel``, ``left_toe``, ``right_heel``, ``right_toe``; a toe label
is on when the ball or the toe end is in contact.

**Floor.**  Estimated robustly from the clip, not from its single lowest
sample: the floor is a plane :math:`z = f + s \cdot (p_{xy} - o)` fitted to
the *slow* samples of every foot point (horizontal speed below
``floor_speed``), each point with its own offset, by least squares repeated
on the samples within a band around the previous fit that shrinks from 5 cm to
``floor_trim`` (lifted feet and glitches drop out).  The slope :math:`s` is
only fitted along horizontal directions in which the slow samples of a point
span at least ``slope_min_extent`` metres (a walk across the capture volume;
real volumes are often calibrated slightly tilted: 0.86 % along the CMU walk
12_01) and is dropped, with a warning, if steeper than ``max_floor_slope``.
Each point's *stance level* :math:`l_p` is the ``floor_percentile`` percentile
of its slow samples' heights above the plane, and the floor height :math:`f`
is the lowest stance level, so the toe end sits at about 0 and the ankle
joint a few centimetres up.

**Detection.**  Per point and frame, with :math:`h = z - \text{plane} - (l_p -
f)` the height above the point's own stance level, :math:`v` the horizontal
speed and :math:`\dot z` the vertical velocity (central differences over
``speed_window`` seconds), a hysteresis state machine:

* *enter* contact when :math:`h < h_{enter}`, :math:`v < v_{enter}` and
  :math:`\dot z < \dot z_{lift}` have held for ``min_contact`` seconds;
* *leave* contact when :math:`h > h_{exit}`, :math:`v > v_{exit}` or
  :math:`\dot z > \dot z_{lift}` has held for ``min_gap`` seconds.

Heel and toe have their own thresholds because they move differently in gait:
the heel leaves the floor by rising, slowly at first (heel rise, about 10-30
cm/s upward while it barely moves forward), so its lift speed decides; the
forefoot pivots and rolls before toe-off (toe markers often lift a few
centimetres and slide while the toes stay down), so its exit height, speed
and lift speed are generous.  Thresholds are in metres, m/s and seconds, so
the defaults work at 30 and 120 Hz alike (tuned on the hand-labelled CMU walk,
checked on the other shared clips and on 30 Hz resamples).

**Causal use.**  :class:`ContactDetector` is the state machine; it only needs
the current frame's heights and velocities.  :class:`ContactStream` feeds it
from positions one frame at a time with backward differences (a look-behind
of ``speed_window`` seconds) and a floor estimated beforehand, for a streaming
retargeter.  Its transitions are committed ``min_contact`` / ``min_gap``
seconds after they begin.  The batch function :func:`detect_contacts` runs
the same machine on centred differences and back-dates every transition to
the frame its condition began, so batch labels are the streaming labels
without their lag.

**User labels.**  :func:`load_contact_csv` reads frame ranges per point from a
CSV file instead (see its docstring); :func:`write_contact_csv` writes labels
in that format.  :func:`contact_sites_labels` maps labels onto a character's
contact sites (heel label to the heel site, toe label to the ball and toe-tip
sites).
"""

from __future__ import annotations

import csv
import math
import os
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from ..errors import InputError, MappingError, OptionError, warn
from ..fileio import atomic_open
from ..spill import release

__all__ = [
    "CONTACT_LABELS",
    "ContactOptions",
    "Contacts",
    "ContactDetector",
    "ContactStream",
    "FloorPlane",
    "detect_contacts",
    "detect_point_contacts",
    "contact_points",
    "estimate_floor",
    "central_velocity",
    "backward_velocity",
    "central_speed",
    "backward_speed",
    "load_contact_csv",
    "write_contact_csv",
    "contact_sites_labels",
    "label_f1",
]

SIDES = ("left", "right")
#: The contact labels every :class:`Contacts` carries.
CONTACT_LABELS = ("left_heel", "left_toe", "right_heel", "right_toe")
#: Contact point -> canonical joint it is measured on.
POINT_JOINTS = {"heel": "ankle", "ball": "toe", "toe_end": "toe_end"}
#: Contact label -> the points (in order of preference) that make it up.
LABEL_POINTS = {
    f"{side}_{part}": tuple(f"{side}_{p}" for p in pts)
    for side in SIDES
    for part, pts in (("heel", ("heel",)), ("toe", ("ball", "toe_end")))
}


@dataclass
class ContactOptions:
    """Thresholds of contact detection (metres, m/s, seconds, percent).

    Heights are above each point's own stance level (see the module docstring).

    Attributes:
        heel_height_enter: The heel may enter contact below this height.
        heel_height_exit: The heel leaves contact above this height.
        toe_height_enter: A toe point may enter contact below this height.
        toe_height_exit: A toe point leaves contact above this height.
        speed_enter: Any point may enter contact below this horizontal speed.
        heel_speed_exit: The heel leaves contact above this horizontal speed.
        toe_speed_exit: A toe point leaves contact above this horizontal speed.
        heel_lift_speed: The heel leaves contact when rising faster than this (m/s).
        toe_lift_speed: A toe point leaves contact when rising faster than this (m/s).
        min_contact: The enter condition must hold this long (s) to start a contact.
        min_gap: The exit condition must hold this long (s) to end a contact.
        speed_window: Span (s) of the central difference for horizontal speed.
        floor_percentile: Percentile of a point's slow heights taken as its stance level.
        floor_speed: Samples slower than this (m/s) inform the floor estimate.
        floor_trim: Final half-width (m) of the band around the plane fit that samples must lie in.
        fit_slope: Fit a tilted floor plane (else a level floor).
        slope_min_extent: Fit a slope only if slow samples span this many metres.
        max_floor_slope: A steeper fitted slope (rise over run) is dropped with a warning.
    """

    heel_height_enter: float = 0.025
    heel_height_exit: float = 0.03
    toe_height_enter: float = 0.015
    toe_height_exit: float = 0.04
    speed_enter: float = 0.30
    heel_speed_exit: float = 0.60
    toe_speed_exit: float = 0.80
    heel_lift_speed: float = 0.12
    toe_lift_speed: float = 0.30
    min_contact: float = 0.05
    min_gap: float = 0.05
    speed_window: float = 0.035
    floor_percentile: float = 5.0
    floor_speed: float = 0.20
    floor_trim: float = 0.01
    fit_slope: bool = True
    slope_min_extent: float = 1.0
    max_floor_slope: float = 0.03

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name == "fit_slope":
                continue
            if not isinstance(v, (int, float)) or math.isnan(v) or v < 0:
                raise OptionError(f"contact option {f.name} must be a number >= 0, got {v!r}")
            if math.isinf(v) and f.name not in _MAY_BE_INF:
                raise OptionError(f"contact option {f.name} must be finite, got {v!r}")
        for part in ("heel", "toe"):
            enter = getattr(self, f"{part}_height_enter")
            leave = getattr(self, f"{part}_height_exit")
            if enter > leave:
                raise OptionError(
                    f"contact option {part}_height_enter ({enter}) must not exceed "
                    f"{part}_height_exit ({leave}) (hysteresis)"
                )
            vexit = getattr(self, f"{part}_speed_exit")
            if self.speed_enter > vexit:
                raise OptionError(
                    f"contact option speed_enter ({self.speed_enter}) must not exceed "
                    f"{part}_speed_exit ({vexit}) (hysteresis)"
                )
        if not 0.0 <= self.floor_percentile <= 100.0:
            raise OptionError(f"contact option floor_percentile must be in [0, 100], got {self.floor_percentile}")

    def thresholds(self, kind: str) -> tuple[float, float, float, float, float]:
        """``(height_enter, height_exit, speed_enter, speed_exit, lift_speed)``
        for ``"heel"`` or ``"toe"``."""
        part = "heel" if kind == "heel" else "toe"
        return (
            getattr(self, f"{part}_height_enter"),
            getattr(self, f"{part}_height_exit"),
            self.speed_enter,
            getattr(self, f"{part}_speed_exit"),
            getattr(self, f"{part}_lift_speed"),
        )


#: Options that may be ``math.inf`` (to disable that exit test).
_MAY_BE_INF = {"heel_height_exit", "toe_height_exit", "heel_speed_exit", "toe_speed_exit", "heel_lift_speed", "toe_lift_speed"}


def _kind(point: str) -> str:
    return "heel" if point.endswith("_heel") else "toe"


# ---------------------------------------------------------------------------
# Speeds
# ---------------------------------------------------------------------------


def _half_window(fps: float, window: float) -> int:
    return max(1, int(round(window * fps / 2.0)))


def central_velocity(xyz: np.ndarray, fps: float, window: float = 0.035) -> np.ndarray:
    """``(F, 3)`` velocity (m/s) by central differences over ``window`` seconds.

    :math:`\\dot p_t = (p_{i_+} - p_{i_-}) \\cdot fps / (i_+ - i_-)` with
    :math:`i_\\pm = t \\pm k` clamped to the clip (one-sided at its ends) and
    :math:`k = \\max(1, \\mathrm{round}(window \\cdot fps / 2))`.  With
    ``window`` at most two frames this is metrics.md's plain central difference.
    """
    p = np.asarray(xyz, dtype=float)
    F = p.shape[0]
    if F < 2:
        return np.zeros_like(p)
    k = _half_window(fps, window)
    t = np.arange(F)
    hi = np.minimum(t + k, F - 1)
    lo = np.maximum(t - k, 0)
    return (p[hi] - p[lo]) * (fps / (hi - lo))[:, None]


def backward_velocity(xyz: np.ndarray, fps: float, window: float = 0.035) -> np.ndarray:
    """Causal counterpart of :func:`central_velocity`: the difference over the
    last ``2k`` frames, so frame ``t`` needs only frames ``t - 2k .. t`` (it
    lags the central estimate by ``k`` frames)."""
    p = np.asarray(xyz, dtype=float)
    F = p.shape[0]
    if F < 2:
        return np.zeros_like(p)
    k2 = 2 * _half_window(fps, window)
    t = np.arange(F)
    lo = np.maximum(t - k2, 0)
    span = np.maximum(t - lo, 1)
    return (p[t] - p[lo]) * (fps / span)[:, None]


def central_speed(xyz: np.ndarray, fps: float, window: float = 0.035) -> np.ndarray:
    """``(F,)`` horizontal speed (m/s) from :func:`central_velocity`."""
    return np.linalg.norm(central_velocity(xyz, fps, window)[:, :2], axis=1)


def backward_speed(xyz: np.ndarray, fps: float, window: float = 0.035) -> np.ndarray:
    """``(F,)`` horizontal speed (m/s) from :func:`backward_velocity` (causal)."""
    return np.linalg.norm(backward_velocity(xyz, fps, window)[:, :2], axis=1)


# ---------------------------------------------------------------------------
# Floor
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class FloorPlane:
    """The actor's floor: :math:`z = height + slope \\cdot (p_{xy} - origin)`.

    Attributes:
        height: Floor height at ``origin`` (metres).
        slope: ``(dz/dx, dz/dy)`` rise over run.
        origin: ``(x, y)`` where ``height`` applies (the centre of the slow samples).
        levels: Point -> its stance level above the floor (metres).
    """

    height: float
    slope: tuple[float, float] = (0.0, 0.0)
    origin: tuple[float, float] = (0.0, 0.0)
    levels: dict = field(default_factory=dict)

    def at(self, xy: np.ndarray) -> np.ndarray:
        """Floor height under horizontal positions ``(..., 2)`` (or ``(..., 3)``)."""
        xy = np.asarray(xy, dtype=float)[..., :2]
        return self.height + (xy - np.asarray(self.origin)) @ np.asarray(self.slope)

    def heights(self, xyz: np.ndarray) -> np.ndarray:
        """Height above the floor of points ``(..., 3)``."""
        xyz = np.asarray(xyz, dtype=float)
        return xyz[..., 2] - self.at(xyz)


def estimate_floor(
    points: Mapping[str, np.ndarray],
    speeds: Mapping[str, np.ndarray],
    options: ContactOptions | None = None,
) -> FloorPlane:
    """Fit the floor plane and every point's stance level (module docstring).

    Args:
        points: Point name -> ``(F, 3)`` world positions (metres, Z-up; NaN where missing).
        speeds: Point name -> ``(F,)`` horizontal speed (m/s).
        options: Thresholds (``floor_*``, ``fit_slope``, ``slope_min_extent``, ``max_floor_slope``).
    """
    opt = options or ContactOptions()
    names = list(points)
    samples = []  # (point index, x, y, z)
    for i, name in enumerate(names):
        p = np.asarray(points[name], dtype=float)
        v = np.asarray(speeds[name], dtype=float)
        ok = np.all(np.isfinite(p), axis=1) & np.isfinite(v)
        slow = ok & (v < opt.floor_speed)
        if slow.sum() < max(10, 0.05 * ok.sum()):
            slow = ok  # a clip with hardly any slow frames: use all of them
        sel = p[slow]
        release(p)  # positions in a temporary file: their pages not held through the fit
        samples.append(np.column_stack([np.full(len(sel), i), sel]))
    data = np.concatenate(samples) if samples else np.zeros((0, 4))
    del samples  # held once (a long clip has several samples a frame, and the fit copies them)
    if data.shape[0] == 0:
        raise InputError("no finite foot positions to estimate the floor from")
    idx = data[:, 0].astype(int)
    z = data[:, 3].copy()
    origin = np.median(data[:, 1:3], axis=0)
    d = data[:, 1:3] - origin
    del data  # what the fit reads is copied out: a long clip's samples are not held twice
    P = len(names)
    slope = np.zeros(2)
    if opt.fit_slope and d.shape[0] > 2:
        # fit along the principal horizontal directions along which some
        # point's slow samples span at least slope_min_extent (a walk is long
        # in one direction only; a slope across a few centimetres is noise)
        _, axes = np.linalg.eigh(np.cov(d.T))
        proj = d @ axes
        span = np.array(
            [max(float(np.ptp(proj[idx == i, a])) if np.any(idx == i) else 0.0 for i in range(P)) for a in range(2)]
        )
        del proj
        use = axes[:, span >= opt.slope_min_extent]
        if use.shape[1]:
            u = d @ use
            # least squares with per-point offsets, trimmed around the current
            # fit with a shrinking band (lifted or glitching samples drop out)
            offset = np.array([np.median(z[idx == i]) if np.any(idx == i) else 0.0 for i in range(P)])
            coef = np.zeros(use.shape[1])
            for band in (0.05, 0.03, 0.02, opt.floor_trim, opt.floor_trim):
                resid = z - offset[idx] - u @ coef
                keep = np.abs(resid) < max(band, opt.floor_trim)
                del resid
                if keep.sum() < 3 * (P + 2):
                    break
                A = np.zeros((int(keep.sum()), P + use.shape[1]))
                A[np.arange(A.shape[0]), idx[keep]] = 1.0
                A[:, P:] = u[keep]
                sol, *_ = np.linalg.lstsq(A, z[keep], rcond=None)
                del A  # not held while the next band's is built
                offset, coef = sol[:P], sol[P:]
            slope = use @ coef
            steep = float(np.hypot(*slope))
            if steep > opt.max_floor_slope:
                warn(
                    f"the fitted floor slope ({100 * steep:.1f} %) is steeper than max_floor_slope "
                    f"({100 * opt.max_floor_slope:.1f} %); assuming a level floor"
                )
                slope = np.zeros(2)
    flat = z - d @ slope
    offset = np.array(
        [np.percentile(flat[idx == i], opt.floor_percentile) if np.any(idx == i) else np.nan for i in range(P)]
    )
    height = float(np.nanmin(offset))
    levels = {n: float(offset[i] - height) if np.isfinite(offset[i]) else 0.0 for i, n in enumerate(names)}
    return FloorPlane(height=height, slope=(float(slope[0]), float(slope[1])), origin=(float(origin[0]), float(origin[1])), levels=levels)


# ---------------------------------------------------------------------------
# The state machine
# ---------------------------------------------------------------------------


#: Frames :meth:`ContactDetector.run` turns into Python numbers at a time.
RUN_BLOCK_FRAMES = 4096


class ContactDetector:
    """Per-point hysteresis state machine with minimum durations (causal).

    Args:
        kinds: ``"heel"`` or ``"toe"`` per point (selects the thresholds).
        fps: Frame rate (converts ``min_contact`` / ``min_gap`` to frames,
            at least one).
        options: Thresholds.

    :meth:`step` takes one frame's heights above each point's stance level
    (metres) and horizontal speeds (m/s) and returns the labels.  NaN inputs
    (a missing sample) hold the current state.  Every committed change is
    appended to :attr:`transitions` as ``(point index, first frame of the
    condition, new state)``, which the batch detector uses to back-date it.
    """

    def __init__(self, kinds: Sequence[str], fps: float, options: ContactOptions | None = None) -> None:
        self.options = opt = options or ContactOptions()
        if not (math.isfinite(fps) and fps > 0):
            raise OptionError(f"fps must be positive, got {fps}")
        th = np.array([opt.thresholds(k) for k in kinds], dtype=float).reshape(-1, 5)
        self.h_enter, self.h_exit, self.v_enter, self.v_exit, self.lift = th.T
        self.n_on = max(1, int(round(opt.min_contact * fps)))
        self.n_off = max(1, int(round(opt.min_gap * fps)))
        self.reset()

    def reset(self) -> None:
        n = len(self.h_enter)
        # per point, as Python scalars (a few points: cheaper than arrays frame by frame)
        self._thresholds = list(zip(*(a.tolist() for a in (self.h_enter, self.h_exit, self.v_enter, self.v_exit, self.lift))))
        self.state = [False] * n
        self.count = [0] * n
        self.since = [0] * n
        self.frame = 0
        self.transitions: list[tuple[int, int, bool]] = []

    def step(self, heights: np.ndarray, speeds: np.ndarray, climb: np.ndarray | None = None) -> np.ndarray:
        """One frame: heights above each point's stance level (m), horizontal
        speeds (m/s) and vertical velocities (m/s, up positive; None: not
        used) in; the labels ``(P,)`` out."""
        h = np.asarray(heights, dtype=float).reshape(-1).tolist()
        v = np.asarray(speeds, dtype=float).reshape(-1).tolist()
        c = [0.0] * len(h) if climb is None else np.asarray(climb, dtype=float).reshape(-1).tolist()
        self._advance(h, v, c)
        return np.array(self.state, dtype=bool)

    def run(self, heights: np.ndarray, speeds: np.ndarray, climb: np.ndarray | None = None) -> None:
        """:meth:`step` over a whole clip: ``(F, P)`` heights, speeds and vertical velocities
        (None: not used), frame by frame; the labels are in :attr:`transitions`.  The samples
        are turned into Python floats :data:`RUN_BLOCK_FRAMES` frames at a time (a whole
        clip's would take about 150 bytes per point and frame)."""
        H = np.asarray(heights, dtype=float)
        V = np.asarray(speeds, dtype=float)
        C = np.zeros(H.shape) if climb is None else np.asarray(climb, dtype=float)
        for s in range(0, H.shape[0], RUN_BLOCK_FRAMES):
            for h, v, c in zip(*(a[s : s + RUN_BLOCK_FRAMES].tolist() for a in (H, V, C))):
                self._advance(h, v, c)

    def _advance(self, h: list[float], v: list[float], c: list[float]) -> None:
        """One frame, point by point.  A point *wants* to change when its sample is known
        (finite) and, in contact, ``h > h_exit`` or ``v > v_exit`` or ``c > lift``; out of
        contact, ``h < h_enter`` and ``v < v_enter`` and ``c < lift``.  A change is committed
        once wanted on ``n_on`` (entering) or ``n_off`` (leaving) frames in a row, dated to
        the first of them; an unknown sample holds the count."""
        state, count, since, frame = self.state, self.count, self.since, self.frame
        for i, (hi, vi, ci, (h_enter, h_exit, v_enter, v_exit, lift)) in enumerate(zip(h, v, c, self._thresholds)):
            known = math.isfinite(hi) and math.isfinite(vi) and math.isfinite(ci)
            if state[i]:
                want = known and (hi > h_exit or vi > v_exit or ci > lift)
            else:
                want = known and hi < h_enter and vi < v_enter and ci < lift
            if want:
                if count[i] == 0:
                    since[i] = frame
                count[i] += 1
            elif known:
                count[i] = 0
            if count[i] >= (self.n_off if state[i] else self.n_on):
                self.transitions.append((i, since[i], not state[i]))
                state[i] = not state[i]
                count[i] = 0
        self.frame = frame + 1

    def finish(self) -> None:
        """End of the clip: commit every change whose condition has held to the
        last frame but not yet for its minimum duration (batch use only)."""
        for i, n in enumerate(self.count):
            if n > 0:
                self.transitions.append((i, self.since[i], not self.state[i]))
                self.state[i] = not self.state[i]
                self.count[i] = 0


class StanceLevels:
    r"""Each contact point's stance level learnt causally, as the stream goes.

    A stream starts with the levels of its first frame (each point's height, the lower of
    the two feet), which is a stance level only if the actor stands flat there: a first
    frame mid-stride or with the heels up (its ankles above where they stand) stood the
    OptiTrack actor 4.5 cm too low, its knees bent 10 degrees.  Offline, a point's level is the ``floor_percentile`` of its
    heights on the frames it moves slower than ``floor_speed``
    (:func:`estimate_floor`); here the same percentile of its slow heights so far, kept
    in a histogram of :data:`BIN` metres (bounded memory, exact to the bin), once
    :data:`MIN_TIME` seconds of slow samples are in, and never above the starting level.
    Metres, m/s.
    """

    #: Histogram bin (m) and range (m above the floor) of the heights kept.
    BIN = 0.001
    LOW, HIGH = -0.25, 0.50
    #: Seconds of slow samples a point needs before its level is learnt.
    MIN_TIME = 0.2

    def __init__(self, start: np.ndarray, fps: float, options: ContactOptions) -> None:
        self.start = np.array(start, dtype=float)
        self.levels = self.start.copy()
        self.options = options
        self.bins = int(round((self.HIGH - self.LOW) / self.BIN))
        self.counts = np.zeros((self.start.size, self.bins), dtype=np.int64)
        self.min_samples = max(1, int(math.ceil(self.MIN_TIME * float(fps))))

    def update(self, heights: np.ndarray, speeds: np.ndarray) -> np.ndarray:
        """The levels ``(P,)`` after this frame's point heights above the floor ``(P,)``
        and horizontal speeds ``(P,)`` (m/s)."""
        slow = np.flatnonzero((speeds < self.options.floor_speed) & np.isfinite(heights))
        if not slow.size:
            return self.levels
        b = np.clip(((heights[slow] - self.LOW) / self.BIN).astype(np.int64), 0, self.bins - 1)
        self.counts[slow, b] += 1
        for i in slow:
            n = int(self.counts[i].sum())
            if n < self.min_samples:
                continue
            k = int(np.searchsorted(np.cumsum(self.counts[i]), self.options.floor_percentile / 100.0 * n))
            self.levels[i] = min(self.start[i], self.LOW + (k + 0.5) * self.BIN)
        return self.levels


class ContactStream:
    """Streaming contact detection from foot point positions, one frame at a time.

    Causal: frame ``t``'s labels use frames ``t - 2k .. t`` only (``k`` the
    half speed window), so the look-behind is bounded.  The floor must be
    known beforehand (e.g. :func:`estimate_floor` on a calibration clip or the
    first seconds); labels lag the batch labels of :func:`detect_contacts` by
    about ``k`` frames plus ``min_contact`` (onsets) or ``min_gap`` (ends).

    Args:
        points: Point names (``left_heel``, ``left_ball``, ``left_toe_end`` ...).
        fps: Frame rate.
        floor: The floor plane with each point's stance level to start from (the
            levels are learnt as frames come: :class:`StanceLevels`, ``levels``).
        options: Thresholds.
    """

    def __init__(self, points: Sequence[str], fps: float, floor: FloorPlane, options: ContactOptions | None = None) -> None:
        self.options = opt = options or ContactOptions()
        self.points = tuple(points)
        self.fps = float(fps)
        self.floor = floor
        self.stance = StanceLevels(np.array([floor.levels.get(p, 0.0) for p in self.points]), fps, opt)
        self.levels = self.stance.levels
        self.detector = ContactDetector([_kind(p) for p in self.points], fps, opt)
        self.k2 = 2 * _half_window(fps, opt.speed_window)
        self.history: list[np.ndarray] = []

    def step(self, positions: np.ndarray) -> dict[str, bool]:
        """Positions ``(P, 3)`` of this frame's points in; foot labels out
        (:data:`CONTACT_LABELS` -> bool; a toe is on if its ball or toe end is)."""
        x = np.asarray(positions, dtype=float).reshape(len(self.points), 3)
        self.history.append(x)
        if len(self.history) > self.k2 + 1:
            self.history.pop(0)
        old = self.history[0]
        span = max(len(self.history) - 1, 1)
        vel = (x - old) * (self.fps / span)
        h = self.floor.heights(x)
        speed = np.linalg.norm(vel[:, :2], axis=1)
        self.levels = self.stance.update(h, speed)
        state = self.detector.step(h - self.levels, speed, vel[:, 2])
        on = dict(zip(self.points, state))
        out = {}
        for label, pts in LABEL_POINTS.items():
            present = [p for p in pts if p in on] or [label.split("_", 1)[0] + "_heel"]
            out[label] = bool(any(on.get(p, False) for p in present))
        return out


# ---------------------------------------------------------------------------
# Contacts
# ---------------------------------------------------------------------------


@dataclass(eq=False)
class Contacts:
    """Foot contact labels of a clip.

    Attributes:
        labels: :data:`CONTACT_LABELS` -> ``(F,)`` bool.
        fps: Frames per second (None if unknown, e.g. labels from a CSV).
        floor: The floor (:class:`FloorPlane`), or None for user labels.
        heights: Point -> ``(F,)`` height above the floor (metres).
        speeds: Point -> ``(F,)`` horizontal speed (m/s).
        point_labels: Point -> ``(F,)`` bool, before heel/toe grouping.
        groups: Label -> the points it combines.
        joints: Point -> source joint index it was measured on.
        source: Where the labels came from (``"detected"`` or a CSV path).
        body_labels: Knees, hands and pelvis resting on the floor
            (:mod:`physmocap.ik.body_contacts`): part -> ``(F,)`` bool.
    """

    labels: dict[str, np.ndarray]
    fps: float | None = None
    floor: FloorPlane | None = None
    heights: dict[str, np.ndarray] = field(default_factory=dict)
    speeds: dict[str, np.ndarray] = field(default_factory=dict)
    point_labels: dict[str, np.ndarray] = field(default_factory=dict)
    groups: dict[str, tuple[str, ...]] = field(default_factory=dict)
    joints: dict[str, int] = field(default_factory=dict)
    source: str = "detected"
    body_labels: dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def num_frames(self) -> int:
        return int(next(iter(self.labels.values())).shape[0]) if self.labels else 0

    @property
    def floor_height(self) -> float:
        """Floor height in metres (0 for user labels, which carry no floor)."""
        return 0.0 if self.floor is None else self.floor.height

    def foot(self, side: str) -> np.ndarray:
        """``(F,)`` True where any point of the ``"left"`` or ``"right"`` foot is in contact."""
        out = np.zeros(self.num_frames, dtype=bool)
        for name, lab in self.labels.items():
            if name.startswith(side + "_"):
                out |= lab
        return out

    def segments(self, label: str) -> list[tuple[int, int]]:
        """Contact intervals of ``label`` as ``[(start, end), ...]`` (end exclusive)."""
        return _segments(self.labels[label])

    def slice_frames(self, start: int, end: int) -> "Contacts":
        """The labels and signals of frames ``[start, end)``."""
        cut = lambda d: {k: v[start:end] for k, v in d.items()}  # noqa: E731
        return Contacts(
            labels=cut(self.labels),
            fps=self.fps,
            floor=self.floor,
            heights=cut(self.heights),
            speeds=cut(self.speeds),
            point_labels=cut(self.point_labels),
            groups=dict(self.groups),
            joints=dict(self.joints),
            source=self.source,
            body_labels=cut(self.body_labels),
        )


def _segments(mask: np.ndarray) -> list[tuple[int, int]]:
    m = np.concatenate([[False], np.asarray(mask, dtype=bool), [False]])
    d = np.flatnonzero(np.diff(m.astype(np.int8)))
    return [(int(a), int(b)) for a, b in zip(d[::2], d[1::2])]


def contact_points(joint_indices: Mapping[str, int]) -> dict[str, int]:
    """Contact point -> source joint index, from canonical joint indices.

    ``left_heel`` is measured on ``left_ankle``, ``left_ball`` on ``left_toe``,
    ``left_toe_end`` on ``left_toe_end``; points whose joint is absent are left
    out.  Raises :class:`MappingError` if an ankle is missing.
    """
    out: dict[str, int] = {}
    for side in SIDES:
        for point, joint in POINT_JOINTS.items():
            j = joint_indices.get(f"{side}_{joint}")
            if j is not None:
                out[f"{side}_{point}"] = int(j)
        if f"{side}_heel" not in out:
            raise MappingError(f"contact detection needs the {side} ankle joint, which is not mapped")
    return out


def detect_point_contacts(
    points: Mapping[str, np.ndarray],
    fps: float,
    options: ContactOptions | None = None,
    floor: FloorPlane | None = None,
) -> Contacts:
    """Contacts of named foot points given their world positions.

    Args:
        points: Point name (``left_heel``, ``left_ball``, ``left_toe_end``, same
            for ``right``) -> ``(F, 3)`` positions in metres, Z-up.  At least the
            heels; a toe label uses whichever of ball and toe end are present
            (the heel if neither is).
        fps: Frame rate.
        options: Thresholds.
        floor: A known floor (e.g. a character's ``z = 0`` with its contact
            sites' levels); estimated from the clip when None.
    """
    opt = options or ContactOptions()
    names = [n for n in points]
    pos = {n: np.asarray(points[n], dtype=float) for n in names}
    F = next(iter(pos.values())).shape[0] if pos else 0
    vel = {n: central_velocity(pos[n], fps, opt.speed_window) for n in names}
    speeds = {n: np.linalg.norm(vel[n][:, :2], axis=1) for n in names}
    if floor is None:
        floor = estimate_floor(pos, speeds, opt)
    heights = {n: floor.heights(pos[n]) for n in names}
    rel = np.array([heights[n] - floor.levels.get(n, 0.0) for n in names]).reshape(len(names), F)
    spd = np.array([speeds[n] for n in names]).reshape(len(names), F)
    climb = np.array([vel[n][:, 2] for n in names]).reshape(len(names), F)
    det = ContactDetector([_kind(n) for n in names], fps, opt)
    det.run(rel.T, spd.T, climb.T)
    det.finish()
    lab = np.zeros((len(names), F), dtype=bool)
    for i, since, state in det.transitions:  # back-date every change to its onset
        lab[i, since:] = state
    point_labels = {n: lab[i] for i, n in enumerate(names)}
    labels, groups = {}, {}
    for label, pts in LABEL_POINTS.items():
        present = tuple(p for p in pts if p in point_labels)
        if not present:
            side = label.split("_", 1)[0]
            present = (f"{side}_heel",) if f"{side}_heel" in point_labels else ()
        groups[label] = present
        out = np.zeros(F, dtype=bool)
        for p in present:
            out |= point_labels[p]
        labels[label] = out
    return Contacts(
        labels=labels,
        fps=float(fps),
        floor=floor,
        heights=heights,
        speeds=speeds,
        point_labels=point_labels,
        groups=groups,
    )


def detect_contacts(
    motion, joint_indices: Mapping[str, int], options: ContactOptions | None = None, body_options=None
) -> Contacts:
    """Detect foot contacts on an actor's :class:`~physmocap.motion.Motion`.

    Args:
        motion: The actor's motion (metres, Z-up).
        joint_indices: Canonical joint name -> joint index in ``motion``
            (``map_skeleton(...).indices``); uses the ankles, and the toes and
            toe ends where present.
        options: Thresholds (:class:`ContactOptions`).
        body_options: Knee, hand and pelvis thresholds
            (:class:`~physmocap.ik.body_contacts.BodyContactOptions`).

    Returns:
        :class:`Contacts` with labels for :data:`CONTACT_LABELS`, the floor,
        and per-point heights above the floor and horizontal speeds.
    """
    from .body_contacts import detect_body_contacts

    pts = contact_points(joint_indices)
    body = {name: j for name, j in joint_indices.items() if name in _body_contact_joints()}
    world, column = motion.joint_world_positions([*pts.values(), *body.values()])
    try:
        contacts = detect_point_contacts({n: world[:, column[j]] for n, j in pts.items()}, motion.fps, options)
    except InputError as exc:
        raise InputError(exc.message, path=motion.source) from None
    contacts.joints = pts
    contacts.source = "detected"
    release(world)  # a long clip's: the feet's pages leave the memory before the body's are read
    if contacts.floor is not None:
        canonical = {name: world[:, column[j]] for name, j in body.items()}
        contacts.body_labels = detect_body_contacts(canonical, motion.fps, contacts.floor, body_options)
    return contacts


def _body_contact_joints() -> frozenset[str]:
    """Canonical joints :func:`~physmocap.ik.body_contacts.detect_body_contacts` reads: its
    parts' joints and the legs (hip, knee, ankle) its thresholds scale with."""
    from .body_contacts import BODY_PARTS

    legs = (f"{side}_{j}" for side in SIDES for j in ("hip", "knee", "ankle"))
    return frozenset([*legs, *(j for joints in BODY_PARTS.values() for j in joints)])


# ---------------------------------------------------------------------------
# User labels
# ---------------------------------------------------------------------------

_WHOLE_FOOT = {side: (f"{side}_heel", f"{side}_toe") for side in SIDES}


def load_contact_csv(path: str | os.PathLike, num_frames: int, fps: float | None = None) -> Contacts:
    """Read user contact labels: frame ranges per foot point.

    Format: UTF-8 CSV; lines starting with ``#`` and blank lines are ignored;
    a header row, either ``point,start,end`` (0-based frames, ``end``
    exclusive like Python ranges and ``--end``) or ``point,first,last`` (both
    inclusive); then one range per row.  ``point`` is one of
    :data:`CONTACT_LABELS`, or ``left`` / ``right`` for the whole foot.
    Ranges may overlap; a point without rows is never in contact (warned).

    Raises:
        InputError: naming the file and line for a missing header, an unknown
            point, a non-integer frame, an empty range or one outside
            ``0 .. num_frames``.
    """
    p = Path(path)
    if not p.exists():
        raise InputError("contact label file not found", path=p)
    labels = {n: np.zeros(int(num_frames), dtype=bool) for n in CONTACT_LABELS}
    try:
        text = p.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read contact labels: {exc}", path=p) from None
    header = None
    inclusive = False
    seen: set[str] = set()
    for lineno, row in _csv_rows(text):
        if header is None:
            header = [c.strip().lower() for c in row]
            if header == ["point", "start", "end"]:
                inclusive = False
            elif header == ["point", "first", "last"]:
                inclusive = True
            else:
                raise InputError(
                    f"expected the header 'point,start,end' (end exclusive) or 'point,first,last' "
                    f"(inclusive), got {','.join(row)!r}",
                    path=p,
                    line=lineno,
                )
            continue
        if len(row) != 3:
            raise InputError(f"expected 3 columns (point, {header[1]}, {header[2]}), got {len(row)}", path=p, line=lineno)
        point = row[0].strip()
        if point not in labels and point not in _WHOLE_FOOT:
            raise InputError(
                f"unknown contact point {point!r}; expected one of {', '.join(CONTACT_LABELS)}, left, right",
                path=p,
                line=lineno,
            )
        try:
            a, b = int(row[1].strip()), int(row[2].strip())
        except ValueError:
            raise InputError(f"frames must be integers, got {row[1].strip()!r} and {row[2].strip()!r}", path=p, line=lineno) from None
        if inclusive:
            b += 1
        if a < 0 or b > num_frames or a >= b:
            shown = f"{header[1]} {row[1].strip()}, {header[2]} {row[2].strip()}"
            raise InputError(
                f"frame range ({shown}) is empty or outside the clip's frames 0 to {num_frames - 1}"
                + (" (end is exclusive)" if not inclusive else ""),
                path=p,
                line=lineno,
            )
        for name in _WHOLE_FOOT.get(point, (point,)):
            labels[name][a:b] = True
            seen.add(name)
    if header is None:
        raise InputError("empty contact label file: expected a header 'point,start,end' and frame ranges", path=p)
    unlabelled = [n for n in CONTACT_LABELS if n not in seen]
    if unlabelled:
        warn(f"{p}: no ranges for {', '.join(unlabelled)}; never in contact")
    return Contacts(labels=labels, fps=fps, source=str(p), groups={n: (n,) for n in CONTACT_LABELS})


def _csv_rows(text: str):
    lines = text.splitlines()
    for lineno, line in enumerate(lines, start=1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        yield lineno, next(csv.reader([line]))


def write_contact_csv(contacts: Contacts, path: str | os.PathLike, comment: str | None = None) -> Path:
    """Write ``contacts.labels`` as ``point,start,end`` ranges (end exclusive), atomically."""
    p = Path(path)
    with atomic_open(p, "w") as fh:
        if comment:
            for line in comment.splitlines():
                fh.write(f"# {line}\n")
        fh.write("point,start,end\n")
        for name in CONTACT_LABELS:
            if name in contacts.labels:
                for a, b in _segments(contacts.labels[name]):
                    fh.write(f"{name},{a},{b}\n")
    return p


# ---------------------------------------------------------------------------
# Characters and evaluation
# ---------------------------------------------------------------------------


def contact_sites_labels(contacts: Contacts, character) -> dict[str, np.ndarray]:
    """Map foot labels onto a character's contact sites.

    ``character.contacts`` lists each side's sites heel first, then toward the
    toes; the first site takes the heel label and every other site the toe
    label (so a humanoid's ball and toe tip, or a robot's toe, follow the toe).
    """
    out: dict[str, np.ndarray] = {}
    for side, sites in character.contacts.items():
        if side not in SIDES:
            continue
        for k, site in enumerate(sites):
            label = f"{side}_heel" if k == 0 else f"{side}_toe"
            out[site] = np.asarray(contacts.labels[label], dtype=bool).copy()
    return out


def label_f1(predicted: np.ndarray, truth: np.ndarray) -> float:
    """Frame-level F1 score of boolean labels (1.0 when both are all False)."""
    pred = np.asarray(predicted, dtype=bool)
    true = np.asarray(truth, dtype=bool)
    tp = int(np.sum(pred & true))
    fp = int(np.sum(pred & ~true))
    fn = int(np.sum(~pred & true))
    if tp + fp + fn == 0:
        return 1.0
    return 2.0 * tp / (2.0 * tp + fp + fn)
