r"""Fidelity: does the character move like the actor?

Constraint figures (limits, floor, skating on the project's own contact labels)
say nothing about whether the retarget *looks like* the actor.  These figures
compare the character's joint centres with the actor's, frame by frame, with
nothing taken from the solver or its targets: the actor's joint centres come
from the source motion's forward kinematics (canonical joints from the name
mapping), the character's from the sites or bodies its mapping ties to the
same canonical joints.  Both worlds are metres, Z-up; the retargeter keeps the
character in the actor's world orientation, so directions compare directly.

* **Segment direction error** (degrees): per frame and segment, the angle
  between the character's segment direction and the actor's.  Segments
  (:data:`SEGMENTS`): torso (pelvis to neck), upper arms (shoulder to
  elbow), forearms (elbow to wrist), thighs (hip to knee), shanks (knee to
  ankle).  The torso runs from the pelvis joint, the root of the spine, as the
  eye reads a trunk's lean: a CMU actor's hip centres sit 6 cm in front of and
  9 cm below its pelvis joint, and a character whose hips are straight below
  its spine that matched the line from the hip centres stood 7-9 degrees
  leaned back where the actor's spine is upright.
* **Facing error** (degrees): the angle about the vertical between the
  character's pelvis heading and the actor's; the heading is the horizontal
  direction perpendicular to the right-to-left hip line,
  :math:`\hat h = \widehat{(l - r) \times \hat z}`.
* **Pelvis path deviation** (cm): the actor's mid-hip path on the floor is
  mapped onto the character's by one similarity transform for the whole clip
  (uniform scale, rotation about the vertical, translation; least squares,
  Umeyama 1991), then the distance per frame.
* **Pelvis vertical speed**: the 99th percentile of :math:`|\dot z|` of the
  character's mid-hip against the actor's scaled by the root scale (m/s).
* **Velocity-cap saturation**: frames on which some joint moves at 99 % or
  more of its velocity limit (the solver's frame-to-frame bound), and the
  share of frames of the joint that sits at its cap most often.
* **Pops** (cm): a joint that jumps where the actor's does not.  Per joint and
  frame, the character's second difference :math:`|c_{t+1} - 2 c_t + c_{t-1}|`
  (metres; a jump of :math:`d` in one frame gives about :math:`d`, whatever the
  frame rate) beyond the actor's, scaled by the root scale, taken as the largest of
  the joint's and its parent's on frames :math:`t-1 .. t+1` (a source whose knee
  jumps moves the ankle too: the actor's own pop is not the character's).  A frame
  pops where some joint exceeds it by more than :data:`POP_M`.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Mapping, Sequence

import mujoco
import numpy as np
from scipy.ndimage import maximum_filter1d

from ..spill import blocks, release, spilled_empty

__all__ = [
    "SEGMENTS",
    "SegmentError",
    "Fidelity",
    "figure_joints",
    "actor_joint_positions",
    "character_joint_positions",
    "segment_direction_errors",
    "angle_deg",
    "facing_errors",
    "similarity_fit_2d",
    "path_deviation",
    "vertical_speed_p99",
    "velocity_saturation",
    "saturation_matrix",
    "GeomFloorContact",
    "geom_floor_contact",
    "fidelity",
    "SEGMENT_WARN_DEG",
    "FACING_WARN_DEG",
    "Pops",
    "pops",
    "POP_M",
    "POP_WARN_M",
]

#: Segment name -> (proximal canonical joint, distal canonical joint).
SEGMENTS: dict[str, tuple[str, str]] = {
    "torso": ("pelvis", "neck"),
    "left_upper_arm": ("left_shoulder", "left_elbow"),
    "right_upper_arm": ("right_shoulder", "right_elbow"),
    "left_forearm": ("left_elbow", "left_wrist"),
    "right_forearm": ("right_elbow", "right_wrist"),
    "left_thigh": ("left_hip", "left_knee"),
    "right_thigh": ("right_hip", "right_knee"),
    "left_shank": ("left_knee", "left_ankle"),
    "right_shank": ("right_knee", "right_ankle"),
}
#: A segment this far off (degrees) counts as wrong on that frame.
SEGMENT_WARN_DEG = 45.0
#: Facing this far off (degrees) is warned about.
FACING_WARN_DEG = 30.0
#: A joint at this fraction of its velocity limit counts as saturated.
SATURATION_RATIO = 0.99
#: Metres: a joint whose second difference over frames exceeds the actor's by more than this
#: pops on that frame (:func:`pops`): 2 cm, a jump the eye catches at any frame rate.
POP_M = 0.02
#: Metres: pops larger than this are warned about (:func:`fidelity_warnings`).
POP_WARN_M = 0.05


@dataclass(frozen=True)
class SegmentError:
    """Direction error of one segment over a clip (degrees)."""

    median_deg: float
    p95_deg: float
    share_over_45: float


@dataclass(frozen=True)
class Pops:
    """Where the character's joints jump and the actor's do not (:func:`pops`).

    Attributes:
        frames: Frames (indices into the retargeted clip) on which some joint pops.
        share: Their share of the clip's frames.
        worst_cm: The largest excess of a joint's second difference over the actor's (cm).
        worst_joint, worst_frame: Where it is (None without any excess).
        warn_frames: Frames with a pop over :data:`POP_WARN_M`.
    """

    frames: np.ndarray
    share: float
    worst_cm: float
    worst_joint: str | None
    worst_frame: int | None
    warn_frames: np.ndarray

    def as_dict(self) -> dict:
        return {
            "frames": int(self.frames.size),
            "share": self.share,
            "worst_cm": self.worst_cm,
            "worst_joint": self.worst_joint,
            "worst_frame": self.worst_frame,
        }


@dataclass(frozen=True)
class Fidelity:
    """Fidelity figures of one retarget (see the module docstring).

    Attributes:
        segments: Segment name -> :class:`SegmentError` (segments both sides have).
        share_any_over_45: Share of frames on which any segment is more than 45 degrees off.
        frames_any_over_45: Those frames (indices into the retargeted clip).
        facing_median_deg, facing_p95_deg: Facing error (None without hips).
        frames_facing_over_30: Frames with facing more than 30 degrees off.
        path_mean_cm, path_max_cm: Pelvis path deviation after the similarity fit.
        path_scale: Scale of the fitted similarity (about the root scale).
        drift_mean_cm, drift_max_cm: Horizontal distance between the character's pelvis and
            its target, the actor's pelvis as the retarget scaled and placed it, with no fit
            (None without the targets): a body that comes to walk beside or behind the actor
            and stays there (a stream following its feet) shows here, where the similarity
            fit of the path takes most of it in.
        pelvis_vz_p99, actor_vz_p99_scaled: 99th percentile vertical speeds (m/s).
        saturated_frames: Frame transitions ``t -> t+1`` with a joint at its velocity cap.
        saturated_share: Their share of the clip's transitions.
        saturated_joint, saturated_joint_share: The joint that sits at its cap on
            the most transitions, and their share (the issue's "no joint at its
            cap on more than 0.5 % of frames" is this figure).
        pops: Joints that jump where the actor's do not (:class:`Pops`; None without
            a joint on both sides).
    """

    segments: dict[str, SegmentError]
    share_any_over_45: float
    frames_any_over_45: np.ndarray
    facing_median_deg: float | None
    facing_p95_deg: float | None
    frames_facing_over_30: np.ndarray
    path_mean_cm: float | None
    path_max_cm: float | None
    path_scale: float | None
    pelvis_vz_p99: float | None
    actor_vz_p99_scaled: float | None
    saturated_frames: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    saturated_share: float = 0.0
    floor: "GeomFloorContact | None" = None
    saturated_joint: str | None = None
    saturated_joint_share: float = 0.0
    drift_mean_cm: float | None = None
    drift_max_cm: float | None = None
    pops: Pops | None = None

    @property
    def worst_segment_median_deg(self) -> float:
        return max((s.median_deg for s in self.segments.values()), default=0.0)

    def as_dict(self) -> dict:
        """Plain figures for the JSON report (frame lists left out)."""
        return {
            "segments": {
                k: {"median_deg": v.median_deg, "p95_deg": v.p95_deg, "share_over_45": v.share_over_45}
                for k, v in self.segments.items()
            },
            "share_any_segment_over_45": self.share_any_over_45,
            "facing": {"median_deg": self.facing_median_deg, "p95_deg": self.facing_p95_deg},
            "pelvis_path": {"mean_cm": self.path_mean_cm, "max_cm": self.path_max_cm, "scale": self.path_scale},
            "pelvis_drift": {"mean_cm": self.drift_mean_cm, "max_cm": self.drift_max_cm},
            "pelvis_vertical_speed": {
                "character_p99": self.pelvis_vz_p99,
                "actor_p99_scaled": self.actor_vz_p99_scaled,
            },
            "velocity_saturation": {
                "frames": int(self.saturated_frames.size),
                "share": self.saturated_share,
                "worst_joint": self.saturated_joint,
                "worst_joint_share": self.saturated_joint_share,
            },
            "geoms_on_floor": None if self.floor is None else self.floor.as_dict(),
            "pops": None if self.pops is None else self.pops.as_dict(),
        }


#: Frames whose kinematics are held at once while joint positions are gathered: the
#: figures keep ``(F, 3)`` per joint they read, never every joint of the skeleton.
BLOCK_FRAMES = 1024


def figure_joints() -> frozenset[str]:
    """The canonical joints the figures read: both ends of every segment of
    :data:`SEGMENTS` (``mid_hip`` as the two hips), and the pelvis (the mid-hip of a
    skeleton without hips)."""
    ends = {j for seg in SEGMENTS.values() for j in seg} - {"mid_hip"}
    return frozenset(ends | {"left_hip", "right_hip", "pelvis"})


def actor_joint_positions(motion, joint_indices: dict[str, int], names=None) -> dict[str, np.ndarray]:
    """Canonical joint -> ``(F, 3)`` world positions of the actor (metres, Z-up; NaN where lost).

    Only the joints in ``names`` are kept (None: every mapped joint), read by
    :meth:`~physmocap.motion.Motion.joint_world_positions` (the forward kinematics a block of
    frames at a time, laid out joint by joint).  Where the motion says a joint is lost
    (``confidence``) or its positions are the motion's own (a positional source), the
    columns are copied into one array laid out joint by joint (:func:`_joint_columns`)
    and marked NaN there, a column at a time."""
    wanted = {n: j for n, j in joint_indices.items() if names is None or n in names}
    world, column = motion.joint_world_positions(list(wanted.values()), BLOCK_FRAMES)
    if motion.confidence is None and motion.rotations is not None:
        return {name: world[:, column[j]] for name, j in wanted.items()}
    array, out = _joint_columns(wanted, motion.num_frames)
    for name, j in wanted.items():
        out[name][:] = world[:, column[j]]
        if motion.confidence is not None:
            out[name][motion.confidence[:, j] <= 0.0] = np.nan
        release(array)
        release(world)
    return out


def _joint_columns(names, frames: int) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """``(array (frames, K, 3), name -> array[:, k])``: the joints' positions laid out joint by
    joint, in a temporary file for a long clip (:func:`~physmocap.spill.spilled_empty`), so a
    figure reading a few joints maps in only their pages."""
    names = list(names)
    out = spilled_empty((int(frames), len(names), 3), by_column=True)
    return out, {n: out[:, k] for k, n in enumerate(names)}


def _let_go(*joint_sets: Mapping[str, np.ndarray]) -> None:
    """:func:`~physmocap.spill.release` the joint positions of ``joint_sets`` (those kept in a
    temporary file: the pages read so far leave the memory; nothing for arrays in memory)."""
    for joints in joint_sets:
        for column in joints.values():
            release(column)


def character_joint_positions(traj, names=None) -> dict[str, np.ndarray]:
    """Canonical joint -> ``(F, 3)`` world positions of the character's mapped sites/bodies
    (only the joints in ``names``; None: every tracked joint), kept as
    :func:`actor_joint_positions` keeps them."""
    ch = traj.character
    model = ch.model
    data = mujoco.MjData(model)
    wanted = [n for n in ch.tracked if names is None or n in names]
    sites = [(k, model.site(ch.tracked[n].name).id) for k, n in enumerate(wanted) if ch.tracked[n].kind == "site"]
    bodies = [(k, model.body(ch.tracked[n].name).id) for k, n in enumerate(wanted) if ch.tracked[n].kind != "site"]
    s_k, s_id = (np.array([a for a, _ in sites], int), np.array([b for _, b in sites], int))
    b_k, b_id = (np.array([a for a, _ in bodies], int), np.array([b for _, b in bodies], int))
    out, columns = _joint_columns(wanted, traj.num_frames)
    for s, rows in blocks(traj.qpos, BLOCK_FRAMES):  # a spilled trajectory: read a block at a time
        for t, q in enumerate(rows, start=s):
            data.qpos[:] = q
            mujoco.mj_kinematics(model, data)
            if s_k.size:
                out[t, s_k] = data.site_xpos[s_id]
            if b_k.size:
                out[t, b_k] = data.xpos[b_id]
        release(out)
    return columns


def _point(joints: dict[str, np.ndarray], name: str) -> np.ndarray | None:
    if name == "mid_hip":
        if "left_hip" in joints and "right_hip" in joints:
            return 0.5 * (joints["left_hip"] + joints["right_hip"])
        return joints.get("pelvis")
    return joints.get(name)


def angle_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle between vectors (degrees), NaN where either is degenerate or unknown."""
    na = np.linalg.norm(a, axis=-1)
    nb = np.linalg.norm(b, axis=-1)
    ok = (na > 1e-6) & (nb > 1e-6)
    cos = np.einsum("...i,...i->...", a, b) / np.where(ok, na * nb, 1.0)
    ang = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
    return np.where(ok, ang, np.nan)


def segment_direction_errors(actor: dict[str, np.ndarray], character: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Segment name -> ``(F,)`` angle in degrees between the character's segment
    and the actor's (NaN where the actor lost a joint); segments both have.  Joint
    positions kept in a temporary file are let go segment by segment (:func:`_let_go`)."""
    out = {}
    for seg, (a, b) in SEGMENTS.items():
        pa, da, pc, dc = _point(actor, a), _point(actor, b), _point(character, a), _point(character, b)
        if pa is None or da is None or pc is None or dc is None:
            continue
        out[seg] = angle_deg(dc - pc, da - pa)
        _let_go(actor, character)
    return out


def _heading(left: np.ndarray, right: np.ndarray) -> np.ndarray:
    """``(F,)`` heading angle (radians) of the direction ``(left - right) x z``."""
    d = left - right
    fwd = np.stack([d[:, 1], -d[:, 0]], axis=-1)  # (l - r) x z, horizontal part
    return np.arctan2(fwd[:, 1], fwd[:, 0])


def facing_errors(actor: dict[str, np.ndarray], character: dict[str, np.ndarray]) -> np.ndarray | None:
    """``(F,)`` absolute pelvis heading difference in degrees (0..180), or None without hips."""
    if not all(h in actor and h in character for h in ("left_hip", "right_hip")):
        return None
    ha = _heading(actor["left_hip"], actor["right_hip"])
    hc = _heading(character["left_hip"], character["right_hip"])
    d = np.angle(np.exp(1j * (hc - ha)))
    return np.degrees(np.abs(d))


def _second_difference(x: np.ndarray) -> np.ndarray:
    """``(F,)`` metres: :math:`|x_{t+1} - 2 x_t + x_{t-1}|` of ``x (F, 3)`` on frame :math:`t`
    (0 on the first and last frames; NaN where a neighbour is unknown)."""
    out = np.zeros(x.shape[0])
    if x.shape[0] > 2:
        out[1:-1] = np.linalg.norm(x[2:] - 2.0 * x[1:-1] + x[:-2], axis=1)
    return out


def pops(actor: dict[str, np.ndarray], character: dict[str, np.ndarray], scale: float = 1.0) -> Pops | None:
    """Frames on which a character joint jumps where the actor's does not (see the module
    docstring): per joint both have, the character's second difference minus the largest of
    the actor's (times ``scale``) at the joint and at its nearest ancestor among the joints
    given (:func:`~physmocap.canonical.canonical_parent`) over the frame and its neighbours; a
    lost actor joint (NaN) excuses its frames.  None without a joint on both sides."""
    from ..canonical import canonical_parent

    both = [j for j in character if j in actor]
    if not both:
        return None
    present = set(both)
    own = {j: np.nan_to_num(_second_difference(actor[j]) * scale, nan=np.inf) for j in both}
    F = len(next(iter(character.values())))
    worst = np.zeros(F)
    worst_at = np.full(F, -1)
    for k, j in enumerate(both):
        allowed = own[j]
        parent = canonical_parent(j, present)
        if parent is not None:
            allowed = np.maximum(allowed, own[parent])
        window = maximum_filter1d(allowed, size=3, mode="nearest") if F else allowed  # frames t-1 .. t+1
        excess = np.nan_to_num(_second_difference(character[j]), nan=0.0) - window
        better = excess > worst
        worst[better], worst_at[better] = excess[better], k
    frames = np.flatnonzero(worst > POP_M)
    t = int(np.argmax(worst)) if F else 0
    top = float(worst[t]) if F else 0.0
    return Pops(
        frames=frames,
        share=float(frames.size / max(F, 1)),
        worst_cm=100.0 * max(top, 0.0),
        worst_joint=both[int(worst_at[t])] if top > 0 else None,
        worst_frame=t if top > 0 else None,
        warn_frames=np.flatnonzero(worst > POP_WARN_M),
    )


def similarity_fit_2d(src: np.ndarray, dst: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    r"""Least-squares similarity :math:`x \mapsto s R x + t` taking ``src (F, 2)`` onto
    ``dst (F, 2)`` (Umeyama 1991): returns ``(s, R (2, 2), t (2,))``."""
    mu_s, mu_d = src.mean(axis=0), dst.mean(axis=0)
    a, b = src - mu_s, dst - mu_d
    var = float(np.mean(np.sum(a * a, axis=1)))
    if var < 1e-12:  # the actor stands still: translation only
        return 1.0, np.eye(2), mu_d - mu_s
    cov = b.T @ a / len(src)
    U, S, Vt = np.linalg.svd(cov)
    D = np.diag([1.0, np.sign(np.linalg.det(U @ Vt)) or 1.0])
    R = U @ D @ Vt
    s = float(np.trace(np.diag(S) @ D) / var)
    return s, R, mu_d - s * R @ mu_s


def path_deviation(actor: dict[str, np.ndarray], character: dict[str, np.ndarray]) -> tuple[np.ndarray, float] | None:
    """``((F,) cm, fitted scale)``: distance between the character's mid-hip floor
    path and the actor's after one similarity fit; None without a pelvis."""
    pa, pc = _point(actor, "mid_hip"), _point(character, "mid_hip")
    if pa is None or pc is None:
        return None
    ok = np.all(np.isfinite(pa[:, :2]), axis=1)
    if ok.sum() < 2:
        return None
    s, R, t = similarity_fit_2d(pa[ok, :2], pc[ok, :2])
    mapped = pa[:, :2] @ (s * R).T + t
    d = np.linalg.norm(mapped - pc[:, :2], axis=1) * 100.0
    d[~ok] = np.nan
    return d, s


def vertical_speed_p99(z: np.ndarray, fps: float) -> float | None:
    """99th percentile of :math:`|\\dot z|` (central differences, m/s)."""
    z = z[np.isfinite(z)]
    if z.size < 3:
        return None
    return float(np.percentile(np.abs(np.gradient(z) * fps), 99))


def saturation_matrix(
    model: mujoco.MjModel, qpos: np.ndarray, fps: float, limits: dict[str, float], groups: Sequence[Sequence[str]] = ()
) -> np.ndarray:
    """``(F-1, J)`` bool: joint ``j`` (in ``limits`` order) moves at :data:`SATURATION_RATIO`
    of its velocity limit or faster on transition ``t -> t+1`` (speeds in rad/s or m/s,
    computed :data:`BLOCK_FRAMES` transitions at a time); a hinge of one of ``groups`` (the
    character's ``velocity_groups``) by its body's angular speed along its axis, the speed the
    solver bounds (:func:`~physmocap.models.hinge_groups.joint_speeds`)."""
    from ..models.hinge_groups import joint_speeds

    F = qpos.shape[0]
    if F < 2 or not limits:
        return np.zeros((max(F - 1, 0), len(limits)), dtype=bool)
    names = list(limits)
    vmax = np.array([limits[n] for n in names], dtype=float)
    out = np.empty((F - 1, len(limits)), dtype=bool)
    for s in range(0, F - 1, BLOCK_FRAMES):
        e = min(F - 1, s + BLOCK_FRAMES)
        out[s:e] = joint_speeds(model, qpos[s : e + 1], fps, names, groups, limits) >= SATURATION_RATIO * vmax
        release(qpos)
    return out


def velocity_saturation(
    model: mujoco.MjModel, qpos: np.ndarray, fps: float, limits: dict[str, float], groups: Sequence[Sequence[str]] = ()
) -> np.ndarray:
    """Indices ``t`` of transitions ``t -> t+1`` on which some hinge/slide joint moves at
    :data:`SATURATION_RATIO` of its velocity limit or faster (:func:`saturation_matrix`)."""
    return np.flatnonzero(np.any(saturation_matrix(model, qpos, fps, limits, groups), axis=1))


#: A collision geom whose lowest point is within this of the floor rests on it (metres).
RESTING_HEIGHT = 0.002
#: A collision geom whose lowest point is within this of the floor is near it (metres).
NEAR_FLOOR_HEIGHT = 0.01
#: A near-floor geom moving horizontally faster than this scuffs (m/s).
SCUFF_SPEED = 0.30


@dataclass(frozen=True)
class GeomFloorContact:
    """Slip and scuffing measured on the character's collision geoms.

    Attributes:
        slip_mean_cm_s, slip_p95_cm_s: Horizontal slip of the feet resting on the
            floor, cm/s: per foot (its bodies, toes included; every other body on
            its own) and transition with a resting geom, the speed of the least
            moving point of its resting contact patch (:func:`pivot_slip`): a foot
            turning about a point it stands on pivots and does not slip; a foot
            whose every resting point moves does.
        resting_samples: Foot-transitions counted there.
        geom_slip_mean_cm_s, geom_slip_p95_cm_s: Horizontal speed of the material
            lowest point of every resting geom (lowest point within
            :data:`RESTING_HEIGHT` on both frames of a transition), cm/s: pivots
            count here (a heel swivelling about the ball slides).
        geom_resting_samples: Geom-transitions counted there.
        scuff_share: Share of near-floor geom-transitions (lowest point within
            :data:`NEAR_FLOOR_HEIGHT` on both frames) on which a geom of a foot that
            does not rest on the floor moves faster than :data:`SCUFF_SPEED`: a swing
            foot skimming the floor (a planted foot's moves are its slip).
        near_samples: Near-floor geom-transitions.
    """

    slip_mean_cm_s: float
    slip_p95_cm_s: float
    resting_samples: int
    scuff_share: float
    near_samples: int
    geom_slip_mean_cm_s: float = 0.0
    geom_slip_p95_cm_s: float = 0.0
    geom_resting_samples: int = 0

    def as_dict(self) -> dict:
        return {
            "slip_mean_cm_s": self.slip_mean_cm_s,
            "slip_p95_cm_s": self.slip_p95_cm_s,
            "resting_samples": self.resting_samples,
            "geom_slip_mean_cm_s": self.geom_slip_mean_cm_s,
            "geom_slip_p95_cm_s": self.geom_slip_p95_cm_s,
            "geom_resting_samples": self.geom_resting_samples,
            "scuff_share": self.scuff_share,
            "near_samples": self.near_samples,
        }


_BOX_CORNERS = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=float)


def _contact_patch(model: mujoco.MjModel, data: mujoco.MjData, g: int, tie: float = 1e-3) -> np.ndarray:
    """``(k, 3)`` the geom's lowest material points in its own frame (metres): the
    points of a face or edge lying flat within ``tie`` of the lowest (a box's bottom
    corners, a capsule's two end caps), one point otherwise."""
    R = data.geom_xmat[g].reshape(3, 3)
    size = model.geom_size[g]
    gtype = int(model.geom_type[g])
    G = mujoco.mjtGeom
    down = R.T @ np.array([0.0, 0.0, -1.0])  # world down in geom coordinates
    if gtype == G.mjGEOM_SPHERE:
        return (size[0] * down)[None]
    if gtype == G.mjGEOM_CAPSULE:
        pts = np.array([[0.0, 0.0, size[1]], [0.0, 0.0, -size[1]]])
    elif gtype == G.mjGEOM_BOX:
        pts = _BOX_CORNERS * size
    elif gtype == G.mjGEOM_MESH:
        mesh = int(model.geom_dataid[g])
        start, n = int(model.mesh_vertadr[mesh]), int(model.mesh_vertnum[mesh])
        pts = np.asarray(model.mesh_vert[start : start + n], dtype=float)
    else:  # cylinders, ellipsoids: the point under the centre
        return np.zeros((1, 3))
    z = pts @ R[2]
    low = pts[z <= z.min() + tie]
    return low + (size[0] * down if gtype == G.mjGEOM_CAPSULE else 0.0)


def _lowest_material_point(model: mujoco.MjModel, data: mujoco.MjData, g: int, tie: float = 1e-3) -> np.ndarray:
    """The geom's lowest point in its own frame (metres): for a face or edge lying
    flat, the centroid of its :func:`_contact_patch`."""
    return _contact_patch(model, data, g, tie).mean(axis=0)


def _distance_to_hull(c: np.ndarray, points: np.ndarray) -> float:
    """Distance (metres) from the 2-D point ``c`` to the convex hull of ``points (k, 2)``
    (0 inside it)."""
    from scipy.spatial import ConvexHull, QhullError

    if len(points) >= 3:
        try:
            hull = ConvexHull(points)
        except QhullError:  # collinear points: a segment, below
            hull = None
        if hull is not None:
            if np.all(hull.equations[:, :2] @ c + hull.equations[:, 2] <= 1e-12):
                return 0.0
            ring = points[hull.vertices]
            return min(_distance_to_segment(c, ring[i], ring[(i + 1) % len(ring)]) for i in range(len(ring)))
    if len(points) == 1:
        return float(np.linalg.norm(c - points[0]))
    axis = points[-1] - points[0] if len(points) == 2 else np.linalg.svd(points - points.mean(axis=0))[2][0]
    t = (points - points[0]) @ axis
    return _distance_to_segment(c, points[np.argmin(t)], points[np.argmax(t)])


def _distance_to_segment(c: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    ab = b - a
    n = float(ab @ ab)
    t = 0.0 if n < 1e-18 else min(max(float((c - a) @ ab) / n, 0.0), 1.0)
    return float(np.linalg.norm(c - (a + t * ab)))


def pivot_slip(before: np.ndarray, after: np.ndarray) -> float:
    r"""Horizontal displacement (metres) of the least moving point of a contact patch.

    ``before``, ``after``: ``(k, 2)`` horizontal positions of the patch's material
    points on two frames.  Their motion is fitted by a planar rigid motion
    :math:`x \mapsto R_\theta x + T` (least squares, 2-D Kabsch); its fixed point
    :math:`c = (I - R_\theta)^{-1} T` is the pivot, and every point :math:`p` moves by
    :math:`2|\sin(\theta/2)|\,|p - c|`.  The least moving point of the patch (its
    convex hull) therefore moves :math:`2|\sin(\theta/2)|\,d(c, \mathrm{hull})`: 0 for
    a foot turning about a point it stands on, the common displacement for a foot
    sliding without turning.  Where the points do not move rigidly (toes bending), the
    least displacement of any one of them bounds the figure.
    """
    before = np.asarray(before, dtype=float)
    after = np.asarray(after, dtype=float)
    least = float(np.linalg.norm(after - before, axis=1).min())
    if len(before) == 1:
        return least
    pc, qc = before.mean(axis=0), after.mean(axis=0)
    H = (before - pc).T @ (after - qc)
    theta = float(np.arctan2(H[0, 1] - H[1, 0], H[0, 0] + H[1, 1]))
    if abs(np.sin(theta / 2.0)) < 1e-9:
        return min(least, float(np.linalg.norm(qc - pc)))
    c_, s_ = np.cos(theta), np.sin(theta)
    R = np.array([[c_, -s_], [s_, c_]])
    T = qc - R @ pc
    pivot = np.linalg.solve(np.eye(2) - R, T)
    return min(least, 2.0 * abs(np.sin(theta / 2.0)) * _distance_to_hull(pivot, before))


def _geom_groups(model: mujoco.MjModel, geoms: list[int], feet: Mapping[str, Sequence[int]]) -> np.ndarray:
    """``(len(geoms),)`` group of each geom: its foot's index for the bodies of ``feet``,
    else a group of its own body."""
    group_of_body = {}
    for i, bodies in enumerate(feet.values()):
        for b in bodies:
            group_of_body[int(b)] = i
    n = len(feet)
    return np.array([group_of_body.get(int(model.geom_bodyid[g]), n + int(model.geom_bodyid[g])) for g in geoms])


def geom_floor_contact(
    model: mujoco.MjModel, qpos: np.ndarray, fps: float, floor: float = 0.0, feet: Mapping[str, Sequence[int]] | None = None
) -> GeomFloorContact:
    """:class:`GeomFloorContact` of a trajectory ``qpos (F, nq)`` on a floor at height ``floor``.

    Geom slip is the horizontal speed of the *material* point of a resting geom that
    touches the floor (its lowest point on the first frame of a transition, followed
    to the next frame): a foot rolling over its toe edge or a capsule rolling does
    not slip; a foot sliding does, and so does a heel swivelling about the ball.
    Foot slip (:func:`pivot_slip`) takes each foot's resting patch as a whole
    (``feet``: name -> body ids, e.g. :func:`~physmocap.models.geometry.foot_bodies`;
    other bodies each on their own), so a pivot is not slip.  Scuffing uses the
    material points of near-floor geoms; a geom of a foot resting on the floor on that
    transition does not scuff.
    """
    from ..models.geometry import character_geoms, geom_z_extent

    geoms = character_geoms(model, collision_only=True)
    F = qpos.shape[0]
    if F < 2 or not geoms:
        return GeomFloorContact(0.0, 0.0, 0, 0.0, 0)
    groups = _geom_groups(model, geoms, feet or {})
    data = mujoco.MjData(model)
    geom_slip: list[float] = []
    foot_slip: list[float] = []
    scuffs = near_count = 0
    prev = None  # (low, patches, pos, mat) of the previous frame
    for t in range(F):
        data.qpos[:] = qpos[t]
        mujoco.mj_kinematics(model, data)
        low = np.array([geom_z_extent(model, data, g)[0] - floor for g in geoms])
        pos = data.geom_xpos[geoms].copy()
        mat = data.geom_xmat[geoms].reshape(-1, 3, 3).copy()
        # a patch is needed only where the geom is near the floor (it may rest or scuff next)
        patches = [_contact_patch(model, data, g) if low[k] < NEAR_FLOOR_HEIGHT else None for k, g in enumerate(geoms)]
        if prev is not None:
            p_low, p_patches, p_pos, p_mat = prev
            resting = (low < RESTING_HEIGHT) & (p_low < RESTING_HEIGHT)
            # near the floor on both frames: the whole move skims the floor (a geom lifting off or
            # landing crosses the band in one transition, further the lower the frame rate)
            near = (low < NEAR_FLOOR_HEIGHT) & (p_low < NEAR_FLOOR_HEIGHT)
            planted_groups = set(groups[resting].tolist())
            moved: dict[int, tuple[list[np.ndarray], list[np.ndarray]]] = {}
            for k in np.flatnonzero(near):
                local = p_patches[k]
                before = p_pos[k] + local @ p_mat[k].T
                after = pos[k] + local @ mat[k].T
                speed = float(np.linalg.norm((after.mean(axis=0) - before.mean(axis=0))[:2])) * fps
                near_count += 1
                if resting[k]:
                    geom_slip.append(speed)
                    b, a = moved.setdefault(int(groups[k]), ([], []))
                    b.append(before[:, :2])
                    a.append(after[:, :2])
                elif int(groups[k]) not in planted_groups:
                    scuffs += speed > SCUFF_SPEED
            for b, a in moved.values():
                foot_slip.append(pivot_slip(np.concatenate(b), np.concatenate(a)) * fps)
        prev = (low, patches, pos, mat)
    foot = np.asarray(foot_slip) * 100.0
    geom = np.asarray(geom_slip) * 100.0
    return GeomFloorContact(
        slip_mean_cm_s=float(foot.mean()) if foot.size else 0.0,
        slip_p95_cm_s=float(np.percentile(foot, 95)) if foot.size else 0.0,
        resting_samples=int(foot.size),
        scuff_share=float(scuffs / near_count) if near_count else 0.0,
        near_samples=int(near_count),
        geom_slip_mean_cm_s=float(geom.mean()) if geom.size else 0.0,
        geom_slip_p95_cm_s=float(np.percentile(geom, 95)) if geom.size else 0.0,
        geom_resting_samples=int(geom.size),
    )


def _nan_stats(x: np.ndarray) -> tuple[float, float]:
    x = x[np.isfinite(x)]
    if x.size == 0:
        return float("nan"), float("nan")
    return float(np.median(x)), float(np.percentile(x, 95))


def fidelity(
    actor: dict[str, np.ndarray],
    character: dict[str, np.ndarray],
    fps: float,
    scale: float = 1.0,
    *,
    model: mujoco.MjModel | None = None,
    qpos: np.ndarray | None = None,
    velocity_limits: dict[str, float] | None = None,
    floor_contact: bool = True,
    feet: Mapping[str, Sequence[int]] | None = None,
    velocity_groups: Sequence[Sequence[str]] = (),
) -> Fidelity:
    """All fidelity figures from the actor's and the character's joint centres.

    Args:
        actor, character: Canonical joint -> ``(F, 3)`` world positions (metres, Z-up).
        fps: Frame rate.
        scale: Root scale of the retarget (character leg length over the actor's),
            for the vertical-speed comparison.
        model, qpos, velocity_limits: The character's model, trajectory and
            velocity limits, for the saturation count (optional).
        floor_contact: Also measure slip and scuffing on the collision geoms
            (:func:`geom_floor_contact`; the slowest figure).
        feet: Foot name -> the character's body ids of that foot, for the slip of whole
            feet (:func:`~physmocap.models.geometry.foot_bodies`; None: each body alone).
        velocity_groups: The character's ``velocity_groups`` (hinges whose limits bound
            their body's angular speed along their axes), for the saturation count.
    """
    seg = segment_direction_errors(actor, character)
    segments = {}
    over = None
    for name, err in seg.items():
        med, p95 = _nan_stats(err)
        big = np.nan_to_num(err, nan=0.0) > SEGMENT_WARN_DEG
        segments[name] = SegmentError(med, p95, float(np.mean(big)))
        over = big if over is None else over | big
    frames_over = np.flatnonzero(over) if over is not None else np.zeros(0, dtype=int)
    n = len(over) if over is not None else 1
    used = figure_joints()  # whatever else the caller gave (the same figure from every caller)
    jumps = pops({k: v for k, v in actor.items() if k in used}, {k: v for k, v in character.items() if k in used}, scale)
    _let_go(actor, character)
    face = facing_errors(actor, character)
    _let_go(actor, character)
    f_med, f_p95 = _nan_stats(face) if face is not None else (None, None)
    frames_face = np.flatnonzero(np.nan_to_num(face, nan=0.0) > FACING_WARN_DEG) if face is not None else np.zeros(0, dtype=int)
    path = path_deviation(actor, character)
    _let_go(actor, character)
    p_mean = p_max = p_scale = None
    if path is not None:
        d, p_scale = path
        p_mean, p_max = float(np.nanmean(d)), float(np.nanmax(d))
    vz_c = vz_a = None
    pa, pc = _point(actor, "mid_hip"), _point(character, "mid_hip")
    if pa is not None and pc is not None:
        vz_c = vertical_speed_p99(pc[:, 2], fps)
        va = vertical_speed_p99(pa[:, 2], fps)
        vz_a = None if va is None else va * scale
    sat = np.zeros(0, dtype=int)
    worst_joint, worst_share = None, 0.0
    transitions = max(1, (qpos.shape[0] - 1) if qpos is not None else 1)
    if model is not None and qpos is not None and velocity_limits:
        matrix = saturation_matrix(model, qpos, fps, velocity_limits, velocity_groups)
        sat = np.flatnonzero(np.any(matrix, axis=1))
        if matrix.size and matrix.any():
            counts = matrix.sum(axis=0)
            worst_joint = list(velocity_limits)[int(np.argmax(counts))]
            worst_share = float(counts.max() / transitions)
    floor_figures = geom_floor_contact(model, qpos, fps, feet=feet) if floor_contact and model is not None and qpos is not None else None
    return Fidelity(
        segments=segments,
        share_any_over_45=float(frames_over.size / n),
        frames_any_over_45=frames_over,
        facing_median_deg=f_med,
        facing_p95_deg=f_p95,
        frames_facing_over_30=frames_face,
        path_mean_cm=p_mean,
        path_max_cm=p_max,
        path_scale=p_scale,
        pelvis_vz_p99=vz_c,
        actor_vz_p99_scaled=vz_a,
        saturated_frames=sat,
        saturated_share=float(sat.size / transitions),
        floor=floor_figures,
        saturated_joint=worst_joint,
        saturated_joint_share=worst_share,
        pops=jumps,
    )


def trajectory_fidelity(traj, floor_contact: bool = True) -> Fidelity:
    """:func:`fidelity` of a retargeted trajectory against the source it was retargeted from."""
    motion = traj.source_motion
    joints = traj.joint_indices
    if motion is None or joints is None:
        raise ValueError(
            f"{traj.source}: the trajectory does not carry the motion it was retargeted from "
            "(source_motion and joint_indices): fidelity compares the two"
        )
    used = figure_joints()
    actor = actor_joint_positions(motion, joints, used)
    character = character_joint_positions(traj, used)
    scale = float(getattr(traj.targets, "scale", 1.0)) if traj.targets is not None else 1.0
    ch = traj.character
    from ..models.geometry import foot_bodies

    fid = fidelity(
        actor, character, traj.fps, scale, model=ch.model, qpos=traj.qpos, velocity_limits=ch.velocity_limits,
        floor_contact=floor_contact, feet=foot_bodies(ch.model, ch.contacts),
        velocity_groups=getattr(ch, "velocity_groups", ()),
    )
    return with_pelvis_drift(fid, traj, character.get("pelvis"))


def pelvis_drift(traj, pelvis: np.ndarray | None) -> tuple[float, float] | None:
    """``(mean, max)`` cm: horizontal distance between the character's ``pelvis (F, 3)``
    and its target in ``traj.targets`` (no fit; the targets read :data:`BLOCK_FRAMES` frames at
    a time); None without either."""
    targets = getattr(traj, "targets", None)
    if pelvis is None or targets is None or "pelvis" not in targets.names:
        return None
    col = list(targets.names).index("pelvis")
    d = np.empty(min(len(pelvis), targets.num_frames))
    for s, rows in blocks(targets.positions[: d.size], BLOCK_FRAMES):
        d[s : s + rows.shape[0]] = np.linalg.norm(pelvis[s : s + rows.shape[0], :2] - rows[:, col, :2], axis=1) * 100.0
    d = d[np.isfinite(d)]
    return (float(d.mean()), float(d.max())) if d.size else None


def with_pelvis_drift(fid: Fidelity, traj, pelvis: np.ndarray | None) -> Fidelity:
    """``fid`` with the :func:`pelvis_drift` of ``traj`` (``fid`` itself where there is none)."""
    drift = pelvis_drift(traj, pelvis)
    return fid if drift is None else replace(fid, drift_mean_cm=drift[0], drift_max_cm=drift[1])


#: Share of the clip above which segments more than :data:`SEGMENT_WARN_DEG` off are warned about.
SEGMENT_WARN_SHARE = 0.01


def _frames_text(frames: np.ndarray, offset: int) -> str:
    """``"12-40, 97, ..."``: runs of consecutive frames (source numbering), the first few."""
    if frames.size == 0:
        return ""
    f = np.asarray(frames, dtype=int) + int(offset)
    breaks = np.flatnonzero(np.diff(f) > 1)
    starts = np.concatenate([[f[0]], f[breaks + 1]])
    ends = np.concatenate([f[breaks], [f[-1]]])
    parts = [str(a) if a == b else f"{a}-{b}" for a, b in zip(starts, ends)]
    return ", ".join(parts[:6]) + (" ..." if len(parts) > 6 else "")


def fidelity_warnings(fid: Fidelity, offset: int = 0) -> list[str]:
    """One message per fidelity problem worth a warning (frames in source numbering:
    ``offset`` is the source frame of the trajectory's first frame).

    * a segment more than :data:`SEGMENT_WARN_DEG` off on more than
      :data:`SEGMENT_WARN_SHARE` of the clip;
    * facing more than :data:`FACING_WARN_DEG` off;
    * joints at their velocity caps on more than 0.5 % of the clip;
    * a joint that jumps more than :data:`POP_WARN_M` further than the actor's in one frame.
    """
    out = []
    if fid.share_any_over_45 > SEGMENT_WARN_SHARE:
        worst = [k for k, v in fid.segments.items() if v.share_over_45 > SEGMENT_WARN_SHARE] or list(fid.segments)
        out.append(
            f"the character does not follow the actor: {', '.join(worst)} more than {SEGMENT_WARN_DEG:.0f} degrees "
            f"off on {100 * fid.share_any_over_45:.1f} % of the frames ({_frames_text(fid.frames_any_over_45, offset)})"
        )
    if fid.frames_facing_over_30.size:
        out.append(
            f"the character faces more than {FACING_WARN_DEG:.0f} degrees away from the actor on "
            f"{fid.frames_facing_over_30.size} frame(s) ({_frames_text(fid.frames_facing_over_30, offset)})"
        )
    if fid.saturated_share > 0.005:
        out.append(
            f"joints move at their velocity caps on {fid.saturated_frames.size} frame(s) "
            f"({100 * fid.saturated_share:.1f} %: {_frames_text(fid.saturated_frames, offset)}); the character lags "
            "the actor there"
        )
    jumps = fid.pops
    if jumps is not None and jumps.warn_frames.size:
        out.append(
            f"the character jumps where the actor does not on {jumps.warn_frames.size} frame(s) "
            f"({_frames_text(jumps.warn_frames, offset)}; worst {jumps.worst_cm:.1f} cm, {jumps.worst_joint} "
            f"at frame {int(jumps.worst_frame) + int(offset)})"
        )
    return out
