r"""The source skeleton, placed where the retargeter put the character.

The retargeter maps the actor's world onto the character's (:mod:`physmocap.ik.targets`):
horizontally :math:`x' = s + k (x - s)` about the actor's start point :math:`s`, vertically
:math:`z' = k (z - z_{floor} - h_a) + h_c` (actor ankle height :math:`h_a` above its floor,
the character's :math:`h_c`), after levelling a tilted floor; :math:`k` is the ratio of leg
lengths.  Every joint of the source skeleton goes through the same map, so the skeleton
has the character's size and stands on its floor, facing the same way.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..rotations import quat_apply

__all__ = ["Placement", "SourceSkeleton", "source_skeleton", "side_of_joints"]

LEFT, CENTRE, RIGHT = 1, 0, -1


@dataclass(frozen=True)
class SourceSkeleton:
    """Bones of the source skeleton in the character's world (metres).

    Attributes:
        positions: ``(F, J, 3)`` joint positions, NaN where the source lost a joint.
        bones: ``(B, 2)`` (parent, child) joint indices.
        side: ``(J,)`` +1 left, -1 right, 0 centre.
    """

    positions: np.ndarray
    bones: np.ndarray
    side: np.ndarray


def side_of_joints(parents: np.ndarray, joint_indices: dict[str, int]) -> np.ndarray:
    """``(J,)`` +1 for joints in the subtree of a mapped left hip, clavicle or shoulder,
    -1 for the right ones, 0 otherwise."""
    J = len(parents)
    side = np.zeros(J, dtype=int)
    for sign, prefix in ((LEFT, "left_"), (RIGHT, "right_")):
        roots = {joint_indices[f"{prefix}{c}"] for c in ("hip", "clavicle", "shoulder") if f"{prefix}{c}" in joint_indices}
        for j in range(J):
            a = j
            while a >= 0 and a not in roots:
                a = int(parents[a])
            if a >= 0:
                side[j] = sign
    return side


def _subtree(parents: np.ndarray, root: int) -> np.ndarray:
    """``(J,)`` True for ``root`` and its descendants (the body below a wrapper root joint)."""
    inside = np.zeros(len(parents), dtype=bool)
    for j in range(len(parents)):  # parents come before their children
        inside[j] = j == root or (parents[j] >= 0 and inside[parents[j]])
    return inside


@dataclass(frozen=True, eq=False)
class Placement:
    """The retargeter's map from the actor's world to the character's (module doc).

    Attributes:
        scale: :math:`k`, the leg-length ratio.
        start_xy: :math:`s`, the actor's start point (m).
        floor: :math:`z_{floor}`, the actor's floor height after levelling (m).
        ankle_actor, ankle_character: :math:`h_a`, :math:`h_c` (m).
        level: Rotation (x-y-z-w) levelling a tilted floor, or None.
        level_centre: Point it turns about (m), or None.
    """

    scale: float
    start_xy: np.ndarray
    floor: float
    ankle_actor: float
    ankle_character: float
    level: np.ndarray | None = None
    level_centre: np.ndarray | None = None

    def apply(self, points: np.ndarray) -> np.ndarray:
        """``(..., 3)`` actor world points -> character world points (metres)."""
        P = np.asarray(points, dtype=float)
        if self.level is not None:
            c = np.asarray(self.level_centre, dtype=float)
            P = quat_apply(self.level, P - c) + np.array([c[0], c[1], 0.0])
        out = np.empty_like(P)
        out[..., :2] = self.start_xy + self.scale * (P[..., :2] - self.start_xy)
        out[..., 2] = self.scale * (P[..., 2] - self.floor - self.ankle_actor) + self.ankle_character
        return out


def source_skeleton(motion, joint_indices: dict[str, int], placement: Placement) -> SourceSkeleton:
    """The source skeleton of ``motion`` (as retargeted: cut, resampled) placed by ``placement``.

    Joints above the mapped pelvis (a wrapper root such as Bandai's ``joint_Root``) are not
    bones of the body and are left out; joints with zero confidence are NaN.
    """
    P = np.array(motion.world_positions(), dtype=float)
    if motion.confidence is not None:
        P[motion.confidence <= 0.0] = np.nan
    out = placement.apply(P)
    parents = np.asarray(motion.skeleton.parents)
    body = _subtree(parents, joint_indices.get("pelvis", 0))
    bones = np.array([(int(p), j) for j, p in enumerate(parents) if p >= 0 and body[j] and body[p]], dtype=int).reshape(-1, 2)
    return SourceSkeleton(positions=out, bones=bones, side=side_of_joints(parents, joint_indices))
