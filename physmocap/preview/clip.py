"""What a preview shows: the character's trajectory and the source skeleton beside it.

:func:`retarget_clip` (which calls :func:`physmocap.ik.retarget`) and
:func:`result_clip` (which reads what it returns) are the only places where the
preview touches the retargeter; everything else works on the
:class:`PreviewClip` built here.

The source skeleton is drawn where the retargeter put the actor: the source
joints' world positions :math:`p` (metres, Z-up, from the motion's forward
kinematics) go through the same root placement as the pelvis target
(:mod:`physmocap.ik.targets`): an optional floor levelling rotation, then a
uniform scale :math:`k` (character / actor hip height) about the start point
on the actor's floor, lifted so the actor's ankle height maps to the
character's:

.. math::
    p'_{xy} = o_{xy} + k (p_{xy} - o_{xy}), \\qquad
    p'_z = k (p_z - z_{floor} - a_{actor}) + a_{character}.
"""

from __future__ import annotations

import os
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import mujoco
import numpy as np

from ..errors import OptionError
from ..motion import Motion
from ..rotations import quat_apply
from ..trajectory import Trajectory

__all__ = ["CENTRE", "LEFT", "RIGHT", "Placement", "PreviewClip", "SourceSkeleton", "result_clip", "retarget_clip", "trajectory_clip", "tree_sides"]

CENTRE, LEFT, RIGHT = 0, 1, 2


def tree_sides(parents: np.ndarray, seeds: dict[int, int]) -> np.ndarray:
    """Body side (:data:`CENTRE`, :data:`LEFT`, :data:`RIGHT`) of every node of a tree.

    ``parents[j] < j`` (roots: ``-1`` or themselves).  A seeded node keeps its
    side; any other node takes its nearest sided ancestor's side, else the side
    of its seeded descendants when they all lie on one side (a CMU
    ``LHipJoint`` above the left hip), else centre.
    """
    parents = np.asarray(parents, dtype=np.int64)
    n = parents.size
    below = np.zeros(n, dtype=np.int64)  # bit mask of seeded sides in the subtree
    for j in range(n - 1, -1, -1):
        if j in seeds:
            below[j] |= 1 << seeds[j]
        p = int(parents[j])
        if 0 <= p < j:
            below[p] |= below[j]
    sides = np.full(n, CENTRE, dtype=np.int8)
    for j in range(n):
        p = int(parents[j])
        if j in seeds:
            sides[j] = seeds[j]
        elif 0 <= p < j and sides[p] != CENTRE:
            sides[j] = sides[p]
        elif below[j] in (1 << LEFT, 1 << RIGHT):
            sides[j] = LEFT if below[j] == 1 << LEFT else RIGHT
    return sides


def canonical_side(name: str) -> int:
    """Side of a canonical joint name (``left_knee`` -> :data:`LEFT`)."""
    return LEFT if name.startswith("left_") else RIGHT if name.startswith("right_") else CENTRE


@dataclass(frozen=True, eq=False)
class Placement:
    """The retargeter's root placement of the actor in the character's world (see module doc).

    Attributes:
        scale: :math:`k`, character over actor hip height.
        origin_xy: :math:`o_{xy}`, the actor's start point (m).
        source_floor: :math:`z_{floor}`, the actor's floor height (m).
        ankle_actor, ankle_character: Ankle heights above the floor (m).
        level: Floor levelling rotation (x-y-z-w) or None.
        level_centre: Point the levelling rotates about (m) or None.
    """

    scale: float = 1.0
    origin_xy: np.ndarray = field(default_factory=lambda: np.zeros(2))
    source_floor: float = 0.0
    ankle_actor: float = 0.0
    ankle_character: float = 0.0
    level: np.ndarray | None = None
    level_centre: np.ndarray | None = None

    def apply(self, points: np.ndarray) -> np.ndarray:
        """``(..., 3)`` source world points -> character world points (metres)."""
        p = np.asarray(points, dtype=float)
        if self.level is not None and self.level_centre is not None:
            c = np.asarray(self.level_centre, dtype=float)
            p = quat_apply(self.level, p - c) + np.array([c[0], c[1], 0.0])
        out = np.empty_like(p)
        out[..., :2] = self.origin_xy + self.scale * (p[..., :2] - self.origin_xy)
        out[..., 2] = self.scale * (p[..., 2] - self.source_floor - self.ankle_actor) + self.ankle_character
        return out


@dataclass(frozen=True, eq=False)
class SourceSkeleton:
    """The actor's skeleton per frame, placed in the character's world.

    Attributes:
        positions: ``(F, J, 3)`` joint positions, metres (NaN where the joint is lost);
            float32 is plenty for drawing.
        parents: ``(J,)`` parent index, ``-1`` for a root; bones join joint and parent.
        sides: ``(J,)`` :data:`CENTRE` / :data:`LEFT` / :data:`RIGHT`.
    """

    positions: np.ndarray
    parents: np.ndarray
    sides: np.ndarray

    def take(self, frames: np.ndarray) -> "SourceSkeleton":
        return SourceSkeleton(self.positions[frames], self.parents, self.sides)


@dataclass(frozen=True, eq=False)
class PreviewClip:
    """Everything a preview draws, frame-aligned with ``trajectory.qpos``.

    Attributes:
        trajectory: The character's motion.
        frame_numbers: ``(F,)`` source frame each frame came from (what images are labelled with).
        source_fps: The source's frame rate (frame number / rate = time in the source, s).
        skeleton: The source skeleton, or None when it is not known.
        planted: Character contact site name -> ``(F,)`` bool, True while planted.
    """

    trajectory: Trajectory
    frame_numbers: np.ndarray
    source_fps: float
    skeleton: SourceSkeleton | None = None
    planted: dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def num_frames(self) -> int:
        return self.trajectory.num_frames

    def between(self, start: int | None, end: int | None) -> "PreviewClip":
        """The frames whose source frame number is in ``[start, end)`` (None: open)."""
        n = self.frame_numbers
        keep = (n >= (n[0] if start is None else start)) & (n < (n[-1] + 1 if end is None else end))
        if not keep.any():
            raise OptionError(
                f"frame range [{start}, {end}) selects no frame; this clip has frames {n[0]} to {n[-1]} "
                f"(--start is inclusive, --end exclusive)",
                path=self.trajectory.source,
            )
        return self if keep.all() else self.take(np.flatnonzero(keep))

    def take(self, frames: np.ndarray) -> "PreviewClip":
        """The clip restricted to trajectory frames ``frames`` (indices, in order)."""
        frames = np.asarray(frames, dtype=np.int64)
        t = self.trajectory
        traj = Trajectory(character=t.character, qpos=t.qpos[frames], fps=t.fps, source=t.source)
        return PreviewClip(
            traj,
            self.frame_numbers[frames],
            self.source_fps,
            None if self.skeleton is None else self.skeleton.take(frames),
            {k: v[frames] for k, v in self.planted.items()},
        )


def planted_sites(character, labels: dict[str, np.ndarray] | None) -> dict[str, np.ndarray]:
    """Contact labels (``left_heel`` ...) -> the character's heel / toe contact sites."""
    out: dict[str, np.ndarray] = {}
    for label, on in (labels or {}).items():
        side, _, point = label.partition("_")
        sites = character.contacts.get(side, ())
        if sites:
            out[sites[0] if point == "heel" else sites[-1]] = np.asarray(on, dtype=bool)
    return out


def source_skeleton(motion: Motion, joint_indices: dict[str, int], placement: Placement) -> SourceSkeleton:
    """The actor's joints from ``motion``'s forward kinematics, placed like the retargeter.

    Joints above the mapped pelvis (a vendor's wrapper root on the floor, such as
    Bandai's ``joint_Root``) are left out (NaN): they are not part of the body.
    """
    seeds = {int(j): canonical_side(c) for c, j in joint_indices.items() if canonical_side(c) != CENTRE}
    parents = motion.skeleton.parents
    positions = placement.apply(motion.world_positions()).astype(np.float32)  # half the memory of a long clip
    j = int(parents[joint_indices["pelvis"]]) if "pelvis" in joint_indices else -1
    while j >= 0:
        positions[:, j] = np.nan
        j = int(parents[j])
    return SourceSkeleton(positions, parents, tree_sides(parents, seeds))


def retarget_clip(motion: Motion, character, **retarget_options) -> PreviewClip:
    """Retarget ``motion`` onto ``character`` (``physmocap.ik.retarget`` options)
    and gather what the preview draws."""
    from ..ik.retarget import retarget

    return result_clip(retarget(motion, character, **retarget_options), motion)


def result_clip(result: Trajectory, motion: Motion) -> PreviewClip:
    """What the preview draws, from the retargeter's result for ``motion`` (as read).

    With :func:`retarget_clip`, the only code that knows the retargeter's API.
    """
    traj = result
    used: Motion = traj.stats["source_motion"]
    start = int(traj.stats["source_start"])
    contacts = traj.stats.get("contacts")
    cal = traj.targets.calibration
    placement = Placement(
        scale=float(cal.scale),
        origin_xy=np.asarray(cal.start_xy, dtype=float),
        source_floor=float(cal.floor),
        ankle_actor=float(cal.ankle_actor),
        ankle_character=float(cal.ankle_character),
        level=cal.level,
        level_centre=cal.level_centre,
    )
    frames = start + np.rint(np.arange(traj.num_frames) * motion.fps / used.fps).astype(np.int64)
    return PreviewClip(
        trajectory=traj,
        frame_numbers=frames,
        source_fps=float(motion.fps),
        skeleton=source_skeleton(used, traj.stats["joint_indices"], placement),
        planted=planted_sites(traj.character, None if contacts is None else contacts.labels),
    )


def is_trajectory_file(path: str | os.PathLike) -> bool:
    """True for an ``.npz`` holding a ``qpos`` array (``physmocap retarget --qpos``),
    as opposed to a joint-position recording."""
    p = Path(path)
    if p.suffix.lower() != ".npz" or not p.is_file():
        return False
    try:
        with np.load(p, allow_pickle=False) as z:
            return "qpos" in getattr(z, "files", ())
    except (OSError, ValueError, EOFError, zipfile.BadZipFile):
        return False


def trajectory_clip(path, character=None) -> PreviewClip:
    """A trajectory saved by ``physmocap retarget --qpos``.  The source motion is
    not in the file, so the IK targets it tracked (when stored) stand in for the
    source skeleton, joined along the canonical hierarchy."""
    from ..canonical import CANONICAL_NAMES, canonical_parent
    from ..report import load_trajectory

    traj = load_trajectory(path, character)
    frames = int(traj.stats.get("source_start", 0)) + np.arange(traj.num_frames)
    targets = traj.targets
    if targets is None:
        return PreviewClip(trajectory=traj, frame_numbers=frames, source_fps=traj.fps)
    rank = {c: i for i, c in enumerate(CANONICAL_NAMES)}
    order = sorted(range(len(targets.names)), key=lambda i: rank.get(targets.names[i], len(rank)))
    names = [targets.names[i] for i in order]  # parents before children
    present = set(names)
    parents = np.array(
        [-1 if (p := canonical_parent(n, present)) is None else names.index(p) for n in names], dtype=np.int64
    )
    seeds = {i: canonical_side(n) for i, n in enumerate(names) if canonical_side(n) != CENTRE}
    pos = np.where(targets.valid[..., None], targets.positions, np.nan)[:, order]
    skeleton = SourceSkeleton(pos, parents, tree_sides(parents, seeds))
    return PreviewClip(trajectory=traj, frame_numbers=frames, source_fps=traj.fps, skeleton=skeleton)


def character_sides(character) -> np.ndarray:
    """``(nbody,)`` side of every body of the character, from its mapped canonical joints."""
    model: mujoco.MjModel = character.model
    seeds: dict[int, int] = {}
    for canon, tf in character.tracked.items():
        side = canonical_side(canon)
        if side == CENTRE:
            continue
        body = int(model.site_bodyid[model.site(tf.name).id]) if tf.kind == "site" else model.body(tf.name).id
        seeds[body] = side
    parents = np.array(model.body_parentid, dtype=np.int64)
    parents[0] = -1
    return tree_sides(parents, seeds)
