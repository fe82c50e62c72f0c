"""``physmocap replay``: stream a recording through the causal retargeter and time it."""

from __future__ import annotations

import argparse
import json
import time
import warnings
from pathlib import Path

import numpy as np

from ..errors import OptionError
from ..resources import display_path
from ..fileio import OutputSet, announce, atomic_open, check_distinct, check_not_input, check_writable, suffix_error


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "replay",
        help="replay a recording frame by frame through the streaming retargeter",
        description=(
            "Feed a recording (MCAP, BVH, tracker CSV/NPZ/JSONL, or 'example') one frame at a time to "
            "the causal streaming retargeter, at the recorded rate (--realtime) or as fast as "
            "possible, and report per-frame latency (median, p99) and dropped frames."
        ),
    )
    p.add_argument("input", metavar="RECORDING", help="recording (.mcap, .bvh, .csv, .npz, .jsonl) or 'example'")
    p.add_argument("--character", metavar="PATH", help="MJCF file or bundled name (humanoid, robot)")
    p.add_argument("--map", metavar="MAP.toml", help="character mapping file (TOML)")
    p.add_argument("--source-map", metavar="MAP.toml", help="source skeleton mapping file (TOML)")
    p.add_argument("--realtime", action="store_true", help="pace frames at the recorded rate; late frames are dropped")
    p.add_argument("--floor", type=float, help="the actor's floor height in the recording (m); default: from the first frame")
    p.add_argument("-o", "--output", help="write the streamed result (.bvh, .npz, .csv, .mcap)")
    p.add_argument("--stats", metavar="STATS.json", help="write the latency figures as JSON")
    p.add_argument("--compare", action="store_true", help="also retarget offline and report the difference")
    p.add_argument("--calibrate", metavar="ROM", help="marker recordings: calibrate the actor on this range-of-motion "
                   "clip (.c3d, .trc, .mcap) instead of the recording's first seconds")
    p.add_argument("--calibration-seconds", type=float, default=None,
                   help="marker recordings: seconds at the start used to calibrate the actor (default 10)")
    p.add_argument("--marker-set", metavar="SET.toml", help="marker recordings: marker roles overriding the aliases")
    p.add_argument("--no-arm-branches", action="store_true",
                   help="leave an arm stuck on a branch of its joint ranges that cannot reach the actor where it is "
                        "(by default it is pulled over to one that can, at its joints' velocity limits)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..ik.retarget import retarget
    from ..ik.stream import StreamingRetargeter
    from ..models import load_character
    from ..sources import load_motion
    from ..sources.markers import is_marker_file
    from ..trajectory import Trajectory

    out = Path(args.output) if args.output else None
    if out is not None:
        from .retarget import WRITERS

        if out.suffix.lower() not in WRITERS:
            raise suffix_error(out, WRITERS)
        check_writable(args.output)
    if args.stats:
        check_writable(args.stats)
    check_distinct([out, args.stats])
    # a run never overwrites its capture or the files that describe it
    check_not_input([out, args.stats], [args.input, args.map, args.source_map, args.calibrate, args.marker_set])
    if not is_marker_file(args.input):
        given = [flag for flag, value in (("--calibrate", args.calibrate), ("--marker-set", args.marker_set),
                                          ("--calibration-seconds", args.calibration_seconds is not None)) if value]
        if given:
            raise OptionError(f"{', '.join(given)}: for marker recordings only (.c3d, .trc, marker .mcap)", path=args.input)
    else:
        from ..markers.replay import replay_markers

        return replay_markers(args, out)
    motion = load_motion(args.input, min_frames=1)
    character = load_character(args.character, args.map)
    floor = args.floor if args.floor is not None else motion.meta.get("floor_z")
    streamer = StreamingRetargeter(
        character,
        skeleton=motion.skeleton,
        fps=motion.fps,
        translated=motion.translated,
        mapping=args.source_map or motion.meta.get("source_mapping"),
        source=str(motion.source),
        **({} if floor is None else {"source_floor": float(floor)}),
        **({"arm_branches": False} if args.no_arm_branches else {}),
    )
    F = motion.num_frames
    qpos = np.empty((F, character.model.nq))
    dropped = 0
    period = 1.0 / motion.fps
    start = time.perf_counter()
    last = None
    t = 0
    while t < F:
        if args.realtime:
            due = start + t * period
            now = time.perf_counter()
            if now < due:
                time.sleep(due - now)
            else:
                # late: skip to the newest frame that is due (a live source would not wait)
                newest = min(F - 1, int((now - start) / period))
                if newest > t and last is not None:
                    qpos[t:newest] = last
                    dropped += newest - t
                    t = newest
        if motion.is_rotational:
            q = streamer.step(rotations=motion.rotations[t], translations=motion.translations[t], index=t)
        else:
            conf = None if motion.confidence is None else motion.confidence[t]
            q = streamer.step(positions=motion.positions[t], confidence=conf, index=t)
        qpos[t] = last = q
        t += 1
    wall = time.perf_counter() - start
    all_lat = np.array(streamer.latencies) * 1000.0
    processed = len(all_lat)
    # the first frame calibrates and converges from the rest pose: reported on its own
    lat = all_lat[1:] if processed > 1 else all_lat
    stats = {
        "recording": display_path(motion.source),
        "character": str(character.name),
        "frames": F,
        "fps": float(motion.fps),
        "mode": "realtime" if args.realtime else "as fast as possible",
        "processed_frames": processed,
        "dropped_frames": int(dropped),
        "latency_ms": {
            "median": float(np.median(lat)),
            "p99": float(np.percentile(lat, 99)),
            "max": float(lat.max()),
            "first_frame": float(all_lat[0]),
        },
        "throughput_fps": float(processed / wall),
    }
    traj = Trajectory(character, qpos, motion.fps, source=str(motion.source))
    if args.compare:
        with warnings.catch_warnings():  # the comparison's own (its frame 0 may be a T-pose) are not the stream's
            warnings.simplefilter("ignore")
            offline = retarget(  # frame for frame, as streamed (no reference-frame skipping)
                motion, character, mapping=args.source_map or motion.meta.get("source_mapping"), start=0, progress=False
            )
        a, _ = offline.body_poses()
        b, _ = traj.body_poses()
        d = np.linalg.norm(a[:, 1:] - b[:, 1:], axis=-1) * 100.0
        stats["offline_difference_cm"] = {"mean": float(d.mean()), "p95": float(np.percentile(d, 95)), "max": float(d.max())}
    print(
        f"replayed {processed}/{F} frames of {display_path(motion.source)} onto {character.name} ({stats['mode']}): "
        f"latency median {stats['latency_ms']['median']:.2f} ms, p99 {stats['latency_ms']['p99']:.2f} ms, "
        f"max {stats['latency_ms']['max']:.1f} ms (first frame {stats['latency_ms']['first_frame']:.0f} ms); "
        f"dropped frames {dropped}; {stats['throughput_fps']:.0f} frames/s"
    )
    if args.compare:
        c = stats["offline_difference_cm"]
        print(f"streaming vs offline body positions: mean {c['mean']:.2f} cm, p95 {c['p95']:.2f} cm, max {c['max']:.2f} cm")
    write_results(traj, out, stats, args.stats)
    return 0


def write_results(traj, out: Path | None, stats: dict, stats_path: str | None) -> None:
    """The streamed result (``out``, any retarget output) and the latency figures (JSON),
    renamed into place together, or none."""
    with OutputSet():
        if out is not None:
            from .retarget import write_outputs

            write_outputs(traj, [out], argparse.Namespace(up=None, units=None))
        if stats_path:
            with atomic_open(stats_path, "w") as fh:
                json.dump(stats, fh, indent=2, sort_keys=True)
                fh.write("\n")
            announce(f"wrote {stats_path}")
