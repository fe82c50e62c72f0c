"""Streaming marker solve: calibrate the actor once, then solve one frame of markers at a time.

:func:`.solve.calibrate_actor` runs once on a calibration recording (a range-of-motion clip, or
the first seconds of the take: :func:`calibration_slice`); :class:`MarkerStream` then takes
each new frame of labelled markers (the calibration's labels, in any order) and returns the
actor's pose from the same warm-started marker-driven IK as the offline solve (every marker a
position target weighted by the inverse of its scatter, joint ranges, joint speeds and the
floor hard).  It is causal: a frame is solved from that frame and the previous pose only.
Per-frame latency (wall time of :meth:`MarkerStream.step`) is recorded.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError
from .markerset import MarkerSet
from .recording import MarkerRecording
from .solve import ActorModel, MarkerSolveOptions, calibrate_actor

__all__ = ["MarkerStream", "StreamFrame", "calibration_slice"]

#: Seconds of a take used to calibrate when no range-of-motion clip is given.
CALIBRATION_SECONDS = 10.0


def calibration_slice(rec: MarkerRecording, seconds: float = CALIBRATION_SECONDS) -> MarkerRecording:
    """The first ``seconds`` of a recording (all of it when shorter)."""
    if not (np.isfinite(seconds) and seconds > 0):
        raise InputError(f"the calibration needs a positive duration, got {seconds} s", path=rec.source)
    n = max(1, min(rec.num_frames, int(round(seconds * rec.fps))))
    return rec.frames(0, n)


@dataclass
class StreamFrame:
    """One solved frame.

    Attributes:
        qpos: The actor model's ``qpos`` (a copy).
        joints: ``(J, 3)`` canonical joint positions (metres, Z-up, floor at 0), in
            :attr:`MarkerStream.joint_names` order.
        residual_rms: RMS distance (metres) of the frame's valid markers from their sites.
        latency: Wall seconds of the solve.
    """

    qpos: np.ndarray
    joints: np.ndarray
    residual_rms: float
    latency: float


@dataclass
class MarkerStream:
    """Frame-by-frame marker solve on a calibrated actor.

    Args:
        actor: The :class:`~.solve.ActorModel` from :func:`~.solve.calibrate_actor`.
        labels: Labels of the incoming frames' markers (default: the calibration's).
    """

    actor: ActorModel
    labels: tuple[str, ...] | None = None
    latencies: list[float] = field(default_factory=list)

    def __post_init__(self) -> None:
        labels = tuple(self.actor.labels if self.labels is None else self.labels)
        where = {lab: k for k, lab in enumerate(labels)}
        missing = [self.actor.labels[i] for i in self.actor.attached if self.actor.labels[i] not in where]
        if len(missing) == len(self.actor.attached):
            raise InputError("none of the calibrated markers is in the stream: " + ", ".join(missing[:8]))
        self.labels = labels
        #: stream column of each attached marker (-1: absent from the stream, always off)
        self._cols = np.array([where.get(self.actor.labels[i], -1) for i in self.actor.attached])
        self._solver = self.actor.frame_solver()
        model = self.actor.character.model
        self._sids = np.array([model.site(self.actor.site_names[i]).id for i in self.actor.attached])
        self.joint_names = list(self.actor.character.tracked)
        self._jids = np.array([model.site(self.actor.character.tracked[n].name).id for n in self.joint_names])
        self._orient = np.tile([0.0, 0.0, 0.0, 1.0], (len(self.actor.attached), 1))
        self.frame = 0

    @classmethod
    def calibrate(cls, rec: MarkerRecording, marker_set: str | os.PathLike | MarkerSet | None = None,
                  options: MarkerSolveOptions | None = None, labels: tuple[str, ...] | None = None) -> "MarkerStream":
        """Calibrate on ``rec`` (:func:`~.solve.calibrate_actor`) and open a stream."""
        return cls(calibrate_actor(rec, marker_set, options), labels)

    def step(self, points: np.ndarray) -> StreamFrame:
        """Solve one frame: ``points`` ``(M, 3)`` metres in the calibration's axes, in
        :attr:`labels` order, NaN where a marker is not seen."""
        t0 = time.perf_counter()
        P = np.asarray(points, dtype=float)
        if P.shape != (len(self.labels), 3):
            raise InputError(f"a frame needs ({len(self.labels)}, 3) marker positions, got {P.shape}", frame=self.frame)
        cols = self._cols
        X = np.full((len(cols), 3), np.nan)
        X[cols >= 0] = P[cols[cols >= 0]]
        Pz = self.actor.to_solver_frame(X)
        on = np.all(np.isfinite(Pz), axis=1)
        if self.frame == 0:
            full = np.full((len(self.actor.labels), 3), np.nan)
            full[self.actor.attached] = X
            self._solver.reset(self.actor.start_pose(full))
        q, _, _ = self._solver.solve_frame(np.nan_to_num(Pz), self._orient, on, first=(self.frame == 0))
        data = self._solver.configuration.data
        d = np.linalg.norm(data.site_xpos[self._sids] - Pz, axis=1)[on]
        joints = data.site_xpos[self._jids].copy()
        dt = time.perf_counter() - t0
        self.latencies.append(dt)
        self.frame += 1
        return StreamFrame(qpos=np.array(q), joints=joints, residual_rms=float(np.sqrt(np.mean(d**2))) if d.size else float("nan"),
                           latency=dt)
