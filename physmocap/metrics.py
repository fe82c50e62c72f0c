"""Quality metrics of a character trajectory (and of source motions).

Definitions follow ``shared/design/metrics.md``; units are stated per figure
(cm/s, mm, degrees, rad/s).  Every function is pure: arrays in, numbers out.

* **Joint-limit violations**: frames x joints whose value lies outside the
  joint's range by more than 1e-6 rad: count and largest excess (degrees).
* **Velocity**: per joint :math:`|q_{t+1} - q_t| \\cdot fps` against its limit:
  violations and peak speed (rad/s).
* **Penetration**: depth below the floor of the lowest point of any geom
  (true lowest point of spheres, capsules, boxes, meshes), in mm: max over the
  clip, mean over penetrating frames, share of frames deeper than 1 mm.
* **Smoothness**: mean absolute joint acceleration (rad/s^2) and jerk (rad/s^3)
  over hinge joints.
* **Tracking error**: distance between each tracked site and its target (cm,
  mean and p95) and orientation error (degrees) for oriented targets.
"""

from __future__ import annotations

import mujoco
import numpy as np

from .ik.limits import GeomCandidates
from .rotations import Rotation, wxyz_to_xyzw

__all__ = [
    "LIMIT_TOLERANCE",
    "joint_limit_violations",
    "velocity_violations",
    "penetration",
    "smoothness",
    "tracking_errors",
    "trajectory_metrics",
]

LIMIT_TOLERANCE = 1e-6  # rad
KEY_JOINTS = ("ankle", "knee", "wrist", "elbow")


def _hinges(model: mujoco.MjModel) -> np.ndarray:
    return np.flatnonzero(np.isin(model.jnt_type, [mujoco.mjtJoint.mjJNT_HINGE, mujoco.mjtJoint.mjJNT_SLIDE]))


def joint_limit_violations(model: mujoco.MjModel, qpos: np.ndarray, tol: float = LIMIT_TOLERANCE) -> dict:
    """Count of (frame, joint) outside range by more than ``tol``, and the largest excess in degrees."""
    j = np.array([x for x in _hinges(model) if model.jnt_limited[x]], dtype=int)
    if j.size == 0:
        return {"count": 0, "max_deg": 0.0, "worst_joint": None}
    q = qpos[:, model.jnt_qposadr[j]]
    lo, hi = model.jnt_range[j, 0], model.jnt_range[j, 1]
    excess = np.maximum(lo - q, 0.0) + np.maximum(q - hi, 0.0)
    count = int(np.sum(excess > tol))
    worst = None
    if count:
        t, k = np.unravel_index(np.argmax(excess), excess.shape)
        worst = f"{model.joint(int(j[k])).name} on frame {int(t)}"
    return {"count": count, "max_deg": float(np.degrees(excess.max())), "worst_joint": worst}


def velocity_violations(
    model: mujoco.MjModel, qpos: np.ndarray, fps: float, limits: dict[str, float], tol: float = 1e-6
) -> dict:
    """Frame-to-frame joint speeds against velocity limits (rad/s)."""
    kinds = (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))
    names = [n for n in limits if int(model.jnt_type[model.joint(n).id]) in kinds]
    if qpos.shape[0] < 2 or not names:
        return {"count": 0, "peak_speed": 0.0, "peak_ratio": 0.0}
    adr = np.array([model.joint(n).qposadr[0] for n in names])
    vmax = np.array([limits[n] for n in names])
    speed = np.abs(np.diff(qpos[:, adr], axis=0)) * fps
    over = speed > vmax + tol * fps
    return {
        "count": int(over.sum()),
        "peak_speed": float(speed.max()),
        "peak_ratio": float((speed / vmax).max()),
    }


def lowest_heights(model: mujoco.MjModel, qpos: np.ndarray) -> np.ndarray:
    """``(F,)`` height of the lowest point of any non-world geom per frame (metres)."""
    data = mujoco.MjData(model)
    geoms = [g for g in range(model.ngeom) if model.geom_bodyid[g] != 0]
    cand = GeomCandidates(model, geoms)
    out = np.empty(qpos.shape[0])
    for t, q in enumerate(qpos):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        z, _ = cand.points(data)
        out[t] = z.min() if z.size else np.inf
    return out


def penetration(model: mujoco.MjModel, qpos: np.ndarray, floor: float = 0.0) -> dict:
    """Floor penetration in mm (max, mean over penetrating frames, share of frames > 1 mm)."""
    depth = np.maximum(floor - lowest_heights(model, qpos), 0.0) * 1000.0
    pen = depth[depth > 0]
    return {
        "max_mm": float(depth.max()) if depth.size else 0.0,
        "mean_mm": float(pen.mean()) if pen.size else 0.0,
        "share_over_1mm": float(np.mean(depth > 1.0)) if depth.size else 0.0,
    }


def smoothness(model: mujoco.MjModel, qpos: np.ndarray, fps: float) -> dict:
    """Mean absolute joint acceleration (rad/s^2) and jerk (rad/s^3) over hinge joints."""
    j = _hinges(model)
    q = qpos[:, model.jnt_qposadr[j]]
    acc = np.diff(q, n=2, axis=0) * fps**2 if q.shape[0] > 2 else np.zeros((0, len(j)))
    jerk = np.diff(q, n=3, axis=0) * fps**3 if q.shape[0] > 3 else np.zeros((0, len(j)))
    return {
        "mean_abs_acc": float(np.abs(acc).mean()) if acc.size else 0.0,
        "mean_abs_jerk": float(np.abs(jerk).mean()) if jerk.size else 0.0,
    }


def tracking_errors(traj, mask: np.ndarray | None = None) -> dict:
    """Per canonical joint: position error (cm, mean and p95) and orientation error (deg).

    ``mask`` (``(F,)`` or ``(F, N)`` bool) restricts the frames counted.
    """
    targets = traj.targets
    model = traj.model
    ch = traj.character
    data = mujoco.MjData(model)
    F, N = targets.positions.shape[:2]
    pos = np.empty((F, N, 3))
    quat = np.empty((F, N, 4))
    refs = []
    for name in targets.names:
        tf = ch.tracked[name]
        refs.append((tf.kind, model.site(tf.name).id if tf.kind == "site" else model.body(tf.name).id))
    for t in range(F):
        data.qpos[:] = traj.qpos[t]
        mujoco.mj_kinematics(model, data)
        for k, (kind, i) in enumerate(refs):
            if kind == "site":
                pos[t, k] = data.site_xpos[i]
                mat = data.site_xmat[i]
                q = np.empty(4)
                mujoco.mju_mat2Quat(q, mat)
            else:
                pos[t, k] = data.xpos[i]
                q = data.xquat[i]
            quat[t, k] = wxyz_to_xyzw(q)
    err = np.linalg.norm(pos - targets.positions, axis=-1) * 100.0
    valid = targets.valid.copy()
    if mask is not None:
        m = mask if mask.ndim == 2 else np.broadcast_to(mask[:, None], valid.shape)
        valid &= m
    out: dict = {"position_cm": {}, "orientation_deg": {}}
    for k, name in enumerate(targets.names):
        e = err[valid[:, k], k]
        if e.size:
            out["position_cm"][name] = {"mean": float(e.mean()), "p95": float(np.percentile(e, 95))}
        if targets.has_orientation[k]:
            v = valid[:, k]
            if v.any():
                rel = Rotation.from_quat(quat[v, k]).inv() * Rotation.from_quat(targets.orientations[v, k])
                ang = np.degrees(rel.magnitude())
                out["orientation_deg"][name] = {"mean": float(ang.mean()), "p95": float(np.percentile(ang, 95))}
    key = [n for n in targets.names if n.split("_", 1)[-1] in KEY_JOINTS]
    key_err = np.concatenate([err[valid[:, targets.index(n)], targets.index(n)] for n in key]) if key else np.zeros(0)
    out["key_joints_mean_cm"] = float(key_err.mean()) if key_err.size else 0.0
    out["key_joints_p95_cm"] = float(np.percentile(key_err, 95)) if key_err.size else 0.0
    all_err = err[valid]
    out["all_mean_cm"] = float(all_err.mean()) if all_err.size else 0.0
    return out


def trajectory_metrics(traj) -> dict:
    """All trajectory figures that do not need contact labels."""
    model = traj.model
    out = {
        "frames": traj.num_frames,
        "fps": traj.fps,
        "non_finite": int(np.sum(~np.isfinite(traj.qpos))),
        "joint_limits": joint_limit_violations(model, traj.qpos),
        "velocity": velocity_violations(model, traj.qpos, traj.fps, traj.character.velocity_limits),
        "penetration": penetration(model, traj.qpos),
        "smoothness": smoothness(model, traj.qpos, traj.fps),
    }
    if traj.targets is not None:
        out["tracking"] = tracking_errors(traj)
    return out
