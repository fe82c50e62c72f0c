"""Peak joint angular speeds in the shared real recordings vs the humanoid's velocity limits.

Usage: python scripts/joint_speeds.py [BVH ...]   (default: the BVH files in ../shared/data)

For every BVH joint, the local rotation speed |w| = 2 acos(|<q_t, q_t+1>|) * fps is
computed per frame; the table prints its median, 99.9th percentile and maximum in
deg/s next to the smallest velocity limit of the humanoid hinges of that joint
(physmocap/models/velocity.py).  A hinge's speed never exceeds |w| for a one-axis
motion, so a 99.9th percentile below the smallest limit means real capture of that
joint is not clipped.
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

import numpy as np

from physmocap.models.velocity import PEAK_VELOCITY_DEG_S
from physmocap.sources import load_motion

SHARED = Path(__file__).resolve().parents[2] / "shared" / "data"

#: BVH joint name pattern -> humanoid hinge stems moved by that joint.
GROUPS = [
    (r"upleg|thigh|hip(?!s)", ["hip_flexion", "hip_adduction", "hip_rotation"]),
    (r"toe", ["toe_extension"]),
    (r"foot|ankle", ["ankle_dorsiflexion", "ankle_inversion"]),
    (r"leg|knee|shin", ["knee_flexion"]),
    (r"forearm|elbow", ["elbow_flexion", "forearm_pronation"]),
    (r"hand|wrist", ["wrist_flexion", "wrist_deviation"]),
    (r"shoulder|clavicle|collar", ["clavicle_elevation", "clavicle_protraction"]),
    (r"arm", ["shoulder_flexion", "shoulder_abduction", "shoulder_rotation"]),
    (r"neck", ["neck_flexion", "neck_lateral_flexion", "neck_rotation"]),
    (r"head", ["head_flexion", "head_lateral_flexion", "head_rotation"]),
    (r"spine|back|chest", ["lumbar_flexion", "lumbar_lateral_flexion", "lumbar_rotation"]),
]


def group_of(name: str) -> list[str] | None:
    n = name.lower()
    if "thumb" in n or "finger" in n or "index" in n or "end" in n or n.startswith("lhipjoint") or n.startswith("rhipjoint"):
        return None
    for pattern, stems in GROUPS:
        if re.search(pattern, n):
            return stems
    return None


def joint_speeds(path: Path) -> list[tuple[str, float, float, float, float]]:
    """(joint, median, p99.9, max, smallest limit) in deg/s for every mapped joint."""
    motion = load_motion(path)
    q = motion.rotations
    dots = np.abs(np.sum(q[1:] * q[:-1], axis=-1)).clip(0.0, 1.0)
    speed = np.degrees(2.0 * np.arccos(dots)) * motion.fps  # (F-1, J)
    rows = []
    for j, name in enumerate(motion.skeleton.names):
        stems = group_of(name)
        if stems is None or motion.skeleton.end_site[j]:
            continue
        limit = min(PEAK_VELOCITY_DEG_S[s][0] for s in stems)
        s = speed[:, j]
        rows.append((name, float(np.median(s)), float(np.percentile(s, 99.9)), float(s.max()), limit))
    return rows


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("bvh", nargs="*", type=Path, help="BVH files (default: every .bvh in ../shared/data)")
    args = ap.parse_args(argv)
    from physmocap.errors import PhysmocapError

    paths = args.bvh or sorted(SHARED.glob("*.bvh"))
    if not paths:
        print(f"joint_speeds: no BVH given and none in {SHARED}", file=sys.stderr)
        return 2
    for path in paths:
        try:
            rows = joint_speeds(path)
        except PhysmocapError as exc:
            print(f"joint_speeds: {exc}", file=sys.stderr)
            return 1
        print(f"\n{path.name}")
        print(f"  {'joint':<16} {'median':>8} {'p99.9':>8} {'max':>8} {'limit':>8}   (deg/s)")
        for name, med, p999, mx, limit in rows:
            flag = "  <-- above" if p999 > limit else ""
            print(f"  {name:<16} {med:8.0f} {p999:8.0f} {mx:8.0f} {limit:8.0f}{flag}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
