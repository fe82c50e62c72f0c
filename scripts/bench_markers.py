#!/usr/bin/env python3
"""Marker solving speed on the CMU take (../shared/data/cmu_01_01_markers.c3d).

Times the calibration (functional joint centres, actor model, marker sites) and the per-frame
marker-driven IK separately, CPU time (one core: the process's) and wall time, medians of
``--runs`` runs, and prints the marker residuals.  Then the streaming solve
(:class:`physmocap.markers.stream.MarkerStream`): calibrated once on the first 10 s, then one
frame at a time over the whole take; latency per frame in wall time and in the thread's CPU
time (on a shared, loaded machine the wall time also holds the waits for a core: compare the
p99 of a plain NumPy loop printed alongside).

Usage:  python scripts/bench_markers.py [--runs 3] [--iterations 2]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
import warnings
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("PHYSMOCAP_SHARED_DATA", REPO.parent / "shared" / "data"))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--iterations", type=int, default=2, help="IK iterations per frame")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    from physmocap.markers.solve import MarkerSolveOptions, solve_markers
    from physmocap.sources.c3d import read_c3d_markers

    c3d = DATA / "cmu_01_01_markers.c3d"
    if not c3d.exists():
        print(f"skip: {c3d} not found", file=sys.stderr)
        return 0
    rec = read_c3d_markers(c3d)
    cpu, wall, total_cpu, lat = [], [], [], []
    rep = None
    for _ in range(args.runs):
        c0 = time.process_time()
        sol = solve_markers(rec, options=MarkerSolveOptions(max_iterations=args.iterations))
        total_cpu.append(time.process_time() - c0)
        cpu.append(rec.num_frames / sol.cpu_seconds)
        wall.append(rec.num_frames / sol.wall_seconds)
        lat.append(sol.trajectory.solver.latency)
        rep = sol.report()
    import numpy as np

    L = np.concatenate(lat) * 1000
    F = rec.num_frames
    print(f"{F} frames, {len(rec.labels)} markers, {args.iterations} IK iterations per frame, median of {args.runs} runs")
    print(f"per-frame solve: {statistics.median(cpu):.0f} frames/s CPU, {statistics.median(wall):.0f} frames/s wall; "
          f"latency median {np.median(L):.2f} ms, p99 {np.percentile(L, 99):.2f} ms (wall)")
    print(f"whole solve incl. calibration: {statistics.median(total_cpu):.2f} s CPU "
          f"({F / statistics.median(total_cpu):.0f} frames/s)")
    o = rep["overall"]
    print(f"marker residual RMS {o['rms_mm']:.1f} mm, max {o['max_mm']:.0f} mm; relaxed frames {rep['solver']['relaxed_frames']}")
    stream_bench(rec)
    return 0


def stream_bench(rec) -> None:
    """Streaming latency (wall and CPU per frame) on the take, calibrated on its first 10 s."""
    import numpy as np

    from physmocap.markers.stream import MarkerStream, calibration_slice

    t0 = time.perf_counter()
    stream = MarkerStream.calibrate(calibration_slice(rec, 10.0))
    calib = time.perf_counter() - t0
    wall, cpu = [], []
    for t in range(rec.num_frames):
        w, c = time.perf_counter(), time.thread_time()
        stream.step(rec.positions[t])
        wall.append(time.perf_counter() - w)
        cpu.append(time.thread_time() - c)
    W, C = np.array(wall[1:]) * 1000, np.array(cpu[1:]) * 1000
    a = np.random.default_rng(0).random((50, 50))
    noise = []
    for _ in range(2000):  # the machine's own jitter: a fixed NumPy workload of about 0.1 ms
        w = time.perf_counter()
        for _ in range(20):
            a @ a
        noise.append(time.perf_counter() - w)
    N = np.array(noise) * 1000
    print(f"streaming (calibrated on the first 10 s in {calib:.1f} s): latency median {np.median(W):.2f} ms, "
          f"p99 {np.percentile(W, 99):.2f} ms wall; CPU median {np.median(C):.2f} ms, p99 {np.percentile(C, 99):.2f} ms; "
          f"first frame {wall[0] * 1000:.0f} ms")
    print(f"machine jitter: a {np.median(N):.2f} ms NumPy loop has p99 {np.percentile(N, 99):.2f} ms wall")


if __name__ == "__main__":
    sys.exit(main())
