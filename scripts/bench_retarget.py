#!/usr/bin/env python3
"""Benchmark the retargeting IK: frames per second, per-frame latency, peak memory.

For each shared BVH file (../shared/data) and each bundled character, the
targets are built once (file reading and target building are excluded, as
metrics.md's throughput definition asks), then the per-frame IK is timed over
the whole clip ``--runs`` times; the median run is reported.  Per-frame
latency (median, p99) is taken over all frames of all runs.  Peak memory is the
process's maximum resident set size after all runs (ru_maxrss).

Usage:  python scripts/bench_retarget.py [--runs 3] [--frames N] [--characters humanoid robot]
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("PHYSMOCAP_SHARED_DATA", REPO.parent / "shared" / "data"))
CLIPS = ["cmu_12_01_walk.bvh", "pymo_walk.bvh", "cmu_01_01_jumps.bvh", "optitrack_hops_crouch.bvh"]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--frames", type=int, default=None, help="only the first N frames of each clip")
    ap.add_argument("--characters", nargs="+", default=["humanoid", "robot"])
    ap.add_argument("--clips", nargs="+", default=CLIPS)
    args = ap.parse_args()

    from physmocap.ik.retarget import map_motion, split_options
    from physmocap.ik.solver import FrameSolver
    from physmocap.ik.targets import build_targets
    from physmocap.models import load_character
    from physmocap.sources import load_motion

    print(f"{'clip':28s} {'character':10s} {'frames':>6s} {'fps':>8s} {'lat med ms':>10s} {'lat p99 ms':>10s}")
    for clip in args.clips:
        path = DATA / clip
        if not path.exists():
            print(f"skip {clip}: {path} not found", file=sys.stderr)
            continue
        motion = load_motion(path)
        if args.frames:
            motion = motion.slice_frames(0, min(args.frames, motion.num_frames))
        jidx = map_motion(motion)
        for name in args.characters:
            character = load_character(name)
            t_opt, s_opt, _ = split_options({})
            targets = build_targets(motion, jidx, character, t_opt)
            run_fps, lat = [], []
            for _ in range(args.runs):
                solver = FrameSolver(character, targets.names, targets.has_orientation, targets.fps, s_opt)
                t_start = time.perf_counter()
                for t in range(targets.num_frames):
                    t0 = time.perf_counter()
                    solver.set_targets(targets.positions[t], targets.orientations[t], targets.valid[t])
                    solver.solve_frame(first=(t == 0))
                    lat.append(time.perf_counter() - t0)
                run_fps.append(targets.num_frames / (time.perf_counter() - t_start))
            lat_ms = np.array(lat) * 1000.0
            print(
                f"{clip:28s} {name:10s} {targets.num_frames:6d} {statistics.median(run_fps):8.0f} "
                f"{np.median(lat_ms):10.2f} {np.percentile(lat_ms, 99):10.2f}"
            )
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    print(f"peak memory (max RSS): {peak:.0f} MB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
