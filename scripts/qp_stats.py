#!/usr/bin/env python3
"""Where a retarget's QPs go: per pass, per clip and character, what the solver did.

For every clip and character the script retargets with the default configuration and
counts, per pass (first pass, arm passes, the pass that smooths contact changes) and per
frame:

* **QPs** by caller: the iterations' steps, the hinge groups' re-solve
  (``GroupStepLimit.crossed``), the second-order correction, the floor projection,
  frame 0's settling;
* **iterations** and why they stopped: converged (last step below ``tolerance``, every
  hard constraint held), at the iteration cap with the hard constraints held, or after the
  extra iterations with one still off (which one: floor, planted contacts, self-collision);
* **line searches**: trials per search, searches whose full step was refused (halved at least
  once), why each refused trial was refused (the planted contacts' residual or the floor's
  above the bound), and searches that ended by rejecting the step.

The counters only wrap the solver's methods; they change nothing it computes.

Usage:  python scripts/qp_stats.py [--clips cmu_12_01_walk pymo_walk] [--characters humanoid robot]
        [--frames N] [--per-frame out.json] [--set contact_overshoot=0.0005]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
import warnings
from collections import Counter
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("PHYSMOCAP_SHARED_DATA", REPO.parent / "shared" / "data"))


class Recorder:
    """Wraps ``FrameSolver``'s methods and ``retarget._track``; keeps per-pass counters."""

    def __init__(self) -> None:
        import importlib

        rt = importlib.import_module("physmocap.ik.retarget")
        from physmocap.ik.solver import FrameSolver

        self.passes: list[dict] = []
        self.frames: list[dict] = []  # per frame of the current pass
        self.frame: dict | None = None
        self.caller = "step"
        self.search: dict | None = None
        rec = self
        S = FrameSolver
        orig = {n: getattr(S, n) for n in ("_solve", "_line_search", "_accept", "_iterate", "solve_frame",
                                           "_project_floor", "_settle_from_rest", "_corrected", "_step")}
        track = rt._track

        def tracked(*a, **k):
            rec.frames = []
            rec.passes.append({"label": k.get("label", "retarget"), "frames": rec.frames})
            return track(*a, **k)

        rt._track = tracked

        def solve(self, problem):
            if rec.frame is not None:
                rec.frame["qps"][rec.caller] += 1
            return orig["_solve"](self, problem)

        def step(self, level):
            tag = "settle" if rec.caller == "settle" else "step"
            prev, rec.caller = rec.caller, tag
            n0 = rec.frame["qps"][tag] if rec.frame is not None else 0
            try:
                v = orig["_step"](self, level)
            finally:
                if rec.frame is not None and rec.frame["qps"][tag] - n0 > 1:
                    # the second solve of one step: the same QP with the hinge groups' rows
                    rec.frame["qps"][tag] -= 1
                    rec.frame["qps"]["group"] += 1
                rec.caller = prev
            if rec.frame is not None and tag == "step":
                rec.frame["steps"].append(float(np.abs(v).max()))
            return v

        def wrap_caller(name, tag):
            def f(self, *a, **k):
                prev, rec.caller = rec.caller, tag
                try:
                    return orig[name](self, *a, **k)
                finally:
                    rec.caller = prev
            return f

        def line_search(self, v, *a, **k):
            rec.search = {"trials": 0, "contact": 0, "floor": 0, "v": float(np.abs(v).max()), "res": [], "bound": None}
            q0 = self.configuration.data.qpos.copy()
            try:
                return orig["_line_search"](self, v, *a, **k)
            finally:
                s = rec.search
                rec.search = None
                if rec.frame is not None:
                    f = rec.frame
                    f["searches"] += 1
                    f["trials"] += s["trials"]
                    refused = s["contact"] + s["floor"]
                    f["failed"] += refused > 0
                    f["refused_contact"] += s["contact"]
                    f["refused_floor"] += s["floor"]
                    if np.array_equal(self.configuration.data.qpos, q0) and np.abs(v).max() > 0:
                        f["rejected"] += 1
                    f["log"].append(s)

        def accept(self, bound):
            ok = orig["_accept"](self, bound)
            if rec.search is not None:
                rec.search["trials"] += 1
                rec.search["bound"] = bound
                rec.search["res"].append(self._residuals()[0])
                if not ok:
                    rc = self._contact_residual()
                    rec.search["contact" if rc > bound else "floor"] += 1
            return ok

        def iterate(self, total, iters, base):
            it, worst, conv = orig["_iterate"](self, total, iters, base)
            if rec.frame is not None:
                if conv:
                    why = "converged"
                elif worst == 5:
                    why = "failed"
                elif it < total or (self._floor_ok() and self._constraints_ok() and self._apart_ok()):
                    why = "cap"
                else:
                    off = [n for n, ok in (("floor", self._floor_ok()), ("contacts", self._constraints_ok()),
                                           ("apart", self._apart_ok())) if not ok]
                    why = "extra:" + "+".join(off)
                rec.frame["stops"].append(why)
            return it, worst, conv

        def solve_frame(self, *a, **k):
            rec.frame = {"qps": Counter(), "steps": [], "searches": 0, "trials": 0, "failed": 0,
                         "refused_contact": 0, "refused_floor": 0, "rejected": 0, "stops": [], "log": []}
            out = orig["solve_frame"](self, *a, **k)
            rec.frame["iterations"] = int(out[1])
            rec.frame["level"] = int(out[2])
            self._res_cache = None
            rec.frame["residual"] = float(self._residuals()[0])
            rec.frames.append(rec.frame)
            rec.frame = None
            return out

        S._solve, S._step, S._line_search, S._accept, S._iterate, S.solve_frame = (
            solve, step, line_search, accept, iterate, solve_frame)
        S._project_floor = wrap_caller("_project_floor", "floor_projection")
        S._settle_from_rest = wrap_caller("_settle_from_rest", "settle")
        S._corrected = wrap_caller("_corrected", "correction")


def summarise(passes: list[dict], n: int) -> dict:
    """Totals over all passes (per clip frame) and per pass (per pass frame)."""
    out = {"passes": []}
    tot = Counter()
    for p in passes:
        fr = p["frames"]
        m = len(fr)
        qps = Counter()
        stops = Counter()
        for f in fr:
            qps.update(f["qps"])
            stops.update(f["stops"])
        keys = ("searches", "trials", "failed", "refused_contact", "refused_floor", "rejected", "iterations")
        sums = {k: sum(f[k] for f in fr) for k in keys}
        allq = sum(qps.values())
        steps = np.array([len(f["steps"]) for f in fr])
        out["passes"].append({
            "label": p["label"], "frames": m, "qps_per_frame": allq / m,
            "qps_by_caller": {k: v / m for k, v in sorted(qps.items())},
            **{f"{k}_per_frame": v / m for k, v in sums.items()},
            "stops": dict(stops),
            "frames_at_4+_steps": int(np.count_nonzero(steps >= 4)),
            "residual_max": max(f["residual"] for f in fr),
            "residual_over_tolerance": sum(f["residual"] > 5e-5 for f in fr),
        })
        tot["qps"] += allq
        for k in ("failed", "rejected", "searches"):
            tot[k] += sums[k]
    out["qps_per_frame"] = tot["qps"] / n
    out["failed_per_frame"] = tot["failed"] / n
    out["rejected_per_frame"] = tot["rejected"] / n
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--clips", nargs="+", default=["cmu_12_01_walk", "pymo_walk"])
    ap.add_argument("--characters", nargs="+", default=["humanoid", "robot"])
    ap.add_argument("--frames", type=int, default=0, help="only the first N frames (0: all)")
    ap.add_argument("--per-frame", type=Path, help="write every frame's record (JSON) here")
    ap.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE", help="flat retarget options")
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    from physmocap.ik.config import RetargetConfig
    from physmocap.ik.retarget import retarget
    from physmocap.models import load_character
    from physmocap.sources import load_motion

    options = {k: json.loads(v) for k, v in (item.split("=", 1) for item in args.set)}
    rec = Recorder()
    dump = {}
    for clip in args.clips:
        motion = load_motion(DATA / (clip if clip.endswith(".bvh") else clip + ".bvh"))
        if args.frames:
            motion = motion.slice_frames(0, min(args.frames, motion.num_frames))
        for name in args.characters:
            ch = load_character(name)
            rec.passes = []
            c0 = time.process_time()
            traj = retarget(motion, ch, RetargetConfig().with_options(**options), progress=False)
            cpu = time.process_time() - c0
            n = traj.qpos.shape[0]
            s = summarise(rec.passes, n)
            print(f"== {clip} {name}: {n} frames, {s['qps_per_frame']:.3f} QPs/frame, "
                  f"{s['failed_per_frame']:.3f} failed line searches/frame, {s['rejected_per_frame']:.3f} rejected, "
                  f"{n / cpu:.0f} frames/CPU s")
            for p in s["passes"]:
                print(f"  {p['label']}: {p['frames']} frames, QPs {p['qps_per_frame']:.3f} {p['qps_by_caller']}")
                print(f"    iterations {p['iterations_per_frame']:.3f}, searches {p['searches_per_frame']:.3f}, "
                      f"trials {p['trials_per_frame']:.3f}, failed {p['failed_per_frame']:.3f} "
                      f"(refused trials: contacts {p['refused_contact_per_frame']:.3f}, floor "
                      f"{p['refused_floor_per_frame']:.3f}), rejected {p['rejected_per_frame']:.3f}")
                print(f"    stops {p['stops']}, frames with >= 4 steps {p['frames_at_4+_steps']}, planted contacts' "
                      f"residual at the frame's end: max {p['residual_max'] * 1e3:.3f} mm, "
                      f"{p['residual_over_tolerance']} frames over 0.05 mm")
            dump[f"{clip}/{name}"] = [{"label": p["label"], "frames": p["frames"]} for p in rec.passes]
    if args.per_frame:
        args.per_frame.write_text(json.dumps(dump, default=lambda o: dict(o)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
