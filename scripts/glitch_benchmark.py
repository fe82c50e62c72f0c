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
the injected frames, before and after, and its reduction ``1 - after/before``.  The shared clips
are not all clean: the reference has glitches of its own, which the cleaner repairs in every
version of the clip (the dance clip's right thigh and foot flipping 180 degrees on frames
245-253), so a repair there would be scored as error against a glitch.  The error therefore
leaves out the (frame, joint) positions that cleaning the **untouched** clip moves (no truth
there: :func:`own_moved`); that exclusion is printed per type ("own pos", the joint positions
left out of the injected frames' error), and the reduction with every position counted, the
old figure, is printed beside it ("all pos").  "worst +cm" is the largest increase of a frame's
worst joint-position error (over the positions not left out) on any frame the correction
changed, ">1cm worse" how many of those touched frames got more than 1 cm worse; "beyond ROM"
counts the touched frames the correction left beyond a range of motion
(:mod:`physmocap.clean.anatomy`) that the untouched clip is within there.

**Joint-position sources** (``--sources positional`` or ``both``, the default): every shared
BVH as the joint positions of its forward kinematics (a tracker's view of the same motion, every
joint and end site, confidence 1), and every shared marker file whose markers map to joint
centres (the CMU C3D: real positional noise; the upper-body Vicon files have no legs and are
refused, as every command refuses them).  The same protocol, with ``--per-type`` glitches of one
type at a time, 1 frame to 0.5 s long unless said: *stretch* (a joint moved along its bone from
its parent by 15-100 % of the bone's length (or shrunk by 15-90 %) and at least 4 cm, bones of
5 cm or more), *gap* (a joint lost: no position, confidence 0), *swap* (a left joint and its
right twin trading positions) and *pos_frozen* (a joint's position held for 0.1-0.5 s while it
moves).  A (joint, frame) pair is labelled only where the injection moves the joint more than
``--floor-m`` (1 cm: a marker-based joint centre's own noise); the error is the position RMS
of the glitched joints on their glitched frames (a gap has no "before").

Usage:  python scripts/glitch_benchmark.py [--clips ...] [--per-type 6] [--seed 0] [--misses]
            [--sources rotational|positional|both] [--no-methods]

A BVH's glitches depend on the seed and the clip's place among all the shared BVHs, not on the
other clips named with ``--clips``: one clip of a run is reproduced alone.
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
POS_TYPES = ("stretch", "gap", "swap", "pos_frozen")


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


def positional_version(motion):
    """``motion`` as a joint-position source: its forward-kinematics positions (every joint
    and end site), confidence 1, no rotations (what a tracker of the same motion records).
    A joint with animated translation channels besides the root (Bandai Namco's Hips under
    its ``joint_Root``) hangs from no bone: it becomes a root of its own."""
    import dataclasses

    from physmocap.motion import Motion

    P = np.asarray(motion.world_positions(), dtype=float)
    parents = np.array(motion.skeleton.parents, copy=True)
    moved = np.asarray(motion.translated, dtype=int)[np.ptp(np.asarray(motion.translations), axis=0).max(axis=-1) > 1e-6]
    parents[moved] = -1
    skeleton = dataclasses.replace(motion.skeleton, parents=parents)
    return Motion(skeleton, motion.fps, positions=P, confidence=np.ones(P.shape[:2]),
                  source=f"{motion.source} (positions)")


def inject_positional(motion, rng: np.random.Generator, per_type: int, kind: str, floor: float = 0.01, start: int = 0):
    """A copy of the positional ``motion`` with ``per_type`` glitches of ``kind`` (one of
    :data:`POS_TYPES`, module docstring) from frame ``start`` on, the truth (the set of
    (joint, frame) moved more than ``floor`` metres) and the injected pairs moved less."""
    import dataclasses

    from physmocap.clean.detect import canonical_joints
    from physmocap.clean.positional import twin_pairs

    P = np.array(motion.positions, dtype=float, copy=True)
    C = np.ones(P.shape[:2]) if motion.confidence is None else np.array(motion.confidence, dtype=float, copy=True)
    F, J = P.shape[:2]
    fps = float(motion.fps)
    parents = motion.skeleton.parents
    with np.errstate(invalid="ignore"):
        bone = np.array([np.nanmedian(np.linalg.norm(P[:, j] - P[:, p], axis=1)) if p >= 0 else 0.0
                         for j, p in enumerate(parents)])  # fmt: skip
    longest = max(1, int(round(0.5 * fps)))
    pairs = twin_pairs(motion, canonical_joints(motion)) if kind == "swap" else []
    lost = ~np.isfinite(P).all(axis=-1) | (C <= 0)
    truth: set[tuple[int, int]] = set()
    faint: set[tuple[int, int]] = set()
    taken = np.zeros((F, J), dtype=bool)
    placed = tries = 0
    while placed < per_type and tries < 1000:
        tries += 1
        if kind == "pos_frozen":
            n = max(3, int(round(rng.uniform(0.1, 0.5) * fps)))
        else:
            n = int(rng.integers(1, longest + 1))
        if F - n - 2 <= start + 1:
            break
        a = int(rng.integers(start + 1, F - n - 2))
        span = slice(a, a + n)
        if kind == "swap":
            if not pairs:
                break
            joints = list(pairs[int(rng.integers(len(pairs)))])
        else:
            joints = [int(rng.integers(J))]
        lo, hi = max(0, a - int(fps)), min(F, a + n + int(fps))
        near = joints + [int(parents[j]) for j in joints if parents[j] >= 0] + np.flatnonzero(np.isin(parents, joints)).tolist()
        if taken[lo:hi, near].any() or lost[lo:hi, joints].any():
            continue  # a second glitch on it or a bone it shares (or the source's own gap) within a second is not attributable
        new = P[span][:, joints].copy()
        j = joints[0]
        if kind == "stretch":
            p = int(parents[j])
            if p < 0 or not bone[j] >= 0.05:
                continue  # no bone (or two names for one point) to stretch
            grow = rng.uniform(0.15, 1.0) if rng.random() < 0.5 else -rng.uniform(0.15, 0.9)
            if abs(grow) * bone[j] < 0.04:
                continue
            new[:, 0] = P[span, p] + (1.0 + grow) * (P[span, j] - P[span, p])
        elif kind == "gap":
            new[:] = np.nan
        elif kind == "swap":
            new = new[:, ::-1]
        else:  # pos_frozen
            if np.nanmax(np.linalg.norm(P[a : a + n + 1, j] - P[a - 1, j], axis=-1)) < 1e-4:
                continue  # the joint does not move there: nothing to freeze
            new[:, 0] = P[a - 1, j]
        with np.errstate(invalid="ignore"):
            moved = np.linalg.norm(new - P[span][:, joints], axis=-1)
        moved = np.where(np.isnan(moved), np.inf, moved)  # a lost sample is labelled
        P[span, joints] = new
        if kind == "gap":
            C[span, joints] = 0.0
        taken[span, joints] = True
        for i in range(n):
            for k, jj in enumerate(joints):
                (truth if moved[i, k] > floor else faint).add((jj, a + i))
        placed += 1
    return dataclasses.replace(motion, positions=P, confidence=C), truth, faint


def positional_clips(args: argparse.Namespace) -> list[tuple[str, object]]:
    """(name, positional motion) of every shared BVH (:func:`positional_version`) and marker
    file that maps to joints; the others said why they are left out."""
    from physmocap.errors import PhysmocapError
    from physmocap.sources import load_motion

    names = args.clips or sorted(p.name for p in DATA.iterdir() if p.suffix.lower() in (".bvh", ".c3d", ".trc"))
    out = []
    for name in names:
        try:
            m = load_motion(DATA / name)
        except PhysmocapError as exc:
            print(f"{name:26s} left out: {exc.message[:100]}")
            continue
        out.append((name, positional_version(m) if m.is_rotational else m))
    return out


def positional_benchmark(args: argparse.Namespace) -> None:
    """The joint-position benchmark (module docstring), printed."""
    from physmocap.clean import clean
    from physmocap.ik.retarget import default_start

    types = args.pos_types
    count = {t: np.zeros(3, int) for t in types}
    own_fp = {t: 0 for t in types}
    # sum sq before, n before, sum sq after, n after, worst increase (cm), touched frames, of them > 1 cm worse
    err = {t: [0.0, 0, 0.0, 0, 0.0, 0, 0] for t in types}
    faint_total = {t: 0 for t in types}
    print(f"{'positions of':26s} {'frames':>6s} {'untouched flagged %':>19s} {'changed %':>9s}  "
          + " ".join(f"{t[:10] + ' P/R':>14s}" for t in types) + "  (strict P)")  # fmt: skip
    for ci, (clip, motion) in enumerate(positional_clips(args)):
        names = {n: j for j, n in enumerate(motion.skeleton.names)}
        jn = motion.skeleton.names
        P0 = np.asarray(motion.positions, dtype=float)
        base_fixed, base = clean(motion)
        own_fix = np.any(np.asarray(base_fixed.positions) != P0, axis=(1, 2)) & np.isfinite(P0).all(axis=(1, 2))
        flagged = {t for g in base.glitches for t in range(g.start, g.end + 1)}
        base_pairs = _flagged(base, names)
        if args.misses:
            for g in base.glitches:
                print(f"    untouched  {g.kind:13s} {g.joint:18s} frames {g.start}-{g.end} severity {g.severity:.3f} {g.unit}")
        start = default_start(motion) + 2
        cells = []
        for ti, t in enumerate(types):
            rng = np.random.default_rng([args.seed, 100 + ci, POS_TYPES.index(t)])  # the same glitches whichever types run
            glitched, truth, faint = inject_positional(motion, rng, args.per_type, t, args.floor_m, start)
            fixed, report = clean(glitched)
            det = _flagged(report, names) - faint
            tp, fp, fn = len(det & truth), len(det - truth), len(truth - det)
            count[t] += (tp, fp, fn)
            own_fp[t] += len((det - truth) & base_pairs)
            faint_total[t] += len(faint)
            p, r, _ = _prf(tp, fp, fn)
            cells.append(f"{p:6.3f}/{r:6.3f}")
            if args.misses:
                for label, pairs in (("MISS", truth - det), ("FP", det - truth)):
                    for j in sorted({j for j, _ in pairs}):
                        fr = sorted(f for jj, f in pairs if jj == j)
                        kinds = {g.kind for g in report.glitches if names[g.joint] == j}
                        inj = sorted(f for jj, f in truth if jj == j)
                        print(f"    {t:10s} {label:4s} {jn[j]:18s} frames {fr[0]}-{fr[-1]} ({len(fr)})"
                              f" injected {inj[0] if inj else '-'}-{inj[-1] if inj else '-'} found as {sorted(kinds)}")
            frames = sorted({f for _, f in truth})
            if not frames:
                continue
            Pg, Pf = np.asarray(glitched.positions), np.asarray(fixed.positions)
            jj, ff = (np.array(x) for x in zip(*sorted(truth)))  # the glitched joints on their frames
            eb = np.sum((Pg[ff, jj] - P0[ff, jj]) ** 2, axis=-1)
            ea = np.sum((Pf[ff, jj] - P0[ff, jj]) ** 2, axis=-1)
            err[t][0] += np.nansum(eb)
            err[t][1] += int(np.isfinite(eb).sum())
            err[t][2] += np.nansum(ea)
            err[t][3] += int(np.isfinite(ea).sum())
            with np.errstate(invalid="ignore"):
                changed = np.any(~((Pf == Pg) | (np.isnan(Pf) & np.isnan(Pg))), axis=(1, 2))
            changed = np.flatnonzero(changed & ~own_fix)
            if len(changed):
                # a lost joint had no error before: it counts as its error after
                wb = np.nanmax(np.nan_to_num(np.linalg.norm(Pg[changed] - P0[changed], axis=-1), nan=0.0), axis=-1)
                wa = np.nanmax(np.linalg.norm(Pf[changed] - P0[changed], axis=-1), axis=-1)
                err[t][4] = max(err[t][4], 100 * float(np.nanmax(wa - wb)))
                err[t][5] += len(changed)
                err[t][6] += int(np.sum(wa - wb > 0.01))
        print(f"{clip:26s} {motion.num_frames:6d} {100 * len(flagged) / motion.num_frames:19.2f} "
              f"{100 * own_fix.mean():9.2f}  " + " ".join(f"{c:>14s}" for c in cells), flush=True)  # fmt: skip
    print()
    print(f"{'type':11s} {'strict P':>9s} {'injected P':>10s} {'recall':>7s} {'F1':>6s} {'pairs':>6s} {'sub-noise':>9s} "
          f"{'RMS before':>10s} {'after cm':>8s} {'removed':>7s} {'worst +cm':>9s} {'>1cm worse':>12s}")  # fmt: skip
    tot = np.zeros(3, int)
    for t in types:
        tot += count[t]
        p, r, f = _prf(*count[t])
        pi, _, f = _prf(count[t][0], count[t][1] - own_fp[t], count[t][2])
        b, nb, a, na, w, touched, worse = err[t]
        rb, ra = np.sqrt(b / max(1, nb)) * 100, np.sqrt(a / max(1, na)) * 100
        before = f"{rb:10.2f}" if nb else f"{'lost':>10s}"
        removed = f"{1 - ra / max(1e-12, rb):7.1%}" if nb else f"{'-':>7s}"
        print(f"{t:11s} {p:9.3f} {pi:10.3f} {r:7.3f} {f:6.3f} {count[t][0] + count[t][2]:6d} {faint_total[t]:9d} "
              f"{before} {ra:8.2f} {removed} {w:9.2f} {worse:5d}/{touched:<6d}")  # fmt: skip
    p, r, f = _prf(*tot)
    pi, _, f = _prf(tot[0], tot[1] - sum(own_fp.values()), tot[2])
    print(f"{'all':11s} {p:9.3f} {pi:10.3f} {r:7.3f} {f:6.3f} {tot[0] + tot[2]:6d}   (F1 of the injected precision)")


#: Rotational repairs compared per type (the second table): the hard-limited IK re-solve
#: (:mod:`physmocap.clean.resolve`) left out ("never"), used where the interpolated pose leaves
#: a range of motion (the default, "limits"), used wherever it can be ("always"), and per
#: glitch the better of "never" and "always" against the clean clip ("oracle": what a perfect
#: choice between interpolation and IK would give).
METHODS = ("never", "limits", "always", "oracle")


def _method_errors(
    glitched, fixed, report, P0: np.ndarray, frames: list[int], own: np.ndarray, own_pos: np.ndarray | None = None
) -> dict[str, np.ndarray]:
    """Method -> ``[sum of squared joint-position errors (m^2) over ``frames``, their count,
    repaired glitches better than the glitch, repaired glitches]``; a glitch is better where
    its span's joint-position RMS error (all joints) after the repair is below the one
    before.  ``fixed``: the default ("limits") repair of ``glitched``; ``own (F,)``: the
    frames the untouched clip's own repairs change (no truth there: their glitches are not
    counted); ``own_pos (F, J)``: the positions they move, left out of the error
    (:func:`own_moved`; none where not given)."""
    import dataclasses

    from physmocap.clean.correct import REPAIRED, correct_glitches

    names = {n: j for j, n in enumerate(glitched.skeleton.names)}
    found = list(report.glitches)
    R = {m: np.asarray(correct_glitches(glitched, found, resolve=m)[0].rotations) for m in ("never", "always")}
    R["limits"] = np.asarray(fixed.rotations)
    spans = [(names[g.joint], g.start, g.end) for g in found
             if g.corrected and REPAIRED.get(g.kind) == "rotation" and not own[g.start : g.end + 1].any()]

    def positions(rot: np.ndarray, s: int = 0, e: int = -1) -> np.ndarray:
        return dataclasses.replace(glitched, rotations=rot).slice_frames(s, e + 1 if e >= 0 else None).world_positions()

    def span_rms(rot: np.ndarray, s: int, e: int) -> float:
        return float(np.sqrt(np.mean(np.sum((positions(rot, s, e) - P0[s : e + 1]) ** 2, axis=-1))))

    oracle = R["never"].copy()
    for j, s, e in spans:  # greedy: each glitch's IK kept where it lowers its span's error
        trial = oracle.copy()
        trial[s : e + 1, j] = R["always"][s : e + 1, j]
        if span_rms(trial, s, e) < span_rms(oracle, s, e):
            oracle = trial
    R["oracle"] = oracle
    Rg = np.asarray(glitched.rotations)
    P = {m: positions(R[m]) for m in METHODS}
    out = {}
    for m in METHODS:
        sq = np.sum((P[m][frames] - P0[frames]) ** 2, axis=-1)
        if own_pos is not None:
            sq = sq[~own_pos[frames]]
        better = sum(span_rms(R[m], s, e) < span_rms(Rg, s, e) for _, s, e in spans)
        out[m] = np.array([np.nansum(sq), np.isfinite(sq).sum(), better, len(spans)], dtype=float)
    return out


def _print_methods(types, sums: dict[str, dict[str, np.ndarray]]) -> None:
    """The second rotational table: per type and method (:data:`METHODS`), the joint-position
    RMS error after the repair (cm) and the share of repaired glitches it leaves better than
    the glitch."""
    print()
    print(f"{'repair':11s} " + " ".join(f"{m + ' cm':>10s} {'better':>7s}" for m in METHODS))
    for t in types:
        cells = []
        for m in METHODS:
            sq, n, better, spans = sums[t][m]
            cells.append(f"{100 * np.sqrt(sq / max(1, n)):10.2f} {better / max(1, spans):7.1%}")
        print(f"{t:11s} " + " ".join(cells))


def own_moved(motion, base_fixed) -> np.ndarray:
    """``(F, J)``: the world positions (joints and end sites) of ``motion`` that its own
    cleaning, ``base_fixed``, moves at all: the clip's own glitches, where the reference is
    itself glitched and a repair has no truth to be scored against."""
    return np.any(np.asarray(base_fixed.world_positions()) != np.asarray(motion.world_positions()), axis=-1)


def position_errors(Pg: np.ndarray, Pf: np.ndarray, P0: np.ndarray, frames, own: np.ndarray) -> np.ndarray:
    """``[squared joint-position error before, after, positions counted, positions left out]``
    summed over ``frames`` of the glitched ``Pg`` and corrected ``Pf (F, J, 3)`` against the
    reference ``P0``, the positions ``own (F, J)`` marks (:func:`own_moved`) left out."""
    keep = ~own[frames]
    eb = np.sum((Pg[frames] - P0[frames]) ** 2, axis=-1)[keep]
    ea = np.sum((Pf[frames] - P0[frames]) ** 2, axis=-1)[keep]
    return np.array([np.nansum(eb), np.nansum(ea), np.isfinite(eb).sum(), (~keep).sum()], dtype=float)


def worst_increase(Pg: np.ndarray, Pf: np.ndarray, P0: np.ndarray, frames, own: np.ndarray) -> np.ndarray:
    """``(len(frames),)``: per frame, how much the worst joint-position error (over the
    positions ``own`` does not mark) grew from ``Pg`` to ``Pf`` (m; 0 where every position is
    marked)."""
    keep = ~own[frames]
    wb = np.where(keep, np.linalg.norm(Pg[frames] - P0[frames], axis=-1), 0.0).max(axis=-1, initial=0.0)
    wa = np.where(keep, np.linalg.norm(Pf[frames] - P0[frames], axis=-1), 0.0).max(axis=-1, initial=0.0)
    return wa - wb


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
    ap.add_argument("--pos-types", nargs="+", default=list(POS_TYPES), choices=POS_TYPES)
    ap.add_argument("--sources", choices=["rotational", "positional", "both"], default="both")
    ap.add_argument("--per-type", type=int, default=6)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--floor", type=float, default=0.5, help="degrees an injection must change a pair to label it")
    ap.add_argument("--floor-m", type=float, default=0.01, help="metres an injection must move a joint to label it")
    ap.add_argument("--misses", action="store_true", help="print every missed and falsely flagged span")
    ap.add_argument("--no-methods", action="store_true",
                    help="leave out the rotational repairs' comparison (the second table: two more repairs per run, the IK's slow)")
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    if args.sources in ("rotational", "both"):
        rotational(args)
    if args.sources in ("positional", "both"):
        if args.sources == "both":
            print()
        positional_benchmark(args)
    return 0


def rotational(args: argparse.Namespace) -> None:
    """The rotational benchmark (module docstring) on the shared BVHs, printed."""
    from physmocap.clean import clean
    from physmocap.sources import load_motion

    clips = [c for c in args.clips if c.endswith(".bvh")] if args.clips else sorted(p.name for p in DATA.glob("*.bvh"))
    count = {t: np.zeros(3, int) for t in args.types}  # tp, fp, fn
    own_fp = {t: 0 for t in args.types}  # false positives the untouched clip already had
    # sum sq before, sum sq after, n (the positions the untouched clip's own repairs move left
    # out), worst increase (cm), touched frames, of them > 1 cm worse, of them beyond a range of
    # motion the untouched clip is within, positions left out, sum sq before and after and n
    # with every position counted
    err = {t: [0.0, 0.0, 0, 0.0, 0, 0, 0, 0, 0.0, 0.0, 0] for t in args.types}
    methods = {t: {m: np.zeros(4) for m in METHODS} for t in args.types}
    faint_total = {t: 0 for t in args.types}
    print(f"{'clip':26s} {'frames':>6s} {'untouched flagged %':>19s} {'changed %':>9s}  " + " ".join(f"{t[:9] + ' P/R':>13s}" for t in args.types) + "  (strict P)")
    every = sorted(p.name for p in DATA.glob("*.bvh"))
    for clip in clips:
        ci = every.index(clip) if clip in every else len(every)  # a clip's glitches whichever clips run
        motion = load_motion(DATA / clip)
        names = {n: j for j, n in enumerate(motion.skeleton.names)}
        jn = motion.skeleton.names
        base_fixed, base = clean(motion)
        own_fix = np.any(np.asarray(base_fixed.rotations) != np.asarray(motion.rotations), axis=(1, 2))
        own_pos = own_moved(motion, base_fixed)
        flagged = {t for g in base.glitches for t in range(g.start, g.end + 1)}
        base_pairs = _flagged(base, names)
        base_rom = _beyond_rom(motion)
        if args.misses:
            for g in base.glitches:
                print(f"    untouched  {g.kind:13s} {g.joint:18s} frames {g.start}-{g.end} severity {g.severity:.1f} {g.unit}")
        cells = []
        P0 = motion.world_positions()
        for t in args.types:
            rng = np.random.default_rng([args.seed, ci, TYPES.index(t)])  # the same glitches whichever types run
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
                if not args.no_methods:
                    for m, v in _method_errors(glitched, fixed, report, P0, frames, own_fix, own_pos).items():
                        methods[t][m] += v
                Pg, Pf = glitched.world_positions(), fixed.world_positions()
                b, a, n, left = position_errors(Pg, Pf, P0, frames, own_pos)  # no truth where the clip's own repairs move
                err[t][0] += b
                err[t][1] += a
                err[t][2] += int(n)
                err[t][7] += int(left)
                b, a, n, _ = position_errors(Pg, Pf, P0, frames, np.zeros_like(own_pos))  # every position
                err[t][8] += b
                err[t][9] += a
                err[t][10] += int(n)
                changed = np.any(np.asarray(fixed.rotations) != np.asarray(glitched.rotations), axis=(1, 2))
                changed = np.flatnonzero(changed & ~own_pos.all(axis=1))
                if len(changed):
                    grew = worst_increase(Pg, Pf, P0, changed, own_pos)
                    err[t][3] = max(err[t][3], 100 * float(np.max(grew)))
                    err[t][4] += len(changed)
                    err[t][5] += int(np.sum(grew > 0.01))
                    err[t][6] += len(set(changed.tolist()) & (_beyond_rom(fixed) - base_rom))
        print(f"{clip:26s} {motion.num_frames:6d} {100 * len(flagged) / motion.num_frames:19.2f} {100 * own_fix.mean():9.2f}  " + " ".join(f"{c:>13s}" for c in cells), flush=True)
    print()
    print(f"{'type':11s} {'strict P':>9s} {'injected P':>10s} {'recall':>7s} {'F1':>6s} {'pairs':>6s} {'sub-noise':>9s} {'RMS before':>10s} {'after cm':>8s} {'removed':>7s} {'worst +cm':>9s} {'>1cm worse':>12s} {'beyond ROM':>10s} {'own pos':>7s} {'all pos':>7s}")
    tot = np.zeros(3, int)
    for t in args.types:
        tot += count[t]
        p, r, f = _prf(*count[t])
        pi, _, f = _prf(count[t][0], count[t][1] - own_fp[t], count[t][2])
        b, a, n, w, touched, worse, rom, left, ball, aall, nall = err[t]
        rb, ra = np.sqrt(b / max(1, n)) * 100, np.sqrt(a / max(1, n)) * 100
        # the share removed with every position counted, the clip's own glitches too (the old figure)
        every = f"{1 - np.sqrt(aall / ball):7.1%}" if ball > 0 else f"{'n/a':>7s}"
        print(f"{t:11s} {p:9.3f} {pi:10.3f} {r:7.3f} {f:6.3f} {count[t][0] + count[t][2]:6d} {faint_total[t]:9d} {rb:10.2f} {ra:8.2f} {1 - ra / max(1e-12, rb):7.1%} {w:9.2f} {worse:5d}/{touched:<6d} {rom:10d} {left:7d} {every}")
    p, r, f = _prf(*tot)
    pi, _, f = _prf(tot[0], tot[1] - sum(own_fp.values()), tot[2])
    print(f"{'all':11s} {p:9.3f} {pi:10.3f} {r:7.3f} {f:6.3f} {tot[0] + tot[2]:6d}   (F1 of the injected precision)")
    print("RMS, removed, worst and worse leave out the joint positions the untouched clip's own repairs move (no truth there);"
          " 'own pos' counts those left out of the injected frames, 'all pos' is the share removed with them counted.")
    if not args.no_methods:
        _print_methods(args.types, methods)


if __name__ == "__main__":
    sys.exit(main())
