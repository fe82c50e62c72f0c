#!/usr/bin/env python3
"""Preview rendering speed: frames per second (CPU and wall time) and peak memory.

Retargets the bundled example once, then renders N frames at the given size
offscreen (mujoco.Renderer, EGL or OSMesa) three times and prints the median
rate, plus the rate of a full MP4 encode (imageio-ffmpeg) of the same frames;
without and with ``--antialias``.  CPU rates count every thread and the ffmpeg
child process: the rate one core would reach.
Rates drift up to 2x on this machine between minutes: compare ratios measured
in one run.

Usage:  python scripts/bench_render.py [--size 640x480] [--frames 300]
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import sys
import tempfile
import time
import warnings
from pathlib import Path


def _cpu() -> float:
    """CPU seconds of this process (Mesa's render threads included) and of its finished
    children (the ffmpeg encoder): the time one core would need."""
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--size", default="640x480")
    ap.add_argument("--frames", type=int, default=300)
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    from physmocap import load_motion, retarget
    from physmocap.render.backend import ensure_backend
    from physmocap.render.output import write_video
    from physmocap.render.scene import PreviewOptions, PreviewScene, parse_size
    from physmocap.render.source import preview_input

    print(f"backend {ensure_backend()}", file=sys.stderr)
    traj = retarget(load_motion("example"), end=args.frames + 1, progress=False)
    w, h = parse_size(args.size)
    n = traj.num_frames
    inp = preview_input(traj)
    for antialias in (False, True):
        with PreviewScene(traj, inp.skeleton, inp.contacts, PreviewOptions(width=w, height=h, antialias=antialias)) as scene:
            runs = []
            for _ in range(3):
                c0, w0 = _cpu(), time.perf_counter()
                for t in range(n):
                    scene.render(t)
                runs.append((n / (_cpu() - c0), n / (time.perf_counter() - w0)))
            print(f"render {w}x{h}{' --antialias' if antialias else ''}: {statistics.median(r[0] for r in runs):.0f} "
                  f"frames/s CPU, {statistics.median(r[1] for r in runs):.0f} frames/s wall (median of 3, {n} frames)")
            with tempfile.TemporaryDirectory() as tmp:
                c0, w0 = _cpu(), time.perf_counter()
                write_video(scene, range(n), Path(tmp) / "b.mp4", traj.fps, 0, False)
                print(f"  + MP4 encode: {n / (_cpu() - c0):.0f} frames/s CPU (ffmpeg's included), "
                      f"{n / (time.perf_counter() - w0):.0f} frames/s wall")
    print(f"peak memory {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MiB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
