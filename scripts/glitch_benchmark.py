#!/usr/bin/env python3
"""Glitch detection and repair, measured on injected glitches (seeded).

For every BVH in ../shared/data: first the untouched clip (share of frames flagged = false
positives), then the clip with glitches injected into random animated joints: spikes (1-3
frames, 20-120 degrees about a random axis), segments (0.05-0.5 s offsets, 20-120 degrees),
flips (180 degrees, 1-10 frames), frozen joints (0.1-0.5 s held while moving) and anatomical
glitches (a knee or elbow bent backwards past its range of motion, from 1 to 90 degrees past
it, log-uniform, for 1 frame to 0.5 s: the joint's rotation turned about its own hinge axis
so that the signed flexion of :mod:`physmocap.clean.anatomy` reads the injected value).  Prints per
type the frame-level precision, recall and F1 of detection (a (joint, frame) pair is a
sample) and the joint-position RMS error against the clean clip before and after correction
over the injected frames.

Usage:  python scripts/glitch_benchmark.py [--clips ...] [--per-type 6] [--seed 0]
"""

from __future__ import annotations

import argparse
import os
import sys
import warnings
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("PHYSMOCAP_SHARED_DATA", REPO.parent / "shared" / "data"))
TYPES = ("spike", "segment", "flip", "frozen", "anatomical")


def inject(motion, rng: np.random.Generator, per_type: int):
    """A copy of ``motion`` with glitches, and the truth: type -> set of (joint, frame)."""
    import dataclasses

    from physmocap.clean.anatomy import bend_past_range
    from physmocap.ik.retarget import default_start
    from physmocap.rotations import Rotation, quat_mul

    R = np.array(motion.rotations, copy=True)
    F = R.shape[0]
    fps = motion.fps
    start = default_start(motion) + 2
    moving = [j for j in range(R.shape[1]) if not motion.skeleton.end_site[j] and np.ptp(R[:, j], axis=0).max() > 1e-3]
    truth = {t: set() for t in TYPES}
    taken = np.zeros((F, R.shape[1]), dtype=bool)
    for kind in TYPES:
        placed = 0
        while placed < per_type:
            j = int(rng.choice(moving))
            if kind == "spike":
                n = int(rng.integers(1, 4))
            elif kind == "anatomical":
                n = max(1, int(round(np.exp(rng.uniform(0.0, np.log(0.5 * fps))))))
            elif kind == "segment":
                n = int(round(rng.uniform(0.05, 0.5) * fps))
            elif kind == "flip":
                n = int(rng.integers(1, 11))
            else:
                n = max(3, int(round(rng.uniform(0.1, 0.5) * fps)))
            a = int(rng.integers(start, F - n - 2))
            lo, hi = max(0, a - int(fps)), min(F, a + n + int(fps))
            if taken[lo:hi, j].any():
                continue
            if kind == "anatomical":
                side, limb = str(rng.choice(["left", "right"])), str(rng.choice(["knee", "elbow"]))
                excess = float(np.exp(rng.uniform(0.0, np.log(90.0))))
                bent = bend_past_range(dataclasses.replace(motion, rotations=R), f"{side}_{limb}", range(a, a + n), excess)
                if bent is None or taken[lo:hi, bent[0]].any():
                    continue
                j = bent[0]
                R[a : a + n, j] = bent[1]
            elif kind == "frozen":
                if np.max(np.abs(np.diff(R[a : a + n + 1, j], axis=0))) < 1e-4:
                    continue  # the joint does not move there: nothing to freeze
                R[a : a + n, j] = R[a - 1, j]
            else:
                axis = rng.normal(size=3)
                axis /= np.linalg.norm(axis)
                deg = 180.0 if kind == "flip" else rng.uniform(20.0, 120.0)
                q = Rotation.from_rotvec(np.radians(deg) * axis).as_quat()
                R[a : a + n, j] = quat_mul(np.broadcast_to(q, (n, 4)), R[a : a + n, j])
            taken[a : a + n, j] = True
            truth[kind].update((j, t) for t in range(a, a + n))
            placed += 1
    return dataclasses.replace(motion, rotations=R), truth


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--clips", nargs="+", default=None)
    ap.add_argument("--per-type", type=int, default=6)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    from physmocap.clean import clean
    from physmocap.sources import load_motion

    clips = args.clips or sorted(p.name for p in DATA.glob("*.bvh"))
    rng = np.random.default_rng(args.seed)
    totals = {t: [0, 0, 0] for t in TYPES}  # detected-true, truth, (unused)
    fp_total = det_total = 0
    print(f"{'clip':26s} {'clean: flagged %':>16s} " + " ".join(f"{t + ' recall':>14s}" for t in TYPES) + f" {'precision':>9s} {'RMS before':>10s} {'after cm':>8s}")
    for clip in clips:
        motion = load_motion(DATA / clip)
        names = {n: j for j, n in enumerate(motion.skeleton.names)}
        _, base = clean(motion)
        flagged = {t for g in base.glitches for t in range(g.start, g.end + 1)}
        glitched, truth = inject(motion, rng, args.per_type)
        fixed, report = clean(glitched)
        detected = {(names[g.joint], t) for g in report.glitches for t in range(g.start, g.end + 1)}
        all_truth = set().union(*truth.values())
        hits = detected & all_truth
        fp_total += len(detected - all_truth)
        det_total += len(detected)
        recalls = []
        for t in TYPES:
            got = len(truth[t] & detected)
            totals[t][0] += got
            totals[t][1] += len(truth[t])
            recalls.append(got / max(1, len(truth[t])))
        P0, Pg, Pf = motion.world_positions(), glitched.world_positions(), fixed.world_positions()
        frames = sorted({t for _, t in all_truth})
        rms_before = np.sqrt(np.nanmean(np.sum((Pg[frames] - P0[frames]) ** 2, axis=-1))) * 100
        rms_after = np.sqrt(np.nanmean(np.sum((Pf[frames] - P0[frames]) ** 2, axis=-1))) * 100
        precision = len(hits) / max(1, len(detected))
        print(f"{clip:26s} {100 * len(flagged) / motion.num_frames:16.2f} " + " ".join(f"{r:14.3f}" for r in recalls)
              + f" {precision:9.3f} {rms_before:10.2f} {rms_after:8.2f}", flush=True)
    print(f"{'all':26s} {'':16s} " + " ".join(f"{totals[t][0] / max(1, totals[t][1]):14.3f}" for t in TYPES)
          + f" {1 - fp_total / max(1, det_total):9.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
