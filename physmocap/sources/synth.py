"""Synthetic tracker streams made from real motion capture, for tests and benchmarks.

:func:`tracker_stream` turns a solved clip (e.g. the CMU walk BVH) into what a
depth-camera skeleton tracker would have produced watching that performance:
the tracker's joints only (NITE's 15 by default), derived from the clip's world
positions through the name-mapping profiles (tracker joint -> canonical joint
-> source joint), seen from a camera placed in front of the performer, in the
camera frame and unit of :mod:`physmocap.sources.sensor`, resampled to the
tracker's rate, with Gaussian noise, per-joint dropouts (short and long), low
confidence samples and whole lost frames.  Everything is drawn from one seeded
generator, so a stream is reproducible.  Writers for the three position
formats read by :mod:`physmocap.sources.positions` are included.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..fileio import atomic_open
from ..motion import Motion, Skeleton
from .positions import TRACKER_LAYOUTS

__all__ = ["TrackerStream", "tracker_stream", "write_stream_csv", "write_stream_npz", "write_stream_jsonl"]


@dataclass
class TrackerStream:
    """A synthetic tracker recording.

    Attributes:
        names: Tracker joint names.
        positions: ``(F, J, 3)`` camera-frame positions in ``units`` (NaN where lost).
        confidence: ``(F, J)`` in [0, 1].
        fps: Frame rate.
        units: ``"mm"`` or ``"m"``.
        mirrored: The camera-frame convention used (see :mod:`.sensor`).
        truth: ``(F, J, 3)`` noiseless world positions (metres, Z-up, the source clip's world).
        camera_position: ``(3,)`` world position of the camera (metres).
        camera_axes: ``(3, 3)`` columns: the camera frame's X, Y, Z axes in the world.
        events: What was injected: ``dropouts`` (joint, start, end) and ``lost`` frame runs.
    """

    names: tuple[str, ...]
    positions: np.ndarray
    confidence: np.ndarray
    fps: float
    units: str
    mirrored: bool
    truth: np.ndarray
    camera_position: np.ndarray
    camera_axes: np.ndarray
    events: dict = field(default_factory=dict)

    @property
    def num_frames(self) -> int:
        return int(self.positions.shape[0])

    def floor_plane(self) -> tuple[float, float, float, float]:
        """The world's floor z = 0 as ``(a, b, c, d)`` in this stream's camera frame and units."""
        up_cam = self.camera_axes.T @ np.array([0.0, 0.0, 1.0])
        # a point p on the floor: n . p_cam + d = 0 with p_cam = A^T (p - c)
        d = float(up_cam @ (self.camera_axes.T @ self.camera_position))
        scale = 1000.0 if self.units == "mm" else 1.0
        n = up_cam.copy()
        if not self.mirrored:
            n[0] = -n[0]
        return float(n[0]), float(n[1]), float(n[2]), d * scale


def _tracker_to_source(motion: Motion, layout: tuple[str, ...]) -> tuple[dict[int, int], dict[str, int]]:
    """Tracker joint index -> the source joint at the same canonical joint (for
    the tracker joints that have one); and the tracker's canonical map."""
    from .profiles import map_skeleton

    J = len(layout)
    probe = Skeleton(names=layout, parents=-np.ones(J, dtype=np.int64), offsets=np.zeros((J, 3)))
    tracker_map = map_skeleton(probe)
    source_map = map_skeleton(motion)
    by_tracker = {j: c for c, j in tracker_map.indices.items()}
    out: dict[int, int] = {}
    for j in range(J):
        c = by_tracker.get(j)
        if c is not None and c in source_map.indices:
            out[j] = int(source_map.indices[c])
    return out, dict(tracker_map.indices)


def tracker_stream(
    motion: Motion,
    *,
    layout: str = "nite",
    fps: float = 30.0,
    units: str = "mm",
    mirrored: bool = True,
    camera_distance: float = 2.0,
    camera_height: float = 1.0,
    camera_pitch_deg: float = 10.0,
    camera_yaw_deg: float = 0.0,
    noise: float = 0.008,
    short_dropouts: int = 6,
    long_dropouts: int = 2,
    lost_runs: int = 2,
    low_confidence: float = 0.03,
    seed: int = 0,
) -> TrackerStream:
    """A tracker's view of ``motion`` (see the module docstring).

    The camera stands ``camera_distance`` metres beyond where the performer's
    pelvis ends the clip, along the clip's overall direction of travel (or
    its facing, if it stays put), ``camera_height`` above the floor, turned
    ``camera_yaw_deg`` about the vertical and pitched down by
    ``camera_pitch_deg`` towards the performer.

    Args:
        motion: A solved clip (metres, Z-up), e.g. a BVH.
        layout: Tracker joint set (:data:`physmocap.sources.positions.TRACKER_LAYOUTS`);
            tracker joints with no counterpart in ``motion`` are left out.
        fps: Tracker frame rate (the clip is resampled).
        units: ``"mm"`` (OpenNI, Azure Kinect) or ``"m"`` (Kinect v2).
        mirrored: Camera-frame convention (:mod:`physmocap.sources.sensor`).
        noise: Standard deviation of the Gaussian position noise, metres.
        short_dropouts: Per-joint dropouts of 2 to 4 frames (NaN, confidence 0).
        long_dropouts: Per-joint dropouts of 0.5 to 1 s.
        lost_runs: Runs of 1 to 5 frames where every joint is lost.
        low_confidence: Fraction of samples reported at confidence 0.5 (inferred).
        seed: Random seed.
    """
    layout_names = TRACKER_LAYOUTS[layout]
    pairs, canon = _tracker_to_source(motion, layout_names)
    keep = sorted(pairs)
    names = tuple(layout_names[j] for j in keep)
    src_idx = [pairs[j] for j in keep]
    if "left_hip" not in canon or "right_hip" not in canon or canon["left_hip"] not in pairs:
        raise ValueError(f"the {layout} layout has no hips to place the camera by")
    lh, rh = keep.index(canon["left_hip"]), keep.index(canon["right_hip"])
    m = motion.resample(fps) if abs(motion.fps - fps) > 1e-9 else motion
    world = m.world_positions()
    floor = motion.floor_height()
    truth = world[:, src_idx].copy()
    truth[..., 2] -= floor
    F, J = truth.shape[:2]
    rng = np.random.default_rng(seed)

    # camera placement
    pelvis = 0.5 * (truth[:, lh] + truth[:, rh])
    travel = pelvis[-1, :2] - pelvis[0, :2]
    if np.linalg.norm(travel) > 0.5:
        ahead = travel / np.linalg.norm(travel)
    else:
        lat = truth[0, lh, :2] - truth[0, rh, :2]
        ahead = np.array([lat[1], -lat[0]]) / max(np.linalg.norm(lat), 1e-9)  # facing = left x up
    yaw = np.radians(camera_yaw_deg)
    c, s = np.cos(yaw), np.sin(yaw)
    cam = np.array([*(pelvis[-1, :2] + camera_distance * ahead), camera_height])
    look = -np.array([ahead[0], ahead[1], 0.0])
    look = np.array([c * look[0] - s * look[1], s * look[0] + c * look[1], 0.0])
    pitch = np.radians(camera_pitch_deg)
    fwd = np.cos(pitch) * look + np.sin(pitch) * np.array([0.0, 0.0, -1.0])
    up = np.cross(fwd, np.cross(np.array([0.0, 0.0, 1.0]), fwd))
    up /= np.linalg.norm(up)
    x_axis = np.cross(up, fwd)  # the camera's left: the facing performer's right
    axes = np.stack([x_axis, up, fwd], axis=1)

    noisy = truth + rng.normal(0.0, noise, truth.shape)
    cam_pos = (noisy - cam) @ axes
    if not mirrored:
        cam_pos[..., 0] *= -1.0
    scale = 1000.0 if units == "mm" else 1.0
    cam_pos *= scale
    conf = np.ones((F, J))
    conf[rng.random((F, J)) < low_confidence] = 0.5

    events: dict = {"dropouts": [], "lost": []}
    for count, (lo, hi) in ((short_dropouts, (2, 4)), (long_dropouts, (int(0.5 * fps), int(fps)))):
        for _ in range(count):
            n = int(rng.integers(lo, hi + 1))
            j = int(rng.integers(0, J))
            start = int(rng.integers(1, max(F - n - 1, 2)))
            cam_pos[start : start + n, j] = np.nan
            conf[start : start + n, j] = 0.0
            events["dropouts"].append((names[j], start, start + n - 1))
    for _ in range(lost_runs):
        n = int(rng.integers(1, 6))
        start = int(rng.integers(1, max(F - n - 1, 2)))
        cam_pos[start : start + n] = np.nan
        conf[start : start + n] = 0.0
        events["lost"].append((start, start + n - 1))
    return TrackerStream(
        names=tuple(names),
        positions=cam_pos,
        confidence=conf,
        fps=float(fps),
        units=units,
        mirrored=mirrored,
        truth=truth,
        camera_position=cam,
        camera_axes=axes,
        events=events,
    )


def _num(x: float) -> str:
    return "" if not np.isfinite(x) else repr(float(x))


def write_stream_csv(stream: TrackerStream, path: str | os.PathLike) -> Path:
    """Wide CSV: ``frame,time,<joint>_x,<joint>_y,<joint>_z,<joint>_conf...`` with option comments."""
    p = Path(path)
    header = ["frame", "time"]
    for n in stream.names:
        header += [f"{n}_x", f"{n}_y", f"{n}_z", f"{n}_conf"]
    with atomic_open(p, "w") as fh:
        fh.write(f"# fps: {stream.fps!r}\n# units: {stream.units}\n# frame: camera\n")
        fh.write(f"# mirrored: {str(stream.mirrored).lower()}\n")
        fh.write(",".join(header) + "\n")
        for f in range(stream.num_frames):
            row = [str(f), repr(f / stream.fps)]
            for j in range(len(stream.names)):
                row += [_num(v) for v in stream.positions[f, j]] + [repr(float(stream.confidence[f, j]))]
            fh.write(",".join(row) + "\n")
    return p


def write_stream_npz(stream: TrackerStream, path: str | os.PathLike) -> Path:
    """NPZ with ``positions``, ``names``, ``confidence``, ``fps`` and the option scalars."""
    p = Path(path)
    with atomic_open(p, "wb") as fh:
        np.savez(
            fh,
            positions=stream.positions,
            names=np.array(stream.names, dtype=str),
            confidence=stream.confidence,
            fps=np.array(stream.fps),
            units=np.array(stream.units),
            frame=np.array("camera"),
            mirrored=np.array(stream.mirrored),
        )
    return p


def write_stream_jsonl(stream: TrackerStream, path: str | os.PathLike) -> Path:
    """JSON lines: a header object, then ``{"frame", "time", "joints": {name: [x, y, z, c] | null}}``."""
    p = Path(path)
    with atomic_open(p, "w") as fh:
        header = {"fps": stream.fps, "units": stream.units, "frame": "camera", "mirrored": stream.mirrored}
        fh.write(json.dumps(header) + "\n")
        for f in range(stream.num_frames):
            joints = {}
            for j, n in enumerate(stream.names):
                v = stream.positions[f, j]
                joints[n] = None if not np.all(np.isfinite(v)) else [*v.tolist(), float(stream.confidence[f, j])]
            fh.write(json.dumps({"frame": f, "time": f / stream.fps, "joints": joints}) + "\n")
    return p
