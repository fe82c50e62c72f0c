"""The result of mapping a skeleton, and the canonical motion it gives.

A :class:`JointMap` says which source joint is each canonical joint.  The
canonical arrays below are ordered like :data:`physmocap.canonical.CANONICAL_NAMES`
(``N = len(CANONICAL_NAMES)``), with NaN rows and a False mask entry for the
canonical joints the source does not provide.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Mapping

import numpy as np

from ...canonical import CANONICAL_NAMES, REQUIRED_JOINTS
from ...motion import Motion, Skeleton

__all__ = [
    "JointMap",
    "canonical_positions",
    "canonical_rotations",
    "canonical_rest_positions",
    "canonical_confidence",
]

@dataclass(frozen=True, eq=False)
class JointMap:
    """Which joint of one source skeleton is each canonical joint.

    Attributes:
        profile: The profile used (``"cmu"``...), ``"topology"`` (found from
            the skeleton's shape), or ``"custom"`` (a mapping file or dict
            changed it; see ``based_on``).
        indices: Canonical name -> joint index in the source skeleton, for the
            canonical joints that *are* a source joint (position and rotation).
        names: The source skeleton's joint names, which ``indices`` point into.
        derived: Canonical name -> ``((joint index, weight), ...)``: canonical
            joints computed as a weighted sum of source joint positions (a
            pelvis between the hips when the source has none).  They have a
            position but no rotation.
        notes: What the mapping rules decided, for people (``physmocap inspect``).
        based_on: For ``"custom"``, the profile the mapping file started from.
        pose: Where the geometry was read (``"rest pose"``, ``"frame 0"``).
    """

    profile: str
    indices: Mapping[str, int]
    names: tuple[str, ...] = ()
    derived: Mapping[str, tuple[tuple[int, float], ...]] = field(default_factory=dict)
    notes: tuple[str, ...] = ()
    based_on: str | None = None
    pose: str = "rest pose"

    def __post_init__(self) -> None:
        order = {c: k for k, c in enumerate(CANONICAL_NAMES)}
        ind = {c: int(self.indices[c]) for c in sorted(self.indices, key=order.__getitem__)}
        der = {
            c: tuple((int(j), float(w)) for j, w in self.derived[c])
            for c in sorted(self.derived, key=order.__getitem__)
        }
        object.__setattr__(self, "indices", MappingProxyType(ind))
        object.__setattr__(self, "derived", MappingProxyType(der))
        object.__setattr__(self, "names", tuple(self.names))
        object.__setattr__(self, "notes", tuple(self.notes))

    # -- queries --------------------------------------------------------------------
    @property
    def mapped(self) -> tuple[str, ...]:
        """Canonical joints the source provides (directly or derived), canonical order."""
        return tuple(c for c in CANONICAL_NAMES if c in self.indices or c in self.derived)

    @property
    def unmapped(self) -> tuple[str, ...]:
        """Canonical joints the source does not provide (the retargeter does not track them)."""
        return tuple(c for c in CANONICAL_NAMES if c not in self.indices and c not in self.derived)

    def missing(self, required=REQUIRED_JOINTS) -> tuple[str, ...]:
        """The ``required`` canonical joints that are not mapped, canonical order."""
        req = set(required)
        return tuple(c for c in self.unmapped if c in req)

    def source_name(self, skeleton: Skeleton | None, canonical: str) -> str | None:
        """Name of the source joint that is ``canonical``, or None (unmapped or derived).

        ``skeleton`` may be None: the names recorded when mapping are used.
        """
        j = self.indices.get(canonical)
        if j is None:
            return None
        names = skeleton.names if skeleton is not None else self.names
        return names[j]

    def describe(self, canonical: str) -> str | None:
        """The source joint's name, or how a derived joint is made, or None."""
        if canonical in self.indices:
            return self.names[self.indices[canonical]]
        if canonical in self.derived:
            parts = self.derived[canonical]
            if len(parts) == 2 and all(abs(w - 0.5) < 1e-12 for _, w in parts):
                return f"midpoint of {self.names[parts[0][0]]} and {self.names[parts[1][0]]}"
            return " + ".join(f"{w:g} * {self.names[j]}" for j, w in parts)
        return None

    def as_mapping(self) -> dict[str, str]:
        """Canonical name -> source joint name (direct joints), canonical order."""
        return {c: self.names[j] for c, j in self.indices.items()}

    def to_toml(self) -> str:
        """This mapping as a mapping file (``--map``) to edit and reuse."""
        lines = [
            "# physmocap source mapping: canonical joint = source joint name",
            "# (set an entry to false to leave that joint untracked)",
        ]
        base = self.based_on or (self.profile if self.profile not in ("custom", "topology") else None)
        if base:
            lines.append(f'profile = "{base}"')
        lines.append("")
        lines.append("[joints]")
        for c, name in self.as_mapping().items():
            esc = name.replace("\\", "\\\\").replace('"', '\\"')
            lines.append(f'{c} = "{esc}"')
        for c in self.unmapped:
            lines.append(f"# {c} = ...")
        return "\n".join(lines) + "\n"

    def check_skeleton(self, skeleton: Skeleton) -> None:
        """Raise ValueError unless this map was made for ``skeleton``'s joints."""
        if self.names and tuple(skeleton.names) != self.names:
            raise ValueError("this JointMap was made for a skeleton with other joint names")


def _index_arrays(jmap: JointMap) -> tuple[np.ndarray, np.ndarray]:
    cols = np.array([k for k, c in enumerate(CANONICAL_NAMES) if c in jmap.indices], dtype=int)
    src = np.array([jmap.indices[CANONICAL_NAMES[k]] for k in cols], dtype=int)
    return cols, src


def _canonical_from(world: np.ndarray, jmap: JointMap) -> tuple[np.ndarray, np.ndarray]:
    lead = world.shape[:-2]
    N = len(CANONICAL_NAMES)
    out = np.full(lead + (N, 3), np.nan)
    mask = np.zeros(N, dtype=bool)
    cols, src = _index_arrays(jmap)
    out[..., cols, :] = world[..., src, :]
    mask[cols] = True
    for c, parts in jmap.derived.items():
        k = CANONICAL_NAMES.index(c)
        out[..., k, :] = sum(w * world[..., j, :] for j, w in parts)
        mask[k] = True
    return out, mask


def canonical_positions(
    motion: Motion, jmap: JointMap, world: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """World positions of the canonical joints over the motion.

    Args:
        motion: The source motion (the skeleton ``jmap`` was made for).
        jmap: Its joint map.
        world: ``(F, J, 3)`` precomputed ``motion.world_positions()``, to skip
            forward kinematics.

    Returns:
        ``(positions (F, N, 3), mask (N,))``: metres, Z up, in
        :data:`~physmocap.canonical.CANONICAL_NAMES` order; rows of unmapped
        joints are NaN and their mask entry False.  A derived joint is the
        weighted sum of its source joints (NaN if any of them is).
    """
    jmap.check_skeleton(motion.skeleton)
    if world is None:
        world = motion.world_positions()
    return _canonical_from(np.asarray(world, dtype=float), jmap)


def canonical_rest_positions(skeleton: Skeleton, jmap: JointMap) -> tuple[np.ndarray, np.ndarray]:
    """``(positions (N, 3), mask (N,))`` of the canonical joints in the skeleton's rest pose."""
    jmap.check_skeleton(skeleton)
    return _canonical_from(skeleton.rest_positions(), jmap)


def canonical_rotations(
    motion: Motion, jmap: JointMap, world_rotations: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """World rotations (x-y-z-w) of the canonical joints of a rotational motion.

    A canonical joint's rotation is its source joint's world rotation, the
    orientation of the segment that starts there, in the source's own bone
    frame (rest-pose conventions differ between sources; compare against the
    rest pose, where every local rotation is identity).

    Args:
        motion: A rotational motion (the skeleton ``jmap`` was made for).
        jmap: Its joint map.
        world_rotations: ``(F, J, 4)`` precomputed ``motion.world_rotations()``.

    Returns:
        ``(rotations (F, N, 4), mask (N,))``; NaN rows and False mask entries
        for unmapped and derived joints.

    Raises:
        ValueError: The motion is positional (it has no rotations).
    """
    jmap.check_skeleton(motion.skeleton)
    if not motion.is_rotational:
        raise ValueError("a positional motion has no joint rotations")
    if world_rotations is None:
        world_rotations = motion.world_rotations()
    wr = np.asarray(world_rotations, dtype=float)
    N = len(CANONICAL_NAMES)
    out = np.full(wr.shape[:-2] + (N, 4), np.nan)
    mask = np.zeros(N, dtype=bool)
    cols, src = _index_arrays(jmap)
    out[..., cols, :] = wr[..., src, :]
    mask[cols] = True
    return out, mask


def canonical_confidence(motion: Motion, jmap: JointMap) -> np.ndarray:
    """``(F, N)`` confidence in [0, 1] of each canonical joint per frame.

    1 for rotational motions' mapped joints, the source confidence (1 where
    the source has none) for positional ones, the minimum over the parts of a
    derived joint, and 0 for unmapped joints.
    """
    jmap.check_skeleton(motion.skeleton)
    F = motion.num_frames
    J = motion.skeleton.num_joints
    conf = motion.confidence if motion.confidence is not None else np.ones((F, J))
    if motion.positions is not None:
        conf = np.where(np.all(np.isfinite(motion.positions), axis=-1), conf, 0.0)
    N = len(CANONICAL_NAMES)
    out = np.zeros((F, N))
    cols, src = _index_arrays(jmap)
    out[:, cols] = conf[:, src]
    for c, parts in jmap.derived.items():
        out[:, CANONICAL_NAMES.index(c)] = np.min(np.stack([conf[:, j] for j, _ in parts]), axis=0)
    return out
