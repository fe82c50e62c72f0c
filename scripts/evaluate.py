#!/usr/bin/env python3
"""Quality of the retargeting on the shared clips: the figures the README quotes.

For every shared BVH clip (../shared/data) and bundled character, retargets
with the default options and prints, with physmocap.metrics (definitions in
docs/metrics.md): stance foot skating (mean, p95 cm/s), floor
penetration (max mm), hovering in contact (median, p95 mm), flat feet (the highest
contact site of a foot the actor has flat: median mm, share of frames over 1 cm), joint-limit and
velocity-limit violations, and the tracking error of ankles, knees, wrists and
elbows (feet counted outside their contacts), next to the source's own
skating.

Usage:  python scripts/evaluate.py [--characters humanoid robot] [--clips ...]
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
CLIPS = ["cmu_12_01_walk.bvh", "pymo_walk.bvh", "cmu_01_01_jumps.bvh", "optitrack_hops_crouch.bvh"]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--characters", nargs="+", default=["humanoid", "robot"])
    ap.add_argument("--clips", nargs="+", default=None,
                    help="file names in the data folder, .bvh optional (default: the four the README quotes)")
    args = ap.parse_args()
    clips = resolve_clips(DATA, args.clips, CLIPS, "evaluate")  # a named clip not there: status 2, before any work
    warnings.simplefilter("ignore")

    from physmocap import metrics
    from physmocap.ik.retarget import map_motion, retarget
    from physmocap.models import load_character
    from physmocap.sources import load_motion

    head = (
        f"{'clip':26s} {'character':9s} {'src skate':>9s} {'skate mean':>10s} {'p95':>5s} {'pen max':>7s}"
        f" {'hover med':>9s} {'p95':>5s} {'flat med':>8s} {'>1cm %':>6s} {'lim':>3s} {'vel':>3s} {'track cm':>8s} {'self mm':>7s}"
    )
    print(head)
    for path in clips:
        clip = path.name
        motion = load_motion(path)
        src = metrics.source_skating(motion, map_motion(motion))["mean_cm_s"]
        for name in args.characters:
            ch = load_character(name)
            traj = retarget(motion, ch, progress=False)
            sk = metrics.character_skating(traj)
            hv = metrics.character_hovering(traj, traj.contacts)
            fl = metrics.character_flat_feet(traj, traj.contacts)
            pen = metrics.penetration(ch.model, traj.qpos)["max_mm"]
            lim = metrics.joint_limit_violations(ch.model, traj.qpos)["count"]
            vel = metrics.velocity_violations(ch.model, traj.qpos, traj.fps, ch.velocity_limits, groups=ch.velocity_groups)["count"]
            trk = metrics.tracking_errors(traj, metrics.outside_stance_mask(traj))["key_joints_mean_cm"]
            selfpen = metrics.self_penetration(ch, traj.qpos)["max_mm"]
            print(
                f"{clip:26s} {name:9s} {src:9.1f} {sk['mean_cm_s']:10.2f} {sk['p95_cm_s']:5.2f} {pen:7.2f}"
                f" {hv['median_mm']:9.2f} {hv['p95_mm']:5.1f} {fl['median_mm']:8.1f} {100 * fl['share_over_band']:6.1f}"
                f" {lim:3d} {vel:3d} {trk:8.2f} {selfpen:7.2f}"
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
