"""Quality metrics of a character trajectory (and of source motions).

Definitions: ``docs/metrics.md`` in the repository; units are stated per figure
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
* **Foot skating**: horizontal speed of contact points on their stance frames
  (central differences x fps), in cm/s: mean, p95, max, and the share of
  stance frames faster than 5 cm/s.  Stance is *height only*: within 1 cm of
  the floor ``z = 0`` for a character's contact sites; within 1 cm of the
  point's own 5th-percentile height for a source's toe (ball) joints and toe
  end sites.  A foot that slides while down counts as sliding.
* **Hovering**: on frames where a foot is labelled in contact, the height of
  that foot's lowest contact point above the floor (mm, clipped at 0, since
  depth below the floor is penetration): median and p95.

Figures that a clip cannot have (no stance frames, no labelled contacts) are
None, which the JSON report writes as ``null``.
"""

from __future__ import annotations

from typing import Sequence

import mujoco
import numpy as np

from ..rotations import Rotation, wxyz_to_xyzw

__all__ = [
    "LIMIT_TOLERANCE",
    "joint_limit_violations",
    "velocity_violations",
    "penetration",
    "self_penetration",
    "lowest_heights",
    "geom_lowest_heights",
    "smoothness",
    "tracking_errors",
    "trajectory_metrics",
    "STANCE_TOLERANCE",
    "SKATE_SPEED",
    "horizontal_speeds",
    "skating",
    "character_stance",
    "source_stance",
    "character_skating",
    "labelled_skating",
    "source_skating",
    "source_labelled_skating",
    "hovering",
    "character_hovering",
    "character_flat_feet",
    "source_hovering",
    "source_penetration",
    "source_metrics",
]

LIMIT_TOLERANCE = 1e-6  # rad
STANCE_TOLERANCE = 0.01  # m: stance is within 1 cm of the floor (metrics.md)
SKATE_SPEED = 0.05  # m/s: stance frames faster than this count as skating
SOURCE_STANCE_PERCENTILE = 5.0
#: Canonical joints that are a source's contact points (toe/ball joints and toe end sites).
SOURCE_CONTACT_JOINTS = ("toe", "toe_end")
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
    model: mujoco.MjModel, qpos: np.ndarray, fps: float, limits: dict[str, float], tol: float = 1e-6,
    groups: Sequence[Sequence[str]] = (),
) -> dict:
    """Frame-to-frame joint speeds against velocity limits (rad/s; a hinge of one of
    ``groups``: its body's angular speed along its axis,
    :func:`~physmocap.models.hinge_groups.joint_speeds`); ``tol`` in rad (m) per frame."""
    from ..models.hinge_groups import joint_speeds

    kinds = (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))
    names = [n for n in limits if int(model.jnt_type[model.joint(n).id]) in kinds]
    if qpos.shape[0] < 2 or not names:
        return {"count": 0, "peak_speed": 0.0, "peak_ratio": 0.0}
    vmax = np.array([limits[n] for n in names])
    speed = joint_speeds(model, qpos, fps, names, [g for g in groups if all(n in names for n in g)], limits)
    over = speed > vmax + tol * fps
    return {
        "count": int(over.sum()),
        "peak_speed": float(speed.max()),
        "peak_ratio": float((speed / vmax).max()),
    }


def geom_lowest_heights(model: mujoco.MjModel, data: mujoco.MjData, geoms: np.ndarray | None = None) -> np.ndarray:
    """Exact height of each geom's lowest surface point (metres), from ``data``'s kinematics.

    With :math:`R` the geom's world rotation, :math:`c` its centre and
    :math:`r_i = R_{2i}` the world-z row: sphere :math:`c_z - \\rho`; capsule
    :math:`c_z - h |r_2| - \\rho`; cylinder :math:`c_z - h |r_2| - \\rho
    \\sqrt{1 - r_2^2}`; box :math:`c_z - \\sum_i s_i |r_i|`; ellipsoid
    :math:`c_z - \\lVert (s_i r_i)_i \\rVert`; mesh: its lowest vertex.  Planes,
    height fields and SDFs give ``+inf``.  The formulas are the characters
    layer's (:func:`physmocap.models.geometry.geom_z_extent`), independent of the
    solver's floor constraint (:class:`physmocap.ik.limits.GeomCandidates`), so
    the metric checks the solver.
    """
    from ..models.geometry import geom_z_extent

    if geoms is None:
        geoms = np.array([g for g in range(model.ngeom) if model.geom_bodyid[g] != 0], dtype=int)
    return np.array([geom_z_extent(model, data, int(g))[0] for g in geoms], dtype=float)


def lowest_heights(model: mujoco.MjModel, qpos: np.ndarray) -> np.ndarray:
    """``(F,)`` height of the lowest point of any non-world geom per frame (metres)
    (:func:`geom_lowest_heights`); visual-only meshes are left out, as in the floor
    constraint (:func:`physmocap.models.geometry.is_visual_only`)."""
    from ..models.geometry import is_visual_only

    data = mujoco.MjData(model)
    geoms = np.array([g for g in range(model.ngeom) if model.geom_bodyid[g] != 0 and not is_visual_only(model, g)], dtype=int)
    out = np.empty(qpos.shape[0])
    for t, q in enumerate(qpos):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        z = geom_lowest_heights(model, data, geoms)
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


def self_penetration(character, qpos: np.ndarray) -> dict:
    """Limbs passing through each other or the trunk (the pairs of
    :func:`physmocap.models.selfcollision.self_collision_pairs`): deepest overlap in mm,
    share of frames overlapping more than 2 mm, and the worst pair's geom names."""
    from ..models.selfcollision import pair_distances, self_collision_pairs

    model = character.model
    pairs = self_collision_pairs(character)
    if not pairs or qpos.shape[0] == 0:
        return {"max_mm": 0.0, "share_over_2mm": 0.0, "worst_pair": None, "pairs": len(pairs)}
    data = mujoco.MjData(model)
    worst = np.empty(qpos.shape[0])
    which = np.empty(qpos.shape[0], dtype=int)
    for t, q in enumerate(qpos):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        d = pair_distances(model, data, pairs)
        which[t] = int(np.argmin(d))
        worst[t] = d[which[t]]
    depth = np.maximum(-worst, 0.0) * 1000.0
    t = int(np.argmax(depth))

    def name(g: int) -> str:
        return model.geom(g).name or f"{model.body(model.geom_bodyid[g]).name} geom {g}"

    return {
        "max_mm": float(depth.max()),
        "share_over_2mm": float(np.mean(depth > 2.0)),
        "worst_pair": None if depth[t] <= 0 else f"{name(pairs[which[t]][0])} / {name(pairs[which[t]][1])}",
        "pairs": len(pairs),
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
        refs.append((tf.kind, tf.object_id(model)))
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


def trajectory_metrics(traj, contacts=None) -> dict:
    """All figures of a character trajectory.

    Args:
        traj: A :class:`~physmocap.trajectory.Trajectory`.
        contacts: Foot contact labels (:class:`~physmocap.ik.contacts.Contacts`,
            same frames as ``traj``); without them hovering is not measured.
    """
    model = traj.model
    out = {
        "frames": traj.num_frames,
        "fps": traj.fps,
        "non_finite": int(np.sum(~np.isfinite(traj.qpos))),
        "joint_limits": joint_limit_violations(model, traj.qpos),
        "velocity": velocity_violations(
            model, traj.qpos, traj.fps, traj.character.velocity_limits, groups=getattr(traj.character, "velocity_groups", ())
        ),
        "penetration": penetration(model, traj.qpos),
        "self_penetration": self_penetration(traj.character, traj.qpos),
        "smoothness": smoothness(model, traj.qpos, traj.fps),
    }
    if traj.targets is not None:
        out["tracking"] = tracking_errors(traj)
    if getattr(traj.character, "contacts", None):
        sites, pos = _contact_sites(traj)
        out["skating"] = skating(pos, traj.fps, character_stance(pos[..., 2]))
        if contacts is not None:
            out["hovering"] = _character_hovering(traj, contacts, pos)
            out["flat_feet"] = _flat_foot_lift(traj, contacts, pos)
            out["skating_labelled"] = labelled_skating(traj, contacts, sites, pos)
    return out


def labelled_skating(traj, contacts, sites: list[str] | None = None, pos: np.ndarray | None = None) -> dict:
    """Diagnostic beside metrics.md's skating: the same figures restricted to
    stance samples whose site is labelled in contact (heel site: heel label;
    other sites: toe label).  Skating outside it comes from frames the
    contact labels leave free (landing, toe-off, swing close to the floor)."""
    from ..ik.contacts import contact_sites_labels

    _check_frames(traj.num_frames, contacts, "trajectory")
    if sites is None or pos is None:
        sites, pos = _contact_sites(traj)
    labels = contact_sites_labels(contacts, traj.character)
    lab = np.stack([labels[s] for s in sites], axis=1)
    return skating(pos, traj.fps, character_stance(pos[..., 2]) & lab)


# ---------------------------------------------------------------------------
# Feet: skating and hovering
# ---------------------------------------------------------------------------


def horizontal_speeds(points: np.ndarray, fps: float) -> np.ndarray:
    """``(F, P)`` horizontal speed (m/s) of points ``(F, P, 3)``: central
    differences over frames (one-sided on the first and last), times fps."""
    p = np.asarray(points, dtype=float)
    if p.shape[0] < 2:
        return np.zeros(p.shape[:2])
    v = np.gradient(p[..., :2], axis=0) * fps
    return np.linalg.norm(v, axis=-1)


def _stats(values: np.ndarray, scale: float) -> tuple:
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)] * scale
    if v.size == 0:
        return None, None, None
    return float(v.mean()), float(np.percentile(v, 95)), float(v.max())


def skating(points: np.ndarray, fps: float, stance: np.ndarray) -> dict:
    """Foot skating of points ``(F, P, 3)`` on their ``stance`` ``(F, P)`` frames.

    Returns mean, p95 and max horizontal speed in cm/s, the share of stance
    frames faster than 5 cm/s, and the number of (frame, point) stance samples.
    """
    v = horizontal_speeds(points, fps)
    st = np.asarray(stance, dtype=bool) & np.isfinite(v)
    s = v[st]
    mean, p95, vmax = _stats(s, 100.0)
    return {
        "mean_cm_s": mean,
        "p95_cm_s": p95,
        "max_cm_s": vmax,
        "share_over_5cm_s": float(np.mean(s > SKATE_SPEED)) if s.size else None,
        "stance_samples": int(s.size),
    }


def character_stance(heights: np.ndarray, floor: float = 0.0, tol: float = STANCE_TOLERANCE) -> np.ndarray:
    """Stance of a character's contact sites: height within ``tol`` of the floor
    (or below it)."""
    h = np.asarray(heights, dtype=float)
    with np.errstate(invalid="ignore"):
        return h - floor <= tol


def source_stance(
    heights: np.ndarray, tol: float = STANCE_TOLERANCE, percentile: float = SOURCE_STANCE_PERCENTILE
) -> np.ndarray:
    """Stance of a source's contact points ``(F, P)``: within ``tol`` of each
    point's own ``percentile`` height (NaN samples are never in stance)."""
    h = np.asarray(heights, dtype=float)
    out = np.zeros(h.shape, dtype=bool)
    for k in range(h.shape[1]):
        col = h[:, k]
        ok = np.isfinite(col)
        if ok.any():
            out[ok, k] = col[ok] <= np.percentile(col[ok], percentile) + tol
    return out


def _contact_sites(traj) -> tuple[list[str], np.ndarray]:
    sites = [s for side in sorted(traj.character.contacts) for s in traj.character.contacts[side]]
    return sites, traj.site_positions(sites)


def character_skating(traj, floor: float = 0.0) -> dict:
    """Skating of the character's declared contact sites (stance: within 1 cm of the floor)."""
    _, pos = _contact_sites(traj)
    return skating(pos, traj.fps, character_stance(pos[..., 2], floor))


def _source_points(motion, joint_indices) -> tuple[list[str], np.ndarray]:
    names = [
        f"{side}_{j}" for side in ("left", "right") for j in SOURCE_CONTACT_JOINTS if f"{side}_{j}" in joint_indices
    ]
    if not names:  # a skeleton without toes: its ankles are the best it has
        names = [n for n in ("left_ankle", "right_ankle") if n in joint_indices]
    world = motion.world_positions()
    return names, world[:, [joint_indices[n] for n in names]]


def source_skating(motion, joint_indices: dict[str, int]) -> dict:
    """Skating of a source motion's toe (ball) joints and toe end sites
    (stance: within 1 cm of the point's own 5th-percentile height)."""
    names, pos = _source_points(motion, joint_indices)
    if not names:
        return skating(np.zeros((motion.num_frames, 0, 3)), motion.fps, np.zeros((motion.num_frames, 0), bool))
    return skating(pos, motion.fps, source_stance(pos[..., 2]))


def hovering(heights: np.ndarray, in_contact: np.ndarray) -> dict:
    """Hovering: ``heights`` ``(F, feet)`` of each foot's lowest contact point
    above the floor (metres) on the frames ``in_contact`` ``(F, feet)``; in mm,
    clipped at 0 (depth below the floor is penetration)."""
    h = np.asarray(heights, dtype=float)
    m = np.asarray(in_contact, dtype=bool) & np.isfinite(h)
    v = np.maximum(h[m], 0.0) * 1000.0
    return {
        "median_mm": float(np.median(v)) if v.size else None,
        "p95_mm": float(np.percentile(v, 95)) if v.size else None,
        "contact_samples": int(v.size),
    }


def _check_frames(n: int, contacts, what: str) -> None:
    if contacts.num_frames != n:
        from ..errors import OptionError

        raise OptionError(
            f"the contact labels cover {contacts.num_frames} frames but the {what} has {n}",
            path=None if contacts.source == "detected" else contacts.source,
        )


def _character_hovering(traj, contacts, pos: np.ndarray, floor: float = 0.0) -> dict:
    _check_frames(traj.num_frames, contacts, "trajectory")
    ch = traj.character.contacts
    sides = sorted(ch)
    lowest, labelled = [], []
    k = 0
    for side in sides:
        n = len(ch[side])
        lowest.append(pos[:, k : k + n, 2].min(axis=1) - floor)
        labelled.append(contacts.foot(side))
        k += n
    return hovering(np.column_stack(lowest), np.column_stack(labelled))


def _flat_foot_lift(traj, contacts, pos: np.ndarray, floor: float = 0.0) -> dict:
    """Lift of feet the actor has flat: on the frames both of a foot's labels (heel and
    toe) are on, the height of its *highest* contact site (mm; hovering takes the lowest,
    so a foot standing tilted on its ball or heel passes it), median, 95th percentile and
    the share of those frames over the stance band (:data:`STANCE_TOLERANCE`)."""
    _check_frames(traj.num_frames, contacts, "trajectory")
    ch = traj.character.contacts
    highest, flat = [], []
    k = 0
    for side in sorted(ch):
        n = len(ch[side])
        highest.append(pos[:, k : k + n, 2].max(axis=1) - floor)
        none = np.zeros(traj.num_frames, dtype=bool)  # a label file may leave a point out
        heel, toe = contacts.labels.get(f"{side}_heel", none), contacts.labels.get(f"{side}_toe", none)
        flat.append(np.asarray(heel, bool) & np.asarray(toe, bool))
        k += n
    h, m = np.column_stack(highest), np.column_stack(flat)
    out = hovering(h, m)
    up = h[m & np.isfinite(h)]
    out["share_over_band"] = float(np.mean(up > STANCE_TOLERANCE)) if up.size else None
    return out


def character_flat_feet(traj, contacts, floor: float = 0.0) -> dict:
    """:func:`_flat_foot_lift` of a trajectory's contact sites (see docs/metrics.md)."""
    _, pos = _contact_sites(traj)
    return _flat_foot_lift(traj, contacts, pos, floor)


def character_hovering(traj, contacts, floor: float = 0.0) -> dict:
    """Hovering of the character's feet on the frames ``contacts`` labels a foot in contact."""
    _, pos = _contact_sites(traj)
    return _character_hovering(traj, contacts, pos, floor)


def _source_floor(motion, joint_indices, contacts):
    """The source's floor: the contacts' own, else estimated as detection does
    (user labels from a CSV carry no floor)."""
    if contacts is not None and contacts.floor is not None:
        return contacts.floor
    from ..ik.contacts import detect_contacts

    return detect_contacts(motion, joint_indices).floor


def source_hovering(motion, joint_indices: dict[str, int], contacts, floor=None) -> dict:
    """Hovering of a source's feet above its estimated floor (``floor``, by
    default ``contacts.floor`` or a fresh estimate) on the frames it is
    labelled in contact; contact points as for skating."""
    _check_frames(motion.num_frames, contacts, "source motion")
    names, pos = _source_points(motion, joint_indices)
    if floor is None:
        floor = _source_floor(motion, joint_indices, contacts)
    lowest, labelled = [], []
    for side in ("left", "right"):
        cols = [i for i, n in enumerate(names) if n.startswith(side + "_")]
        if not cols:
            continue
        h = pos[:, cols, 2] - (floor.at(pos[:, cols]) if floor is not None else 0.0)
        lowest.append(h.min(axis=1))
        labelled.append(contacts.foot(side))
    if not lowest:
        return hovering(np.zeros((motion.num_frames, 0)), np.zeros((motion.num_frames, 0), bool))
    return hovering(np.column_stack(lowest), np.column_stack(labelled))


def source_penetration(motion, floor=None) -> dict:
    """Penetration of a source: depth of its lowest joint below the floor (mm).

    ``floor`` is a :class:`~physmocap.ik.contacts.FloorPlane` (or a height);
    default: :meth:`Motion.floor_height`.  Same figures as :func:`penetration`.
    """
    world = motion.world_positions()
    if floor is None:
        z = world[..., 2] - motion.floor_height()
    elif hasattr(floor, "heights"):
        z = floor.heights(world)
    else:
        z = world[..., 2] - float(floor)
    with np.errstate(invalid="ignore"):
        low = np.nanmin(np.where(np.isfinite(z), z, np.nan), axis=1) if z.size else np.zeros(0)
    depth = np.maximum(-np.nan_to_num(low, nan=0.0), 0.0) * 1000.0
    pen = depth[depth > 0]
    return {
        "max_mm": float(depth.max()) if depth.size else 0.0,
        "mean_mm": float(pen.mean()) if pen.size else 0.0,
        "share_over_1mm": float(np.mean(depth > 1.0)) if depth.size else 0.0,
    }


def source_metrics(motion, joint_indices: dict[str, int], contacts=None) -> dict:
    """The figures a source motion has: skating, penetration and (with
    contact labels) hovering; penetration and hovering are measured against
    the floor contact detection estimates (``contacts.floor`` if it has one)."""
    floor = _source_floor(motion, joint_indices, contacts)
    out = {
        "frames": motion.num_frames,
        "fps": float(motion.fps),
        "skating": source_skating(motion, joint_indices),
        "penetration": source_penetration(motion, floor),
    }
    if contacts is not None:
        out["hovering"] = source_hovering(motion, joint_indices, contacts, floor)
        out["skating_labelled"] = source_labelled_skating(motion, joint_indices, contacts)
    return out


def source_labelled_skating(motion, joint_indices: dict[str, int], contacts) -> dict:
    """:func:`source_skating` restricted to stance samples whose point is
    labelled in contact (toe points: the toe label; ankles: the heel label)."""
    _check_frames(motion.num_frames, contacts, "source motion")
    names, pos = _source_points(motion, joint_indices)
    lab = np.zeros((motion.num_frames, len(names)), dtype=bool)
    for k, n in enumerate(names):
        side, joint = n.split("_", 1)
        lab[:, k] = contacts.labels[f"{side}_{'heel' if joint == 'ankle' else 'toe'}"]
    return skating(pos, motion.fps, source_stance(pos[..., 2]) & lab)


def outside_stance_mask(traj) -> np.ndarray:
    """``(F, N)`` mask over the trajectory's targets: a foot's knee, ankle and toes
    count only on frames where that foot is not in contact (everything else always).

    For "tracking outside stance": while a foot is planted its joints follow the
    plant, not the actor.
    """
    contacts = traj.contacts
    names = traj.targets.names
    mask = np.ones((traj.num_frames, len(names)), dtype=bool)
    for side in ("left", "right"):
        swing = ~contacts.foot(side)
        for k, n in enumerate(names):
            if n.startswith(side + "_") and n.split("_", 1)[1] in ("knee", "ankle", "toe", "toe_end"):
                mask[:, k] = swing
    return mask
