#!/usr/bin/env python3
"""Compare this checkout's IK with a reference checkout's, clip by clip.

For every shared BVH clip (``../shared/data``) and character, both checkouts
retarget the clip (each in its own subprocess, ``PYTHONPATH`` = the checkout)
and the script prints, per clip and character:

* **max joint difference**: the largest ``|q_this - q_ref|`` over frames and
  hinge/slide joints (radians or metres), the largest root position difference
  (metres) and root rotation difference (radians);
* **QPs per frame**: every QP the frame solver solves (iterations, the first
  frame's settling, the floor projection), counted by wrapping
  ``FrameSolver._solve``;
* **failed line searches per frame**: line searches whose full step was refused
  (the step halved at least once), counted by wrapping
  ``FrameSolver._line_search`` and ``FrameSolver._integrate``;
* **constraint figures** of each output: joint-limit violations, deepest floor
  penetration (mm), deepest self-penetration (mm), frames that needed a
  relaxation, mean IK iterations per frame;
* **quality**: mean tracking error of every target (cm), mean absolute joint
  acceleration (rad/s^2), and the retarget's frames per CPU second (one run: a
  hint only, ``bench_retarget.py`` measures speed).

The wrapping only counts calls; it changes nothing the solver computes.

Usage:  python scripts/compare_solvers.py --ref ../main [--clips a.bvh ...] [--characters humanoid G1.xml]
        [--no-plant] [--frames N] [--set second_order_correction=true]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("PHYSMOCAP_SHARED_DATA", REPO.parent / "shared" / "data"))
G1 = DATA.parent / "robots" / "unitree_g1" / "g1_mocap_29dof.xml"


def _count_calls() -> dict[str, int]:
    """Wrap ``FrameSolver._solve``, ``_line_search`` and ``_integrate`` to count QPs and
    refused full steps; returns the live counters."""
    from physmocap.ik.solver import FrameSolver

    counts = {"qps": 0, "line_searches": 0, "failed_line_searches": 0}
    depth = {"in_search": False, "moves": 0}
    solve, search, integrate = FrameSolver._solve, FrameSolver._line_search, FrameSolver._integrate

    def counted_solve(self, problem):
        counts["qps"] += 1
        return solve(self, problem)

    def counted_search(self, v, *args, **kwargs):
        depth["in_search"], depth["moves"] = True, 0
        try:
            return search(self, v, *args, **kwargs)
        finally:
            depth["in_search"] = False
            counts["line_searches"] += 1
            counts["failed_line_searches"] += depth["moves"] > 1

    def counted_integrate(self, v, alpha):
        if depth["in_search"]:
            depth["moves"] += 1
        return integrate(self, v, alpha)

    FrameSolver._solve, FrameSolver._line_search, FrameSolver._integrate = counted_solve, counted_search, counted_integrate
    return counts


def _worker(clip: str, character: str, plant: bool, frames: int, out: Path, options: dict) -> None:
    """Retarget one clip with counters (and flat retarget ``options``); writes ``out``
    (.npz: qpos) and prints JSON figures."""
    from physmocap.ik.retarget import retarget
    from physmocap.metrics import joint_limit_violations, penetration, self_penetration, smoothness, tracking_errors
    from physmocap.models import load_character
    from physmocap.sources import load_motion

    counts = _count_calls()
    motion = load_motion(DATA / clip)
    if frames:
        motion = motion.slice_frames(0, min(frames, motion.num_frames))
    ch = load_character(character)
    c0 = time.process_time()
    traj = retarget(motion, ch, progress=False, plant=plant, **options)
    cpu = time.process_time() - c0
    n = traj.qpos.shape[0]
    np.savez(out, qpos=traj.qpos)
    figures = {
        "frames": n,
        "qps_per_frame": counts["qps"] / n,
        "failed_ls_per_frame": counts["failed_line_searches"] / n,
        "line_searches_per_frame": counts["line_searches"] / n,
        "iterations_per_frame": float(np.mean(traj.solver.iterations)),
        "relaxed_frames": int(np.count_nonzero(traj.solver.relaxation)),
        "limit_violations": joint_limit_violations(ch.model, traj.qpos)["count"],
        "floor_pen_mm": penetration(ch.model, traj.qpos)["max_mm"],
        "self_pen_mm": self_penetration(ch, traj.qpos)["max_mm"],
        "tracking_cm": tracking_errors(traj)["all_mean_cm"],
        "acc_rad_s2": smoothness(ch.model, traj.qpos, traj.fps)["mean_abs_acc"],
        "cpu_fps": n / cpu,
    }
    print(json.dumps(figures))


def _run(checkout: Path, clip: str, character: str, plant: bool, frames: int, out: Path, options: dict) -> dict:
    """One worker run with ``PYTHONPATH=checkout``."""
    env = dict(os.environ, PYTHONPATH=str(checkout))
    res = subprocess.run(
        [sys.executable, str(Path(__file__).resolve()), "--worker", clip, character, "1" if plant else "0", str(frames),
         str(out), json.dumps(options)],
        env=env, check=True, capture_output=True, text=True,
    )
    return json.loads(res.stdout.strip().splitlines()[-1])


def joint_differences(model, qa: np.ndarray, qb: np.ndarray) -> tuple[float, float, float]:
    """``(hinge/slide max |dq| (rad or m), root position max (m), root rotation max (rad))``."""
    import mujoco

    hinge = [int(model.jnt_qposadr[j]) for j in range(model.njnt)
             if int(model.jnt_type[j]) in (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))]
    dj = float(np.max(np.abs(qa[:, hinge] - qb[:, hinge]))) if hinge else 0.0
    free = [int(model.jnt_qposadr[j]) for j in range(model.njnt) if int(model.jnt_type[j]) == int(mujoco.mjtJoint.mjJNT_FREE)]
    if not free:
        return dj, 0.0, 0.0
    a = free[0]
    dp = float(np.max(np.abs(qa[:, a : a + 3] - qb[:, a : a + 3])))
    ra, rb = qa[:, a + 3 : a + 7], qb[:, a + 3 : a + 7]
    rb = rb * np.where(np.sum(ra * rb, axis=1) < 0.0, -1.0, 1.0)[:, None]  # q and -q: one rotation
    # angle between unit quaternions, stable at 0: 4 asin(|a - b| / 2)
    dr = float(np.max(4.0 * np.arcsin(np.clip(np.linalg.norm(ra - rb, axis=1) / 2.0, 0.0, 1.0))))
    return dj, dp, dr


def main() -> int:
    if len(sys.argv) > 1 and sys.argv[1] == "--worker":
        warnings.simplefilter("ignore")
        clip, character, plant, frames, out, options = sys.argv[2:8]
        _worker(clip, character, plant == "1", int(frames), Path(out), json.loads(options))
        return 0
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--ref", type=Path, required=True, help="reference checkout (e.g. ../main)")
    ap.add_argument("--clips", nargs="+", default=sorted(p.name for p in DATA.glob("*.bvh")))
    ap.add_argument("--characters", nargs="+", default=["humanoid"] + ([str(G1)] if G1.exists() else []))
    ap.add_argument("--no-plant", action="store_true")
    ap.add_argument("--frames", type=int, default=0, help="only the first N frames (0: all)")
    ap.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE",
                    help="flat retarget options for this checkout only, e.g. second_order_correction=true")
    args = ap.parse_args()
    from physmocap.models import load_character

    plant = not args.no_plant
    options = {k: json.loads(v) for k, v in (item.split("=", 1) for item in args.set)}
    cols = ("qps_per_frame", "failed_ls_per_frame", "iterations_per_frame", "relaxed_frames",
            "limit_violations", "floor_pen_mm", "self_pen_mm", "tracking_cm", "acc_rad_s2", "cpu_fps")
    print(f"this {REPO} {options or ''} vs reference {args.ref}; {'planting' if plant else 'no planting'}")
    print(f"{'clip':28s} {'character':16s} {'max dq':>9s} {'root m':>9s} {'root rad':>9s}  "
          + "  ".join(f"{c} this/ref" for c in cols))
    worst = 0.0
    with tempfile.TemporaryDirectory() as tmp:
        for character in args.characters:
            model = load_character(character).model
            for clip in args.clips:
                ours = _run(REPO, clip, character, plant, args.frames, Path(tmp) / "this.npz", options)
                ref = _run(args.ref, clip, character, plant, args.frames, Path(tmp) / "ref.npz", {})
                qa, qb = np.load(Path(tmp) / "this.npz")["qpos"], np.load(Path(tmp) / "ref.npz")["qpos"]
                dj, dp, dr = joint_differences(model, qa, qb)
                worst = max(worst, dj, dr)
                label = Path(character).stem
                figs = "  ".join(f"{ours[c]:.3g}/{ref[c]:.3g}" for c in cols)
                print(f"{clip:28s} {label:16s} {dj:9.2e} {dp:9.2e} {dr:9.2e}  {figs}", flush=True)
    print(f"largest joint difference: {worst:.3e} rad")
    return 0


if __name__ == "__main__":
    sys.exit(main())
