#!/usr/bin/env python3
"""Marker solving speed on the CMU take (../shared/data/cmu_01_01_markers.c3d).

Times the calibration (functional joint centres, actor model, marker sites) and the per-frame
marker-driven IK separately, CPU time (one core: the process's) and wall time, medians of
``--runs`` runs, and prints the marker residuals.

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
    return 0


if __name__ == "__main__":
    sys.exit(main())
