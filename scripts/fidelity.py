#!/usr/bin/env python3
"""Fidelity of the retargeting on the shared clips: does the character do what the actor does?

For every BVH clip in ../shared/data and each bundled character, retargets with
the default options and prints the figures of physmocap.metrics.fidelity
(definitions in docs/metrics.md): worst segment direction error (median over
frames, of the worst segment), share of frames with any segment over 45 degrees,
facing error (median, p95), pelvis path deviation after a similarity fit (mean,
max cm) and its drift from its target with no fit (mean cm), the pelvis's vertical speed against the actor's (p99 m/s), velocity-cap
saturation (any joint, and the worst single joint), mean absolute joint acceleration with planting against the same
clip retargeted with planting off, slip and scuffing, and pops (frames on which a joint jumps more than 2 cm
beyond the actor's, and the largest, cm).

``--stream`` retargets causally, frame by frame, as ``physmocap replay`` does.

Usage:  python scripts/fidelity.py [--characters humanoid robot] [--clips ...] [--frames N] [--stream]
"""

from __future__ import annotations

import argparse
import os
import sys
import warnings
from pathlib import Path

from _clips import resolve_clips
REPO = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("PHYSMOCAP_SHARED_DATA", REPO.parent / "shared" / "data"))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--characters", nargs="+", default=["humanoid", "robot"])
    ap.add_argument("--clips", nargs="+", default=None, help="file names in the data folder, .bvh optional (default: every .bvh)")
    ap.add_argument("--frames", type=int, default=None, help="retarget only the first N frames of each clip")
    ap.add_argument("--no-plant-ratio", action="store_true", help="also retarget with planting off for the jerk ratio")
    ap.add_argument("--stream", action="store_true", help="retarget causally, frame by frame (physmocap.ik.stream.stream_motion)")
    args = ap.parse_args()
    every = sorted(p.name for p in DATA.glob("*.bvh"))
    clips = resolve_clips(DATA, args.clips, every, "fidelity")  # a named clip not there: status 2, before any work
    warnings.simplefilter("ignore")

    from physmocap.ik.retarget import retarget
    from physmocap.ik.stream import stream_motion
    from physmocap.metrics import smoothness
    from physmocap.metrics.fidelity import trajectory_fidelity
    from physmocap.models import load_character
    from physmocap.sources import load_motion

    print(
        f"{'clip':26s} {'char':8s} {'seg med':>7s} {'worst':>14s} {'>45%':>5s} {'face med':>8s} {'p95':>5s}"
        f" {'path cm':>7s} {'max':>5s} {'drift':>5s} {'vz':>5s} {'vz act':>6s} {'sat%':>5s} {'1jt%':>5s} {'acc':>6s} {'ratio':>5s} {'slip':>5s} {'gslip':>5s} {'scuf%':>5s} {'pops':>4s} {'popcm':>5s}"
    )
    for path in clips:
        clip = path.name
        motion = load_motion(path)
        end = args.frames
        for name in args.characters:
            ch = load_character(name)
            if args.stream:
                traj = stream_motion(motion if end is None else motion.slice_frames(0, min(end, motion.num_frames)), ch)
            else:
                traj = retarget(motion, ch, progress=False, end=end)
            fid = trajectory_fidelity(traj)
            worst = max(fid.segments.items(), key=lambda kv: kv[1].median_deg)
            acc = smoothness(ch.model, traj.qpos, traj.fps)["mean_abs_acc"]
            ratio = float("nan")
            if args.no_plant_ratio:
                free = stream_motion(motion, ch, plant=False) if args.stream else retarget(motion, ch, progress=False, end=end, plant=False)
                ratio = acc / max(smoothness(ch.model, free.qpos, free.fps)["mean_abs_acc"], 1e-9)
            print(
                f"{clip:26s} {name:8s} {worst[1].median_deg:7.1f} {worst[0]:>14s} {100 * fid.share_any_over_45:5.1f}"
                f" {fid.facing_median_deg:8.1f} {fid.facing_p95_deg:5.1f} {fid.path_mean_cm:7.1f} {fid.path_max_cm:5.1f} {fid.drift_mean_cm if fid.drift_mean_cm is not None else float('nan'):5.1f}"
                f" {fid.pelvis_vz_p99:5.2f} {fid.actor_vz_p99_scaled:6.2f} {100 * fid.saturated_share:5.1f}"
                f" {100 * fid.saturated_joint_share:5.1f} {acc:6.1f} {ratio:5.2f} {fid.floor.slip_mean_cm_s:5.2f} {fid.floor.geom_slip_mean_cm_s:5.2f} {100 * fid.floor.scuff_share:5.1f}"
                f" {fid.pops.frames.size if fid.pops else 0:4d} {fid.pops.worst_cm if fid.pops else float('nan'):5.1f}",
                flush=True,
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
