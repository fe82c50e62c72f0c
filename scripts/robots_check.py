#!/usr/bin/env python3
"""Retarget walks onto humanoid robots the project does not ship, with no mapping file (issue 13).

Each robot MJCF under ROBOTS (a folder given on the command line, for example a checkout of
MuJoCo Menagerie: nothing of it is bundled) is loaded as `physmocap retarget --character`
loads a model with no mapping beside it, with the mapping `physmocap character init`
proposes, and the clips are retargeted with the default options.  One line per robot and
clip: the worst segment's median direction error and which, the facing error p95, the share
of frames with any segment more than 45 degrees off, and the contact points found on the feet;
or the one-line error a model gets.  Without the folder (or with none of the models in it),
it says so on stderr and exits 0: nothing to check.

Usage:  python scripts/robots_check.py ROBOTS [--models unitree_h1/h1.xml ...] [--clips pymo_walk cmu_12_01_walk]
        [--frames N]
"""

from __future__ import annotations

import argparse
import os
import sys
import warnings
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("PHYSMOCAP_SHARED_DATA", REPO.parent / "shared" / "data"))

#: Menagerie's humanoids with arms and legs, the model file with the bodies (not scene.xml)
MODELS = (
    "unitree_g1/g1.xml",
    "unitree_h1/h1.xml",
    "booster_t1/t1.xml",
    "apptronik_apollo/apptronik_apollo.xml",
    "fourier_n1/n1.xml",
    "bxi_elf2/elf2_dof25.xml",
    "atlas/atlas.xml",
    "berkeley_humanoid/berkeley_humanoid.xml",
)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("robots", nargs="?", default=None, help="folder holding the models (a Menagerie checkout)")
    ap.add_argument("--models", nargs="+", default=list(MODELS), help="model files relative to the folder")
    ap.add_argument("--clips", nargs="+", default=["pymo_walk", "cmu_12_01_walk"], help="BVH clips in the data folder")
    ap.add_argument("--frames", type=int, default=None, help="retarget only the first N frames of each clip")
    args = ap.parse_args()
    if args.robots is None or not Path(args.robots).is_dir():
        print(f"robots_check: no robot folder{'' if args.robots is None else ' ' + args.robots}: nothing to check",
              file=sys.stderr)
        return 0
    root = Path(args.robots)
    found = [m for m in args.models if (root / m).is_file()]
    if not found:
        print(f"robots_check: none of the models under {root}: nothing to check", file=sys.stderr)
        return 0
    clips = []
    for c in args.clips:
        p = DATA / (c if c.endswith(".bvh") else c + ".bvh")
        if not p.is_file():
            print(f"robots_check: error: clip not found: {p}", file=sys.stderr)
            return 2
        clips.append(p)

    from physmocap import load_motion
    from physmocap.errors import PhysmocapError
    from physmocap.ik.retarget import retarget
    from physmocap.metrics.fidelity import trajectory_fidelity
    from physmocap.models import load_character

    warnings.simplefilter("ignore")
    print(f"{'model':<42} {'clip':<16} {'worst segment median':<30} {'facing p95':>10} {'> 45 deg':>9}  feet")
    for m in found:
        try:
            ch = load_character(root / m)
        except PhysmocapError as exc:
            print(f"{m:<42} {'-':<16} error: {' '.join(str(exc).split())}")
            continue
        feet = ",".join(f"{side}:{len(pts)}" for side, pts in sorted(ch.contacts.items()))
        for clip in clips:
            traj = retarget(load_motion(clip), ch, progress=False, end=args.frames)
            fid = trajectory_fidelity(traj)
            name, seg = max(fid.segments.items(), key=lambda kv: kv[1].median_deg)
            face = "-" if fid.facing_p95_deg is None else f"{fid.facing_p95_deg:.1f}"
            print(f"{m:<42} {clip.stem:<16} {name + f' {seg.median_deg:.1f}':<30} {face:>10} "
                  f"{100 * fid.share_any_over_45:>8.1f}%  {feet}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
