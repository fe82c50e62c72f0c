#!/usr/bin/env python3
"""Dataset-scale throughput of `physmocap batch`: every BVH in ../shared/data, repeated (as
links) until at least 10,000 frames, retargeted with 1 and then 2 worker processes.

Prints frames per second overall and per core, and the speed-up from 1 to 2 workers (close
to 2x on an idle 2-core machine; less when other work shares the cores).

Usage:  python scripts/bench_batch.py [--min-frames 10000] [--workers 1 2]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("PHYSMOCAP_SHARED_DATA", REPO.parent / "shared" / "data"))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--min-frames", type=int, default=10000)
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    args = ap.parse_args()
    from physmocap.batch import plan, run_batch
    from physmocap.sources.bvh import read_bvh

    clips = sorted(DATA.glob("*.bvh"))
    if not clips:
        print(f"skip: no BVH in {DATA}", file=sys.stderr)
        return 0
    frames = {c: read_bvh(c).num_frames for c in clips}
    with tempfile.TemporaryDirectory() as tmp:
        src = Path(tmp) / "in"
        src.mkdir()
        total, k = 0, 0
        while total < args.min_frames:
            for c in clips:
                (src / f"{k:03d}_{c.name}").symlink_to(c)
                total += frames[c]
            k += 1
        print(f"{len(list(src.iterdir()))} files, {total} source frames")
        base = None
        for w in args.workers:
            out = Path(tmp) / f"out{w}"
            jobs = plan(str(src), out, ".npz")
            options = {k: None for k in ("character", "map", "profile", "source_map", "in_units", "start", "end", "fps",
                                         "max_iterations", "contacts")}
            options.update(no_floor=False, no_velocity_limits=False, no_plant=False, up="Y", units="m")
            t0 = time.perf_counter()
            results = run_batch(jobs, out, options, workers=w, progress=False)
            dt = time.perf_counter() - t0
            done = sum(r.frames for r in results if r.status == "done")
            rate = done / dt
            base = base or rate
            print(f"{w} worker(s): {rate:.0f} frames/s overall, {rate / w:.0f} per core, speed-up {rate / base:.2f}x "
                  f"({dt:.1f} s wall, {sum(r.status == 'failed' for r in results)} failed)", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
