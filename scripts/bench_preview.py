#!/usr/bin/env python3
"""Benchmark ``physmocap preview`` rendering: frames per second and memory.

Retargets ``cmu_12_01_walk.bvh`` (or the bundled example when ../shared is
absent) once, untimed, then for each of ``--runs`` runs, back to back:

* render: :meth:`ClipRenderer.frame` of ``--frames`` frames at ``--size``
  (character, source skeleton beside it, floor grid, caption);
* mp4: the same frames streamed to the H.264 encoder (``write_preview``);
* sheet: an 8-frame PNG contact sheet (16 tiles of 240x320).

It prints the median frames per second by wall time and by CPU time (this
process, llvmpipe's render threads and the ffmpeg child process together:
the rate one core would reach), and the resident memory after a short and after a long MP4 (the
clip repeated ``--long`` times): streamed frames keep it flat.  The machine's
speed drifts: compare figures from one run only.

Usage:  python scripts/bench_preview.py [--runs 3] [--frames 300] [--size 640x480] [--long 8]
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("PHYSMOCAP_SHARED_DATA", REPO.parent / "shared" / "data"))


def _rss_mb() -> float:
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    return float("nan")


def _cpu() -> float:
    """CPU seconds of this process and its finished children (the ffmpeg encoder)."""
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def _timed(fn) -> tuple[float, float]:
    w, c = time.perf_counter(), _cpu()
    fn()
    return time.perf_counter() - w, _cpu() - c


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--size", default="640x480")
    ap.add_argument("--long", type=int, default=8, help="repeat the clip this many times for the memory check")
    args = ap.parse_args()
    from physmocap.models import load_character
    from physmocap.preview.clip import retarget_clip
    from physmocap.preview.output import write_preview
    from physmocap.preview.render import ClipRenderer, RenderOptions
    from physmocap.sources import load_motion

    clip_path = DATA / "cmu_12_01_walk.bvh"
    motion = load_motion(clip_path if clip_path.exists() else "example")
    clip = retarget_clip(motion, load_character(None), progress=False)
    n = min(args.frames, clip.num_frames)
    short = clip.take(np.arange(n))
    w, h = (int(v) for v in args.size.split("x"))
    options = RenderOptions(width=w, height=h)
    results: dict[str, list[tuple[float, float]]] = {"render": [], "mp4": [], "sheet": []}
    with tempfile.TemporaryDirectory() as tmp, ClipRenderer(short, options) as renderer:
        renderer.frame(0)  # warm up the GL context
        for _ in range(args.runs):
            results["render"].append(_timed(lambda: [renderer.frame(i) for i in range(n)]))
            results["mp4"].append(_timed(lambda: write_preview(short, Path(tmp) / "a.mp4", options, fps=short.trajectory.fps, progress=False)))
            results["sheet"].append(_timed(lambda: write_preview(short, Path(tmp) / "a.png", progress=False)))
        rss_short = _rss_mb()
        long = clip.take(np.tile(np.arange(n), args.long))
        wall_long, _ = _timed(lambda: write_preview(long, Path(tmp) / "b.mp4", options, fps=long.trajectory.fps, progress=False))
        rss_long = _rss_mb()
    frames = {"render": n, "mp4": n, "sheet": 16}
    print(f"clip: {motion.source.name if hasattr(motion.source, 'name') else motion.source}, {n} frames, {args.size}, {args.runs} runs")
    print(f"{'operation':10s} {'fps (wall)':>11s} {'fps (cpu)':>10s}")  # cpu: one core's rate
    for op, runs in results.items():
        wall = statistics.median(frames[op] / r[0] for r in runs)
        cpu = statistics.median(frames[op] / r[1] for r in runs)
        print(f"{op:10s} {wall:11.1f} {cpu:10.1f}" + ("   (tiles per second)" if op == "sheet" else ""))
    print(f"resident memory after {n} frames to MP4: {rss_short:.0f} MB; after {n * args.long} frames "
          f"({n * args.long / clip.trajectory.fps:.0f} s of motion, {wall_long:.0f} s): {rss_long:.0f} MB")


if __name__ == "__main__":
    main()
