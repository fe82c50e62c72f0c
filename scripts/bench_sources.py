#!/usr/bin/env python3
"""Benchmark the tracker and MCAP paths: reading, writing, gap filling, filtering.

Prints medians over ``--runs`` runs (wall-clock seconds and derived rates):

* MCAP write and read of each shared BVH clip (whole clip, all joints), and
  the file size per frame;
* a NITE 15-joint tracker stream made from the CMU walk (30 Hz), written as
  CSV, NPZ and JSON lines, read back through the whole positional pipeline
  (units, frame, gaps, levelling, floor, hierarchy);
* the gap policy and the One Euro filter on a long stream (``--frames``
  frames x 25 joints), and the per-frame cost of the streaming filter step.

Usage:  python scripts/bench_sources.py [--runs 5] [--frames 30000]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("PHYSMOCAP_SHARED_DATA", REPO.parent / "shared" / "data"))
CLIPS = ["cmu_12_01_walk.bvh", "pymo_walk.bvh", "cmu_01_01_jumps.bvh", "optitrack_hops_crouch.bvh"]


def median_time(fn, runs: int) -> float:
    times = []
    for _ in range(runs):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--frames", type=int, default=30000, help="length of the synthetic gap/filter stream")
    args = ap.parse_args()

    import warnings

    from physmocap.errors import PhysmocapWarning
    from physmocap.export.mcap import write_motion_mcap
    from physmocap.filters import OneEuroFilter, one_euro_filter
    from physmocap.sources import load_motion
    from physmocap.sources.gaps import fill_gaps
    from physmocap.sources.mcap import read_mcap
    from physmocap.sources.positions import read_positions
    from physmocap.sources.synth import tracker_stream, write_stream_csv, write_stream_jsonl, write_stream_npz

    warnings.simplefilter("ignore", PhysmocapWarning)
    tmp = Path(tempfile.mkdtemp(prefix="physmocap-bench-"))
    print(f"median of {args.runs} runs; python {sys.version.split()[0]}")

    print("\nMCAP (FrameTransforms + joint positions, JSON, zstd)")
    print(f"{'clip':28s} {'frames':>6s} {'joints':>6s} {'write s':>8s} {'read s':>8s} {'write f/s':>10s} "
          f"{'read f/s':>9s} {'bytes/frame':>11s}")  # fmt: skip
    for clip in CLIPS:
        path = DATA / clip
        if not path.exists():
            print(f"{clip:28s} (missing)")
            continue
        m = load_motion(path)
        out = tmp / (path.stem + ".mcap")
        tw = median_time(lambda: write_motion_mcap(m, out), args.runs)
        tr = median_time(lambda: read_mcap(out), args.runs)
        F = m.num_frames
        print(f"{clip:28s} {F:6d} {m.skeleton.num_joints:6d} {tw:8.3f} {tr:8.3f} {F / tw:10.0f} {F / tr:9.0f} "
              f"{out.stat().st_size / F:11.0f}")  # fmt: skip

    print("\nNITE stream from cmu_12_01_walk.bvh (30 Hz, 15 joints), full positional pipeline")
    walk = load_motion(DATA / "cmu_12_01_walk.bvh")
    stream = tracker_stream(walk)
    for suffix, writer in ((".csv", write_stream_csv), (".npz", write_stream_npz), (".jsonl", write_stream_jsonl)):
        p = writer(stream, tmp / f"nite{suffix}")
        t = median_time(lambda: read_positions(p), args.runs)
        print(f"  read {suffix:6s} {stream.num_frames} frames: {t * 1000:7.1f} ms  ({stream.num_frames / t:8.0f} frames/s)")

    F, J = args.frames, 25
    rng = np.random.default_rng(0)
    pos = rng.normal(size=(F, J, 3))
    miss = rng.random((F, J)) < 0.02
    pos[miss] = np.nan
    names = [f"j{k}" for k in range(J)]
    t = median_time(lambda: fill_gaps(pos, None, names, max_gap_frames=6), args.runs)
    print(f"\ngap policy, {F} frames x {J} joints, 2% missing: {t * 1000:.1f} ms ({F / t:.0f} frames/s)")
    clean = np.nan_to_num(pos)
    t = median_time(lambda: one_euro_filter(clean, fps=30.0), args.runs)
    print(f"One Euro filter (batch), {F} frames x {J} joints: {t * 1000:.1f} ms ({F / t:.0f} frames/s)")
    f = OneEuroFilter()
    steps = []
    for i in range(min(F, 5000)):
        t0 = time.perf_counter()
        f.step(clean[i], i / 30.0)
        steps.append(time.perf_counter() - t0)
    print(f"One Euro filter step (streaming, {J} joints): median {statistics.median(steps) * 1e6:.1f} us, "
          f"p99 {np.percentile(steps, 99) * 1e6:.1f} us")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
