#!/usr/bin/env python3
"""Benchmark retargeting: frames per second, per-frame latency, peak memory.

For each shared BVH clip (../shared/data) and each bundled character:

* **retarget fps**: the whole of :func:`physmocap.ik.retarget.retarget` on an
  already-read motion (name mapping, contact detection, targets, per-frame IK
  with planting), i.e. everything but file reading (metrics.md's throughput);
* **IK fps** and **per-frame latency** (median, p99): the per-frame loop alone
  (:func:`physmocap.ik.retarget.solve_targets` with the contacts);

each the median of ``--runs`` runs.  Peak memory is the process's maximum
resident set size at the end (ru_maxrss).  Also prints the streaming
retargeter's latency on the CMU walk.

Usage:  python scripts/bench_retarget.py [--runs 3] [--frames N] [--characters humanoid robot]
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import sys
import time
import warnings
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
    ap.add_argument("--no-plant", action="store_true", help="pure tracking: no contact detection or planting")
    args = ap.parse_args()
    warnings.simplefilter("ignore")

    from physmocap.ik.contacts import detect_contacts
    from physmocap.ik.retarget import map_motion, retarget, solve_targets
    from physmocap.ik.stream import stream_motion
    from physmocap.ik.targets import build_targets
    from physmocap.models import load_character
    from physmocap.sources import load_motion

    print(
        f"{'clip':27s} {'character':9s} {'frames':>6s} {'retarget fps':>12s} {'IK fps':>7s}"
        f" {'lat med ms':>10s} {'lat p99 ms':>10s}"
    )
    for clip in args.clips:
        path = DATA / clip
        if not path.exists():
            print(f"skip {clip}: {path} not found", file=sys.stderr)
            continue
        motion = load_motion(path)
        if args.frames:
            motion = motion.slice_frames(0, min(args.frames, motion.num_frames))
        for name in args.characters:
            character = load_character(name)
            full, ik, lat = [], [], []
            for _ in range(args.runs):
                t0 = time.perf_counter()
                retarget(motion, character, progress=False, plant=not args.no_plant)
                full.append(motion.num_frames / (time.perf_counter() - t0))
                idx = map_motion(motion)
                contacts = detect_contacts(motion, idx)
                targets = build_targets(motion, idx, character, floor=contacts.floor)
                t0 = time.perf_counter()
                labels = None if args.no_plant else contacts.labels
                traj = solve_targets(targets, character, labels=labels, progress=False)
                ik.append(motion.num_frames / (time.perf_counter() - t0))
                lat.extend(traj.solver.latency[1:])
            lat_ms = np.array(lat) * 1000.0
            print(
                f"{clip:27s} {name:9s} {motion.num_frames:6d} {statistics.median(full):12.0f}"
                f" {statistics.median(ik):7.0f} {np.median(lat_ms):10.2f} {np.percentile(lat_ms, 99):10.2f}"
            )
    walk = DATA / "cmu_12_01_walk.bvh"
    if walk.exists():
        motion = load_motion(walk)
        for name in args.characters:
            lat = []
            for _ in range(args.runs):
                lat.extend(stream_motion(motion, load_character(name)).solver.latency[1:])
            lat_ms = np.array(lat) * 1000.0
            print(
                f"streaming {walk.name} onto {name}: latency median {np.median(lat_ms):.2f} ms,"
                f" p99 {np.percentile(lat_ms, 99):.2f} ms (first frame excluded)"
            )
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    print(f"peak memory (max RSS): {peak:.0f} MB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
