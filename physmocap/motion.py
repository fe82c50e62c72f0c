"""The motion data model: a named-joint skeleton animated over frames.

This is the one data type that sources produce and the retargeter consumes.

Conventions (see :mod:`physmocap.rotations`): metres, radians, Z-up world,
quaternions x-y-z-w.  A source converts its file's units and up axis when it
builds a :class:`Motion`; nothing downstream needs to know what the file used.

A motion comes in one of two kinds:

* **Rotational** (BVH and other solved skeletons): per frame, the local
  rotation of every joint and the local translation of the joints that carry
  position channels (at least the root).  Forward kinematics gives world
  positions and world rotations of every joint and end site:

  .. math::

      R^w_j = R^w_{p(j)} R_j, \\qquad
      x^w_j = x^w_{p(j)} + R^w_{p(j)} t_j

  where :math:`t_j` is the joint's animated translation if it has one and its
  rest offset otherwise.  With every local rotation at identity (the *rest
  pose*) the skeleton stands in the pose its offsets describe.

* **Positional** (trackers, markers): world positions of every joint per frame,
  with an optional per-joint confidence in [0, 1].  Orientations are unknown.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from .rotations import hamilton, quat_apply, quat_mul, rotate
from .spill import release, spilled_empty

__all__ = ["Skeleton", "Motion", "forward_kinematics", "MAX_FPS"]

#: Highest frame rate a motion may be resampled to (capture systems top out well below).
MAX_FPS = 2000.0


#: Most joints (end sites included) a skeleton may have, and the deepest chain from a root:
#: real captures have at most a few hundred joints, chains of a few dozen.
MAX_JOINTS = 1000
MAX_DEPTH = 100


def hierarchy_depth(parents) -> int:
    """Number of joints on the longest root-to-leaf chain (``parents[j] < j``)."""
    depth: list[int] = []
    for p in parents:
        depth.append(1 if p < 0 else depth[p] + 1)
    return max(depth, default=0)


#: Frames of world positions computed at a time by :meth:`Motion.joint_world_positions`.
WORLD_BLOCK_FRAMES = 4096


@dataclass(frozen=True, eq=False)
class Skeleton:
    """A tree (or forest) of named joints with rest offsets.

    Attributes:
        names: Joint names, unique.  BVH end sites are joints too, named
            ``<parent>_End`` (or ``<parent>_End2`` ... when a joint has several).
        parents: ``(J,)`` int parent index per joint, ``-1`` for a root.
            Parents always come before their children (``parents[j] < j``).
        offsets: ``(J, 3)`` rest offset of each joint from its parent, in metres
            and world (Z-up) axes; for a root, its rest position.
        end_site: ``(J,)`` bool, True for end sites (leaves with no channels).
    """

    names: tuple[str, ...]
    parents: np.ndarray
    offsets: np.ndarray
    end_site: np.ndarray = field(default=None)  # type: ignore[assignment]

    def __post_init__(self) -> None:
        names = tuple(str(n) for n in self.names)
        parents = np.asarray(self.parents, dtype=np.int64).reshape(-1)
        offsets = np.asarray(self.offsets, dtype=float).reshape(-1, 3)
        n = len(names)
        end_site = (
            np.zeros(n, dtype=bool)
            if self.end_site is None
            else np.asarray(self.end_site, dtype=bool).reshape(-1)
        )
        if parents.shape != (n,) or offsets.shape != (n, 3) or end_site.shape != (n,):
            raise ValueError(
                f"skeleton arrays disagree: {n} names, parents {parents.shape}, "
                f"offsets {offsets.shape}, end_site {end_site.shape}"
            )
        if n > MAX_JOINTS:
            raise ValueError(f"{n} joints; physmocap reads skeletons of at most {MAX_JOINTS}")
        if len(set(names)) != n:
            dup = sorted({x for x in names if names.count(x) > 1})
            raise ValueError(f"duplicate joint names: {dup}")
        if n and np.any(parents >= np.arange(n)):
            raise ValueError("parents must come before their children (parents[j] < j)")
        if np.any(parents < -1):
            raise ValueError("parent indices must be >= -1")
        if not np.all(np.isfinite(offsets)):
            raise ValueError("skeleton offsets must be finite")
        if hierarchy_depth(parents.tolist()) > MAX_DEPTH:
            raise ValueError(f"a chain of {hierarchy_depth(parents.tolist())} joints; physmocap reads chains "
                             f"of at most {MAX_DEPTH}")
        for arr in (parents, offsets, end_site):
            arr.setflags(write=False)
        object.__setattr__(self, "names", names)
        object.__setattr__(self, "parents", parents)
        object.__setattr__(self, "offsets", offsets)
        object.__setattr__(self, "end_site", end_site)

    # -- lookup ---------------------------------------------------------------
    @property
    def num_joints(self) -> int:
        return len(self.names)

    def index(self, name: str) -> int:
        """Index of joint ``name``; raises KeyError naming the available joints."""
        try:
            return self.names.index(name)
        except ValueError:
            raise KeyError(f"no joint {name!r}; joints are {list(self.names)}") from None

    def children(self, j: int) -> list[int]:
        return [int(c) for c in np.flatnonzero(self.parents == j)]

    def roots(self) -> list[int]:
        return [int(r) for r in np.flatnonzero(self.parents == -1)]

    def chain(self, j: int) -> list[int]:
        """Indices from the root down to ``j`` inclusive."""
        out = []
        while j >= 0:
            out.append(j)
            j = int(self.parents[j])
        return out[::-1]

    def depth(self) -> np.ndarray:
        d = np.zeros(self.num_joints, dtype=int)
        for j, p in enumerate(self.parents):
            d[j] = 0 if p < 0 else d[p] + 1
        return d

    # -- rest pose ------------------------------------------------------------
    def rest_positions(self) -> np.ndarray:
        """``(J, 3)`` world positions with every local rotation at identity."""
        pos = np.zeros((self.num_joints, 3))
        for j, p in enumerate(self.parents):
            pos[j] = self.offsets[j] if p < 0 else pos[p] + self.offsets[j]
        return pos

    def height(self) -> float:
        """Vertical (Z) extent of the rest pose in metres."""
        z = self.rest_positions()[:, 2]
        return float(z.max() - z.min()) if z.size else 0.0

    def subset(self, keep: Sequence[int]) -> "Skeleton":
        """A skeleton of the joints ``keep`` (sorted), each re-parented to its
        nearest kept ancestor with the offsets summed along the removed chain."""
        keep = sorted(set(int(k) for k in keep))
        rest = self.rest_positions()
        new_index = {old: new for new, old in enumerate(keep)}
        parents, offsets = [], []
        for old in keep:
            p = int(self.parents[old])
            while p >= 0 and p not in new_index:
                p = int(self.parents[p])
            parents.append(-1 if p < 0 else new_index[p])
            offsets.append(rest[old] if p < 0 else rest[old] - rest[p])
        return Skeleton(
            names=tuple(self.names[k] for k in keep),
            parents=np.array(parents, dtype=np.int64),
            offsets=np.array(offsets),
            end_site=self.end_site[keep],
        )


#: Frames forward kinematics works on at a time: its temporaries (local translations, the
#: float64 copy of a float32 clip, each depth's products) are this many frames, not the clip.
FK_CHUNK_FRAMES = 4096


def forward_kinematics(
    skeleton: Skeleton,
    rotations: np.ndarray,
    translations: np.ndarray | None = None,
    translated: np.ndarray | None = None,
    *,
    with_rotations: bool = True,
) -> tuple[np.ndarray, np.ndarray | None]:
    """World positions and rotations of every joint, vectorised over frames.

    Frames are independent, so they are computed :data:`FK_CHUNK_FRAMES` at a time (the
    same operations on each frame, so the same numbers as one pass over the clip).

    Args:
        skeleton: The skeleton (offsets in metres).
        rotations: ``(F, J, 4)`` local rotations, x-y-z-w.
        translations: ``(F, K, 3)`` animated local translations in metres.
        translated: ``(K,)`` joint indices that ``translations`` belong to.
        with_rotations: False returns None for the world rotations (they are then only
            held a chunk at a time).

    Returns:
        ``(positions (F, J, 3), world_rotations (F, J, 4) or None)``, float64.
    """
    F, J = np.shape(rotations)[:2]
    pos = np.empty((F, J, 3))
    wrot = np.empty((F, J, 4)) if with_rotations else None
    moved = translations is not None and translated is not None and len(translated)
    for s in range(0, F, FK_CHUNK_FRAMES):
        e = min(F, s + FK_CHUNK_FRAMES)
        tra = translations[s:e] if moved else None  # type: ignore[index]
        chunk_rot = None if wrot is None else wrot[s:e]
        _fk_chunk(skeleton, np.asarray(rotations[s:e], dtype=float), tra, translated, pos[s:e], chunk_rot)
        release(rotations)  # a spilled clip (a long BVH's): the frames read leave the memory
    return pos, wrot


def _fk_chunk(
    skeleton: Skeleton,
    rotations: np.ndarray,
    translations: np.ndarray | None,
    translated: np.ndarray | None,
    pos: np.ndarray,
    wrot: np.ndarray | None,
) -> None:
    """Forward kinematics of a few frames into ``pos`` (and ``wrot`` if given):
    one vectorised pass per tree depth (all joints of a depth at once)."""
    n, J = rotations.shape[:2]
    local_t = np.broadcast_to(skeleton.offsets, (n, J, 3)).copy()
    if translations is not None:
        local_t[:, np.asarray(translated, dtype=int)] = translations
    wrot = np.empty((n, J, 4)) if wrot is None else wrot
    if n == 1:  # a stream's frame: joint by joint on Python floats (a fifth of the time)
        _fk_frame(skeleton, rotations[0], local_t[0], pos[0], wrot[0])
        return
    for level, (idx, par) in enumerate(_depth_levels(skeleton)):
        if level == 0:
            pos[:, idx] = local_t[:, idx]
            wrot[:, idx] = rotations[:, idx]
        else:
            pos[:, idx] = pos[:, par] + quat_apply(wrot[:, par], local_t[:, idx])
            wrot[:, idx] = quat_mul(wrot[:, par], rotations[:, idx])


def _fk_frame(skeleton: Skeleton, rotations: np.ndarray, local_t: np.ndarray, pos: np.ndarray, wrot: np.ndarray) -> None:
    """Forward kinematics of one frame into ``pos`` ``(J, 3)`` and ``wrot`` ``(J, 4)``: the
    products of :func:`_fk_chunk`, in the same order, joint by joint on Python floats
    (:func:`~physmocap.rotations.hamilton`, :func:`~physmocap.rotations.rotate`): the same
    numbers without numpy's overhead on a few joints at a time."""
    R, T = rotations.tolist(), local_t.tolist()
    P: list = [None] * len(R)
    W: list = [None] * len(R)
    for level, (idx, par) in enumerate(_depth_levels(skeleton)):
        for j, p in zip(idx.tolist(), par.tolist()):
            if level == 0:
                P[j], W[j] = T[j], R[j]
            else:
                d = rotate(W[p], T[j])
                q = P[p]
                P[j] = [q[0] + d[0], q[1] + d[1], q[2] + d[2]]
                W[j] = hamilton(W[p], R[j])
    pos[:] = P
    wrot[:] = W


def _depth_levels(skeleton: Skeleton) -> list[tuple[np.ndarray, np.ndarray]]:
    """``[(joints, their parents)]`` per tree depth, roots first (cached on the skeleton)."""
    cached = skeleton.__dict__.get("_levels")
    if cached is None:
        depth = skeleton.depth()
        cached = []
        for d in range(int(depth.max()) + 1 if depth.size else 0):
            idx = np.flatnonzero(depth == d)
            cached.append((idx, skeleton.parents[idx]))
        object.__setattr__(skeleton, "_levels", cached)
    return cached


@dataclass(eq=False)
class Motion:
    """A skeleton animated over frames (see the module docstring).

    Attributes:
        skeleton: The joints.
        fps: Frames per second.
        rotations: ``(F, J, 4)`` local rotations x-y-z-w (rotational motions), or None.
        translations: ``(F, K, 3)`` local translations in metres of the joints
            in ``translated`` (rotational motions), or None.
        translated: ``(K,)`` indices of the joints that have animated translations.
        positions: ``(F, J, 3)`` world positions in metres (positional motions), or None.
        confidence: ``(F, J)`` per-joint confidence in [0, 1] (positional), or None.
        source: Where the motion came from (a path), for messages.
        units: Name of the file's length unit (``"m"``, ``"cm"``, ``"inch"``, ``"cmu"``...).
        unit_scale: Metres per file unit.
        file_up: The file's up axis (``"Y"`` or ``"Z"``), so writers can restore it.
        meta: Free-form extra information from the source (JSON-serialisable).
    """

    skeleton: Skeleton
    fps: float
    rotations: np.ndarray | None = None
    translations: np.ndarray | None = None
    translated: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    positions: np.ndarray | None = None
    confidence: np.ndarray | None = None
    source: str = "<memory>"
    units: str = "m"
    unit_scale: float = 1.0
    file_up: str = "Z"
    meta: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        J = self.skeleton.num_joints
        if not (np.isfinite(self.fps) and self.fps > 0):
            raise ValueError(f"fps must be positive and finite, got {self.fps}")
        self.translated = np.asarray(self.translated, dtype=np.int64).reshape(-1)
        if (self.rotations is None) == (self.positions is None):
            raise ValueError("a Motion has either rotations or positions (exactly one)")
        if self.rotations is not None:
            self.rotations = _floats(self.rotations)
            if self.rotations.ndim != 3 or self.rotations.shape[1:] != (J, 4):
                raise ValueError(f"rotations must be (F, {J}, 4), got {self.rotations.shape}")
            F = self.rotations.shape[0]
            if self.translations is None:
                self.translations = np.zeros((F, 0, 3))
                self.translated = np.zeros(0, dtype=np.int64)
            self.translations = _floats(self.translations)
            K = len(self.translated)
            if self.translations.shape != (F, K, 3):
                raise ValueError(
                    f"translations must be (F={F}, K={K}, 3), got {self.translations.shape}"
                )
        else:
            self.positions = np.asarray(self.positions, dtype=float)
            if self.positions.ndim != 3 or self.positions.shape[1:] != (J, 3):
                raise ValueError(f"positions must be (F, {J}, 3), got {self.positions.shape}")
            if self.confidence is not None:
                self.confidence = np.asarray(self.confidence, dtype=float)
                if self.confidence.shape != self.positions.shape[:2]:
                    raise ValueError("confidence must be (F, J)")

    # -- basic facts ----------------------------------------------------------
    @property
    def is_rotational(self) -> bool:
        return self.rotations is not None

    @property
    def num_frames(self) -> int:
        arr = self.rotations if self.rotations is not None else self.positions
        assert arr is not None
        return int(arr.shape[0])

    @property
    def dt(self) -> float:
        return 1.0 / self.fps

    @property
    def duration(self) -> float:
        """Seconds from the first to one frame past the last frame."""
        return self.num_frames / self.fps

    # -- kinematics -------------------------------------------------------------
    def forward_kinematics(self) -> tuple[np.ndarray, np.ndarray | None]:
        """``(positions (F, J, 3), world rotations (F, J, 4) or None)``."""
        if self.rotations is None:
            assert self.positions is not None
            return self.positions, None
        return forward_kinematics(self.skeleton, self.rotations, self.translations, self.translated)

    def world_positions(self) -> np.ndarray:
        """``(F, J, 3)`` world positions in metres, Z-up (world rotations computed a chunk of
        frames at a time and not kept)."""
        if self.rotations is None:
            assert self.positions is not None
            return self.positions
        return forward_kinematics(
            self.skeleton, self.rotations, self.translations, self.translated, with_rotations=False
        )[0]

    def joint_world_positions(self, joints: Sequence[int], block: int = WORLD_BLOCK_FRAMES) -> tuple[np.ndarray, dict[int, int]]:
        """World positions of some joints: ``(positions (F, K, 3) metres Z-up, joint index ->
        column of it)``.

        A rotational motion's forward kinematics runs ``block`` frames at a time and keeps
        only the ``joints`` asked for (the same values as :meth:`world_positions`, without its
        whole ``(F, J, 3)``), laid out joint by joint, in a temporary file for a long clip
        (:func:`~physmocap.spill.spilled_empty`; each block's pages let go once written), so
        a reader of a few joints maps in only theirs; a positional motion's positions are
        returned as they are (not a copy: do not write into them).
        """
        if self.rotations is None:
            return self.world_positions(), {int(j): int(j) for j in joints}
        wanted = sorted(set(int(j) for j in joints))
        F = self.num_frames
        out = spilled_empty((F, len(wanted), 3), by_column=True)
        for start in range(0, F, block):
            end = min(start + block, F)
            out[start:end] = self.slice_frames(start, end).world_positions()[:, wanted]
            release(out)
        return out, {j: k for k, j in enumerate(wanted)}

    def world_rotations(self) -> np.ndarray | None:
        """``(F, J, 4)`` world rotations x-y-z-w, or None for positional motions."""
        return self.forward_kinematics()[1]

    def floor_height(self, percentile: float = 5.0) -> float:
        """Robust floor estimate: a low percentile of the per-frame lowest joint height.

        The single lowest sample is often an outlier (a glitching toe); a low
        percentile of the per-frame minimum is not.  A source that established
        the floor itself (a tracker levelled on its feet, whose lowest joints
        are ankles above the floor) records its height as ``meta["floor_z"]``,
        which is returned instead.  The world positions are computed
        :data:`WORLD_BLOCK_FRAMES` frames at a time (the same values as one pass).
        """
        if "floor_z" in self.meta:
            return float(self.meta["floor_z"])
        F = self.num_frames
        lowest = np.empty(F)
        for start in range(0, F, WORLD_BLOCK_FRAMES):
            end = min(start + WORLD_BLOCK_FRAMES, F)
            z = self.slice_frames(start, end).world_positions()[..., 2]
            if self.positions is not None:
                z = np.where(np.isfinite(z), z, np.inf)
            lowest[start:end] = z.min(axis=1)
        lowest = lowest[np.isfinite(lowest)]
        if lowest.size == 0:
            return 0.0
        return float(np.percentile(lowest, percentile))

    # -- editing ----------------------------------------------------------------
    def replace(self, **changes) -> "Motion":
        return dataclasses.replace(self, **changes)

    def slice_frames(self, start: int = 0, end: int | None = None) -> "Motion":
        """Frames ``[start, end)`` (Python slice semantics, end exclusive)."""
        F = self.num_frames
        end = F if end is None else end
        if not (0 <= start < end <= F):
            raise ValueError(f"frame range [{start}, {end}) is outside the clip's 0..{F}")
        s = slice(start, end)
        if self.rotations is not None:
            assert self.translations is not None
            return self.replace(rotations=self.rotations[s], translations=self.translations[s])
        assert self.positions is not None
        conf = None if self.confidence is None else self.confidence[s]
        return self.replace(positions=self.positions[s], confidence=conf)

    def resample(self, fps: float) -> "Motion":
        """Resample to ``fps``: slerp for rotations, linear for translations/positions.

        The new clip covers the same time span ``[0, (F-1)/fps_old]``.
        """
        if not (np.isfinite(fps) and 0 < fps <= MAX_FPS):
            from .errors import OptionError

            raise OptionError(f"the frame rate must be a number in (0, {MAX_FPS:g}] frames/s, got {fps:g}", path=self.source)
        F = self.num_frames
        t_old = np.arange(F) / self.fps
        n_new = int(np.floor((F - 1) * fps / self.fps + 1e-9)) + 1
        t_new = np.arange(n_new) / fps
        t_new = np.minimum(t_new, t_old[-1])
        i0 = np.clip(np.searchsorted(t_old, t_new, side="right") - 1, 0, max(F - 2, 0))
        i1 = np.minimum(i0 + 1, F - 1)
        span = np.where(i1 > i0, t_old[i1] - t_old[i0], 1.0)
        w = np.clip((t_new - t_old[i0]) / span, 0.0, 1.0)

        def lerp(a: np.ndarray) -> np.ndarray:
            wb = w.reshape(-1, *([1] * (a.ndim - 1)))
            return a[i0] * (1.0 - wb) + a[i1] * wb

        if self.rotations is not None:
            assert self.translations is not None
            q0 = self.rotations[i0]
            q1 = self.rotations[i1]
            rot = _slerp(q0, q1, w[:, None])
            return self.replace(fps=float(fps), rotations=rot, translations=lerp(self.translations))
        assert self.positions is not None
        conf = None if self.confidence is None else lerp(self.confidence)
        return self.replace(fps=float(fps), positions=lerp(self.positions), confidence=conf)


def _floats(a) -> np.ndarray:
    """A float array, keeping float32 (long clips are stored compactly) and float64."""
    a = np.asarray(a)
    return a if a.dtype in (np.float32, np.float64) else a.astype(np.float64)


def _slerp(q0: np.ndarray, q1: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Spherical linear interpolation between xyzw quaternion arrays (shortest arc)."""
    dot = np.sum(q0 * q1, axis=-1)
    q1 = np.where((dot < 0)[..., None], -q1, q1)
    dot = np.abs(dot)
    theta = np.arccos(np.clip(dot, -1.0, 1.0))
    sin_t = np.sin(theta)
    small = sin_t < 1e-9
    safe = np.where(small, 1.0, sin_t)
    a = np.where(small, 1.0 - w, np.sin((1.0 - w) * theta) / safe)
    b = np.where(small, w, np.sin(w * theta) / safe)
    q = a[..., None] * q0 + b[..., None] * q1
    return q / np.linalg.norm(q, axis=-1, keepdims=True)
