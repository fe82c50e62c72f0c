#!/usr/bin/env python3
"""Marker-derived joint centres against the capture vendor's solved skeleton.

../shared/data/cmu_01_01_markers.c3d and cmu_01_01_jumps.bvh are the same take: the
markers, and the skeleton CMU solved from them.  This script compares three sets of
physmocap joint centres with the vendor's joints:

* ``regression``: anatomical regression only (physmocap.markers.joints);
* ``functional``: functional centres where the take exercises the joint (what
  ``load_motion(take.c3d, solve=False)`` returns; physmocap.markers.functional);
* ``solved``: the joint centres of the actor skeleton solved by marker-driven IK
  (``physmocap solve``; physmocap.markers.solve), with the marker residuals.

For each, it finds the time offset between the files (the lag minimising the distance, +-1 s),
fits one rigid transform (rotation, translation) of the vendor's joints onto physmocap's over
the whole take (Kabsch), and prints the mean distance per joint and the knee/elbow flexion
angle differences (the issue's measure).

Is that comparison apples to apples?  Two things differ besides the tracking:

1. The vendor's BVH is not a sound reference above the pelvis: the AMC-to-BVH conversion drops
   the length of every ASF bone with several children (``Neck``, ``LeftShoulder``,
   ``RightShoulder``, ``LeftFingerBase``, ``LThumb``... have zero offsets), so the neck and
   both arms hang from the *base* of CMU's ``thorax`` bone (the reference checks printed last
   show it: the vendor's head top below the head markers, its shoulder joints far below the
   acromion markers), and its ``LeftHand`` is the start of CMU's ``lwrist`` bone, a forearm
   twist segment, not the wrist.  A dropped bone is a constant vector in its parent's frame
   (``Spine1``'s for the thorax: it moves every arm joint; ``LeftHand``'s for the wrist).
2. Each skeleton places its joint centres by its own model (physmocap: Harrington hips,
   lateral markers moved medially by a half-width, Rab shoulders; the vendor: CMU's Vicon
   BodyBuilder model, unpublished here): a different definition is a constant offset of the
   joint in its segment's frame.

So the second table aligns on the legs only (the joints the vendor defines soundly), and the
third, ``definition-free``, removes by least squares one constant vector per joint in the
frame of the vendor segment that ends at it (3 numbers per joint over the whole take; for
the elbows and wrists one more in the vendor's thorax frame, for the dropped bone; CMU's
clavicles never turn against the thorax, so a shoulder's segment frame is the thorax's) and
prints those vectors' lengths beside what remains: the difference in how the joints *move*,
which no definition explains.  A point anywhere on the vendor's segment passes that test,
so the third table measures tracking, not placement; the placement differences are the
vectors themselves, from the two models (neither is the anatomical truth), and where a
joint has two, the split between them is not determined when the arm moves little against
the trunk.

Usage:  python scripts/markers_vs_vendor.py [--frames N] [--only regression,functional,solved]
"""

from __future__ import annotations

import argparse
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
ANGLES = {"knee": ("hip", "knee", "ankle"), "elbow": ("shoulder", "elbow", "wrist")}


def kabsch(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """R, t minimising |R a + t - b| over rows (N, 3): the calibration's rigid fit, one frame."""
    from physmocap.markers.functional import kabsch as rigid_fit

    R, t = rigid_fit(a, b[None], np.ones((1, len(a))))
    return R[0], t[0]


def angle(a, b, c) -> np.ndarray:
    u, v = a - b, c - b
    cos = np.sum(u * v, -1) / (np.linalg.norm(u, axis=-1) * np.linalg.norm(v, axis=-1))
    return np.degrees(np.arccos(np.clip(cos, -1, 1)))


def align(A: np.ndarray, B: np.ndarray, fit: list[int] | None = None) -> tuple[int, np.ndarray, np.ndarray]:
    """``(lag, R, t)``: the time offset (frames, +-1 s) and the rigid transform of the vendor's
    ``B`` onto ``A`` (both ``(F, 12, 3)``) that minimise the mean distance over the joints
    ``fit`` (all by default), every 10th frame."""
    best = None
    cols = list(range(A.shape[1])) if fit is None else fit
    for lag in range(-120, 121):
        a = A[max(0, lag):]
        b = B[max(0, -lag):]
        n = min(len(a), len(b))
        a, b = a[:n:10, cols].reshape(-1, 3), b[:n:10, cols].reshape(-1, 3)
        ok = np.all(np.isfinite(a), 1) & np.all(np.isfinite(b), 1)
        R, t = kabsch(b[ok], a[ok])
        err = np.mean(np.linalg.norm(b[ok] @ R.T + t - a[ok], axis=1))
        if best is None or err < best[0]:
            best = (err, lag, R, t)
    return best[1], best[2], best[3]


def matched(A: np.ndarray, B: np.ndarray, lag: int, R: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``A`` and the vendor's ``B`` on common frames (``lag``), ``B`` moved by ``R``, ``t``."""
    a = A[max(0, lag):]
    b = B[max(0, -lag):]
    n = min(len(a), len(b))
    return a[:n], b[:n] @ R.T + t


def flexion_differences(a: np.ndarray, b: np.ndarray) -> dict[str, float]:
    """Mean absolute difference (degrees) of the knee and elbow angles of ``a`` and ``b``."""
    col = {j: k for k, j in enumerate(JOINTS)}
    angles = {}
    for s in ("left", "right"):
        for name, (p, m, q) in ANGLES.items():
            ia, ib, ic = (col[f"{s}_{x}"] for x in (p, m, q))
            angles[f"{s}_{name}"] = float(np.nanmean(np.abs(angle(a[:, ia], a[:, ib], a[:, ic]) - angle(b[:, ia], b[:, ib], b[:, ic]))))
    return angles


def compare(A: np.ndarray, B: np.ndarray, fit: list[int] | None = None) -> dict:
    """Distances (m) per joint and flexion differences (deg) of ``A`` (F, 12, 3) against the
    vendor's ``B`` after the best lag and one rigid transform fitted on the joints ``fit``
    (all by default)."""
    lag, R, t = align(A, B, fit)
    a, b = matched(A, B, lag, R, t)
    d = np.linalg.norm(a - b, axis=-1)
    return {"lag": lag, "mean": {j: float(np.nanmean(d[:, k])) for k, j in enumerate(JOINTS)},
            "p95": {j: float(np.nanpercentile(d[:, k], 95)) for k, j in enumerate(JOINTS)},
            "all": float(np.nanmean(d)), "angles": flexion_differences(a, b)}


def compare_definition_free(A: np.ndarray, B: np.ndarray, vendor, joint_index: dict[str, int],
                            legs: list[int]) -> dict:
    """:func:`compare`'s figures (aligned on the legs) after :func:`definition_free` per joint,
    with the removed vectors (``"offsets"``: joint -> ``(length, component along the bone)``
    in cm, the segment's, then for the elbows and wrists the thorax's, along the back) and
    the flexion differences of the corrected vendor joints."""
    lag, R, t = align(A, B, legs)
    a, b = matched(A, B, lag, R, t)
    frames = segment_rotations(vendor, joint_index, lag, len(a), R)
    along = bone_directions(vendor, joint_index)
    d = np.empty(a.shape[:2])
    fixed = b.copy()
    offsets = {}
    for k, j in enumerate(JOINTS):
        c, d[:, k] = definition_free(a[:, k], b[:, k], frames[j])
        fixed[:, k] += sum(np.einsum("fij,j->fi", Rk, ck) for Rk, ck in zip(frames[j], c))
        offsets[j] = [(100 * float(np.linalg.norm(ck)), 100 * float(ck @ u)) for ck, u in zip(c, along[j])]
    return {"lag": lag, "mean": {j: float(np.nanmean(d[:, k])) for k, j in enumerate(JOINTS)},
            "p95": {j: float(np.nanpercentile(d[:, k], 95)) for k, j in enumerate(JOINTS)},
            "all": float(np.nanmean(d)), "angles": flexion_differences(a, fixed), "offsets": offsets}


#: The vendor's thorax frame (the dropped ASF ``thorax`` bone hangs from it) and the joints
#: it moves.
THORAX, ARM_JOINTS = "Spine1", ("shoulder", "elbow", "wrist")


def segment_rotations(vendor, joint_index: dict[str, int], lag: int, n: int, R: np.ndarray) -> dict[str, list[np.ndarray]]:
    """Joint -> the ``(n, 3, 3)`` world rotations (aligned by ``R``, frames matched by ``lag``) of
    the vendor frames a constant definition offset of that joint lives in: the segment ending
    at it (its BVH parent's rotation), and for the arm joints also :data:`THORAX`'s."""
    from scipy.spatial.transform import Rotation

    names, parents = list(vendor.skeleton.names), vendor.skeleton.parents
    Q = vendor.world_rotations()[max(0, -lag):][:n]

    def world(j: int) -> np.ndarray:
        return np.einsum("ij,fjk->fik", R, Rotation.from_quat(Q[:, j]).as_matrix())

    thorax = world(names.index(THORAX))
    out = {}
    for j in JOINTS:
        segment = world(int(parents[joint_index[j]]))
        # CMU's clavicles never turn against the thorax: a shoulder's segment frame is the thorax's
        apart = j.split("_", 1)[1] in ARM_JOINTS and not np.allclose(segment, thorax, atol=1e-9)
        out[j] = [segment, thorax] if apart else [segment]
    return out


def definition_free(a: np.ndarray, b: np.ndarray, frames: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """One joint: the constant vectors ``c_k`` (metres, in the frames ``R_k``, ``(n, 3, 3)``
    each) that best explain ``a - b`` as ``sum_k R_k c_k`` (least squares), and the distances
    (metres, ``(n,)``, NaN where unseen) that remain."""
    d = a - b
    ok = np.all(np.isfinite(d), axis=1)
    M = np.concatenate(frames, axis=2)  # (n, 3, 3K)
    c, *_ = np.linalg.lstsq(M[ok].reshape(-1, M.shape[2]), d[ok].reshape(-1), rcond=None)
    rest = np.full(len(d), np.nan)
    rest[ok] = np.linalg.norm(d[ok] - M[ok] @ c, axis=1)
    return c.reshape(-1, 3), rest


def bone_directions(vendor, joint_index: dict[str, int]) -> dict[str, list[np.ndarray]]:
    """Joint -> unit vectors, in the frames of :func:`segment_rotations`, that a removed vector
    is read along: the vendor bone ending at the joint (its rest offset), and for the thorax
    the back (``Spine1``'s rest offset, the upper back, which the dropped thorax bone
    continues)."""
    names, off = list(vendor.skeleton.names), np.asarray(vendor.skeleton.offsets)

    def unit(v: np.ndarray) -> np.ndarray:
        n = np.linalg.norm(v)
        return v / n if n > 0 else v

    back = unit(off[names.index(THORAX)])
    return {j: [unit(off[joint_index[j]]), back] for j in JOINTS}


def reference_checks(vendor, rec, ms, lag: int) -> list[str]:
    """Where the vendor's upper body sits relative to the markers (cm along the lab's up
    axis, the file frames matched by ``lag``, the skeleton in the lab frame as recorded)."""
    names = list(vendor.skeleton.names)
    a0, b0 = max(0, lag), max(0, -lag)
    n = min(rec.num_frames - a0, vendor.num_frames - b0)
    W = vendor.world_positions()[b0:b0 + n]
    P = rec.positions[a0:a0 + n]
    up = np.argmax(np.abs(np.nanmedian(P[:, ms.roles["LFHD"]] - P[:, ms.roles["LANK"]], 0)))
    vup = np.argmax(np.abs(np.median(W[:, names.index("Head")] - W[:, names.index("LeftFoot")], 0)))
    head = np.nanmean(P[:, [ms.roles[r] for r in ("LFHD", "RFHD", "LBHD", "RBHD")], up], 1)

    def dz(joint: str, z: np.ndarray) -> float:
        return 100 * float(np.nanmedian(W[:, names.index(joint), vup] - z))

    return [f"vendor head top (Head_End) {dz('Head_End', head):+.1f} cm above the head markers' centroid",
            f"vendor neck base (Neck) {dz('Neck', P[:, ms.roles['C7'], up]):+.1f} cm above C7",
            f"vendor shoulder joints {dz('LeftArm', P[:, ms.roles['LSHO'], up]):+.1f} / "
            f"{dz('RightArm', P[:, ms.roles['RSHO'], up]):+.1f} cm above the acromion markers LSHO / RSHO"]


def print_table(title: str, out: dict, results: dict, label: str = "all") -> None:
    """One table: mean distance per joint and method, then the flexion differences."""
    names = list(out)
    print(f"{title:17s}" + "".join(f"{n:>12s}" for n in names))
    for j in JOINTS:
        print(f"{j:17s}" + "".join(f"{100 * out[n]['mean'][j]:12.1f}" for n in names))
    print(f"{label:17s}" + "".join(f"{100 * out[n]['all']:12.1f}" for n in names))
    print("flexion difference (deg, mean)" if label == "all" else "flexion (deg, mean)")
    for a in out[names[0]]["angles"]:
        print(f"{a:17s}" + "".join(f"{out[n]['angles'][a]:12.1f}" for n in names))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, help="only the first N frames of the take")
    ap.add_argument("--only", default="regression,functional,solved")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    from physmocap.ik.retarget import map_motion
    from physmocap.markers.functional import functional_joint_centres
    from physmocap.markers.joints import joint_centres
    from physmocap.markers.markerset import detect_marker_set
    from physmocap.markers.recording import MarkerRecording
    from physmocap.markers.solve import solve_markers
    from physmocap.sources import load_motion
    from physmocap.sources.c3d import read_c3d_markers

    c3d, bvh = DATA / "cmu_01_01_markers.c3d", DATA / "cmu_01_01_jumps.bvh"
    if not (c3d.exists() and bvh.exists()):
        print(f"skip: {c3d} or {bvh} not found", file=sys.stderr)
        return 0
    rec = read_c3d_markers(c3d)
    if args.frames:
        rec = MarkerRecording(rec.labels, rec.positions[: args.frames], rec.fps, rec.source)
    ms = detect_marker_set(rec.labels)
    vendor = load_motion(bvh)
    vi = map_motion(vendor)
    B = vendor.world_positions()[:, [vi[j] for j in JOINTS]]
    results = {}
    only = args.only.split(",")
    if "regression" in only:
        t0 = time.process_time()
        jc = joint_centres(rec, ms)
        dt = time.process_time() - t0
        results["regression"] = (np.stack([jc.positions[j] for j in JOINTS], 1), f"{rec.num_frames / dt:.0f} frames/s CPU")
    if "functional" in only:
        t0 = time.process_time()
        cal = functional_joint_centres(rec, ms)
        dt = time.process_time() - t0
        results["functional"] = (np.stack([cal.positions[j] for j in JOINTS], 1), f"calibration {dt:.2f} s CPU")
    if "solved" in only:
        sol = solve_markers(rec, ms)
        rep = sol.report()
        cpu_fps, wall_fps = sol.frames_per_second()
        results["solved"] = (np.stack([sol.joint_positions[j] for j in JOINTS], 1),
                             f"{cpu_fps:.0f} frames/s CPU, {wall_fps:.0f} wall; marker residual RMS "
                             f"{rep['overall']['rms_mm']:.1f} mm, max {rep['overall']['max_mm']:.0f} mm")
    out = {k: compare(A, B) for k, (A, _) in results.items()}
    print_table("joint (cm, mean)", out, results)
    for n in out:
        print(f"{n}: time offset {out[n]['lag']} frames; {results[n][1]}")
    legs = [k for k, j in enumerate(JOINTS) if j.split("_", 1)[1] in ("hip", "knee", "ankle")]
    print()
    print_table("legs-aligned (cm)", {k: compare(A, B, legs) for k, (A, _) in results.items()}, results, "mean")
    print()
    free = {k: compare_definition_free(A, B, vendor, vi, legs) for k, (A, _) in results.items()}
    print_table("definition-free", free, results, "mean")
    print("constant vectors removed (cm: length, and its part along the vendor bone ending at the joint;")
    print("elbows and wrists: + the thorax's, along the back)")
    for j in JOINTS:
        print(f"{j:17s}" + "".join(f"  {n}: " + " + ".join(f"{size:.1f} ({part:+.1f})" for size, part in free[n]["offsets"][j])
                                   for n in free))
    print()
    print("reference checks (the vendor's upper body against the markers):")
    for line in reference_checks(vendor, rec, ms, out[next(iter(out))]["lag"]):
        print("  " + line)
    return 0


if __name__ == "__main__":
    sys.exit(main())
