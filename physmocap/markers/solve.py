"""Marker-driven IK: a labelled marker recording to the actor's own skeleton, frame by frame.

1. **Calibration** (:mod:`.functional`): joint centres (functional where the clip exercises
   the joint, else regression), segment lengths fixed for the clip, each marker's segment.
2. **Actor model**: the default humanoid scaled to those lengths
   (:func:`physmocap.models.scaling.scaled_humanoid_spec`, MjSpec), so it keeps the
   goniometric joint ranges (:mod:`physmocap.models.rom`) and the sole contact sites.
3. **Marker sites**: the model is posed on a set of calibration frames spread over the clip by
   IK on the joint centres, then each marker gets a site on its segment's body at its mean
   position in the body frame over those frames; the frames are solved again on the markers
   and the sites re-estimated (twice), which settles the limbs' axial rotation.
4. **Solve**: every frame with the existing per-frame solver
   (:class:`physmocap.ik.solver.FrameSolver`): all markers in one
   :class:`~physmocap.ik.tasks.SitesPositionTask`, each weighted by the inverse of its scatter on
   its segment (soft tissue), switched off on frames where it is invalid (its segment's other
   markers carry it: the rigid-body fill); joint ranges, velocity bounds and the floor hard
   constraints; warm-started from the previous frame.  Markers no segment explains (props,
   boxes, strays) are ignored and listed.

Residuals (distance between each measured marker and its solved site) are reported per
marker, per segment and overall; gaps per marker and the frames where a segment has no
valid marker (its pose then comes from the joint limits and its neighbours).
"""

from __future__ import annotations

import os
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from ..errors import InputError, warn
from ..options import check_fields
from .functional import Calibration, attach_by_rigidity, functional_joint_centres, warn_fallbacks
from .joints import up_axis
from .markerset import MarkerSet, recording_marker_set
from .motion import _to_z_up
from .recording import MarkerRecording

__all__ = ["MarkerSolveOptions", "MarkerSolution", "ActorModel", "calibrate_actor", "calibrate_segments", "fit_actor",
           "solve_markers", "frame_ranges", "load_spec_character", "pose_on_centres"]

#: Model body of each marker segment (default humanoid body names).
SEGMENT_BODY = {
    "pelvis": "pelvis", "thorax": "thorax", "head": "head",
    **{f"{s}_{seg}": f"{s}_{body}" for s in ("left", "right")
       for seg, body in (("clavicle", "clavicle"), ("thigh", "thigh"), ("shank", "shank"), ("foot", "foot"),
                         ("upper_arm", "upper_arm"), ("forearm", "forearm"), ("hand", "hand"))},
}

#: Canonical joints tracked (joint centres) when posing the model on the calibration frames.
CALIBRATION_TARGETS = (
    "pelvis", "left_hip", "right_hip", "left_knee", "right_knee", "left_ankle", "right_ankle",
    "left_toe", "right_toe", "neck", "left_shoulder", "right_shoulder", "left_elbow", "right_elbow",
    "left_wrist", "right_wrist", "left_hand_end", "right_hand_end",
)


@dataclass(frozen=True)
class MarkerSolveOptions:
    """How markers are solved: the one options object of ``physmocap solve``, of ``retarget``
    on marker files (``--marker-max-iterations``, ``--marker-no-floor``) and of
    ``load_motion(take.c3d, solve_options=...)``; its values are checked when it is made.

    Attributes:
        max_iterations: QP iterations per frame (warm-started from the previous frame), >= 1.
        calibration_frames: Frames used to place the marker sites (spread over the clip), >= 1.
        velocity_limits: Bound frame-to-frame joint steps by human joint speeds.
        floor: Keep the feet above the floor (found from the feet's lowest points).
        min_weight_scatter: Scatter (metres) below which a marker's weight stops growing, > 0.
        rigidity: Largest scatter (metres) of a marker on a segment for it to be attached, > 0.

    Raises:
        OptionError: A value out of its range, or of the wrong type.
    """

    max_iterations: int = 2
    calibration_frames: int = 60
    velocity_limits: bool = True
    floor: bool = True
    min_weight_scatter: float = 0.005
    rigidity: float = 0.025

    def __post_init__(self) -> None:
        check_fields(self, "marker solve", counts=("max_iterations", "calibration_frames"),
                     positive=("max_iterations", "calibration_frames", "min_weight_scatter", "rigidity"))


@dataclass
class MarkerSolution:
    """What :func:`solve_markers` returns.

    Attributes:
        trajectory: The actor model's :class:`~physmocap.trajectory.Trajectory`.
        calibration: The :class:`~.functional.Calibration` (file axes).
        residuals: ``(F, M)`` metres, NaN where the marker is invalid or unattached.
        segment_of: Marker index -> segment, for the attached markers.
        ignored: Labels of the markers no segment explains.
        joint_positions: Canonical joint -> ``(F, 3)`` solved centres (metres, Z-up, floor at 0).
        to_z_up: ``(3, 3)`` rotation from the file's axes to the solved (Z-up) axes.
        floor: Height (file's up axis, metres) taken as the floor.
        cpu_seconds, wall_seconds: Time of the per-frame solve (without the calibration).
        relaxed: ``(F,)`` relaxation level per frame (0 = every constraint held).
    """

    trajectory: Any
    calibration: Calibration
    residuals: np.ndarray
    segment_of: dict[int, str]
    ignored: list[str]
    joint_positions: dict[str, np.ndarray]
    to_z_up: np.ndarray
    floor: float
    cpu_seconds: float
    wall_seconds: float
    relaxed: np.ndarray
    recording: MarkerRecording = field(repr=False, default=None)  # type: ignore[assignment]

    def report(self) -> dict:
        """The residual and gap report (JSON-ready; millimetres; the same for the same input and
        options: no timings, see :meth:`frames_per_second`)."""
        return marker_report(self)

    def frames_per_second(self) -> tuple[float, float]:
        """``(CPU, wall)`` frames per second of the per-frame solve (this run's; not in :meth:`report`)."""
        frames = self.recording.num_frames
        return frames / max(self.cpu_seconds, 1e-9), frames / max(self.wall_seconds, 1e-9)


def frame_ranges(mask: np.ndarray) -> list[list[int]]:
    """``[[start, end), ...]`` runs of True in a boolean array."""
    m = np.concatenate([[False], np.asarray(mask, bool), [False]])
    d = np.flatnonzero(np.diff(m.astype(np.int8)))
    return [[int(a), int(b)] for a, b in zip(d[::2], d[1::2])]


# -- the actor model -----------------------------------------------------------------
def _actor_lengths(cal: Calibration, base) -> dict[tuple[str, str], float]:
    """Segment lengths of the default humanoid's segments that the calibration measures."""
    L = cal.lengths
    out: dict[tuple[str, str], float] = {}
    for side in ("left", "right"):
        for a, b in (("hip", "knee"), ("knee", "ankle"), ("shoulder", "elbow"), ("elbow", "wrist")):
            v = L.get((f"{side}_{a}", f"{side}_{b}"))
            if v is not None and 0.05 < v < 1.0:
                out[(f"{side}_{a}", f"{side}_{b}")] = v
    if ("left_hip", "right_hip") in L:
        for side in ("left", "right"):
            out[("pelvis", f"{side}_hip")] = L[("left_hip", "right_hip")] / 2.0
    rest = base.rest_positions()
    if ("left_shoulder", "right_shoulder") in L:
        half = L[("left_shoulder", "right_shoulder")] / 2.0
        humanoid_half = float(rest["left_shoulder"][1])
        clav = float(rest["left_clavicle"][1])
        r = max(0.3, (half - clav) / max(humanoid_half - clav, 1e-3))
        for side in ("left", "right"):
            out[(f"{side}_clavicle", f"{side}_shoulder")] = base.segment_lengths[(f"{side}_clavicle", f"{side}_shoulder")] * r
    P = cal.positions
    if all(k in P for k in ("left_hip", "right_hip", "left_shoulder", "right_shoulder")):
        trunk = np.linalg.norm(0.5 * (P["left_shoulder"] + P["right_shoulder"]) - 0.5 * (P["left_hip"] + P["right_hip"]), axis=1)
        trunk = trunk[np.isfinite(trunk)]
        if trunk.size:
            mid_s = 0.5 * (rest["left_shoulder"] + rest["right_shoulder"])
            r = float(np.median(trunk)) / float(np.linalg.norm(mid_s - rest["pelvis"]))
            for seg in (("pelvis", "spine"), ("spine", "chest"), ("chest", "left_clavicle"), ("chest", "right_clavicle"),
                        ("chest", "neck"), ("neck", "head"), ("head", "head_end")):
                out[seg] = base.segment_lengths[seg] * r
    return out


def load_spec_character(spec: mujoco.MjSpec, folder: Path, name: str):
    """Compile ``spec`` into a :class:`~physmocap.models.Character` (through a file, which
    the loader and its mapping need)."""
    from ..models.character import load_character
    from ..models.humanoid_builder import mapping_toml

    xml = folder / f"{name}.xml"
    xml.write_text(spec.to_xml(), encoding="utf-8")
    (folder / f"{name}.map.toml").write_text(mapping_toml().replace('name = "humanoid"', f'name = "{name}"'), encoding="utf-8")
    return load_character(xml)


def _root_pose(P: dict[str, np.ndarray], t: int, fallback: np.ndarray) -> np.ndarray:
    """Root position and w-x-y-z orientation from the hips (left axis) and the neck (up)."""
    from scipy.spatial.transform import Rotation

    try:
        lh, rh = P["left_hip"][t], P["right_hip"][t]
        up_pt = P.get("neck", P.get("left_shoulder"))[t]
    except (KeyError, TypeError):
        return fallback
    if not (np.all(np.isfinite(lh)) and np.all(np.isfinite(rh)) and np.all(np.isfinite(up_pt))):
        return fallback
    mid = 0.5 * (lh + rh)
    y = lh - rh
    y /= np.linalg.norm(y)
    z = up_pt - mid
    z -= y * (z @ y)
    z /= np.linalg.norm(z)
    x = np.cross(y, z)
    q = Rotation.from_matrix(np.stack([x, y, z], 1)).as_quat()  # x-y-z-w
    return np.concatenate([mid, [q[3], q[0], q[1], q[2]]])


def _solver_character(char, tracked_sites: dict[str, str]):
    """The character with ``tracked`` replaced by ``name -> site`` (for FrameSolver)."""
    import dataclasses

    from ..models.mapping import TrackedFrame

    return dataclasses.replace(char, tracked={k: TrackedFrame("site", v) for k, v in tracked_sites.items()})


@dataclass
class ActorModel:
    """The calibrated actor: what every frame's marker-driven IK needs (steps 1-3 of the
    module docstring), from :func:`calibrate_actor`.

    Attributes:
        character: The actor humanoid with one site per attached marker.
        calibration: The :class:`~.functional.Calibration` (file axes).
        labels: The recording's marker labels (frames to solve use the same order).
        attached: Indices of the markers with a site, in target order.
        site_names: Marker index -> site name.
        segment_of: Attached marker index -> segment.
        weights: ``(len(attached),)`` cost per metre of each marker.
        ignored: Labels of the markers no segment explains.
        to_z_up: ``(3, 3)`` rotation from the file's axes to Z-up.
        floor: Height (file's up axis, metres) taken as the floor.
        use_floor: Whether the floor is a constraint.
        rest_pose: A calibrated ``qpos`` to start from (its root is replaced per start).
        fps: The recording's frame rate.
        options: The :class:`MarkerSolveOptions`.
        marker_set: The roles of the markers.
    """

    character: Any
    calibration: Calibration
    labels: tuple[str, ...]
    attached: list[int]
    site_names: dict[int, str]
    segment_of: dict[int, str]
    weights: np.ndarray
    ignored: list[str]
    to_z_up: np.ndarray
    floor: float
    use_floor: bool
    rest_pose: np.ndarray
    fps: float
    options: MarkerSolveOptions
    marker_set: MarkerSet

    def frame_solver(self, max_iterations: int | None = None):
        """A warm-started :class:`~physmocap.ik.solver.FrameSolver` on the marker sites."""
        it = self.options.max_iterations if max_iterations is None else max_iterations
        return _marker_solver(self.character, self.fps, self.attached, self.site_names, self.weights, self.options,
                              self.use_floor, it)

    def to_solver_frame(self, points: np.ndarray) -> np.ndarray:
        """``(..., M, 3)`` markers (metres, file axes) to the solver's Z-up frame, floor at 0."""
        P = np.asarray(points, dtype=float) @ self.to_z_up.T
        P[..., 2] -= self.floor
        return P

    def start_pose(self, points: np.ndarray) -> np.ndarray:
        """``rest_pose`` with the root placed on one frame of markers ``(M, 3)`` (file axes):
        the hips of the regression (:mod:`.joints`) and the neck, else kept."""
        from .joints import joint_centres

        q = np.array(self.rest_pose, float)
        rec = MarkerRecording(self.labels, np.asarray(points, float)[None], self.fps, Path("<frame>"))
        try:
            jc = joint_centres(rec, self.marker_set)
        except InputError:
            return q
        centres = {k: self.to_solver_frame(v) for k, v in jc.positions.items()}
        q[:7] = _root_pose(centres, 0, q[:7])
        return q


def solve_markers(
    rec: MarkerRecording,
    marker_set: str | os.PathLike | MarkerSet | None = None,
    options: MarkerSolveOptions | None = None,
) -> MarkerSolution:
    """Solve a marker recording onto an actor-fitted humanoid (see the module docstring)."""
    from ..trajectory import SolverStats, Trajectory

    actor = calibrate_actor(rec, marker_set, options)
    F, M = rec.num_frames, len(rec.labels)
    char, attached, cal, R = actor.character, actor.attached, actor.calibration, actor.to_z_up
    valid = rec.valid
    Pz = actor.to_solver_frame(rec.positions)
    # -- every frame
    solver = actor.frame_solver()
    model = char.model
    sids = np.array([model.site(actor.site_names[i]).id for i in attached])
    canon = [n for n in char.tracked]  # canonical joints of the actor model (sites)
    canon_ids = np.array([model.site(char.tracked[n].name).id for n in canon])
    qpos = np.zeros((F, model.nq))
    residuals = np.full((F, M), np.nan)
    J = np.zeros((F, len(canon), 3))
    relaxed = np.zeros(F, dtype=np.int8)
    iters = np.zeros(F, dtype=np.int16)
    latency = np.zeros(F)
    orient = np.tile([0.0, 0, 0, 1], (len(attached), 1))
    solver.reset(actor.start_pose(rec.positions[0]))
    data = solver.configuration.data
    c0, w0 = time.process_time(), time.perf_counter()
    for t in range(F):
        ts = time.perf_counter()
        on = valid[t, attached]
        q, it, level = solver.solve_frame(np.nan_to_num(Pz[t, attached]), orient, on, first=(t == 0))
        latency[t] = time.perf_counter() - ts
        qpos[t] = q
        iters[t], relaxed[t] = it, level
        d = np.linalg.norm(data.site_xpos[sids] - Pz[t, attached], axis=1)
        residuals[t, attached] = np.where(on, d, np.nan)
        J[t] = data.site_xpos[canon_ids]
    cpu, wall = time.process_time() - c0, time.perf_counter() - w0
    traj = Trajectory(character=char, qpos=qpos, fps=rec.fps, source=str(rec.source),
                      solver=SolverStats(iterations=iters, relaxation=relaxed, latency=latency))
    return MarkerSolution(
        trajectory=traj, calibration=cal, residuals=residuals, segment_of=dict(actor.segment_of),
        ignored=actor.ignored, joint_positions={n: J[:, k] for k, n in enumerate(canon)}, to_z_up=R, floor=actor.floor,
        cpu_seconds=cpu, wall_seconds=wall, relaxed=relaxed, recording=rec,
    )


def check_calibration_length(rec: MarkerRecording) -> None:
    """An :class:`~physmocap.errors.InputError` when the recording has fewer frames than a
    segment's mean marker constellation needs (:data:`.functional.MIN_CONSTELLATION_FRAMES`)."""
    from .functional import MIN_CONSTELLATION_FRAMES

    if rec.num_frames < MIN_CONSTELLATION_FRAMES:
        raise InputError(f"too short to calibrate ({rec.num_frames} frame{'s' if rec.num_frames != 1 else ''}, need "
                         f"{MIN_CONSTELLATION_FRAMES}): each segment's marker shape is averaged over at least "
                         f"{MIN_CONSTELLATION_FRAMES} frames", path=rec.source)


def calibrate_actor(
    rec: MarkerRecording,
    marker_set: str | os.PathLike | MarkerSet | None = None,
    options: MarkerSolveOptions | None = None,
) -> ActorModel:
    """Calibrate the actor on a recording (a range-of-motion clip, the first seconds of a take,
    or the whole take), steps 1-3 of the module docstring, in two jobs:
    :func:`calibrate_segments` (joint centres, each marker's segment) on the markers alone,
    then :func:`fit_actor` (the scaled humanoid and its marker sites) on the model."""
    opt = options or MarkerSolveOptions()
    ms = recording_marker_set(rec, marker_set)
    cal, seg_of = calibrate_segments(rec, ms, opt)
    return fit_actor(rec, ms, cal, seg_of, opt)


def calibrate_segments(rec: MarkerRecording, ms: MarkerSet,
                       opt: MarkerSolveOptions) -> tuple[Calibration, dict[int, str]]:
    """Step 1: the joint centres (:func:`.functional.functional_joint_centres`, regression
    fallbacks warned) and marker index -> segment (by role and name, then by rigidity:
    :func:`.functional.attach_by_rigidity`; segments left without a marker warned).  An
    :class:`~physmocap.errors.InputError` when no sample is valid or the clip is too short."""
    if not rec.valid.any():
        raise InputError("every marker sample is invalid (NaN, zero or a negative residual): nothing to solve", path=rec.source)
    check_calibration_length(rec)
    cal = functional_joint_centres(rec, ms)
    warn_fallbacks(cal, rec.source)
    seg_of = attach_by_rigidity(rec, cal.frames, cal.segment_of, opt.rigidity)
    seg_of = {i: s for i, s in seg_of.items() if s in SEGMENT_BODY}
    bare = [s for s in SEGMENT_BODY if s not in set(seg_of.values())]
    if bare:
        warn(f"{rec.source}: no marker on {len(bare)} segment(s): {', '.join(bare)}; they keep the actor's rest "
             "pose")
    # segments with too few markers for a frame still take their markers (the IK needs no frame)
    return cal, seg_of


@dataclass
class _SolverFrame:
    """A recording in the solver's frame (metres, Z-up, floor at 0).

    Attributes:
        to_z_up: ``(3, 3)`` rotation from the file's axes.
        markers: ``(F, M, 3)`` the markers.
        centres: Joint -> ``(F, 3)`` the calibrated centres.
        floor: Height (file's up axis, metres) taken as the floor.
        use_floor: Whether the floor is a constraint (asked for, and foot markers exist).
    """

    to_z_up: np.ndarray
    markers: np.ndarray
    centres: dict[str, np.ndarray]
    floor: float
    use_floor: bool


def _solver_frame(rec: MarkerRecording, ms: MarkerSet, cal: Calibration, seg_of: dict[int, str],
                  floor_on: bool) -> _SolverFrame:
    """The markers and centres turned Z-up, the floor (2 cm below the 1st percentile of the
    lowest foot marker per frame: markers sit about 2 cm above the sole) at 0."""
    R = _to_z_up(up_axis(rec, ms))
    Pz = rec.positions @ R.T
    centres = {k: v @ R.T for k, v in cal.positions.items()}
    foot = [i for i, s in seg_of.items() if s.endswith("_foot")]
    floor = 0.0
    if foot:
        lows = np.nanmin(Pz[:, foot, 2], axis=1)
        lows = lows[np.isfinite(lows)]
        if lows.size:
            floor = float(np.percentile(lows, 1)) - 0.02
    Pz[..., 2] -= floor
    centres = {k: v - np.array([0.0, 0.0, floor]) for k, v in centres.items()}
    return _SolverFrame(to_z_up=R, markers=Pz, centres=centres, floor=floor, use_floor=bool(floor_on and foot))


def fit_actor(rec: MarkerRecording, ms: MarkerSet, cal: Calibration, seg_of: dict[int, str],
              opt: MarkerSolveOptions) -> ActorModel:
    """Steps 2-3: the default humanoid scaled to the calibrated lengths, posed by IK on the
    joint centres over calibration frames spread through the clip (:func:`_calibration_frames`,
    :func:`pose_on_centres`), then one site per marker at its mean position on its body,
    refined on the markers (:func:`_place_marker_sites`)."""
    from ..models.character import load_character
    from ..models.scaling import scaled_humanoid_spec

    frame = _solver_frame(rec, ms, cal, seg_of, opt.floor)
    spec = scaled_humanoid_spec(_actor_lengths(cal, load_character()))
    with tempfile.TemporaryDirectory(prefix="physmocap-actor-") as tmp:
        actor = load_spec_character(spec, Path(tmp), "actor")
        centres, names, calib = _calibration_frames(rec, actor, frame.centres, opt.calibration_frames)
        C = np.stack([centres[n] for n in names], 1)
        Q = pose_on_centres(actor, centres, names, C, calib, rec.fps)
        char, site_names, attached, ignored, weights, Q = _place_marker_sites(
            spec, Path(tmp), rec, actor, frame, seg_of, names, C, calib, Q, opt)
    return ActorModel(
        character=char, calibration=cal, labels=tuple(rec.labels), attached=attached, site_names=site_names,
        segment_of={i: seg_of[i] for i in attached}, weights=weights, ignored=ignored, to_z_up=frame.to_z_up,
        floor=frame.floor, use_floor=frame.use_floor, rest_pose=np.array(Q[0]), fps=float(rec.fps), options=opt,
        marker_set=ms,
    )


def _calibration_frames(rec: MarkerRecording, actor, centres: dict[str, np.ndarray],
                        count: int) -> tuple[dict[str, np.ndarray], list[str], np.ndarray]:
    """``(centres, tracked joint names, frame indices)``: the joints the actor is fitted to
    (:data:`CALIBRATION_TARGETS` the calibration places; the pelvis from the hips when
    missing) and up to ``count`` frames spread evenly over those where at least 80 % of them
    are seen.  An InputError naming the file when there is no such joint or frame."""
    centres = dict(centres)
    names = [n for n in CALIBRATION_TARGETS if n in centres and n in actor.tracked]
    if "pelvis" not in centres and "left_hip" in centres and "right_hip" in centres:
        centres["pelvis"] = 0.5 * (centres["left_hip"] + centres["right_hip"])
        names = ["pelvis"] + names
    if not names:
        raise InputError("the markers place none of the joints the actor is fitted to (pelvis or both hips, "
                         f"knees, ankles, shoulders, elbows, wrists); they give only {', '.join(sorted(centres)) or 'none'}: "
                         "too few markers are labelled or mapped (see physmocap inspect, --marker-set)", path=rec.source)
    seen = np.all(np.isfinite(np.stack([centres[n] for n in names], 1)), 2)
    good = np.flatnonzero(seen.mean(1) >= 0.8)
    if len(good) == 0:
        raise InputError("no frame shows enough joint centres to place the markers on the skeleton "
                         "(are the markers labelled and mapped? see physmocap inspect)", path=rec.source)
    calib = good[np.linspace(0, len(good) - 1, min(count, len(good))).astype(int)]
    return centres, names, calib


def pose_on_centres(actor, centres: dict[str, np.ndarray], names: list[str], C: np.ndarray, calib: np.ndarray,
                    fps: float) -> list[np.ndarray]:
    """The actor's ``qpos`` on each calibration frame by IK on the joint centres ``C``
    ``(F, J, 3)`` (metres, Z-up; hand ends and toes at weight 0.3), each frame started from the
    previous pose with the root placed by the hips and the neck (the frames are far apart: the
    actor may have turned), the joint ranges hard.  Also the cleaner's re-solve of a glitched
    span (:mod:`physmocap.clean.resolve`)."""
    from ..ik.solver import FrameSolver, SolverOptions

    seen = np.all(np.isfinite(C), 2)
    sopt = SolverOptions(max_iterations=12, first_frame_iterations=120, self_collision=False,
                         velocity_limits=False, floor=False, smoothness_cost=0.0, segment_cost=0.0,
                         weights={n: ((0.3 if n.endswith("hand_end") or n.endswith("toe") else 1.0), 0.0) for n in names})
    cs = FrameSolver(_solver_character(actor, {n: actor.tracked[n].name for n in names}), names,
                     np.zeros(len(names), bool), fps, sopt)
    q0 = np.array(actor.rest_qpos, float)
    q0[:7] = _root_pose(centres, int(calib[0]), q0[:7])
    cs.reset(q0)
    Q = []
    dummy_o = np.tile([0.0, 0.0, 0.0, 1.0], (len(names), 1))
    for k, t in enumerate(calib):
        q = np.array(cs.configuration.q if k else q0, float)
        q[:7] = _root_pose(centres, int(t), q[:7])
        cs.reset(q)
        q, _, _ = cs.solve_frame(np.nan_to_num(C[t]), dummy_o, seen[t], first=(k == 0))
        Q.append(q)
    return Q


def _place_marker_sites(spec: mujoco.MjSpec, folder: Path, rec: MarkerRecording, actor, frame: _SolverFrame,
                        seg_of: dict[int, str], names: list[str], C: np.ndarray, calib: np.ndarray,
                        Q: list[np.ndarray], opt: MarkerSolveOptions):
    """One site per marker on its segment's body at its median position in the body frame
    over the calibration poses ``Q``; then twice: solve those frames on the markers (weighted
    by the inverse of their scatter) with the centres ``C`` kept as weak targets, and place
    the sites again.  Markers with fewer than 3 valid samples are ignored (one warning).
    Returns ``(character, index -> site name, attached, ignored labels, weights, poses)``."""
    valid, Pz, M = rec.valid, frame.markers, len(rec.labels)
    seen = np.all(np.isfinite(C), 2)
    body_id = {s: actor.model.body(b).id for s, b in SEGMENT_BODY.items()}
    attached = sorted(i for i in seg_of if valid[calib, i].sum() >= 3 or valid[:, i].sum() >= 3)
    local = _marker_locals(actor.model, mujoco.MjData(actor.model), np.array(Q), Pz[calib], attached, seg_of, body_id)
    attached = [i for i in attached if i in local]
    ignored = [rec.labels[i] for i in range(M) if i not in local]
    if not attached:
        raise InputError("no marker could be attached to a segment of the skeleton", path=rec.source)
    if ignored:
        shown = ", ".join(ignored[:12]) + (" ..." if len(ignored) > 12 else "")
        warn(f"{rec.source}: {len(ignored)} marker(s) belong to no segment (props, strays, too few samples) "
             f"and are ignored: {shown}")
    for _ in range(2):
        char, site_names = _with_marker_sites(spec, folder, rec.labels, attached, seg_of, local)
        weights = _weights(_scatter(char.model, Q, Pz[calib], attached, seg_of, local, body_id, M), attached,
                           opt.min_weight_scatter)
        # the calibrated centres stay targets: markers alone would let the skeleton drift
        # inside the marker cloud from one refinement to the next (sites follow poses)
        solver = _marker_solver(char, rec.fps, attached, site_names, weights, opt, frame.use_floor, max_iterations=10,
                                centres=tuple(names))
        Q0, Q = Q, []
        for k, t in enumerate(calib):
            solver.reset(np.array(Q0[k]))
            q, _, _ = solver.solve_frame(np.concatenate([np.nan_to_num(Pz[t, attached]), np.nan_to_num(C[t])]),
                                         np.tile([0.0, 0, 0, 1], (len(attached) + len(names), 1)),
                                         np.concatenate([valid[t, attached], seen[t]]))
            Q.append(q)
        local = _marker_locals(char.model, mujoco.MjData(char.model), np.array(Q), Pz[calib], attached, seg_of,
                               {s: char.model.body(b).id for s, b in SEGMENT_BODY.items()})
    char, site_names = _with_marker_sites(spec, folder, rec.labels, attached, seg_of, local)
    scatter = _scatter(char.model, Q, Pz[calib], attached, seg_of, local,
                       {s: char.model.body(b).id for s, b in SEGMENT_BODY.items()}, M)
    return char, site_names, attached, ignored, _weights(scatter, attached, opt.min_weight_scatter), Q


def _marker_locals(model, data, Q, P, attached, seg_of, body_id) -> dict[int, np.ndarray]:
    """Marker index -> mean position in its body's frame over the frames ``Q`` (poses) / ``P`` (markers)."""
    sums = {i: [] for i in attached}
    for q, p in zip(Q, P):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        for i in attached:
            if not np.all(np.isfinite(p[i])):
                continue
            b = body_id[seg_of[i]]
            Rb = data.xmat[b].reshape(3, 3)
            sums[i].append(Rb.T @ (p[i] - data.xpos[b]))
    return {i: np.median(np.array(v), 0) for i, v in sums.items() if len(v) >= 3}


def _scatter(model, Q, P, attached, seg_of, local, body_id, M) -> np.ndarray:
    """Per marker, RMS distance (metres) of the measured marker from its site over the frames."""
    data = mujoco.MjData(model)
    d2 = {i: [] for i in attached}
    for q, p in zip(Q, P):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        for i in attached:
            if np.all(np.isfinite(p[i])):
                b = body_id[seg_of[i]]
                x = data.xmat[b].reshape(3, 3) @ local[i] + data.xpos[b]
                d2[i].append(float(np.sum((x - p[i]) ** 2)))
    out = np.full(M, np.nan)
    for i, v in d2.items():
        if v:
            out[i] = np.sqrt(np.mean(v))
    return out


def _weights(scatter: np.ndarray, attached: list[int], floor_scatter: float) -> np.ndarray:
    """Cost per metre of each attached marker: inverse of its scatter, median 1."""
    s = np.array([scatter[i] for i in attached])
    s = np.where(np.isfinite(s), np.maximum(s, floor_scatter), np.nanmedian(s) if np.isfinite(s).any() else floor_scatter)
    w = 1.0 / s
    return np.clip(w / np.median(w), 0.2, 3.0)


def _with_marker_sites(spec: mujoco.MjSpec, folder: Path, labels, attached, seg_of, local):
    """The actor character with one site per attached marker; returns ``(character, index -> site name)``."""
    s2 = mujoco.MjSpec.from_string(spec.to_xml())
    names = {}
    for i in attached:
        name = f"marker:{labels[i]}"
        k = 1
        while name in names.values():
            k += 1
            name = f"marker:{labels[i]}#{k}"
        names[i] = name
        s2.body(SEGMENT_BODY[seg_of[i]]).add_site(name=name, pos=[float(x) for x in local[i]], size=[0.008, 0, 0],
                                                  group=5, rgba=[1.0, 0.5, 0.0, 1.0])
    char = load_spec_character(s2, folder, "actor_markers")
    return char, names


def _marker_solver(char, fps: float, attached, site_names, weights, opt: MarkerSolveOptions, use_floor: bool,
                   max_iterations: int, centres: tuple[str, ...] = ()):
    """A :class:`~physmocap.ik.solver.FrameSolver` on the marker sites (keys ``m0, m1...``,
    targets in ``attached`` order) and then the canonical joint sites ``centres`` (weight 0.3)."""
    from ..ik.solver import FrameSolver, SolverOptions

    keys = [f"m{k}" for k in range(len(attached))]
    w = {k: (float(x), 0.0) for k, x in zip(keys, weights)}
    w.update({n: (0.3, 0.0) for n in centres})
    sopt = SolverOptions(
        max_iterations=max_iterations, first_frame_iterations=150, self_collision=False,
        velocity_limits=opt.velocity_limits, floor=use_floor, floor_iterations=2 if use_floor else 0,
        weights=w, smoothness_cost=0.0,  # a fit to measured markers: their own motion, unsmoothed
        segment_cost=0.0,  # the joint centres are estimates for the markers to agree with, not a pose to copy
    )
    sites = {k: site_names[i] for k, i in zip(keys, attached)}
    sites.update({n: char.tracked[n].name for n in centres})
    ch = _solver_character(char, sites)
    return FrameSolver(ch, keys + list(centres), np.zeros(len(keys) + len(centres), bool), fps, sopt)


# -- report --------------------------------------------------------------------------
def _mm(x: np.ndarray) -> dict[str, float | None]:
    x = x[np.isfinite(x)]
    if not x.size:
        return {"rms_mm": None, "max_mm": None, "samples": 0}
    return {"rms_mm": round(float(np.sqrt(np.mean(x**2))) * 1000, 2), "max_mm": round(float(x.max()) * 1000, 2),
            "samples": int(x.size)}


def marker_report(sol: MarkerSolution) -> dict:
    rec = sol.recording
    res = sol.residuals
    valid = rec.valid
    markers = {}
    for i, lab in enumerate(rec.labels):
        entry: dict[str, Any] = {"segment": sol.segment_of.get(i)}
        entry.update(_mm(res[:, i]))
        entry["gap_frames"] = int((~valid[:, i]).sum())
        entry["gaps"] = frame_ranges(~valid[:, i])
        markers[lab] = entry
    segments = {}
    for seg in sorted(set(sol.segment_of.values())):
        idx = [i for i, s in sol.segment_of.items() if s == seg]
        e = _mm(res[:, idx].ravel())
        e["markers"] = [rec.labels[i] for i in idx]
        no_marker = ~np.any(valid[:, idx], axis=1)
        e["frames_without_markers"] = frame_ranges(no_marker)
        segments[seg] = e
    overall = _mm(res.ravel())
    cal = sol.calibration
    F = rec.num_frames
    return {
        "source": str(rec.source),
        "frames": F,
        "fps": rec.fps,
        "overall": overall,
        "segments": segments,
        "markers": markers,
        "ignored_markers": sol.ignored,
        "joint_centres": dict(cal.method),
        "segment_lengths_m": {f"{a}-{b}": round(v, 4) for (a, b), v in cal.lengths.items()},
        "floor_m": round(sol.floor, 4),
        "solver": {  # no timings: a report file is the same bytes for the same input
            "relaxed_frames": int((sol.relaxed > 0).sum()),
            "held_frames": frame_ranges(sol.relaxed >= 5),
        },
    }


# -- export --------------------------------------------------------------------------
def actor_motion(sol: MarkerSolution, up: str = "Y"):
    """The solved actor as a rotational :class:`~physmocap.motion.Motion` with canonical joint
    names (each body named after the canonical joint that moves it: ``left_thigh`` ->
    ``left_hip``; leaves' end sites ``head_end``, ``left_hand_end``, ``left_toe_end``)."""
    import dataclasses

    from ..canonical import CANONICAL_NAMES
    from ..export.character_bvh import character_motion
    from ..motion import Skeleton

    motion = character_motion(sol.trajectory, up=up)
    model = sol.trajectory.character.model
    rename: dict[str, str] = {}
    for b in range(1, model.nbody):
        for s in range(model.nsite):
            if int(model.site_bodyid[s]) == b and model.site(s).name in CANONICAL_NAMES and np.allclose(model.site_pos[s], 0):
                rename[model.body(b).name] = model.site(s).name
    ends = {"head": "head_end", "left_wrist": "left_hand_end", "right_wrist": "right_hand_end",
            "left_toe": "left_toe_end", "right_toe": "right_toe_end"}
    skel = motion.skeleton
    names = []
    for j, n in enumerate(skel.names):
        if skel.end_site[j]:
            parent = rename.get(skel.names[skel.parents[j]], skel.names[skel.parents[j]])
            names.append(ends.get(parent, f"{parent}_End"))
        else:
            names.append(rename.get(n, n))
    channels = {rename.get(k, k): v for k, v in motion.meta.get("bvh_channels", {}).items()}
    meta = dict(motion.meta, bvh_channels=channels, character="actor (physmocap solve)")
    return dataclasses.replace(motion, skeleton=Skeleton(tuple(names), skel.parents, skel.offsets, skel.end_site), meta=meta)


def write_actor_bvh(sol: MarkerSolution, path: str | os.PathLike, up: str = "Y", units: str | float = "m") -> Path:
    """Write the solved actor skeleton as BVH (atomically)."""
    from ..export.bvh import write_bvh

    write_bvh(actor_motion(sol, up=up), path, rotation_order=None, units=units, up=up)
    return Path(path)


def print_report(rep: dict, file=None, frames_per_second: float | None = None) -> None:
    """The residual table (per segment, overall), gaps and ignored markers, on ``file``
    (stdout: a result, as ``retarget``'s report table; warnings and progress go to stderr),
    and the solve's CPU ``frames_per_second`` where given
    (:meth:`MarkerSolution.frames_per_second`)."""
    import sys

    out = file or sys.stdout
    print(f"marker residuals (measured marker to solved marker site), {rep['frames']} frames:", file=out)
    print(f"  {'segment':16s} {'RMS mm':>7s} {'max mm':>7s}  markers", file=out)
    for seg, e in rep["segments"].items():
        rms = "-" if e["rms_mm"] is None else f"{e['rms_mm']:.1f}"
        mx = "-" if e["max_mm"] is None else f"{e['max_mm']:.0f}"
        print(f"  {seg:16s} {rms:>7s} {mx:>7s}  {' '.join(e['markers'])}", file=out)
    o = rep["overall"]
    if o["rms_mm"] is not None:
        print(f"  {'all':16s} {o['rms_mm']:7.1f} {o['max_mm']:7.0f}", file=out)
    gaps = {k: v["gap_frames"] for k, v in rep["markers"].items() if v["gap_frames"]}
    if gaps:
        print("gaps (frames missing per marker): " + ", ".join(f"{k} {v}" for k, v in gaps.items()), file=out)
    bare = {k: v["frames_without_markers"] for k, v in rep["segments"].items() if v["frames_without_markers"]}
    for seg, ranges in bare.items():
        n = sum(b - a for a, b in ranges)
        shown = ", ".join(f"{a}-{b - 1}" for a, b in ranges[:6]) + (" ..." if len(ranges) > 6 else "")
        print(f"segment {seg} has no valid marker on {n} frame(s) ({shown}): posed by its joint limits and neighbours", file=out)
    if rep["ignored_markers"]:
        print("ignored (no segment explains them): " + ", ".join(rep["ignored_markers"]), file=out)
    s = rep["solver"]
    speed = "" if frames_per_second is None else f"{frames_per_second:.0f} frames/s CPU, "
    print(f"solve: {speed}{s['relaxed_frames']} frame(s) relaxed", file=out)
