#!/usr/bin/env python3
"""Benchmark the BVH reader, forward kinematics and the BVH writer.

For each shared BVH recording (``../shared/data``) and for a synthetic
one-hour 120 Hz clip (432 000 frames, made at run time in a temporary folder
by repeating the rows of ``cmu_01_01_jumps.bvh``, or of the bundled example
when the shared data is absent; deleted afterwards), prints:

* read: :func:`physmocap.sources.bvh.read_bvh`;
* fk: ``motion.world_positions()`` of every frame (one call on the whole clip);
* fk/10s: the same in windows of 1200 frames (how a long clip should be walked);
* write: :func:`physmocap.export.bvh.write_bvh` with the source layout;

each as the median wall-clock time over ``--runs`` runs, frames per second, and
peak memory.  "traced MB" is the tracemalloc peak of the operation alone (every
numpy buffer and Python object it allocates; measured in a separate run);
"rss MB" is the peak resident size of a fresh process doing only that
operation (after reading the input, for fk and write, so at least the read's
peak), including the interpreter and imported libraries (about 90 MB).

Usage:  python scripts/bench_bvh.py [--runs 5] [--hour-runs 3] [--minutes 60] [--no-hour]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("PHYSMOCAP_SHARED_DATA", REPO.parent / "shared" / "data"))
CLIPS = ["cmu_01_01_jumps.bvh", "cmu_12_01_walk.bvh", "optitrack_hops_crouch.bvh", "pymo_walk.bvh"]
OPS = ("read", "fk", "fk/10s", "write")
WINDOW = 1200


def _maxrss_mb() -> float:
    """Peak resident size of this process.  Linux's VmHWM (reset by exec, unlike
    ru_maxrss, which a child inherits from a large parent); ru_maxrss elsewhere."""
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    scale = 1024.0 if sys.platform.startswith("linux") else 2**20  # KiB on Linux, bytes on macOS
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / scale


def _operation(op: str, path: Path, out_dir: Path):
    """(setup, run) for one operation on one file."""
    import numpy as np

    from physmocap.export.bvh import write_bvh
    from physmocap.motion import forward_kinematics
    from physmocap.sources.bvh import read_bvh

    state: dict = {}

    def setup() -> None:
        if op != "read":
            state["m"] = read_bvh(path)

    def run():
        if op == "read":
            return read_bvh(path)
        m = state["m"]
        if op == "fk":
            return m.world_positions()
        if op == "fk/10s":
            lowest = np.inf
            for s in range(0, m.num_frames, WINDOW):
                e = s + WINDOW
                pos, _ = forward_kinematics(m.skeleton, m.rotations[s:e], m.translations[s:e], m.translated)
                lowest = min(lowest, float(pos[..., 2].min()))
            return lowest
        if op == "write":
            return write_bvh(m, out_dir / "out.bvh")
        raise ValueError(op)

    return setup, run


def measure(op: str, path: Path, runs: int, out_dir: Path) -> dict:
    """Median time over ``runs`` runs, then one traced run for the memory peak."""
    setup, run = _operation(op, path, out_dir)
    setup()
    times = []
    for _ in range(runs):
        t = time.perf_counter()
        result = run()
        times.append(time.perf_counter() - t)
        del result
    tracemalloc.start()
    result = run()
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    del result
    return {"median_s": statistics.median(times), "traced_mb": peak / 2**20}


def child_main(op: str, path: str, out_dir: str) -> int:
    """A fresh process doing one operation once: its peak RSS."""
    setup, run = _operation(op, Path(path), Path(out_dir))
    setup()
    base = _maxrss_mb()
    run()
    print(json.dumps({"rss_mb": _maxrss_mb(), "base_rss_mb": base}))
    return 0


def rss_of(op: str, path: Path, out_dir: Path) -> float:
    res = subprocess.run(
        [sys.executable, __file__, "--child", op, str(path), str(out_dir)],
        capture_output=True, text=True, check=True,
    )
    return json.loads(res.stdout.strip().splitlines()[-1])["rss_mb"]


def make_long_clip(src: Path, dst: Path, frames: int) -> None:
    """Header of ``src`` with ``Frames: frames`` and its rows repeated cyclically."""
    text = src.read_bytes()
    head_end = text.index(b"\n", text.index(b"Frame Time")) + 1
    header = text[:head_end]
    rows = [r for r in text[head_end:].replace(b"\r\n", b"\n").split(b"\n") if r.strip()]
    start = header.index(b"Frames:")
    end = header.index(b"\n", start)
    header = header[:start] + f"Frames: {frames}".encode() + header[end:]
    block = b"\n".join(rows) + b"\n"
    with open(dst, "wb") as fh:
        fh.write(header)
        full, rest = divmod(frames, len(rows))
        for _ in range(full):
            fh.write(block)
        fh.write(b"\n".join(rows[:rest]) + (b"\n" if rest else b""))


def report(name: str, path: Path, runs: int, tmp: Path, with_rss: bool) -> None:
    import warnings

    from physmocap.errors import PhysmocapWarning
    from physmocap.sources.bvh import read_bvh

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PhysmocapWarning)
        m = read_bvh(path)
    F, J = m.num_frames, m.skeleton.num_joints
    C = sum(len(c) for c in m.meta["bvh_channels"].values())
    size = path.stat().st_size / 2**20
    print(f"\n{name}: {F} frames, {J} joints ({C} channels), {size:.1f} MB of text, "
          f"Motion arrays {(m.rotations.nbytes + m.translations.nbytes) / 2**20:.0f} MB")
    del m
    print(f"  {'op':8s} {'median s':>9s} {'frames/s':>11s} {'traced MB':>10s} {'rss MB':>8s}")
    for op in OPS:
        r = measure(op, path, runs, tmp)
        rss = f"{rss_of(op, path, tmp):8.0f}" if with_rss else f"{'-':>8s}"
        print(f"  {op:8s} {r['median_s']:9.3f} {F / r['median_s']:11.0f} {r['traced_mb']:10.1f} {rss}", flush=True)


def main() -> int:
    if len(sys.argv) > 1 and sys.argv[1] == "--child":
        return child_main(*sys.argv[2:5])
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=5, help="runs per operation on the shared files")
    ap.add_argument("--hour-runs", type=int, default=3, help="runs per operation on the long clip")
    ap.add_argument("--minutes", type=float, default=60.0, help="length of the synthetic clip at 120 Hz")
    ap.add_argument("--no-hour", action="store_true", help="skip the synthetic long clip")
    ap.add_argument("--no-rss", action="store_true", help="skip the per-operation subprocesses (peak RSS)")
    args = ap.parse_args()

    import numpy as np
    import scipy

    print(f"python {sys.version.split()[0]}, numpy {np.__version__}, scipy {scipy.__version__}; "
          f"median of {args.runs} runs ({args.hour_runs} on the long clip); one core")
    tmp = Path(tempfile.mkdtemp(prefix="physmocap-bench-bvh-"))
    try:
        sources = [DATA / c for c in CLIPS if (DATA / c).exists()]
        if not sources:
            print(f"(shared recordings not found in {DATA}; using the bundled example only)")
            from physmocap.resources import example_clip

            sources = [example_clip()]
        for path in sources:
            report(path.name, path, args.runs, tmp, not args.no_rss)
        if not args.no_hour:
            frames = int(round(args.minutes * 60 * 120))
            long_clip = tmp / "long.bvh"
            t = time.perf_counter()
            make_long_clip(sources[0], long_clip, frames)
            print(f"\n(made {long_clip.name} from {sources[0].name} in {time.perf_counter() - t:.1f} s)")
            report(f"synthetic {args.minutes:g} min at 120 Hz", long_clip, args.hour_runs, tmp, not args.no_rss)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
