#!/usr/bin/env python3
"""Glitch detection and repair, measured on injected glitches (seeded).

For every BVH in ../shared/data:

* the **untouched** clip is cleaned first: the share of its frames flagged (any joint) is the
  false-positive rate on real motion, "changed" the share the cleaner rewrites (the rest of
  the flags, discontinuities and out-of-range spans too long to be glitches, are reported only);
* then, **one type at a time**, ``--per-type`` glitches of that type are injected into random
  animated joints of a fresh copy: spikes (1-3 frames, 20-120 degrees about a random axis),
  segments (0.05-0.5 s offsets, 20-120 degrees), flips (180 degrees, 1-10 frames), frozen
  joints (0.1-0.5 s held while the joint moves) and anatomical glitches (a knee or elbow bent
  backwards past its range of motion, from 1 to 90 degrees past it, log-uniform, for 1 frame
  to 0.5 s: the joint's rotation turned about its own hinge axis so that the signed flexion of
  :mod:`physmocap.clean.anatomy` reads the injected value).  Injecting one type per run makes
  every flag of that run attributable.  Recall counts the injected (joint, frame) pairs
  found.  Precision is given twice: *strict* counts every flag that is not an injected pair
  (the clip's own flags included), *injected* leaves out the pairs the untouched clip
  already had flagged (the real captures have glitches of their own -- a CMU thigh flipping
  180 degrees for 9 frames, toes and hands stepping faster than 1500 deg/s in one frame, an
  OptiTrack spine popping 12 degrees out and back -- that the untouched figure measures;
  ``--misses`` lists them).

A (joint, frame) pair is labelled glitched only where the injection changes that joint's
rotation by more than ``--floor`` degrees (0.5: below the angular noise of the captures, a
frozen joint's first held frames are still where the joint was); the pairs it changes less
stay out of both truth and false positives (counted and printed as "sub-noise").

Correction is measured per type as the joint-position RMS error against the clean clip over
the injected frames, before and after, its reduction ``1 - after/before``, and the largest
increase of a frame's worst joint-position error on any frame the correction changed (but
the frames of the clip's own glitches, where the "clean" reference is itself glitched), and how
many of those touched frames got more than 1 cm worse; "beyond ROM" counts the touched frames
the correction left beyond a range of motion (:mod:`physmocap.clean.anatomy`) that the
untouched clip is within there.

Usage:  python scripts/glitch_benchmark.py [--clips ...] [--per-type 6] [--seed 0] [--misses]
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


def inject(motion, rng: np.random.Generator, per_type: int, kinds=TYPES, floor: float = 0.5):
    """A copy of ``motion`` with glitches, the truth (type -> set of (joint, frame) changed by
    more than ``floor`` degrees) and the set of injected pairs changed less (sub-noise)."""
    import dataclasses

    from physmocap.clean.anatomy import bend_past_range
    from physmocap.clean.detect import _angle
    from physmocap.ik.retarget import default_start
    from physmocap.rotations import Rotation, quat_mul

    R = np.array(motion.rotations, copy=True)
    F = R.shape[0]
    fps = motion.fps
    start = default_start(motion) + 2
    moving = [j for j in range(R.shape[1]) if not motion.skeleton.end_site[j] and np.ptp(R[:, j], axis=0).max() > 1e-3]
    truth = {t: set() for t in kinds}
    faint: set[tuple[int, int]] = set()
    taken = np.zeros((F, R.shape[1]), dtype=bool)
    for kind in kinds:
        placed = tries = 0
        while placed < per_type and tries < 1000:
            tries += 1
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
                new = bent[1]
            elif kind == "frozen":
                if np.max(np.abs(np.diff(R[a : a + n + 1, j], axis=0))) < 1e-4:
                    continue  # the joint does not move there: nothing to freeze
                new = np.broadcast_to(R[a - 1, j], (n, 4))
            else:
                axis = rng.normal(size=3)
                axis /= np.linalg.norm(axis)
                deg = 180.0 if kind == "flip" else rng.uniform(20.0, 120.0)
                q = Rotation.from_rotvec(np.radians(deg) * axis).as_quat()
                new = quat_mul(np.broadcast_to(q, (n, 4)), R[a : a + n, j])
            change = _angle(new, R[a : a + n, j])
            R[a : a + n, j] = new
            taken[a : a + n, j] = True
            truth[kind].update((j, a + i) for i in range(n) if change[i] > floor)
            faint.update((j, a + i) for i in range(n) if change[i] <= floor)
            placed += 1
    return dataclasses.replace(motion, rotations=R), truth, faint


def _beyond_rom(motion) -> set[int]:
    """Frames where some anatomical angle of ``motion`` is beyond its range of motion."""
    from physmocap.clean.detect import anatomical_glitches

    return {t for g in anatomical_glitches(motion) for t in range(g.start, g.end + 1)}


def _flagged(report, names) -> set[tuple[int, int]]:
    return {(names[g.joint], t) for g in report.glitches for t in range(g.start, g.end + 1)}


def _prf(tp: int, fp: int, fn: int) -> tuple[float, float, float]:
    p = tp / max(1, tp + fp)
    r = tp / max(1, tp + fn)
    return p, r, 2 * p * r / max(1e-12, p + r)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--clips", nargs="+", default=None)
    ap.add_argument("--types", nargs="+", default=list(TYPES), choices=TYPES)
    ap.add_argument("--per-type", type=int, default=6)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--floor", type=float, default=0.5, help="degrees an injection must change a pair to label it")
    ap.add_argument("--misses", action="store_true", help="print every missed and falsely flagged span")
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    from physmocap.clean import clean
    from physmocap.sources import load_motion

    clips = args.clips or sorted(p.name for p in DATA.glob("*.bvh"))
    count = {t: np.zeros(3, int) for t in args.types}  # tp, fp, fn
    own_fp = {t: 0 for t in args.types}  # false positives the untouched clip already had
    # sum sq before, sum sq after, n, worst increase (cm), touched frames, of them > 1 cm worse,
    # of them beyond a range of motion the untouched clip is within
    err = {t: [0.0, 0.0, 0, 0.0, 0, 0, 0] for t in args.types}
    faint_total = {t: 0 for t in args.types}
    print(f"{'clip':26s} {'frames':>6s} {'untouched flagged %':>19s} {'changed %':>9s}  " + " ".join(f"{t[:9] + ' P/R':>13s}" for t in args.types) + "  (strict P)")
    for ci, clip in enumerate(clips):
        motion = load_motion(DATA / clip)
        names = {n: j for j, n in enumerate(motion.skeleton.names)}
        jn = motion.skeleton.names
        base_fixed, base = clean(motion)
        own_fix = np.any(np.asarray(base_fixed.rotations) != np.asarray(motion.rotations), axis=(1, 2))
        flagged = {t for g in base.glitches for t in range(g.start, g.end + 1)}
        base_pairs = _flagged(base, names)
        base_rom = _beyond_rom(motion)
        if args.misses:
            for g in base.glitches:
                print(f"    untouched  {g.kind:13s} {g.joint:18s} frames {g.start}-{g.end} severity {g.severity:.1f} {g.unit}")
        cells = []
        P0 = motion.world_positions()
        for ti, t in enumerate(args.types):
            rng = np.random.default_rng([args.seed, ci, ti])
            glitched, truth, faint = inject(motion, rng, args.per_type, (t,), args.floor)
            fixed, report = clean(glitched)
            det = _flagged(report, names) - faint
            tp, fp, fn = len(det & truth[t]), len(det - truth[t]), len(truth[t] - det)
            count[t] += (tp, fp, fn)
            own_fp[t] += len((det - truth[t]) & base_pairs)
            faint_total[t] += len(faint)
            p, r, _ = _prf(tp, fp, fn)
            cells.append(f"{p:6.3f}/{r:6.3f}")
            if args.misses:
                for label, pairs in (("MISS", truth[t] - det), ("FP", det - truth[t])):
                    for j in sorted({j for j, _ in pairs}):
                        fr = sorted(f for jj, f in pairs if jj == j)
                        kinds = {g.kind for g in report.glitches if names[g.joint] == j}
                        inj = sorted(f for jj, f in truth[t] if jj == j)
                        print(f"    {t:10s} {label:4s} {jn[j]:18s} frames {fr[0]}-{fr[-1]} ({len(fr)})"
                              f" injected {inj[0] if inj else '-'}-{inj[-1] if inj else '-'} found as {sorted(kinds)}")
            frames = sorted({f for _, f in truth[t]})
            if frames:
                Pg, Pf = glitched.world_positions(), fixed.world_positions()
                eb = np.sum((Pg[frames] - P0[frames]) ** 2, axis=-1)
                ea = np.sum((Pf[frames] - P0[frames]) ** 2, axis=-1)
                err[t][0] += np.nansum(eb)
                err[t][1] += np.nansum(ea)
                err[t][2] += np.isfinite(eb).sum()
                changed = np.any(np.asarray(fixed.rotations) != np.asarray(glitched.rotations), axis=(1, 2))
                changed = np.flatnonzero(changed & ~own_fix)  # not the clip's own glitches: no truth there
                if len(changed):
                    wb = np.nanmax(np.linalg.norm(Pg[changed] - P0[changed], axis=-1), axis=-1)
                    wa = np.nanmax(np.linalg.norm(Pf[changed] - P0[changed], axis=-1), axis=-1)
                    err[t][3] = max(err[t][3], 100 * float(np.max(wa - wb)))
                    err[t][4] += len(changed)
                    err[t][5] += int(np.sum(wa - wb > 0.01))
                    err[t][6] += len(set(changed.tolist()) & (_beyond_rom(fixed) - base_rom))
        print(f"{clip:26s} {motion.num_frames:6d} {100 * len(flagged) / motion.num_frames:19.2f} {100 * own_fix.mean():9.2f}  " + " ".join(f"{c:>13s}" for c in cells), flush=True)
    print()
    print(f"{'type':11s} {'strict P':>9s} {'injected P':>10s} {'recall':>7s} {'F1':>6s} {'pairs':>6s} {'sub-noise':>9s} {'RMS before':>10s} {'after cm':>8s} {'removed':>7s} {'worst +cm':>9s} {'>1cm worse':>12s} {'beyond ROM':>10s}")
    tot = np.zeros(3, int)
    for t in args.types:
        tot += count[t]
        p, r, f = _prf(*count[t])
        pi, _, f = _prf(count[t][0], count[t][1] - own_fp[t], count[t][2])
        b, a, n, w, touched, worse, rom = err[t]
        rb, ra = np.sqrt(b / max(1, n)) * 100, np.sqrt(a / max(1, n)) * 100
        print(f"{t:11s} {p:9.3f} {pi:10.3f} {r:7.3f} {f:6.3f} {count[t][0] + count[t][2]:6d} {faint_total[t]:9d} {rb:10.2f} {ra:8.2f} {1 - ra / max(1e-12, rb):7.1%} {w:9.2f} {worse:5d}/{touched:<6d} {rom:10d}")
    p, r, f = _prf(*tot)
    pi, _, f = _prf(tot[0], tot[1] - sum(own_fp.values()), tot[2])
    print(f"{'all':11s} {p:9.3f} {pi:10.3f} {r:7.3f} {f:6.3f} {tot[0] + tot[2]:6d}   (F1 of the injected precision)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
