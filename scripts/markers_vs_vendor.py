#!/usr/bin/env python3
"""Marker-derived joint centres against the capture vendor's solved skeleton.

../shared/data/cmu_01_01_markers.c3d and cmu_01_01_jumps.bvh are the same take: the
markers, and the skeleton CMU solved from them.  This script computes physmocap's joint
centres from the markers (physmocap.markers), finds the time offset between the files
(the lag minimising the distance, +-1 s), fits one rigid transform (rotation, translation)
of the vendor's joints onto physmocap's over the whole take (Kabsch), and prints the mean
distance per joint and the knee/elbow flexion angle differences.  Also the joint-centre
speed in frames per second.

Usage:  python scripts/markers_vs_vendor.py
"""

from __future__ import annotations

import os
import sys
import time
import warnings
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("PHYSMOCAP_SHARED_DATA", REPO.parent / "shared" / "data"))
JOINTS = ["left_hip", "right_hip", "left_knee", "right_knee", "left_ankle", "right_ankle",
          "left_shoulder", "right_shoulder", "left_elbow", "right_elbow", "left_wrist", "right_wrist"]


def kabsch(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """R, t minimising |R a + t - b| over rows (N, 3)."""
    ma, mb = a.mean(0), b.mean(0)
    U, _, Vt = np.linalg.svd((b - mb).T @ (a - ma))
    D = np.diag([1, 1, np.sign(np.linalg.det(U @ Vt))])
    R = U @ D @ Vt
    return R, mb - R @ ma


def angle(a, b, c) -> np.ndarray:
    u, v = a - b, c - b
    cos = np.sum(u * v, -1) / (np.linalg.norm(u, axis=-1) * np.linalg.norm(v, axis=-1))
    return np.degrees(np.arccos(np.clip(cos, -1, 1)))


def main() -> int:
    warnings.simplefilter("ignore")
    from physmocap.ik.retarget import map_motion
    from physmocap.sources import load_motion

    c3d, bvh = DATA / "cmu_01_01_markers.c3d", DATA / "cmu_01_01_jumps.bvh"
    if not (c3d.exists() and bvh.exists()):
        print(f"skip: {c3d} or {bvh} not found", file=sys.stderr)
        return 0
    t0 = time.process_time()
    ours = load_motion(c3d)
    dt = time.process_time() - t0
    vendor = load_motion(bvh)
    oi, vi = map_motion(ours), map_motion(vendor)
    A = ours.world_positions()[:, [oi[j] for j in JOINTS]]
    B = vendor.world_positions()[:, [vi[j] for j in JOINTS]]
    best = None
    for lag in range(-120, 121):
        a = A[max(0, lag):]
        b = B[max(0, -lag):]
        n = min(len(a), len(b))
        a, b = a[:n:10].reshape(-1, 3), b[:n:10].reshape(-1, 3)
        ok = np.all(np.isfinite(a), 1) & np.all(np.isfinite(b), 1)
        R, t = kabsch(b[ok], a[ok])
        err = np.mean(np.linalg.norm(b[ok] @ R.T + t - a[ok], axis=1))
        if best is None or err < best[0]:
            best = (err, lag, R, t)
    _, lag, R, t = best
    a = A[max(0, lag):]
    b = B[max(0, -lag):]
    n = min(len(a), len(b))
    a, b = a[:n], b[:n] @ R.T + t
    d = np.linalg.norm(a - b, axis=-1) * 100
    print(f"time offset {lag} frames; joint-centre speed {ours.num_frames / dt:.0f} frames/s CPU (whole reader)")
    for k, j in enumerate(JOINTS):
        print(f"{j:15s} {np.nanmean(d[:, k]):5.1f} cm mean  {np.nanpercentile(d[:, k], 95):5.1f} cm p95")
    print(f"{'all':15s} {np.nanmean(d):5.1f} cm mean")
    col = {j: k for k, j in enumerate(JOINTS)}
    for s in ("left", "right"):
        for name, (p, m, q) in {"knee": ("hip", "knee", "ankle"), "elbow": ("shoulder", "elbow", "wrist")}.items():
            ia, ib, ic = (col[f"{s}_{x}"] for x in (p, m, q))
            diff = np.abs(angle(a[:, ia], a[:, ib], a[:, ic]) - angle(b[:, ia], b[:, ib], b[:, ic]))
            print(f"{s}_{name} flexion difference {np.nanmean(diff):5.1f} deg mean")
    return 0


if __name__ == "__main__":
    sys.exit(main())
