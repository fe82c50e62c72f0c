#!/usr/bin/env python3
"""Benchmark retargeting: frames per second, per-frame latency, peak memory.

For each shared BVH clip (../shared/data) and each bundled character:

* **retarget fps**: the whole of :func:`physmocap.ik.retarget.retarget` on an
  already-read motion (name mapping, contact detection, targets, per-frame IK
  with planting), i.e. everything but file reading (metrics.md's throughput);
* **IK fps** and **per-frame latency** (median, p99): the per-frame loop alone
  (:func:`physmocap.ik.retarget.solve_targets` with the contacts);

each the median of ``--runs`` runs, in frames per second of CPU time
(``time.process_time``: what one core does, whatever the other processes on the
machine) and of wall time.  The runs are interleaved (every clip and character
once, then again), so that a slow spell of the machine spreads over all of them.
Peak memory is the process's maximum resident set size at the end (ru_maxrss).
Also prints the streaming retargeter's latency on the CMU walk (with ``--compare``, the
reference's too, run by run alternating, and the ratios of the medians and the p99s).

``--compare REF_DIR`` runs the same benchmark on another checkout (``REF_DIR``,
e.g. the main branch) in a subprocess with ``PYTHONPATH=REF_DIR``, run by run
alternating with this one, and prints both and the ratio (this / reference) of
the median retarget CPU fps.  With ``--fresh`` this checkout runs in fresh subprocesses
too, each after ``--warmup`` untimed frames, so that both sides pay the same (the fair
comparison; without it this checkout runs in the benchmark's own, warmed-up process).

A character is a bundled name (``humanoid``, ``robot``) or an MJCF path (e.g.
``../shared/robots/unitree_g1/g1_mocap_29dof.xml``).

Usage:  python scripts/bench_retarget.py [--runs 5] [--frames N] [--characters humanoid robot]
        [--clips cmu_12_01_walk.bvh] [--no-plant] [--compare ../main [--fresh]] [--set second_order_correction=true]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("PHYSMOCAP_SHARED_DATA", REPO.parent / "shared" / "data"))
CLIPS = ["cmu_12_01_walk.bvh", "pymo_walk.bvh", "cmu_01_01_jumps.bvh", "optitrack_hops_crouch.bvh"]


def _measure(clip: str, character: str, frames: int | None, plant: bool, options: dict | None = None,
             warmup: int = 0) -> dict[str, float]:
    """One run: retarget ``clip`` onto ``character`` (with flat retarget ``options``); CPU and
    wall frames/s, IK latencies.  ``warmup``: first retarget that many frames, untimed (the
    lazy imports and caches a fresh process fills on its first frames)."""
    from physmocap.ik.config import RetargetConfig
    from physmocap.ik.contacts import detect_contacts
    from physmocap.ik.retarget import map_motion, retarget, solve_targets
    from physmocap.ik.targets import build_targets
    from physmocap.models import load_character
    from physmocap.sources import load_motion

    motion = load_motion(DATA / clip)
    if frames:
        motion = motion.slice_frames(0, min(frames, motion.num_frames))
    ch = load_character(character)
    config = RetargetConfig().with_options(**(options or {}))
    if warmup:
        retarget(motion.slice_frames(0, min(warmup, motion.num_frames)), ch, config, progress=False, plant=plant)
    c0, w0 = time.process_time(), time.perf_counter()
    retarget(motion, ch, config, progress=False, plant=plant)
    cpu, wall = time.process_time() - c0, time.perf_counter() - w0
    idx = map_motion(motion)
    contacts = detect_contacts(motion, idx)
    targets = build_targets(motion, idx, ch, floor=contacts.floor)
    c0 = time.process_time()
    traj = solve_targets(targets, ch, config.solver, labels=contacts.labels if plant else None, progress=False)
    ik_cpu = time.process_time() - c0
    lat = np.asarray(traj.solver.latency[1:]) * 1000.0
    n = motion.num_frames
    return {
        "frames": n,
        "cpu_fps": n / cpu,
        "wall_fps": n / wall,
        "ik_cpu_fps": n / ik_cpu,
        "lat_med": float(np.median(lat)),
        "lat_p99": float(np.percentile(lat, 99)),
    }


def _stream_latencies(clip: str, character: str) -> list[float]:
    """Per-frame latencies (ms, wall) of streaming ``clip`` onto ``character``, the first frame
    (the calibration) excluded."""
    from physmocap.ik.stream import stream_motion
    from physmocap.models import load_character
    from physmocap.sources import load_motion

    return [1000.0 * t for t in stream_motion(load_motion(DATA / clip), load_character(character)).solver.latency[1:]]


def _stream_worker() -> int:
    """``--stream-worker CLIP CHARACTER``: one stream's latencies, printed as JSON (for ``--compare``)."""
    warnings.simplefilter("ignore")
    print(json.dumps(_stream_latencies(sys.argv[2], sys.argv[3])))
    return 0


def _subprocess_stream(ref: Path, clip: str, character: str) -> list[float]:
    """:func:`_stream_latencies` in a fresh process with ``PYTHONPATH=ref`` (a checkout)."""
    env = dict(os.environ, PYTHONPATH=str(ref))
    out = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--stream-worker", clip, character],
                         env=env, check=True, capture_output=True, text=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def _worker() -> int:
    """``--worker CLIP CHARACTER FRAMES PLANT WARMUP [OPTIONS_JSON]``: one run, printed as JSON
    (for ``--compare``)."""
    clip, character, frames, plant, warmup = sys.argv[2:7]
    options = json.loads(sys.argv[7]) if len(sys.argv) > 7 else None
    warnings.simplefilter("ignore")
    print(json.dumps(_measure(clip, character, int(frames) or None, plant == "1", options, int(warmup))))
    return 0


def _subprocess_run(ref: Path, clip: str, character: str, frames: int | None, plant: bool, warmup: int = 0,
                    options: dict | None = None) -> dict[str, float]:
    """One run of this script's worker in a fresh process with ``PYTHONPATH=ref`` (a checkout)."""
    env = dict(os.environ, PYTHONPATH=str(ref))
    out = subprocess.run(
        [sys.executable, str(Path(__file__).resolve()), "--worker", clip, character, str(frames or 0),
         "1" if plant else "0", str(warmup), json.dumps(options or {})],
        env=env, check=True, capture_output=True, text=True,
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def _char_label(name: str) -> str:
    return Path(name).stem if name.endswith(".xml") else name


def main() -> int:
    if len(sys.argv) > 1 and sys.argv[1] == "--worker":
        return _worker()
    if len(sys.argv) > 1 and sys.argv[1] == "--stream-worker":
        return _stream_worker()
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=5, help="interleaved runs of every clip and character; medians are printed (default 5)")
    ap.add_argument("--frames", type=int, default=None, help="only the first N frames of each clip")
    ap.add_argument("--characters", nargs="+", default=["humanoid", "robot"],
                    help="bundled names or MJCF paths (default: humanoid robot)")
    ap.add_argument("--clips", nargs="+", default=CLIPS, help="file names in ../shared/data (default: the walks, the jumps and the OptiTrack clip)")
    ap.add_argument("--no-plant", action="store_true", help="pure tracking: no contact detection or planting")
    ap.add_argument("--compare", type=Path, default=None, metavar="REF_DIR",
                    help="also run the checkout REF_DIR (PYTHONPATH=REF_DIR), alternating runs, and print the ratio")
    ap.add_argument("--no-stream", action="store_true", help="skip the streaming latency")
    ap.add_argument("--fresh", action="store_true",
                    help="run this checkout in a fresh process per run too (as the reference is), "
                         "each after a --warmup of 30 frames: the fair back-to-back comparison")
    ap.add_argument("--warmup", type=int, default=30, help="untimed frames first in each --fresh run")
    ap.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE",
                    help="flat retarget options for this checkout only (JSON values), e.g. second_order_correction=true")
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    plant = not args.no_plant
    options = {k: json.loads(v) for k, v in (item.split("=", 1) for item in args.set)}

    import physmocap

    combos = [(c, n) for c in args.clips if (DATA / c).exists() for n in args.characters]
    for c in args.clips:
        if not (DATA / c).exists():
            print(f"skip {c}: {DATA / c} not found", file=sys.stderr)
    ours: dict = {k: [] for k in combos}
    ref: dict = {k: [] for k in combos}
    for k in range(args.runs):  # interleaved: every combination once per round
        for clip, name in combos:
            warmup = args.warmup if args.fresh else 0
            if args.compare is not None:
                ref[(clip, name)].append(_subprocess_run(args.compare, clip, name, args.frames, plant, warmup))
            if args.fresh:
                ours[(clip, name)].append(_subprocess_run(REPO, clip, name, args.frames, plant, warmup, options))
            else:
                ours[(clip, name)].append(_measure(clip, name, args.frames, plant, options))
            # progress on stderr: a whole benchmark takes minutes before its table
            print(f"run {k + 1}/{args.runs}: {clip} onto {_char_label(name)}: "
                  f"{ours[(clip, name)][-1]['cpu_fps']:.0f} frames/s CPU", file=sys.stderr, flush=True)

    def med(runs: list[dict], key: str) -> float:
        return statistics.median(r[key] for r in runs)

    print(f"physmocap from {Path(physmocap.__file__).parent.parent} {options or ''}; {'planting' if plant else 'no planting'};"
          f" medians of {args.runs} interleaved runs")
    head = (f"{'clip':27s} {'character':17s} {'frames':>6s} {'CPU fps':>8s} {'wall fps':>8s} {'IK CPU fps':>10s}"
            f" {'lat med ms':>10s} {'lat p99 ms':>10s}")
    for label, table in [("this checkout", ours)] + ([(f"reference {args.compare}", ref)] if args.compare else []):
        print(f"-- {label}")
        print(head)
        for (clip, name), runs in table.items():
            print(f"{clip:27s} {_char_label(name):17s} {runs[0]['frames']:6d} {med(runs, 'cpu_fps'):8.0f}"
                  f" {med(runs, 'wall_fps'):8.0f} {med(runs, 'ik_cpu_fps'):10.0f}"
                  f" {med(runs, 'lat_med'):10.2f} {med(runs, 'lat_p99'):10.2f}")
    if args.compare is not None:
        print("-- ratio this / reference (median retarget fps)")
        for key in combos:
            print(f"{key[0]:27s} {_char_label(key[1]):17s} CPU x{med(ours[key], 'cpu_fps') / med(ref[key], 'cpu_fps'):.2f}"
                  f"  wall x{med(ours[key], 'wall_fps') / med(ref[key], 'wall_fps'):.2f}")
    walk = DATA / "cmu_12_01_walk.bvh"
    if walk.exists() and not args.no_stream:
        for name in args.characters:
            lat: dict[str, list[float]] = {"this": [], "ref": []}
            for _ in range(args.runs):  # interleaved with the reference's, as above
                if args.compare is not None:
                    lat["ref"].extend(_subprocess_stream(args.compare, walk.name, name))
                lat["this"].extend(_subprocess_stream(REPO, walk.name, name) if args.fresh
                                   else _stream_latencies(walk.name, name))
            for key, label in (("this", "this checkout"), ("ref", f"reference {args.compare}")):
                if lat[key]:
                    ms = np.array(lat[key])
                    print(f"streaming {walk.name} onto {_char_label(name)} ({label}): latency median"
                          f" {np.median(ms):.2f} ms, p99 {np.percentile(ms, 99):.2f} ms (first frame excluded)")
            if lat["ref"]:
                print(f"  ratio this / reference: median x{np.median(lat['this']) / np.median(lat['ref']):.2f},"
                      f" p99 x{np.percentile(lat['this'], 99) / np.percentile(lat['ref'], 99):.2f}")
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    print(f"peak memory (max RSS): {peak:.0f} MB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
