"""A skeleton's tree and one standing pose, with the geometric queries the
mapping rules need (paths, common ancestors, arc lengths, the body's axes).

The *pose* is where joints are in the world (metres, Z up).  It is the rest
pose when that pose stands upright; BVH files whose rest pose is not a body
(LAFAN1 and Bandai Namco store bone-local offsets, so all bones lie along one
axis) are looked at in an animated frame instead (:func:`standing_pose`).

Lengths along a chain use distances between the pose's joint positions, which
for a rotational motion equal the bone lengths in every frame.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ...motion import Motion, Skeleton

__all__ = ["SkeletonView", "standing_pose", "is_upright"]

#: A pose is upright when its vertical extent is at least this fraction of
#: its largest horizontal extent (a T-pose has arm span ~ height, ratio ~1).
UPRIGHT_RATIO = 0.6


def is_upright(pose: np.ndarray) -> bool:
    """True when ``pose (J, 3)`` is taller (Z) than :data:`UPRIGHT_RATIO` of its width."""
    p = pose[np.all(np.isfinite(pose), axis=1)]
    if len(p) < 2:
        return False
    ext = np.ptp(p, axis=0)
    return bool(ext[2] > 1e-9 and ext[2] >= UPRIGHT_RATIO * max(ext[0], ext[1]))


def standing_pose(obj: Skeleton | Motion) -> tuple[np.ndarray, str]:
    """An upright pose to read the skeleton's geometry from, and where it came from.

    A :class:`~physmocap.motion.Skeleton` gives its rest pose.  A
    :class:`~physmocap.motion.Motion` gives its rest pose if upright, else the
    first upright one of up to 9 evenly spaced frames (positional motions:
    joints missing in a frame are filled with their median over those frames),
    else the rest pose.
    """
    if isinstance(obj, Skeleton):
        return obj.rest_positions(), "rest pose"
    skel = obj.skeleton
    rest = skel.rest_positions()
    if obj.is_rotational and is_upright(rest):
        return rest, "rest pose"
    F = obj.num_frames
    frames = np.unique(np.linspace(0, F - 1, min(F, 9)).round().astype(int))
    if obj.is_rotational:
        from ...motion import forward_kinematics

        assert obj.rotations is not None and obj.translations is not None
        pos, _ = forward_kinematics(
            skel, obj.rotations[frames], obj.translations[frames], obj.translated
        )
    else:
        assert obj.positions is not None
        pos = obj.positions[frames]
    if not obj.is_rotational:
        # occluded joints: fill from the other sampled frames
        pos = np.array(pos, dtype=float)
        ok = np.all(np.isfinite(pos), axis=2)  # (S, J)
        for j in np.flatnonzero(ok.any(axis=0) & ~ok.all(axis=0)):
            pos[~ok[:, j], j] = np.median(pos[ok[:, j], j], axis=0)
    finite = np.all(np.isfinite(pos), axis=2).sum(axis=1)
    order = np.argsort(-finite, kind="stable")
    for k in order:
        if finite[k] == finite[order[0]] and is_upright(pos[k]):
            return pos[k], f"frame {int(frames[k])}"
    if not obj.is_rotational:
        return pos[order[0]], f"frame {int(frames[order[0]])}"
    return rest, "rest pose"


@dataclass
class SkeletonView:
    """Tree queries and geometry of one skeleton in one pose."""

    skeleton: Skeleton
    pose: np.ndarray
    children: list[list[int]] = field(init=False)
    eps: float = field(init=False)

    def __post_init__(self) -> None:
        J = self.skeleton.num_joints
        self.children = [[] for _ in range(J)]
        for j, p in enumerate(self.skeleton.parents):
            if p >= 0:
                self.children[int(p)].append(j)
        finite = self.pose[np.all(np.isfinite(self.pose), axis=1)]
        scale = float(np.ptp(finite, axis=0).max()) if len(finite) > 1 else 0.0
        self.scale = scale if scale > 0 else 1.0
        #: Joints closer than this are at the same place (zero-length bones).
        self.eps = 1e-3 * self.scale

    # -- tree ----------------------------------------------------------------------
    @property
    def parents(self) -> np.ndarray:
        return self.skeleton.parents

    def is_end(self, j: int) -> bool:
        return bool(self.skeleton.end_site[j])

    def leaves(self) -> list[int]:
        return [j for j, c in enumerate(self.children) if not c]

    def chain(self, j: int) -> list[int]:
        return self.skeleton.chain(j)

    def is_ancestor(self, a: int, j: int) -> bool:
        """True when ``a`` is ``j`` or one of its ancestors."""
        while j >= 0:
            if j == a:
                return True
            j = int(self.parents[j])
        return False

    def lca(self, *joints: int) -> int:
        """Lowest common ancestor of ``joints`` (``-1`` if they are in different trees)."""
        common = self.chain(joints[0])
        for j in joints[1:]:
            c = self.chain(j)
            n = 0
            while n < min(len(common), len(c)) and common[n] == c[n]:
                n += 1
            common = common[:n]
        return common[-1] if common else -1

    def path(self, a: int, b: int) -> list[int]:
        """Joints from ``a`` down to its descendant ``b``, both included."""
        c = self.chain(b)
        if a not in c:
            raise ValueError(f"joint {a} is not an ancestor of {b}")
        return c[c.index(a):]

    def child_toward(self, a: int, b: int) -> int:
        """The child of ``a`` on the way down to its descendant ``b``."""
        return self.path(a, b)[1]

    def subtree(self, j: int) -> list[int]:
        out, stack = [], [j]
        while stack:
            k = stack.pop()
            out.append(k)
            stack.extend(self.children[k])
        return sorted(out)

    # -- geometry --------------------------------------------------------------------
    def dist(self, a: int, b: int) -> float:
        return float(np.linalg.norm(self.pose[a] - self.pose[b]))

    def same_place(self, a: int, b: int) -> bool:
        return self.dist(a, b) < self.eps

    def points(self, nodes: list[int]) -> list[int]:
        """``nodes[1:]`` without joints at the same place as the previous kept one.

        Of several joints at one place (zero-length bones) the first, the one
        nearest the root, is kept: its world rotation is the segment's.
        """
        out: list[int] = []
        last = nodes[0]
        for j in nodes[1:]:
            if not self.same_place(j, last):
                out.append(j)
                last = j
        return out

    def arc(self, nodes: list[int]) -> np.ndarray:
        """Cumulative length along ``nodes`` (``arc[0] = 0``)."""
        if len(nodes) < 2:
            return np.zeros(len(nodes))
        d = np.linalg.norm(np.diff(self.pose[nodes], axis=0), axis=1)
        return np.concatenate([[0.0], np.cumsum(d)])

    def end_sites_of(self, j: int) -> list[int]:
        """End-site children of ``j`` that are not at ``j``'s place, farthest first."""
        ends = [c for c in self.children[j] if self.is_end(c) and not self.same_place(c, j)]
        return sorted(ends, key=lambda c: -self.dist(c, j))

    def horizontal(self, v: np.ndarray) -> np.ndarray:
        return np.array([v[0], v[1]])
