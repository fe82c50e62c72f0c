"""Offline retargeting: a whole motion onto a character.

``retarget(motion, character, config)`` maps the actor's joints to the
canonical set, detects contacts, builds targets that fit the character
(:mod:`physmocap.ik.targets`), plans them over the whole clip
(:mod:`physmocap.ik.footplan`) and runs the per-frame pipeline
(:class:`~physmocap.ik.frame.FrameRetargeter`, the same one the streaming
retargeter runs) over every frame.  Where an arm is left far off the actor's on a
branch of its joint ranges that cannot reach it, the clip is retargeted again with
the arm guided onto one that can (:mod:`physmocap.ik.branches`; at most two more
passes, ``SolverOptions.arm_branches``).  It returns a
:class:`~physmocap.trajectory.Trajectory` that carries what it used, typed.
"""

from __future__ import annotations

import copy
import warnings
from functools import partial
from typing import Any, Callable, Sequence

import numpy as np

from ..errors import InputError, MappingError, OptionError, warn
from ..metrics.fidelity import (
    actor_joint_positions,
    character_joint_positions,
    fidelity_warnings,
    saturation_matrix,
    segment_direction_errors,
    trajectory_fidelity,
)
from ..motion import Motion
from ..progress import Progress
from ..spill import blocks, release, spill, spilled_copy, spilled_empty
from ..trajectory import SolverStats, Trajectory
from .body_contacts import release_kneeling_feet
from .branches import MAX_PASSES, STUCK_DEG, plan_guides
from .config import RetargetConfig
from .contacts import Contacts, detect_contacts, load_contact_csv
from .footlevel import level_feet
from .footplan import BODY_PART_JOINTS, eased_mask, plant_body_contacts, planted_positions, swing_flatten, toe_bend, turn_foot
from .frame import FrameRetargeter
from .planting import PlantOptions, Planting
from .rigidfoot import level_roll
from .solver import RELAXATION_LEVELS, SolverOptions
from .speedcaps import CAP_PASSES, CapGuides
from .targets import Targets, build_targets, character_rest_frames
from .toetips import extend_toe_tips
from .transitions import TransitionGuides, carried_targets, eased_foot_shifts, moving_joints

__all__ = ["retarget", "solve_targets", "map_motion", "RetargetConfig"]


def resolve_contacts(motion: Motion, joint_indices: dict[str, int], contacts, config: RetargetConfig):
    """Contacts for ``motion``: detected (None), loaded from a CSV path, given, or none (False)."""
    if contacts is False:
        return None
    if contacts is None:
        return detect_contacts(motion, joint_indices, config.contacts, config.body_contacts)
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
    if 0 <= s < F and e <= F and s >= e:
        raise OptionError(f"frame range [{s}, {e}) is empty (--start is inclusive, --end exclusive)", path=motion.source)
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
    config: RetargetConfig | None = None,
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
    **options: Any,
) -> Trajectory:
    """Retarget ``motion`` onto ``character`` (default: the bundled humanoid).

    Args:
        motion: The actor's motion.
        character: A :class:`physmocap.models.Character`, a path to an MJCF,
            or None for the default humanoid.
        config: The :class:`~physmocap.ik.config.RetargetConfig` (default options if None).
        profile: Force a source naming profile (see ``physmocap inspect``).
        mapping: A TOML mapping file (or dict) for the source skeleton.
        joint_indices: Canonical joint -> source joint index, bypassing the mapping.
        start, end: Frame range ``[start, end)`` of the source to retarget.
        fps: Resample the source to this rate first.
        progress: Draw a progress bar on stderr (default: when it is a terminal).
        targets: Precomputed targets (skips target building).
        contacts: Contact labels: None detects them on the (sliced,
            resampled) motion, a path reads a CSV of frame ranges
            (:func:`~physmocap.ik.contacts.load_contact_csv`), a
            :class:`~physmocap.ik.contacts.Contacts` is used as is, False
            turns planting off.
        **options: Flat option names applied on top of ``config``
            (:meth:`RetargetConfig.with_options`: ``max_iterations=8``,
            ``floor=False``, ``scale_root=False``, ``plant=False``...).

    Returns:
        The character's :class:`~physmocap.trajectory.Trajectory`, with the
        targets, contacts, source motion as retargeted, canonical joints,
        first source frame, solver statistics and fidelity figures.
    """
    from ..models import load_character

    if character is None or isinstance(character, (str, bytes)) or hasattr(character, "__fspath__"):
        character = load_character(character)
    config = config or RetargetConfig()
    if not isinstance(config, RetargetConfig):
        raise OptionError(f"config must be a RetargetConfig, got {type(config).__name__}")
    if options:
        config = config.with_options(**options)
    plant = config.plant.plant and contacts is not False
    if not character.contacts and plant:
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
        motion, joint_indices = extend_toe_tips(motion, joint_indices, character.rest_positions())
    found = resolve_contacts(motion, joint_indices, contacts if plant else False, config)
    ours = targets is None  # targets built here are ours to change (the caller's are not)
    if targets is None:
        floor = found.floor if found is not None else None
        targets = build_targets(motion, joint_indices, character, config.targets, floor=floor)
        targets.release_source_positions()  # nothing below reads them: recomputed if ever read
        if found is None and contacts is not False:
            # no planting, but the feet are still levelled where the actor stands flat
            stance = _stance_labels(motion, joint_indices, config)
            if stance is not None:
                targets = level_targets(targets, character, stance, own_orientations=True)
    labels = None
    if found is not None and config.plant.plant:
        labels = release_kneeling_feet(found.labels, found.body_labels or {})
        # the unplanned targets are let go before tracking (the planned ones keep their raw
        # positions); orientations built here are levelled where they are
        targets = plan_targets(targets, character, labels, config.plant, config.solver.floor_height,
                               found.body_labels, own=ours, toe_bends=partial(actor_toe_bends, motion, joint_indices))
    if ours:
        spill_targets(targets)
    traj = _track(targets, character, config.solver, motion.source, progress, labels, config.plant)
    del targets
    traj.contacts = found
    traj.source_motion = motion  # as retargeted: cut and resampled
    traj.joint_indices = dict(joint_indices)
    traj.source_start = int(source_start)
    guides: dict = {}
    if config.solver.arm_branches:
        traj, guides = _second_pass(traj, config, progress, labels)
    shift: Sequence[tuple[np.ndarray, np.ndarray]] = ()
    if labels is not None and config.plant.smooth_transitions:
        traj, shift = _transition_pass(traj, config, progress, labels, found.body_labels or {}, guides)
    if config.solver.ease_caps and config.solver.velocity_limits:
        traj = _cap_pass(traj, config, progress, labels, shift)
    _warn_relaxations(traj)
    traj.fidelity = trajectory_fidelity(traj, floor_contact=False)  # the warnings need no floor figures
    for message in fidelity_warnings(traj.fidelity, source_start):
        warn(f"{motion.source}: {message}")
    return traj


def _arm_errors(traj) -> dict[str, np.ndarray]:
    """Per-frame direction errors (degrees) of the arm segments of ``traj`` against its actor."""
    used = frozenset(j for side in ("left", "right") for j in (f"{side}_shoulder", f"{side}_elbow", f"{side}_wrist"))
    actor = actor_joint_positions(traj.source_motion, traj.joint_indices, used)
    return segment_direction_errors(actor, character_joint_positions(traj, used))


def _second_pass(traj: Trajectory, config: RetargetConfig, progress: bool | None,
                 labels: dict[str, np.ndarray] | None) -> tuple[Trajectory, dict]:
    """``traj`` retargeted again with its stuck arms guided onto the branch of their ranges
    that reaches the actor (:mod:`.branches`), again on that result while arms stick (at
    most ``MAX_PASSES`` in all); the last pass whose arms came closer (:func:`_arms_off`)
    without the solver giving up a hard constraint on more frames, and the guides it was
    retargeted with (empty for ``traj`` itself)."""
    best, errors = traj, _arm_errors(traj)
    if not errors:
        return traj, {}  # no arm on the actor or the character
    score = _arms_off(errors)
    guides: dict = {}
    best_guides: dict = {}
    for _ in range(MAX_PASSES - 1):
        guides = plan_guides(best, errors, config.solver.weights, progress, previous=guides)
        if not guides:
            break
        again = _retrack(best, traj, config, progress, labels, guides, "retarget again, arms guided")
        after = _arm_errors(again)
        if _relaxed(again) > _relaxed(best) or _arms_off(after) >= score:
            break  # no closer, or a hard constraint given up on more frames
        best, errors, score, best_guides = again, after, _arms_off(after), guides
    return best, best_guides


def _retrack(last: Trajectory, first: Trajectory, config: RetargetConfig, progress: bool | None,
             labels: dict[str, np.ndarray] | None, guides: dict, label: str,
             shift: Sequence[tuple[np.ndarray, np.ndarray]] = ()) -> Trajectory:
    """``last``'s targets retargeted again with ``guides`` (and ``shift``, as :func:`_track`),
    carrying ``first``'s contacts, source motion and source frames."""
    again = _track(last.targets, last.character, config.solver, last.source, progress, labels, config.plant,
                   guides, label=label, shift=shift)
    for name in ("contacts", "source_motion", "joint_indices", "source_start"):
        setattr(again, name, getattr(first, name))
    return again


def _transition_pass(traj: Trajectory, config: RetargetConfig, progress: bool | None,
                     labels: dict[str, np.ndarray], body_labels: dict[str, np.ndarray],
                     arm_guides: dict) -> tuple[Trajectory, Sequence[tuple[np.ndarray, np.ndarray]]]:
    """``traj`` retargeted once more with its joints pulled towards their own low-pass
    around every contact change and towards themselves elsewhere (:mod:`.transitions`), the
    arm passes' guides kept; kept if the solver softened or gave up a hard constraint on no
    more frames.  Returns the trajectory kept and the swing-foot shifts it was retargeted
    with (:func:`~.transitions.eased_foot_shifts`; none if ``traj`` is kept)."""
    opt = config.plant
    model = traj.character.model
    joints = moving_joints(model)
    touching = [j for side in ("left", "right") for j in (f"{side}_ankle", f"{side}_toe", f"{side}_toe_end")]
    touching += [j for part, label in body_labels.items() if np.any(label) for j in BODY_PART_JOINTS.get(part, ())]
    carried = carried_targets(traj.character, traj.targets.names, joints, touching)
    guides = TransitionGuides(model, traj.qpos, traj.targets.positions, traj.fps, {**labels, **body_labels}, joints,
                              carried, opt.transition_window, opt.transition_sigma, opt.transition_cost,
                              opt.transition_tolerance, arm_guides, traj.targets.valid)
    if not guides.near.any():
        return traj, ()
    shift = eased_foot_shifts(traj, labels, config.solver)
    again = _retrack(traj, traj, config, progress, labels, guides, "retarget again, contact changes smoothed",
                     shift=shift)
    return (traj, ()) if _gave_up_more(again, traj) else (again, shift)


def _cap_pass(traj: Trajectory, config: RetargetConfig, progress: bool | None,
              labels: dict[str, np.ndarray] | None, shift: Sequence[tuple[np.ndarray, np.ndarray]]) -> Trajectory:
    """``traj`` retargeted once more with the joints that sit at their velocity caps pulled
    towards a reference that spreads their fast moves out in time and every other joint
    towards itself (:mod:`.speedcaps`), the swing feet moved by the ``shift`` ``traj`` was
    retargeted with; kept if fewer joint-transitions saturate and the solver gave up a hard
    constraint (softened a contact equality included) on no more frames, and done again on
    the pass kept (a joint the pass itself brought to its cap) at most
    :data:`~.speedcaps.CAP_PASSES` times in all."""
    ch = traj.character
    sat = saturation_matrix(ch.model, traj.qpos, traj.fps, ch.velocity_limits, ch.velocity_groups)
    for _ in range(CAP_PASSES):
        guides = CapGuides(ch.model, traj.qpos, traj.fps, ch.velocity_limits, sat)
        if not guides.eased:
            break
        again = _retrack(traj, traj, config, progress, labels, guides, "retarget again, velocity caps eased",
                         shift=shift)
        after = saturation_matrix(ch.model, again.qpos, again.fps, ch.velocity_limits, ch.velocity_groups)
        if int(np.count_nonzero(after)) >= int(np.count_nonzero(sat)) or _gave_up_more(again, traj):
            break
        traj, sat = again, after
    return traj


def _gave_up_more(again: Trajectory, traj: Trajectory) -> bool:
    """Whether a later pass ``again`` needed a relaxation (a contact equality softened
    included) on more frames than ``traj``, or gave up a hard constraint on more."""
    softened = int(np.count_nonzero(again.solver.relaxation)) > int(np.count_nonzero(traj.solver.relaxation))
    return softened or _relaxed(again) > _relaxed(traj)


def _relaxed(traj: Trajectory) -> int:
    """Frames on which the solver gave up more than the contact equalities' hardness."""
    return int(np.count_nonzero(traj.solver.relaxation >= 2))


def _arms_off(errors: dict[str, np.ndarray]) -> tuple[int, float]:
    """How far the arms are from the actor's: frames with an arm segment more than
    ``STUCK_DEG`` off, then the sum of the segments' errors (degrees)."""
    e = np.nan_to_num(np.stack(list(errors.values()), axis=1), nan=0.0)
    return int(np.count_nonzero(e.max(axis=1) > STUCK_DEG)), float(e.sum())


def _stance_labels(motion: Motion, joint_indices: dict[str, int], config: RetargetConfig) -> dict[str, np.ndarray] | None:
    """The actor's foot contact labels for levelling the feet when nothing is planted (None
    where the source's feet cannot be labelled: no foot joints, no floor)."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # said again, if it matters, by the planting
            return detect_contacts(motion, joint_indices, config.contacts).labels
    except (InputError, MappingError):
        return None


def plan_targets(
    targets: Targets,
    character,
    labels: dict[str, np.ndarray],
    plant: PlantOptions,
    floor_height: float,
    body_labels: dict[str, np.ndarray] | None = None,
    *,
    own: bool = False,
    toe_bends: Callable[[], dict[str, np.ndarray]] | None = None,
) -> Targets:
    """A copy of ``targets`` planned for planting over the whole clip (:mod:`.footplan`):
    feet levelled on their flat-stance frames (:func:`~physmocap.ik.footlevel.level_feet`),
    then (and knees, hands, pelvis in contact) held where they land, eased in and out
    (``labels`` as planted: :func:`~physmocap.ik.body_contacts.release_kneeling_feet` applied).
    The unplanned positions are kept in ``info["raw_positions"]``, the feet's
    horizontal offsets in ``info["foot_offsets"]``.  With ``own`` the caller gives up
    ``targets``' arrays: the feet are levelled in its orientations (no copy), and its
    positions, kept as the raw ones, move to a temporary file for a long clip
    (:func:`~physmocap.spill.spill`) before they are copied.  ``toe_bends`` gives the actor's
    toe bends (:func:`actor_toe_bends`), called only for a character with rigid feet: their
    swing turn and their heel-up turn in stance are bounded by it (without it the swing turn
    is unbounded and the stance turn at most :data:`~.footplan.TIPTOE_LEAST`)."""
    planting = Planting(character, targets.names, targets.fps, plant, floor=floor_height, anchored=False)
    if own:
        targets.positions = spill(targets.positions)
    levelled = level_targets(targets, character, labels, own_orientations=own)
    release(targets.positions)
    # level_targets's copy of the positions is ours: planned where it is
    rigid = {}
    for side, foot in planting.rigid_feet().items():
        i = targets.names.index(f"{side}_ankle")
        if levelled.has_orientation[i]:  # its front edge is carried by the ankle's orientation target
            orientation = _get_columns(levelled.orientations, [i])[:, 0]  # gathered: one column is on every page
            orientation = level_roll(orientation, foot.rest_quat, _toes_only_weights(labels, side, targets.fps, plant.ease_time))
            _set_columns(levelled.orientations, [i], orientation[:, None])
            rigid[side] = (foot, orientation)
    bends = toe_bends() if rigid and toe_bends is not None else {}  # read only for rigid feet
    _, offsets = planted_positions(
        levelled.positions, targets.names, labels, targets.fps, plant.ease_time, planting.leg_lengths(), planting.stance_heights(),
        planting.toe_contacts(), rigid_feet=rigid, toe_bends=bends, in_place=True,
    )
    for side, (_, orientation) in rigid.items():  # pitched heel up where only the toes are down
        _set_columns(levelled.orientations, [targets.names.index(f"{side}_ankle")], orientation[:, None])
    for side, (foot, orientation) in rigid.items():  # swing feet pitched clear of the floor
        _flatten_swing(levelled, side, foot, orientation, 1.0 - _contact_weights(labels, side, targets.fps, plant.ease_time),
                       plant.clearance, bends.get(side))
    if body_labels:
        plant_body_contacts(levelled.positions, targets.names, body_labels, targets.fps, plant.ease_time, floor_height, in_place=True)
    levelled.info = {**levelled.info, "raw_positions": targets.positions, "foot_offsets": offsets}  # not modified: no copy
    return levelled


def actor_toe_bends(motion: Motion, joint_indices: dict[str, int]) -> dict[str, np.ndarray]:
    """Side -> ``(F,)`` radians: how far the actor's toes point up from its foot
    (:func:`~.footplan.toe_bend` of its ankle, toe and toe end), for the sides that map all
    three (a rigid foot's swing turn is bounded by it: :func:`~.footplan.swing_flatten`)."""
    sides = [s for s in ("left", "right") if all(f"{s}_{j}" in joint_indices for j in ("ankle", "toe", "toe_end"))]
    if not sides:
        return {}
    wanted = [joint_indices[f"{s}_{j}"] for s in sides for j in ("ankle", "toe", "toe_end")]
    P, col = motion.joint_world_positions(wanted)
    out = {}
    for s in sides:
        a, t, e = (np.asarray(P[:, col[joint_indices[f"{s}_{j}"]]], dtype=float) for j in ("ankle", "toe", "toe_end"))
        out[s] = toe_bend(a, t, e)
    release(P)
    return out


def _flatten_swing(targets: Targets, side: str, foot, orientation: np.ndarray, swing: np.ndarray,
                   clearance: float, bend: np.ndarray | None = None) -> None:
    """``side``'s rigid foot targets in ``targets`` (planned, ours) pitched towards level where
    its swing (``swing (F,)``, 0..1) would take it within ``clearance`` of the floor, by at most
    the actor's toe bend ``bend (F,)`` (radians; None: unbounded) (:func:`~.footplan.swing_flatten`):
    the ankle's orientation, and the foot's other joints turned about the ankle with it
    (:func:`~.footplan.turn_foot`)."""
    i = targets.names.index(f"{side}_ankle")
    cols = [i] + [c for c in _foot_columns(targets.names, side) if c != i]
    points = _get_columns(targets.positions, cols)
    turns = swing_flatten(foot, points[:, 0], orientation, swing, clearance, most=bend)
    if np.all(turns[:, 3] == 1.0):
        return
    moved, turned = turn_foot(turns, points[:, 0], points[:, 1:], orientation)
    _set_columns(targets.positions, cols[1:], moved)
    _set_columns(targets.orientations, [i], turned[:, None])


def _contact_weights(labels: dict[str, np.ndarray], side: str, fps: float, ease_time: float) -> np.ndarray:
    """``(F,)`` 1 on the frames where ``side``'s heel or toes are labelled, eased in before
    and out after each contact over ``ease_time`` seconds (:func:`~.footplan.eased_mask`, as
    the plan's heights)."""
    F = len(next(iter(labels.values())))
    down = np.zeros(F, dtype=bool)
    for part in ("heel", "toe"):
        down |= np.asarray(labels.get(f"{side}_{part}", np.zeros(F, dtype=bool)), dtype=bool)
    return eased_mask(down, int(round(ease_time * fps)))


def _toes_only_weights(labels: dict[str, np.ndarray], side: str, fps: float, ease_time: float) -> np.ndarray:
    """``(F,)`` 1 on the frames where only ``side``'s toes are labelled (heel up), eased in
    before and out after each such interval over ``ease_time`` seconds (:func:`~.footplan.eased_mask`)."""
    F = len(next(iter(labels.values())))
    toe, heel = (np.asarray(labels.get(f"{side}_{p}", np.zeros(F, dtype=bool)), dtype=bool) for p in ("toe", "heel"))
    return eased_mask(toe & ~heel, int(round(ease_time * fps)))


def spill_targets(targets: Targets) -> None:
    """Keep ``targets``' positions and orientations, and the unplanned positions
    (``info["raw_positions"]``), in temporary files (:mod:`physmocap.spill`; a long clip's
    1.4 to 2 KB per frame): the tracker, the fidelity figures and the writers read them a
    block of frames at a time.  Only for targets nothing writes any more."""
    targets.positions = spill(targets.positions)
    targets.orientations = spill(targets.orientations)
    if "raw_positions" in targets.info:
        targets.info["raw_positions"] = spill(targets.info["raw_positions"])


#: The joints of a foot that :func:`~physmocap.ik.footlevel.level_feet` reads and levels.
LEVELLED_FOOT_JOINTS = ("ankle", "toe", "toe_end")


def _foot_columns(names: tuple[str, ...], side: str) -> list[int]:
    """Target columns of the joints of one foot (``side``) that
    :func:`~physmocap.ik.footlevel.level_feet` works on (:data:`LEVELLED_FOOT_JOINTS`), in
    target order."""
    foot = {f"{side}_{j}" for j in LEVELLED_FOOT_JOINTS}
    return [i for i, n in enumerate(names) if n in foot]


def _set_columns(array: np.ndarray, cols: list[int], values: np.ndarray) -> None:
    """``array[:, cols] = values``, a block of frames at a time (:func:`~physmocap.spill.blocks`:
    a spilled ``array``'s pages let go after each block)."""
    for s, rows in blocks(array):
        rows[:, cols] = values[s : s + rows.shape[0]]


def _get_columns(array: np.ndarray, cols: list[int]) -> np.ndarray:
    """``array[:, cols]``, gathered a block of frames at a time (a spilled ``array``'s pages
    let go after each block: one column of a frame-major array is on every page)."""
    out = np.empty((array.shape[0], len(cols), *array.shape[2:]), dtype=array.dtype)
    for s, rows in blocks(array):
        out[s : s + rows.shape[0]] = rows[:, cols]
    return out


def level_targets(targets: Targets, character, labels: dict[str, np.ndarray], *, own_orientations: bool = False) -> Targets:
    """A copy of ``targets`` with the feet levelled on the actor's flat-stance frames
    (:func:`~physmocap.ik.footlevel.level_feet`); what was done is in ``info["foot_levels"]``.

    Only one foot's columns at a time are handed to ``level_feet`` (it reads and changes
    nothing else, and levels each foot on its own), then written into a copy of the
    positions (laid out joint by joint: :func:`~physmocap.ik.footplan.planted_positions`
    plans it a column at a time; in a temporary file for a long clip) and of the
    orientations, or into ``targets.orientations`` itself with ``own_orientations`` (the
    caller gives it up)."""
    levelled = copy.copy(targets)  # not dataclasses.replace: released source positions stay released
    levelled.positions = spilled_copy(targets.positions, by_column=True)
    levelled.orientations = targets.orientations if own_orientations else targets.orientations.copy()
    rest = character_rest_frames(character)
    levels = []
    for side in ("left", "right"):
        cols = _foot_columns(targets.names, side)
        positions, orientations, found = level_feet(
            _get_columns(targets.positions, cols), _get_columns(targets.orientations, cols), targets.has_orientation[cols],
            tuple(targets.names[i] for i in cols), labels, rest, targets.fps, in_place=True,
        )
        _set_columns(levelled.positions, cols, positions)
        _set_columns(levelled.orientations, cols, orientations)
        levels += found
    levelled.info = {**targets.info, "foot_levels": levels}
    return levelled


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
    """Run the per-frame pipeline (:class:`~physmocap.ik.frame.FrameRetargeter`) over prepared targets.

    With contact ``labels`` (``left_heel``, ``left_toe``, ``right_heel``,
    ``right_toe`` -> ``(F,)`` bool) the targets are first planned over the
    whole clip (:func:`plan_targets`; the trajectory carries the planned
    copy, ``targets`` itself is not modified), then every frame holds its
    planted contact points.  Without labels, or with ``plant.plant`` False,
    the targets are tracked as they are.
    """
    options = options or SolverOptions()
    plant = plant or PlantOptions()
    if labels is not None and plant.plant:
        labels = release_kneeling_feet(labels, body_labels or {})
        targets = plan_targets(targets, character, labels, plant, options.floor_height, body_labels)
    else:
        labels = None
    traj = _track(targets, character, options, source, progress, labels, plant)
    _warn_relaxations(traj)
    return traj


#: Frames :func:`_track` goes through between two releases of its spilled arrays' pages.
RELEASE_FRAMES = 4096


def _track(
    targets: Targets,
    character,
    options: SolverOptions,
    source: str,
    progress: bool | None,
    labels: dict[str, np.ndarray] | None,
    plant: PlantOptions,
    guides=None,
    label: str = "retarget",
    shift: Sequence[tuple[np.ndarray, np.ndarray]] = (),
) -> Trajectory:
    """Run the per-frame pipeline over (planned) targets, holding the contact points of
    ``labels`` (None: track the targets as they are), with ``guides`` (``guides.get(frame)``:
    a :class:`~.branches.Guide` or None; a dict or :class:`~.transitions.TransitionGuides`)
    and the target columns ``cols`` of each ``(offsets (F, 3), cols)`` in ``shift`` moved by
    that frame's offset (metres; :func:`~.transitions.eased_foot_shifts`), the trajectory
    keeping the unmoved targets; the solver's per-frame figures are
    kept in compact arrays (int32, int8 and float64 seconds per frame).  ``label`` names
    the progress bar (``batch`` follows the ``"retarget"`` one)."""
    guides = {} if guides is None else guides
    planted = labels is not None
    pipeline = FrameRetargeter(
        character, targets.names, targets.has_orientation, targets.fps, options, plant if planted else None, anchored=False
    )
    F = targets.num_frames
    qpos = spilled_empty((F, character.model.nq))
    iterations = np.zeros(F, dtype=np.int32)
    relaxation = np.zeros(F, dtype=np.int8)
    latency = np.zeros(F)
    with Progress(F, label, enabled=progress) as bar:
        for t in range(F):
            frame_labels = {k: bool(v[t]) for k, v in labels.items()} if labels is not None else None
            positions = targets.positions[t]
            moved = [(offsets[t], cols) for offsets, cols in shift if offsets[t].any()]
            if moved:
                positions = np.array(positions, dtype=float)
                for offset, cols in moved:
                    positions[cols] += offset
            result = pipeline.solve(positions, targets.orientations[t], targets.valid[t], frame_labels,
                                    guides.get(t))
            qpos[t] = result.qpos
            iterations[t] = result.iterations
            relaxation[t] = result.relaxation
            latency[t] = result.latency
            bar.update(1)
            if (t + 1) % RELEASE_FRAMES == 0:  # spilled arrays: the frames done leave the memory
                for array in (targets.positions, targets.orientations, qpos):
                    release(array)
    return Trajectory(
        character=character,
        qpos=qpos,
        fps=targets.fps,
        source=source,
        targets=targets,
        solver=SolverStats(iterations=iterations, relaxation=relaxation, latency=latency),
    )


def _warn_relaxations(traj: Trajectory) -> None:
    """One warning per relaxation the solver needed, naming the frames (the first ten)."""
    relaxation = traj.solver.relaxation
    for level in range(1, len(RELAXATION_LEVELS)):
        frames = np.flatnonzero(relaxation == level)
        if frames.size:
            shown = ", ".join(str(f) for f in frames[:10]) + (" ..." if frames.size > 10 else "")
            warn(f"{traj.source}: {RELAXATION_LEVELS[level]} on {frames.size} frame(s): {shown}")
