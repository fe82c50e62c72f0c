"""Write BVH (Biovision Hierarchy) files.

Two levels:

* :func:`write_bvh` writes a rotational :class:`~physmocap.motion.Motion`.  By
  default it restores what the source file had: its channel layout and rotation
  orders (``motion.meta["bvh_channels"]``, recorded by the reader), its length
  unit and its up axis, so reading a file and writing it back reproduces it to
  the printed precision.  Options choose another rotation order, unit, up axis
  or precision.
* :func:`write_bvh_channels` writes a BVH from precomputed parts (names,
  parents, offsets and channel values already in the file's units and axes),
  for exporters that compute their own channels.

The maths (the inverse of :mod:`physmocap.sources.bvh`): with ``M`` the signed
axis permutation from the world (Z-up) to the file's up axis and ``s`` metres
per file unit, offsets and translations are written as ``M t / s`` and a local
rotation ``R`` as the intrinsic Euler angles, in degrees, of ``M R M^T``
(for a quaternion: ``(M v, w)``).  Angles are made continuous from frame to
frame with :func:`~physmocap.rotations.unwrap_euler` (no 360-degree jumps, and
the branch of the decomposition that stays closest to the previous frame).

Every number is printed with ``precision`` decimals after rounding (negative
zero printed as ``0``), so the same motion and options give the same bytes.
Files are written atomically (:func:`~physmocap.fileio.atomic_open`) and
non-finite values are refused before anything is written.
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from ..errors import OptionError, OutputError, warn
from ..fileio import atomic_open, check_writable
from ..motion import Motion, Skeleton
from ..rotations import quat_to_euler, unwrap_euler, up_axis_matrix
from ..sources.bvh import CHANNEL_NAMES, axis_permutation, resolve_units

__all__ = [
    "write_bvh",
    "write_bvh_channels",
    "write_bvh_rows",
    "bvh_channel_layout",
    "check_bvh_options",
    "DEFAULT_ROTATION_ORDER",
]

#: Rotation order of joints whose layout is not known (MotionBuilder's default).
DEFAULT_ROTATION_ORDER = "ZXY"

#: Frames formatted per write call (bounds the size of the text buffer).
_ROWS_PER_BLOCK = 2048


def _check_order(order: str) -> str:
    o = str(order).strip().upper()
    if len(o) != 3 or sorted(o) != ["X", "Y", "Z"]:
        raise OptionError(
            f"rotation order must be a permutation of XYZ (e.g. ZXY, ZYX, XYZ), got {order!r}"
        )
    return o


def _check_precision(precision: int) -> int:
    if isinstance(precision, bool) or not isinstance(precision, (int, np.integer)) or not 0 <= precision <= 15:
        raise OptionError(f"precision must be a whole number of decimals from 0 to 15, got {precision!r}")
    return int(precision)


def check_bvh_options(
    rotation_order: str | None = None,
    precision: int = 6,
    units: str | float | None = None,
    up: str | None = None,
) -> None:
    """Raise :class:`~physmocap.errors.OptionError` for options :func:`write_bvh`
    would refuse (so a command can fail before reading a long input)."""
    if rotation_order is not None:
        _check_order(rotation_order)
    _check_precision(precision)
    if units is not None:
        resolve_units(units)
    if up is not None and str(up).strip().upper() not in ("Y", "Z"):
        raise OptionError(f"up axis must be 'Y' or 'Z', got {up!r}")


def bvh_channel_layout(
    motion: Motion, rotation_order: str | None = None
) -> list[list[str]]:
    """The channel list each joint is written with, before widening.

    With ``rotation_order`` None, a joint keeps the channels the source file
    gave it (``motion.meta["bvh_channels"]``); a joint the meta does not know
    gets its position channels (if it is in ``motion.translated``) then three
    rotation channels in :data:`DEFAULT_ROTATION_ORDER`.  With a
    ``rotation_order``, every joint gets its position channels then three
    rotation channels in that order.  End sites (leaves marked ``end_site``)
    have none.  Position channels are only kept for joints that have animated
    translations.
    """
    known = motion.meta.get("bvh_channels") if isinstance(motion.meta, dict) else None
    return _channel_layout(motion.skeleton, motion.translated, known if isinstance(known, dict) else {}, rotation_order)


def _channel_layout(sk: Skeleton, translated_joints: np.ndarray, known: dict, rotation_order: str | None) -> list[list[str]]:
    """:func:`bvh_channel_layout` from its parts: the skeleton, the joints with animated
    translations and the known channel lists (joint name -> channels)."""
    translated = set(int(k) for k in translated_joints)
    has_children = np.zeros(sk.num_joints, dtype=bool)
    has_children[sk.parents[sk.parents >= 0]] = True
    layout: list[list[str]] = []
    for j, name in enumerate(sk.names):
        if sk.end_site[j] and not has_children[j]:
            layout.append([])
            continue
        orig = known.get(name)
        orig = [c for c in orig if c in CHANNEL_NAMES] if isinstance(orig, list) else None
        if orig is not None:
            pos = [c for c in orig if c.endswith("position")] if j in translated else []
            if not pos and j in translated:
                pos = ["Xposition", "Yposition", "Zposition"]
        else:
            pos = ["Xposition", "Yposition", "Zposition"] if j in translated else []
        if rotation_order is not None:
            rot = [f"{a}rotation" for a in _check_order(rotation_order)]
            layout.append(pos + rot)
        elif orig is not None:
            kept = [c for c in orig if c.endswith("rotation") or c in pos]
            kept += [c for c in pos if c not in kept]
            layout.append(kept)
        else:
            layout.append(pos + [f"{a}rotation" for a in DEFAULT_ROTATION_ORDER])
    return layout


def write_bvh(
    motion: Motion,
    path: str | os.PathLike,
    rotation_order: str | None = None,
    precision: int = 6,
    units: str | float | None = None,
    up: str | None = None,
) -> Path:
    """Write a rotational motion as a BVH file.

    Args:
        motion: A rotational motion (positional motions have no joint rotations
            to write; retarget them first).
        path: Output ``.bvh`` path, written atomically.
        rotation_order: Intrinsic Euler order for every joint (``"ZXY"``...);
            None keeps each joint's order from the source file
            (``motion.meta["bvh_rotation_orders"]``), else ``ZXY``.
        precision: Decimals printed for every number (0-15).
        units: Length unit of the file (name or metres per unit); None writes
            the motion's own ``units``/``unit_scale`` (the source file's).
        up: ``"Y"`` or ``"Z"``; None writes ``motion.file_up`` for a motion read
            from a BVH file and ``"Y"`` (the BVH convention) otherwise.

    A joint whose source layout cannot hold its motion is widened, with a
    warning: missing rotation axes are added when the motion rotates about
    them, missing position components when its translation leaves the offset
    on them (e.g. after changing the up axis).

    Frames are converted and written in blocks, so memory stays a few MB
    above the motion itself however long the clip.

    Raises:
        OptionError: Bad options or a motion without rotations.
        OutputError: Non-finite values, or the path cannot be written.
    """
    path = Path(path)
    precision = _check_precision(precision)
    if rotation_order is not None:
        rotation_order = _check_order(rotation_order)
    if not motion.is_rotational:
        raise OptionError(
            "a BVH file needs joint rotations but this motion has positions only "
            "(retarget it onto a character first)",
            path=path,
        )
    if units is None:
        unit_scale = float(motion.unit_scale)
        if not (np.isfinite(unit_scale) and unit_scale > 0):
            raise OptionError(f"the motion's unit_scale {motion.unit_scale!r} is not a positive number", path=path)
    else:
        _, unit_scale = resolve_units(units, path)
    if up is None:
        is_bvh = isinstance(motion.meta, dict) and motion.meta.get("format") == "bvh"
        up = motion.file_up if is_bvh and str(motion.file_up).upper() in ("Y", "Z") else "Y"
    up = str(up).strip().upper()
    if up not in ("Y", "Z"):
        raise OptionError(f"up axis must be 'Y' or 'Z', got {up!r}", path=path)
    check_writable(path)

    sk = motion.skeleton
    assert motion.rotations is not None and motion.translations is not None
    if not np.all(np.isfinite(sk.offsets)):
        j = int(np.flatnonzero(~np.isfinite(sk.offsets).all(axis=1))[0])
        raise OutputError(f"offset of joint {sk.names[j]!r} is not finite; refusing to write it", path=path)
    F = motion.num_frames
    for s in range(0, F, 1 << 16):  # refuse non-finite values before anything else
        _check_block(motion.rotations[s : s + (1 << 16)], motion.translations[s : s + (1 << 16)],
                     motion.translated, sk.names, s, path)
    conv = _Converter(sk, motion.translated, up, unit_scale, precision)
    layout, plans, widened = conv.plan(bvh_channel_layout(motion, rotation_order), rotation_order,
                                       motion.rotations, motion.translations)
    if widened:
        warn(
            f"{path}: the source channel layout cannot hold this motion for "
            + ", ".join(widened)
            + "; added those channels"
        )
    rows = (lambda s, e: (motion.rotations[s:e], motion.translations[s:e]))  # type: ignore[index]
    return _write_frames(path, conv, layout, plans, F, motion.fps, rows, precision)


def _write_frames(path: Path, conv: "_Converter", layout: list[list[str]], plans, frames: int, fps: float,
                  rows: Callable[[int, int], tuple[np.ndarray, np.ndarray]], precision: int) -> Path:
    """The header, then the rows of ``frames`` frames, :data:`_ROWS_PER_BLOCK` at a time:
    ``rows(s, e)`` gives frames ``[s, e)`` (local rotations, translations, world axes, metres)."""
    sk = conv.skeleton
    header, dfs = _hierarchy(sk.names, sk.parents, conv.offsets, sk.end_site, layout, precision)
    columns = [(j, c) for j in dfs for c in layout[j]]
    with atomic_open(path, "w") as fh:
        fh.write(_header_text(header, frames, 1.0 / fps))
        for s in range(0, frames, _ROWS_PER_BLOCK):
            rot, tra = rows(s, min(frames, s + _ROWS_PER_BLOCK))
            fh.write(_format_rows(conv.block(rot, tra, plans, columns), precision))
    return path


def write_bvh_rows(
    path: str | os.PathLike,
    skeleton: Skeleton,
    translated: np.ndarray,
    channels: dict[str, list[str]],
    frames: int,
    fps: float,
    rows: Callable[[int, int], tuple[np.ndarray, np.ndarray]],
    precision: int = 6,
    units: str | float = "m",
    up: str = "Y",
) -> Path:
    """Write a rotational motion that is never held whole, as BVH (atomically).

    ``rows(s, e)`` gives frames ``[s, e)``: ``(local rotations (n, J, 4) x-y-z-w,
    translations (n, K, 3) in metres of the joints in ``translated``)``, world (Z-up)
    axes, as :class:`~physmocap.motion.Motion` holds them; it is called once per block of
    :data:`_ROWS_PER_BLOCK` frames, in order.  ``channels`` gives every joint with
    channels its full channel list (three rotations; three positions on translated
    joints), so no frame has to be seen before writing.  The bytes are those
    :func:`write_bvh` writes for the same motion with ``meta["bvh_channels"] = channels``.
    Non-finite values are refused block by block; the file is only renamed into place
    once every block is written.

    Raises:
        OptionError: A layout that would need widening (an incomplete channel list).
        OutputError: Non-finite values, or the path cannot be written.
    """
    path = Path(path)
    precision = _check_precision(precision)
    _, unit_scale = resolve_units(units, path)
    up = str(up).strip().upper()
    if up not in ("Y", "Z"):
        raise OptionError(f"up axis must be 'Y' or 'Z', got {up!r}", path=path)
    check_writable(path)
    if not np.all(np.isfinite(skeleton.offsets)):
        j = int(np.flatnonzero(~np.isfinite(skeleton.offsets).all(axis=1))[0])
        raise OutputError(f"offset of joint {skeleton.names[j]!r} is not finite; refusing to write it", path=path)
    translated = np.asarray(translated, dtype=np.int64).reshape(-1)
    conv = _Converter(skeleton, translated, up, unit_scale, precision)
    layout, plans, _ = conv.plan(_channel_layout(skeleton, translated, channels, None), None, None, None)

    def checked(s: int, e: int) -> tuple[np.ndarray, np.ndarray]:
        rot, tra = rows(s, e)
        _check_block(rot, tra, translated, skeleton.names, s, path)
        return rot, tra

    return _write_frames(path, conv, layout, plans, frames, fps, checked, precision)


class _Converter:
    """World-frame motion to file channels (units, axes, Euler angles), block by block."""

    def __init__(self, skeleton: Skeleton, translated: np.ndarray, up: str, unit_scale: float, precision: int) -> None:
        self.skeleton = skeleton
        self.perm, self.sign = axis_permutation(up_axis_matrix("Z", up))
        self.scale = unit_scale
        self.offsets = skeleton.offsets[:, self.perm] * self.sign / unit_scale
        self.tol = 0.5 * 10.0 ** (-precision)
        self.t_index = {int(k): i for i, k in enumerate(translated)}
        self.last: dict = {}  # continuity state between blocks

    def quats(self, q: np.ndarray) -> np.ndarray:
        """World-axis quaternions to file axes: ``(M v, w)``."""
        return np.concatenate([q[..., :3][..., self.perm] * self.sign, q[..., 3:]], axis=-1)

    def translations(self, tra: np.ndarray, k: int) -> np.ndarray:
        """Translations ``(n, K, 3)`` of joint slot ``k`` in file axes and units ``(n, 3)``."""
        return tra[:, k][:, self.perm] * self.sign / self.scale

    def plan(self, layout: list[list[str]], rotation_order: str | None, rot: np.ndarray | None, tra: np.ndarray | None):
        """Final channel lists (widened where the motion ``rot``, ``tra`` (whole clip) needs
        it) and, per joint, ``(padded rotation order or None, number of rotation axes
        written)``.  Without the motion (None) the layout must be complete.

        Raises:
            OptionError: No motion given and a joint's channel list is incomplete.
        """
        sk = self.skeleton
        F = 0 if rot is None else rot.shape[0]
        widened: list[str] = []
        plans: list[tuple[str | None, int]] = []
        out: list[list[str]] = []
        for j, chans in enumerate(layout):
            chans = list(chans)
            name = sk.names[j]
            axes = [c[0] for c in chans if c.endswith("rotation")]
            present = {c[0] for c in chans if c.endswith("position")}
            complete = len(axes) == 3 or (not chans and sk.end_site[j])
            complete &= j not in self.t_index or len(present) == 3
            if rot is None and not complete:
                raise OptionError(f"joint {name!r} needs three rotation (and position) channels to be written in blocks")
            if not axes and (chans or not sk.end_site[j]) and F:
                w = np.clip(np.abs(rot[:, j, 3]) / np.linalg.norm(rot[:, j], axis=-1).clip(1e-300), 0.0, 1.0)
                if np.degrees(2.0 * np.arccos(w.min())) > self.tol:
                    axes = list(rotation_order or DEFAULT_ROTATION_ORDER)
                    chans += [f"{a}rotation" for a in axes]
                    widened.append(f"{name} (rotation)")
            order = "".join(axes) + "".join(a for a in "XYZ" if a not in axes) if axes else None
            k = len(axes)
            if order is not None and k < 3 and F:
                if _subset_euler(self.quats(rot[:, j]), order, k, self.tol) is None:
                    chans += [f"{a}rotation" for a in order[k:]]
                    widened.append(f"{name} (rotation)")
                    k = 3
            if j in self.t_index and F and len(present) < 3:
                t = self.translations(tra, self.t_index[j])
                for a, axis in enumerate("XYZ"):
                    if axis not in present and np.abs(t[:, a] - self.offsets[j, a]).max() > self.tol:
                        chans.append(f"{axis}position")
                        widened.append(f"{name} ({axis}position)")
            out.append(chans)
            plans.append((order, k))
        return out, plans, widened

    def block(self, rot: np.ndarray, tra: np.ndarray, plans, columns) -> np.ndarray:
        """Channel values of consecutive frames (rotations ``rot (n, J, 4)``, translations
        ``tra (n, K, 3)``, the frames after the previous block), columns in file
        (depth-first) order."""
        euler: dict[int, np.ndarray] = {}
        groups: dict[str, list[int]] = {}
        for j, (order, k) in enumerate(plans):
            if order is None:
                continue
            if k == 3:
                groups.setdefault(order, []).append(j)
            else:
                ang = _subset_euler(self.quats(rot[:, j]), order, k, np.inf)
                assert ang is not None
                prev = self.last.get(("sub", j))
                if prev is not None:
                    ang[:, :k] = np.unwrap(np.concatenate([prev[None, :k], ang[:, :k]]), period=360.0, axis=0)[1:]
                self.last[("sub", j)] = ang[-1]
                euler[j] = ang
        for order, js in groups.items():
            with warnings.catch_warnings():
                warnings.filterwarnings("ignore", message="Gimbal lock")  # both solutions are exact
                ang = quat_to_euler(self.quats(rot[:, js]), order, degrees=True)
            prev = self.last.get(("grp", order))
            if prev is not None:
                ang = unwrap_euler(np.concatenate([prev[None], ang]), order, degrees=True)[1:]
            else:
                ang = unwrap_euler(ang, order, degrees=True)
            self.last[("grp", order)] = ang[-1]
            for i, j in enumerate(js):
                euler[j] = ang[:, i]
        block = np.empty((rot.shape[0], len(columns)))
        trans: dict[int, np.ndarray] = {}
        for c, (j, ch) in enumerate(columns):
            axis = "XYZ".index(ch[0])
            if ch.endswith("position"):
                if j not in self.t_index:
                    block[:, c] = self.offsets[j, axis]
                    continue
                if j not in trans:
                    trans[j] = self.translations(tra, self.t_index[j])
                block[:, c] = trans[j][:, axis]
            else:
                block[:, c] = euler[j][:, plans[j][0].index(ch[0])]
        return block


def _check_block(rot: np.ndarray, tra: np.ndarray, translated: np.ndarray, names, s: int, path: Path) -> None:
    for what, arr, joints in (("rotation", rot, None), ("translation", tra, translated)):
        bad = ~np.isfinite(arr).all(axis=-1)
        if bad.any():
            f, k = (int(v) for v in np.argwhere(bad)[0])
            j = k if joints is None else int(joints[k])
            raise OutputError(f"{what} of joint {names[j]!r} is not finite; refusing to write it",
                              path=path, frame=s + f)
    small = np.einsum("...i,...i->...", rot, rot) < 1e-12
    if small.any():
        f, j = (int(v) for v in np.argwhere(small)[0])
        raise OutputError(f"rotation of joint {names[j]!r} is a zero quaternion; refusing to write it",
                          path=path, frame=s + f)


def _wrap180(a: np.ndarray) -> np.ndarray:
    return (a + 180.0) % 360.0 - 180.0


def _subset_euler(q: np.ndarray, order: str, k: int, tol: float) -> np.ndarray | None:
    """Angles ``(F, 3)`` in degrees for a joint whose file layout has only the
    first ``k`` axes of ``order``: per frame, the one of the two Euler solutions
    ``(a, b, c)`` and ``(a + 180, 180 - b, c + 180)`` whose missing angles are
    zero (mod 360), then the present angles made continuous.  None if the
    rotations need the missing axes (beyond ``tol`` degrees)."""
    e = quat_to_euler(q, order, degrees=True)
    alt = e + np.array([180.0, 0.0, 180.0])
    alt[:, 1] = 180.0 - e[:, 1]
    cost_e = np.abs(_wrap180(e[:, k:])).sum(axis=-1)
    cost_alt = np.abs(_wrap180(alt[:, k:])).sum(axis=-1)
    pick = np.where((cost_alt < cost_e)[:, None], alt, e)
    if np.abs(_wrap180(pick[:, k:])).max() > tol:
        return None
    out = np.zeros_like(pick)
    out[:, :k] = np.unwrap(_wrap180(pick[:, :k]), period=360.0, axis=0)
    return out


def _fmt(x: float, precision: int) -> str:
    v = round(float(x), precision) + 0.0
    return f"{v:.{precision}f}"


def write_bvh_channels(
    path: str | os.PathLike,
    names: Sequence[str],
    parents: Sequence[int] | np.ndarray,
    offsets: np.ndarray,
    end_site: Sequence[bool] | np.ndarray,
    channels: Sequence[Sequence[str]],
    data: np.ndarray,
    frame_time: float,
    precision: int = 6,
) -> Path:
    """Write a BVH file from precomputed parts (nothing is converted).

    Args:
        path: Output path (written atomically).
        names: ``J`` joint names (no whitespace-only names, no braces).
        parents: ``(J,)`` parent index, ``-1`` for roots, ``parents[j] < j``.
        offsets: ``(J, 3)`` offsets in the file's units and axes.
        end_site: ``(J,)`` True for end sites: leaves written as ``End Site``
            (they must have no channels).  Other leaves are written as joints.
        channels: Per joint, its channel names (from
            :data:`~physmocap.sources.bvh.CHANNEL_NAMES`, each at most once),
            in the order they are written.
        data: ``(F, C)`` channel values, ``C`` = total number of channels,
            columns grouped by joint in *joint index* order and within a joint
            in ``channels`` order; angles in degrees.  The hierarchy is written
            depth-first, and the columns are reordered to match it.
        frame_time: Seconds per frame.
        precision: Decimals printed for every number.

    Returns:
        The path written.
    """
    path = Path(path)
    precision = _check_precision(precision)
    names = [str(n) for n in names]
    J = len(names)
    parents = np.asarray(parents, dtype=np.int64).reshape(-1)
    offsets = np.asarray(offsets, dtype=float).reshape(-1, 3)
    end_site = np.asarray(end_site, dtype=bool).reshape(-1)
    data = np.asarray(data, dtype=float)
    if J == 0:
        raise OptionError("cannot write a BVH file without joints", path=path)
    if parents.shape != (J,) or offsets.shape != (J, 3) or end_site.shape != (J,) or len(channels) != J:
        raise ValueError("names, parents, offsets, end_site and channels must all have one entry per joint")
    if np.any(parents >= np.arange(J)) or np.any(parents < -1):
        raise ValueError("parents must satisfy -1 <= parents[j] < j")
    for n in names:
        if not n.strip() or any(ch in n for ch in "{}\r\n"):
            raise OutputError(f"joint name {n!r} cannot be written to a BVH file", path=path)
    chans = [list(c) for c in channels]
    children: list[list[int]] = [[] for _ in range(J)]
    for j in range(J):
        if parents[j] >= 0:
            children[int(parents[j])].append(j)
    start = np.zeros(J + 1, dtype=np.int64)
    for j, c in enumerate(chans):
        bad = [x for x in c if x not in CHANNEL_NAMES]
        if bad or len(set(c)) != len(c):
            raise ValueError(f"bad channel list for joint {names[j]!r}: {c}")
        if end_site[j] and not children[j] and c:
            raise ValueError(f"end site {names[j]!r} cannot have channels")
        start[j + 1] = start[j] + len(c)
    C = int(start[-1])
    if data.ndim != 2 or data.shape[1] != C:
        raise ValueError(f"data must be (F, {C}) for these channels, got {data.shape}")
    if not (np.isfinite(frame_time) and frame_time > 0):
        raise OutputError(f"frame time {frame_time!r} is not a positive number of seconds", path=path)
    if not np.all(np.isfinite(offsets)):
        j = int(np.flatnonzero(~np.isfinite(offsets).all(axis=1))[0])
        raise OutputError(f"offset of joint {names[j]!r} is not finite; refusing to write it", path=path)
    if not np.all(np.isfinite(data)):
        f, c = (int(v) for v in np.argwhere(~np.isfinite(data))[0])
        j = int(np.searchsorted(start, c, side="right") - 1)
        raise OutputError(
            f"{names[j]} {chans[j][c - start[j]]} is not finite; refusing to write it", path=path, frame=f
        )

    header, dfs = _hierarchy(names, parents, offsets, end_site, chans, precision)
    cols = np.concatenate([np.arange(start[j], start[j + 1]) for j in dfs]) if dfs else np.zeros(0, int)
    F = data.shape[0]
    with atomic_open(path, "w") as fh:
        fh.write(_header_text(header, F, frame_time))
        for s in range(0, F, _ROWS_PER_BLOCK):
            fh.write(_format_rows(data[s : s + _ROWS_PER_BLOCK][:, cols], precision))
    return path


def _hierarchy(names, parents, offsets, end_site, chans, precision: int) -> tuple[list[str], list[int]]:
    """HIERARCHY lines, depth-first (children in index order), and the order in
    which joints with channels appear (the order of the motion columns)."""
    J = len(names)
    children: list[list[int]] = [[] for _ in range(J)]
    for j in range(J):
        if parents[j] >= 0:
            children[int(parents[j])].append(j)
    lines = ["HIERARCHY"]
    order: list[int] = []
    stack: list[tuple[int, int, bool]] = [(r, 0, False) for r in reversed(np.flatnonzero(np.asarray(parents) < 0).tolist())]
    while stack:
        j, depth, closing = stack.pop()
        ind = "\t" * depth
        if closing:
            lines.append(f"{ind}}}")
            continue
        off = " ".join(_fmt(v, precision) for v in offsets[j])
        if end_site[j] and not children[j]:
            lines += [f"{ind}End Site", f"{ind}{{", f"{ind}\tOFFSET {off}", f"{ind}}}"]
            continue
        kind = "ROOT" if parents[j] < 0 else "JOINT"
        lines += [f"{ind}{kind} {names[j]}", f"{ind}{{", f"{ind}\tOFFSET {off}"]
        lines.append(f"{ind}\tCHANNELS {len(chans[j])}" + "".join(f" {c}" for c in chans[j]))
        order.append(j)
        stack.append((j, depth, True))
        for c in reversed(children[j]):
            stack.append((c, depth + 1, False))
    return lines, order


def _header_text(hierarchy: list[str], frames: int, frame_time: float) -> str:
    return "\n".join(hierarchy + ["MOTION", f"Frames: {frames}", f"Frame Time: {frame_time:.10g}"]) + "\n"


def _format_rows(block: np.ndarray, precision: int) -> str:
    """Rows of ``block`` as text, every number rounded to ``precision`` decimals
    (negative zero printed as 0)."""
    n, C = block.shape
    if C == 0:
        return "\n" * n
    block = np.round(block, precision) + 0.0
    row = " ".join([f"%.{precision}f"] * C) + "\n"
    return (row * n) % tuple(block.ravel().tolist())
