"""``physmocap replay`` on marker recordings: calibrate once, then solve (and retarget) frame by frame.

The actor is calibrated on a range-of-motion clip (``--calibrate``) or the recording's first
seconds (:func:`.stream.calibration_slice`); every frame then goes through
:class:`.stream.MarkerStream` (markers to the actor's pose) and, with ``--character``, the
actor's canonical joint positions through the causal
:class:`~physmocap.ik.stream.StreamingRetargeter`.  Latency per frame is the wall time of both
steps; its CPU time (``time.thread_time``) is reported too, since on a loaded machine the wall
time includes the waits for a core.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from ..errors import OptionError, warn

__all__ = ["replay_markers"]


def _percentiles(x: np.ndarray) -> dict[str, float]:
    """Median, p99 and max of per-frame times, in milliseconds."""
    ms = np.asarray(x, float) * 1000.0
    return {"median": float(np.median(ms)), "p99": float(np.percentile(ms, 99)), "max": float(ms.max())}


def replay_markers(args: argparse.Namespace, out: Path | None) -> int:
    """Run the streaming marker solve on ``args.input`` (see the module docstring)."""
    from ..ik.stream import StreamingRetargeter
    from ..models import load_character
    from ..motion import Skeleton
    from ..sources.markers import read_markers
    from ..trajectory import Trajectory
    from .stream import CALIBRATION_SECONDS, MarkerStream, calibration_slice

    if args.compare or args.source_map or args.floor is not None:
        raise OptionError("--compare, --source-map and --floor are for skeleton recordings, not markers")
    rec = read_markers(args.input)
    character = load_character(args.character, args.map) if args.character else None
    if args.calibrate:
        cal = read_markers(args.calibrate)
    else:
        seconds = CALIBRATION_SECONDS if args.calibration_seconds is None else args.calibration_seconds
        cal = calibration_slice(rec, seconds)
        if seconds * rec.fps > rec.num_frames:
            given = "--calibration-seconds" if args.calibration_seconds is not None else "calibration by default"
            warn(f"{rec.source}: the recording lasts {rec.num_frames / rec.fps:.3g} s, less than the "
                 f"{seconds:g} s of {given}; the actor is calibrated on all of it")
    t0 = time.perf_counter()
    stream = MarkerStream.calibrate(cal, args.marker_set, labels=rec.labels)
    calib_s = time.perf_counter() - t0
    names = stream.joint_names
    retargeter = None
    if character is not None:
        J = len(names)
        skel = Skeleton(names=tuple(names), parents=-np.ones(J, dtype=np.int64), offsets=np.zeros((J, 3)))
        retargeter = StreamingRetargeter(character, skeleton=skel, fps=rec.fps, source=str(rec.source),
                                         **({"arm_branches": False} if getattr(args, "no_arm_branches", False) else {}))
    F = rec.num_frames
    qa = np.empty((F, stream.actor.character.model.nq))
    qc = np.empty((F, character.model.nq)) if character is not None else None
    wall, cpu, rms = np.zeros(F), np.zeros(F), np.zeros(F)
    start = time.perf_counter()
    for t in range(F):
        if args.realtime:  # a live source: frame t arrives at t / fps
            delay = start + t / rec.fps - time.perf_counter()
            if delay > 0:
                time.sleep(delay)
        w, c = time.perf_counter(), time.thread_time()
        fr = stream.step(rec.positions[t])
        qa[t] = fr.qpos
        if retargeter is not None:
            qc[t] = retargeter.step(positions=fr.joints)
        wall[t], cpu[t], rms[t] = time.perf_counter() - w, time.thread_time() - c, fr.residual_rms
    total = time.perf_counter() - start
    rest = slice(1, None) if F > 1 else slice(None)  # the first frame converges from the rest pose
    stats = {
        "recording": str(rec.source),
        "character": None if character is None else str(character.name),
        "frames": F,
        "fps": float(rec.fps),
        "mode": "realtime" if args.realtime else "as fast as possible",
        "calibration": {"source": str(args.calibrate or f"first {cal.num_frames} frames"), "seconds": calib_s,
                        "joint_centres": dict(stream.actor.calibration.method)},
        "latency_ms": {**_percentiles(wall[rest]), "first_frame": float(wall[0] * 1000.0)},
        "cpu_ms": _percentiles(cpu[rest]),
        "marker_residual_rms_mm": float(np.sqrt(np.nanmean(rms**2)) * 1000.0),
        "throughput_fps": float(F / total),
    }
    lat, cp = stats["latency_ms"], stats["cpu_ms"]
    print(f"replayed {F} frames of {rec.source} (markers; actor calibrated on {stats['calibration']['source']} "
          f"in {calib_s:.1f} s){'' if character is None else ' onto ' + str(character.name)}: latency median "
          f"{lat['median']:.2f} ms, p99 {lat['p99']:.2f} ms (CPU p99 {cp['p99']:.2f} ms), first frame "
          f"{lat['first_frame']:.0f} ms; marker residual RMS {stats['marker_residual_rms_mm']:.1f} mm; "
          f"{stats['throughput_fps']:.0f} frames/s")
    from ..cli.replay import write_results

    traj = Trajectory(character or stream.actor.character, qc if character is not None else qa, rec.fps,
                      source=str(rec.source))
    write_results(traj, out, stats, args.stats)
    return 0
