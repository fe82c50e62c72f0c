"""Offline retargeting: a whole motion onto a character, frame by frame.

``retarget(motion, character, **options)`` maps the actor's joints to the
canonical set, builds targets that fit the character
(:mod:`physmocap.ik.targets`), then solves one IK per frame
(:mod:`physmocap.ik.solver`), warm-started from the previous frame, and
returns a :class:`~physmocap.trajectory.Trajectory`.
"""

from __future__ import annotations

import dataclasses
import time
from typing import Any

import numpy as np

from ..errors import MappingError, OptionError, warn
from ..metrics.fidelity import fidelity_warnings, trajectory_fidelity
from ..motion import Motion
from ..progress import Progress
from ..trajectory import Trajectory
from .contacts import ContactOptions, Contacts, detect_contacts, load_contact_csv
from .footplan import plant_body_contacts, planted_positions
from .planting import PlantOptions, Planting
from .solver import RELAXATION_LEVELS, FrameSolver, SolverOptions
from .targets import TargetOptions, Targets, build_targets

__all__ = ["retarget", "split_options", "map_motion"]

_TARGET_FIELDS = {f.name for f in dataclasses.fields(TargetOptions)}
_SOLVER_FIELDS = {f.name for f in dataclasses.fields(SolverOptions)}
_PLANT_FIELDS = {f.name for f in dataclasses.fields(PlantOptions)}
_KNOWN = _TARGET_FIELDS | _SOLVER_FIELDS | _PLANT_FIELDS


def split_options(
    options: dict[str, Any],
) -> tuple[TargetOptions, SolverOptions, dict[str, Any]]:
    """Split flat keyword options into target options, solver options and the rest
    (planting options stay in the rest; see :func:`plant_options`)."""
    t, s, rest = {}, {}, {}
    for k, v in options.items():
        if k in _TARGET_FIELDS:
            t[k] = v
        elif k in _SOLVER_FIELDS:
            s[k] = v
        else:
            rest[k] = v
    return TargetOptions(**t), SolverOptions(**s), rest


def plant_options(rest: dict[str, Any]) -> tuple[PlantOptions, dict[str, Any]]:
    """Take the :class:`PlantOptions` fields out of ``rest``."""
    p = {k: v for k, v in rest.items() if k in _PLANT_FIELDS}
    return PlantOptions(**p), {k: v for k, v in rest.items() if k not in _PLANT_FIELDS}


def resolve_contacts(motion: Motion, joint_indices: dict[str, int], contacts, options: ContactOptions | None):
    """Contacts for ``motion``: detected (None), loaded from a CSV path, given, or none (False)."""
    if contacts is False:
        return None
    if contacts is None:
        return detect_contacts(motion, joint_indices, options)
    if isinstance(contacts, Contacts):
        if contacts.num_frames != motion.num_frames:
            raise OptionError(
                f"contact labels cover {contacts.num_frames} frames but the motion has {motion.num_frames}"
            )
        return contacts
    return load_contact_csv(contacts, motion.num_frames, motion.fps)


def map_motion(motion: Motion, profile: str | None = None, mapping=None) -> dict[str, int]:
    """Canonical joint -> source joint index, using the name-mapping profiles."""
    from ..sources.profiles import map_skeleton

    if mapping is None and profile is None and isinstance(motion.meta.get("source_mapping"), dict):
        # tracker readers record the mapping they used, synthesised joints (a NITE pelvis) included
        mapping = motion.meta["source_mapping"]
    jmap = map_skeleton(motion, profile=profile, mapping=mapping)
    return dict(jmap.indices)


def reference_first_frame(motion: Motion, window: int = 30) -> float | None:
    """If frame 0 is a reference pose (a T-pose or calibration frame that the
    capture jumps away from), the jump in metres; else None.

    Frame 0 counts as a reference pose when its joints move, on average, more
    than 5 cm and more than eight times the clip's typical frame-to-frame
    motion (median over the next ``window`` frames) into frame 1.  CMU's BVH
    exports start this way.
    """
    F = motion.num_frames
    if F < 4:
        return None
    head = motion.slice_frames(0, min(F, window + 2)).world_positions()
    step = np.nanmean(np.linalg.norm(np.diff(head, axis=0), axis=-1), axis=1)
    typical = float(np.nanmedian(step[1:]))
    jump = float(step[0])
    if np.isfinite(jump) and jump > 0.05 and jump > 8.0 * max(typical, 1e-4):
        return jump
    return None


def default_start(motion: Motion) -> int:
    """First frame to retarget when none is given: 1 if frame 0 is a reference pose
    (said on stderr), else 0."""
    jump = reference_first_frame(motion)
    if jump is None:
        return 0
    warn(
        f"{motion.source}: frame 0 looks like a reference pose (the joints jump {jump * 100:.0f} cm "
        f"on average into frame 1): skipped it; pass --start 0 (start=0) to keep it"
    )
    return 1


def _frame_range(motion: Motion, start: int, end: int | None) -> Motion:
    F = motion.num_frames
    s = int(start)
    e = F if end is None else int(end)
    if s < 0 or e > F or s >= e:
        raise OptionError(
            f"frame range [{s}, {e}) is outside the clip, which has frames 0 to {F - 1} "
            f"(--start is inclusive, --end exclusive)",
            path=motion.source,
        )
    return motion if (s, e) == (0, F) else motion.slice_frames(s, e)


def retarget(
    motion: Motion,
    character=None,
    *,
    profile: str | None = None,
    mapping=None,
    joint_indices: dict[str, int] | None = None,
    start: int | None = None,
    end: int | None = None,
    fps: float | None = None,
    progress: bool | None = None,
    targets: Targets | None = None,
    contacts=None,
    contact_options: ContactOptions | None = None,
    **options: Any,
) -> Trajectory:
    """Retarget ``motion`` onto ``character`` (default: the bundled humanoid).

    Args:
        motion: The actor's motion.
        character: A :class:`physmocap.models.Character`, a path to an MJCF,
            or None for the default humanoid.
        profile: Force a source naming profile (see ``physmocap inspect``).
        mapping: A TOML mapping file (or dict) for the source skeleton.
        joint_indices: Canonical joint -> source joint index, bypassing the mapping.
        start, end: Frame range ``[start, end)`` of the source to retarget.
        fps: Resample the source to this rate first.
        progress: Draw a progress bar on stderr (default: when it is a terminal).
        targets: Precomputed targets (skips target building).
        contacts: Foot contact labels: None detects them on the (sliced,
            resampled) motion, a path reads a CSV of frame ranges
            (:func:`~physmocap.ik.contacts.load_contact_csv`), a
            :class:`~physmocap.ik.contacts.Contacts` is used as is, False
            turns planting off.
        contact_options: Detection thresholds (:class:`~physmocap.ik.contacts.ContactOptions`).
        **options: Fields of :class:`~physmocap.ik.targets.TargetOptions`,
            :class:`~physmocap.ik.solver.SolverOptions` and
            :class:`~physmocap.ik.planting.PlantOptions` (e.g.
            ``max_iterations=8``, ``floor=False``, ``scale_root=False``,
            ``plant=False``, ``anchor_release_time=0.4``).

    Returns:
        The character's :class:`~physmocap.trajectory.Trajectory`.
    """
    from ..models import load_character

    if character is None or isinstance(character, (str, bytes)) or hasattr(character, "__fspath__"):
        character = load_character(character)
    target_opt, solver_opt, rest = split_options(options)
    plant_opt, rest = plant_options(rest)
    if rest:
        raise OptionError(f"unknown retarget option(s) {sorted(rest)}; known options: {sorted(_KNOWN)}")
    if not character.contacts and plant_opt.plant and contacts is not False:
        raise MappingError(
            "the character has no foot contact points (none in its mapping and none found on its feet); "
            "add [contacts] to its mapping file, or retarget without planting (--no-plant)",
            path=getattr(character, "map_path", None) or getattr(character, "mjcf_path", None),
        )
    source_start = default_start(motion) if start is None else int(start)
    motion = _frame_range(motion, source_start, end)
    if fps is not None:
        motion = motion.resample(float(fps))
    if joint_indices is None:
        joint_indices = map_motion(motion, profile=profile, mapping=mapping)
    found = resolve_contacts(motion, joint_indices, contacts if plant_opt.plant else False, contact_options)
    if targets is None:
        floor = found.floor if found is not None else None
        targets = build_targets(motion, joint_indices, character, target_opt, floor=floor)
    traj = solve_targets(
        targets,
        character,
        solver_opt,
        source=motion.source,
        progress=progress,
        labels=found.labels if found is not None else None,
        plant=plant_opt,
        body_labels=found.body_labels if found is not None else None,
    )
    traj.stats["contacts"] = found
    traj.stats["source_motion"] = motion  # as retargeted: cut and resampled
    traj.stats["joint_indices"] = dict(joint_indices)
    traj.stats["source_start"] = int(source_start)
    fid = trajectory_fidelity(traj, floor_contact=False)  # the warnings need no floor figures
    traj.stats["fidelity"] = fid
    for message in fidelity_warnings(fid, source_start):
        warn(f"{motion.source}: {message}")
    return traj


def feet_off_kneeling(labels: dict[str, np.ndarray], body_labels: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Foot labels with each foot's contact cleared while its knee rests on the floor.

    A kneeling leg's foot lies on its instep or on tucked toes: holding its
    sole sites on the floor would twist the ankle beyond its range, so the
    foot is left to the floor constraint while the knee is down."""
    out = dict(labels)
    for side in ("left", "right"):
        knee = body_labels.get(f"{side}_knee")
        if knee is None or not np.any(knee):
            continue
        for name in list(out):
            if name.startswith(side + "_"):
                out[name] = np.asarray(out[name], dtype=bool) & ~np.asarray(knee, dtype=bool)
    return out


def solve_targets(
    targets: Targets,
    character,
    options: SolverOptions | None = None,
    source: str = "<memory>",
    progress: bool | None = None,
    labels: dict[str, np.ndarray] | None = None,
    plant: PlantOptions | None = None,
    body_labels: dict[str, np.ndarray] | None = None,
) -> Trajectory:
    """Run the per-frame IK over prepared targets.

    With contact ``labels`` (``left_heel``, ``left_toe``, ``right_heel``,
    ``right_toe`` -> ``(F,)`` bool) the feet are planted
    (:class:`~physmocap.ik.planting.Planting`): the targets the IK tracks
    become ``targets.positions`` with each foot's offsets applied (the
    unshifted ones are kept in ``targets.info["raw_positions"]``).  On frame 0
    the solver first converges from the rest pose without planting, then
    anchors the feet in contact where that solution put them and solves again.
    """
    solver = FrameSolver(character, targets.names, targets.has_orientation, targets.fps, options)
    F = targets.num_frames
    planting = None
    if labels is not None and (plant is None or plant.plant):
        planting = Planting(character, targets.names, targets.fps, plant, floor=solver.options.floor_height, anchored=False)
        targets.info["raw_positions"] = targets.positions.copy()
        labels = feet_off_kneeling(labels, body_labels or {})
        targets.positions, targets.info["foot_offsets"] = planted_positions(
            targets.positions, targets.names, labels, targets.fps, planting.options.ease_time, planting.leg_lengths(), planting.stance_heights()
        )
        if body_labels:
            targets.positions = plant_body_contacts(
                targets.positions, targets.names, body_labels, targets.fps, planting.options.ease_time, solver.options.floor_height
            )
    qpos = np.empty((F, character.model.nq))
    iterations = np.zeros(F, dtype=np.int32)
    relaxation = np.zeros(F, dtype=np.int8)
    latency = np.zeros(F)
    with Progress(F, "retarget", enabled=progress) as bar:
        for t in range(F):
            t_frame = time.perf_counter()
            if planting is not None:
                if t == 0:
                    solver.set_targets(targets.positions[0], targets.orientations[0], targets.valid[0])
                    solver.solve_frame(first=True)
                    solver.q_prev = None
                frame_labels = {k: v[t] for k, v in labels.items()}
                _, solver.extra_tasks, solver.constraints, _ = planting.step(
                    targets.positions[t], frame_labels, solver.configuration.data
                )
                solver.set_clearance(planting.clearance_sites(), planting.clearance_bodies())
            solver.set_targets(targets.positions[t], targets.orientations[t], targets.valid[t])
            q, it, level = solver.solve_frame(first=(t == 0 and planting is None))
            qpos[t] = q
            latency[t] = time.perf_counter() - t_frame
            iterations[t] = it
            relaxation[t] = level
            bar.update(1)
    for level in range(1, len(RELAXATION_LEVELS)):
        frames = np.flatnonzero(relaxation == level)
        if frames.size:
            shown = ", ".join(str(f) for f in frames[:10]) + (" ..." if frames.size > 10 else "")
            warn(f"{source}: {RELAXATION_LEVELS[level]} on {frames.size} frame(s): {shown}")
    return Trajectory(
        character=character,
        qpos=qpos,
        fps=targets.fps,
        source=source,
        targets=targets,
        stats={"iterations": iterations, "relaxation": relaxation, "latency": latency},
    )
