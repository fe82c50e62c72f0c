#!/usr/bin/env python3
"""Peak memory of a long retarget, end to end, and where it goes.

Builds long BVH clips from a shared clip played forwards then backwards (ping-pong: every
seam is continuous, so the clip is a plausible long take, not a sequence of jumps), of 1, 5
and 15 minutes by default (``--minutes 60`` for the hour), and for each runs the real
command line in a fresh process::

    physmocap retarget long.bvh -o out.bvh --qpos out.npz --quiet

(read, retarget with the default humanoid and every constraint, write BVH and NPZ) and reports
its peak resident set size (``os.wait4``'s ``ru_maxrss`` of that process alone).  The growth
per frame is the slope between the two longest clips; ``--extrapolate`` prints the hour from it.

``--breakdown`` retargets the shortest clip in this process and prints the bytes per frame
held by each structure of the result (motion, targets and what they carry, contact labels,
trajectory, solver statistics, fidelity) and the peak of each writer (``tracemalloc``, which
numpy reports its buffers to), per frame.

``--stages`` runs the command on the shortest clip in this process and prints the peak of each
stage (``tracemalloc``, sampled every few milliseconds and filed under the functions the main
thread is in), in bytes per frame.

``--rss-stages`` instead runs the command on each clip in a fresh process that samples its own
resident set size (``/proc/self/statm``) every 20 ms and prints the peak of each stage in MB
(what the system sees, spilled pages included while they are mapped); with ``--stub-solve`` the
per-frame IK solve returns the model's ``qpos0`` at once, which leaves every array and stage as
it is (the solve itself holds a constant few MB) and makes an hour measurable in minutes.

``--identity REF_DIR`` instead retargets every shared BVH clip with the checkout ``REF_DIR``
(``PYTHONPATH=REF_DIR``) and with this one, and compares the BVH and NPZ files byte for byte.

Usage:  python scripts/bench_memory.py [--minutes 1 5 15] [--clip cmu_12_01_walk.bvh] [--breakdown] [--stages]
        python scripts/bench_memory.py --minutes 60 --rss-stages --stub-solve
        python scripts/bench_memory.py --identity ../main
"""

from __future__ import annotations

import argparse
import filecmp
import os
import subprocess
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("PHYSMOCAP_SHARED_DATA", REPO.parent / "shared" / "data"))
MB = 1024.0 * 1024.0


def ping_pong_bvh(src: Path, frames: int, out: Path) -> int:
    """Write ``out``: ``src``'s header and ``frames`` motion rows, frames 1..F-1 of ``src``
    played forwards, backwards, forwards... (frame 0 is skipped: CMU clips start with a
    reference pose).  Returns the number of frames written."""
    lines = src.read_text(encoding="utf-8").splitlines()
    at = next(i for i, ln in enumerate(lines) if ln.strip().lower().startswith("frames:"))
    rows = [ln for ln in lines[at + 2 :] if ln.strip()]
    cycle = rows[1:] + rows[-2:1:-1]  # 1..F-1, then F-2..2: no frame repeated at a seam
    with out.open("w", encoding="utf-8", newline="\n") as fh:
        fh.write("\n".join(lines[:at]) + "\n")
        fh.write(f"Frames: {frames}\n{lines[at + 1].strip()}\n")
        for k in range(frames):
            fh.write(cycle[k % len(cycle)] + "\n")
    return frames


def frame_rate(src: Path) -> float:
    """Frames per second of a BVH file (its ``Frame Time`` line)."""
    for ln in src.read_text(encoding="utf-8").splitlines():
        if ln.strip().lower().startswith("frame time:"):
            return 1.0 / float(ln.split(":", 1)[1])
    raise ValueError(f"{src}: no Frame Time line")


def peak_rss_mb(argv: list[str]) -> tuple[float, float]:
    """Run ``argv`` in a new process; its peak RSS (MB) and wall time (s)."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    proc.returncode = os.waitstatus_to_exitcode(status)
    err = proc.stderr.read().decode(errors="replace") if proc.stderr else ""
    if proc.returncode != 0:
        raise SystemExit(f"{' '.join(argv)} failed ({proc.returncode}):\n{err}")
    return usage.ru_maxrss / 1024.0, wall  # ru_maxrss is in KiB on Linux


def baseline_mb() -> float:
    """Peak RSS of a process that only imports what the retarget imports and loads the humanoid."""
    code = ("import warnings; warnings.simplefilter('ignore'); import physmocap.cli.retarget, physmocap.ik.retarget, "
            "physmocap.export.character_bvh, physmocap.export.trajectory; "
            "from physmocap.models import load_character; load_character(None)")
    return peak_rss_mb([sys.executable, "-c", code])[0]


def cli_run(clip: Path, tmp: Path) -> tuple[float, float]:
    """Peak RSS (MB) and wall time of ``physmocap retarget clip -o out.bvh --qpos out.npz``."""
    argv = [sys.executable, "-m", "physmocap", "retarget", str(clip), "-o", str(tmp / "out.bvh"),
            "--qpos", str(tmp / "out.npz"), "--quiet"]
    return peak_rss_mb(argv)


def array_bytes(obj, seen: set[int] | None = None, depth: int = 0) -> int:
    """Bytes of the numpy arrays reachable from ``obj`` (dataclasses, dicts, lists), each once;
    an array spilled to a temporary file (:mod:`physmocap.spill`) counts nothing: its pages
    are on disk and in the page cache, not the process's own memory."""
    from physmocap.spill import is_spilled

    seen = set() if seen is None else seen
    if id(obj) in seen or depth > 6:
        return 0
    seen.add(id(obj))
    if isinstance(obj, np.ndarray) and is_spilled(obj):
        return 0
    if isinstance(obj, np.ndarray):
        base = obj if obj.base is None else obj.base
        if isinstance(base, np.ndarray) and base is not obj:
            return array_bytes(base, seen, depth + 1)
        return int(obj.nbytes)
    if isinstance(obj, dict):
        return sum(array_bytes(v, seen, depth + 1) for v in obj.values())
    if isinstance(obj, (list, tuple)):
        return sum(array_bytes(v, seen, depth + 1) for v in obj)
    if hasattr(obj, "__dataclass_fields__"):
        return sum(array_bytes(getattr(obj, f), seen, depth + 1) for f in obj.__dataclass_fields__)
    return 0


def traced_peak(fn) -> tuple[object, int]:
    """``fn()``'s result and the peak of the memory it allocated (bytes, tracemalloc)."""
    tracemalloc.start()
    tracemalloc.reset_peak()
    base = tracemalloc.get_traced_memory()[0]
    try:
        result = fn()
        peak = tracemalloc.get_traced_memory()[1] - base
    finally:
        tracemalloc.stop()
    return result, peak


def breakdown(clip: Path, tmp: Path) -> None:
    """Bytes per frame of each structure a retarget keeps, and each stage's peak per frame."""
    import warnings

    warnings.simplefilter("ignore")
    from physmocap.export.character_bvh import write_character_bvh
    from physmocap.export.trajectory import write_trajectory_npz
    from physmocap.ik.retarget import retarget
    from physmocap.models import load_character
    from physmocap.sources import load_motion

    character = load_character(None)
    motion, read_peak = traced_peak(lambda: load_motion(str(clip), min_frames=1))
    t0 = time.perf_counter()
    traj = retarget(motion, character, progress=False)
    wall = time.perf_counter() - t0
    F = traj.num_frames
    seen: set[int] = set()
    rows = [("read (peak of load_motion)", read_peak)]
    kept = [("source motion", traj.source_motion), ("trajectory qpos", traj.qpos), ("solver stats", traj.solver),
            ("contact labels", traj.contacts), ("fidelity", traj.fidelity)]
    targets = traj.targets
    kept += [(f"targets.info[{k!r}]", v) for k, v in sorted(targets.info.items())]  # raw positions first: shared
    held = {name: getattr(targets, name) for name in targets.__dataclass_fields__ if name not in ("info", "source_positions")}
    held["source_positions"] = targets.__dict__.get("_source_positions")  # None once let go (read: recomputed)
    kept += [(f"targets.{name}", value) for name, value in held.items()]
    for name, obj in kept:
        nbytes = array_bytes(obj, seen)
        if nbytes >= F:  # a few bytes per frame at least: the per-frame structures
            rows.append((name, nbytes))
    _, bvh_peak = traced_peak(lambda: write_character_bvh(traj, tmp / "b.bvh"))
    _, npz_peak = traced_peak(lambda: write_trajectory_npz(traj, tmp / "b.npz"))
    rows += [("write BVH (peak)", bvh_peak), ("write NPZ (peak)", npz_peak)]
    print(f"\nbreakdown on {F} frames ({wall:.0f} s to retarget): bytes per frame")
    for name, nbytes in rows:
        print(f"  {name:40s} {nbytes / F:10.1f}")
    held = sum(b for n, b in rows if "peak" not in n)
    print(f"  {'held after retargeting (sum)':40s} {held / F:10.1f}")


def _stage(frame, depth: int) -> str:
    """The physmocap functions on a thread's stack, outermost first, below the command's own
    two (``main``, ``run``), ``depth`` of them: ``retarget.retarget > targets.build_targets``."""
    names = []
    while frame is not None:
        code = frame.f_code
        if f"{os.sep}physmocap{os.sep}" in code.co_filename:
            names.append(f"{Path(code.co_filename).stem}.{code.co_name}")
        frame = frame.f_back
    return " > ".join(reversed(names[:-2][-depth:])) if len(names) > 2 else "-"


def stages(clip: Path, frames: int, tmp: Path, depth: int = 3, every: float = 0.003) -> None:
    """Run the command on ``clip`` (``frames`` frames) in this process and print the peak of each stage
    (``tracemalloc``: what Python and numpy allocate), in MB and in bytes per frame above
    what was traced before the clip was read.  A thread samples the peak every ``every``
    seconds and files it under the stage the main thread is in (:func:`_stage`); block-sized
    temporaries are a constant, so their bytes per frame shrink on longer clips."""
    import importlib
    import threading

    for module in ("physmocap.ik.retarget", "physmocap.export.character_bvh", "physmocap.export.trajectory"):
        importlib.import_module(module)  # imported before tracing: not the clip's memory
    importlib.import_module("physmocap.cli")

    main_thread = threading.get_ident()
    peaks: dict[str, float] = {}
    order: list[str] = []
    done = threading.Event()

    def sample() -> None:
        while not done.wait(every):
            _, peak = tracemalloc.get_traced_memory()
            tracemalloc.reset_peak()
            key = _stage(sys._current_frames().get(main_thread), depth)
            if key not in peaks:
                order.append(key)
            peaks[key] = max(peaks.get(key, 0.0), peak)

    argv = ["retarget", str(clip), "-o", str(tmp / "s.bvh"), "--qpos", str(tmp / "s.npz"), "--quiet"]
    tracemalloc.start()
    base = tracemalloc.get_traced_memory()[0]
    try:
        _run_sampled(argv, sample, done)
    finally:
        tracemalloc.stop()
    print(f"\nstages on {frames} frames: peak traced MB, and bytes per frame above the start")
    for key in order:
        if "<module>" not in key and peaks[key] - base > 0.05 * frames * 1000:  # imports, small stages: skipped
            print(f"  {peaks[key] / MB:7.1f} MB {(peaks[key] - base) / frames:8.0f} B/frame  {key}")


def _run_sampled(argv: list[str], sample, done) -> None:
    """Run ``physmocap argv`` in this process while ``sample`` runs in a thread; ``done`` (a
    ``threading.Event`` that ``sample`` waits on) is set when the command ends."""
    import threading

    from physmocap.cli import main as cli_main

    thread = threading.Thread(target=sample, daemon=True)
    thread.start()
    try:
        cli_main(argv)
    finally:
        done.set()
        thread.join()


def _rss_stage_worker(argv: list[str], stub: bool, every: float = 0.02) -> None:
    """In a fresh process: run ``physmocap argv`` while a thread samples this process's RSS
    every ``every`` seconds, filed under the stage the main thread is in (:func:`_stage`);
    print each stage's peak (MB), then the process's VmHWM.  ``stub``: the per-frame solve
    returns ``qpos0`` (see the module docstring)."""
    import threading

    import physmocap.ik.frame as frame_mod

    if stub:
        def solve(self, positions, orientations, valid, labels=None, guide=None):
            self.frame += 1
            return frame_mod.FrameResult(np.array(self.character.model.qpos0), 1, 0, 0.0)

        frame_mod.FrameRetargeter.solve = solve
    main_thread, page = threading.get_ident(), os.sysconf("SC_PAGE_SIZE")
    peaks: dict[str, int] = {}
    done = threading.Event()

    def sample() -> None:
        with open("/proc/self/statm", encoding="ascii") as fh:
            while not done.wait(every):
                fh.seek(0)
                rss = int(fh.read().split()[1]) * page
                key = _stage(sys._current_frames().get(main_thread), 3)
                peaks[key] = max(peaks.get(key, 0), rss)

    _run_sampled(argv, sample, done)
    for key, peak in peaks.items():
        if "<module>" not in key:
            print(f"  {peak / MB:7.0f} MB  {key}")
    with open("/proc/self/status", encoding="ascii") as fh:
        print(next(line for line in fh if line.startswith("VmHWM")).strip())


def rss_stages(clip: Path, tmp: Path, stub: bool) -> None:
    """Peak RSS of each stage of ``physmocap retarget clip`` in a fresh process (:func:`_rss_stage_worker`)."""
    argv = [sys.executable, str(Path(__file__).resolve()), "--rss-worker", str(clip), str(tmp)] + (["--stub-solve"] if stub else [])
    print(f"\nresident memory by stage of {clip.name}{' (solve stubbed)' if stub else ''}:", flush=True)
    subprocess.run(argv, check=True)


def retarget_with(checkout: Path, clip: Path, out: Path) -> None:
    """``physmocap retarget clip -o out.bvh --qpos out.npz`` with ``PYTHONPATH=checkout``."""
    env = dict(os.environ, PYTHONPATH=str(checkout))
    argv = [sys.executable, "-m", "physmocap", "retarget", str(clip), "-o", str(out.with_suffix(".bvh")),
            "--qpos", str(out.with_suffix(".npz")), "--quiet"]
    subprocess.run(argv, env=env, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


def identity(ref: Path) -> int:
    """Compare this checkout's BVH and NPZ outputs with ``ref``'s on every shared BVH clip;
    0 if every file is byte-identical."""
    clips = sorted(DATA.glob("*.bvh"))
    differ = 0
    with tempfile.TemporaryDirectory() as tmpdir:
        tmp = Path(tmpdir)
        (tmp / "ref").mkdir()
        (tmp / "ours").mkdir()
        for clip in clips:
            retarget_with(ref.resolve(), clip, tmp / "ref" / clip.stem)
            retarget_with(REPO, clip, tmp / "ours" / clip.stem)
            same = {s: filecmp.cmp(tmp / "ref" / (clip.stem + s), tmp / "ours" / (clip.stem + s), shallow=False)
                    for s in (".bvh", ".npz")}
            differ += not all(same.values())
            print(f"{clip.name:28s} " + "  ".join(f"{s[1:]} {'identical' if v else 'DIFFERENT'}" for s, v in same.items()),
                  flush=True)
    return 1 if differ else 0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--minutes", type=float, nargs="+", default=[1.0, 5.0, 15.0])
    ap.add_argument("--clip", default="cmu_12_01_walk.bvh", help="shared clip to loop (default: the CMU walk)")
    ap.add_argument("--breakdown", action="store_true", help="also print bytes per frame by structure (shortest clip)")
    ap.add_argument("--stages", action="store_true",
                    help="also print the traced peak of each stage of the command (shortest clip, in this process)")
    ap.add_argument("--extrapolate", type=float, default=60.0, metavar="MIN",
                    help="print the peak extrapolated to this many minutes (default 60)")
    ap.add_argument("--rss-stages", action="store_true",
                    help="instead print the peak RSS of each stage of the command and its VmHWM (each clip, a fresh process)")
    ap.add_argument("--stub-solve", action="store_true",
                    help="with --rss-stages: the per-frame solve returns qpos0 (every array and stage as it is)")
    ap.add_argument("--identity", type=Path, metavar="REF_DIR",
                    help="compare outputs on every shared clip with the checkout REF_DIR, byte for byte")
    ap.add_argument("--rss-worker", nargs=2, metavar=("CLIP", "OUTDIR"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.rss_worker is not None:
        import warnings

        warnings.simplefilter("ignore")
        clip, out = (Path(a) for a in args.rss_worker)
        _rss_stage_worker(["retarget", str(clip), "-o", str(out / "r.bvh"), "--qpos", str(out / "r.npz"), "--quiet"],
                          args.stub_solve)
        return 0
    if args.identity is not None:
        return identity(args.identity)
    src = DATA / args.clip
    if not src.exists():
        print(f"skip: {src} not found", file=sys.stderr)
        return 0
    fps = frame_rate(src)
    import physmocap

    print(f"physmocap from {Path(physmocap.__file__).parent.parent}; clip {args.clip} ping-ponged at {fps:.0f} Hz")
    base = baseline_mb()
    print(f"baseline (imports + humanoid): {base:.0f} MB")
    points: list[tuple[int, float]] = []
    with tempfile.TemporaryDirectory() as tmpdir:
        tmp = Path(tmpdir)
        for minutes in sorted(args.minutes):
            frames = int(round(minutes * 60.0 * fps))
            clip = tmp / f"long_{minutes:g}min.bvh"
            ping_pong_bvh(src, frames, clip)
            if args.rss_stages:
                rss_stages(clip, tmp, args.stub_solve)
                clip.unlink()
                continue
            peak, wall = cli_run(clip, tmp)
            points.append((frames, peak))
            print(f"{minutes:6g} min {frames:8d} frames: peak RSS {peak:7.0f} MB "
                  f"({(peak - base) * MB / frames:6.0f} B/frame over the baseline), {wall:.0f} s", flush=True)
            clip.unlink()
        if len(points) >= 2:
            (f0, m0), (f1, m1) = points[-2], points[-1]  # the two longest: the long-clip regime
            slope = (m1 - m0) * MB / (f1 - f0)
            target = args.extrapolate * 60.0 * fps
            print(f"growth {slope:.0f} B/frame between {f0} and {f1} frames; "
                  f"{args.extrapolate:g} min ({target:.0f} frames) extrapolates to "
                  f"{m1 + slope * (target - f1) / MB:.0f} MB")
        if args.breakdown or args.stages:
            frames = int(round(min(args.minutes) * 60.0 * fps))
            clip = tmp / "breakdown.bvh"
            ping_pong_bvh(src, frames, clip)
            if args.stages:
                stages(clip, frames, tmp)
            if args.breakdown:
                breakdown(clip, tmp)
    return 0


if __name__ == "__main__":
    sys.exit(main())
